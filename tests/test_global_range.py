"""The third, **global** range of bed-load diffusion (Nikora et al. 2002; issue 20 item 4):
over many rest periods resting grains make ⟨X′²⟩ grow more slowly. ``exponents`` fits it
where a three-segment fit of log⟨X′²⟩ finds a second bend t_g beyond the intermediate range
(``diffusion.global_bend``), and says why not otherwise.

The synthetic walk is a continuous-time random walk seen as a tracer release: every grain
sits still until the release, at the single time origin of the statistics (n_origins=1),
then alternates ballistic flights (duration T ~ U(0.8, 1.2)·τ, streamwise speed
u ~ N(5, 1.5), spanwise w ~ N(0, 0.8)) and rests R with a Pareto density ∝ R^−(1+ν) for
R > R_min, density exponent 1 + ν = 1.3 (infinite mean). With the drift of u, such a walk
gives ⟨X′²⟩ ∝ t^{2ν} at long times (Weeks & Swinney 1998): γx → ν = 0.3 < 0.5. (Time origins
spread over a stationary record do not see this: there the drift makes the rests raise
γx — γx = (3 − α)/2 for rests with tail exponent 1 < α < 2 — so the test uses a release.)
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from saltation.analysis.diffusion import GLOBAL_MIN_BEYOND, GLOBAL_MIN_DROP, exponents, global_bend
from saltation.analysis.variance import make_plan


def ctrw_release(n=300, tau=2.0, dt=0.1, n_samples=20000, nu=0.3, r_min=2.0, rests=True, seed=2):
    """Tracks (particle, t, x, z) of a flight–rest walk released at the first time origin
    of the sampling plan (sample round(0.1 (n_samples − 1))): flights as in the module
    docstring, each followed by a Pareto rest (density exponent 1 + ν, R ≥ r_min) when
    ``rests``, none otherwise (hops back to back: the control)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * dt
    t_rel = make_plan(n_samples, dt, n_origins=1).origins[0] * dt
    tt = np.maximum(t - t_rel, 0.0)  # before the release the grains sit at x = z = 0
    x, z = np.empty((n, n_samples)), np.empty((n, n_samples))
    m = 64
    for p in range(n):
        while True:
            dur = np.zeros(2 * m)
            dur[0::2] = rng.uniform(0.8, 1.2, m) * tau
            if rests:
                dur[1::2] = r_min * (1 + rng.pareto(nu, m))
            u, w = np.zeros(2 * m), np.zeros(2 * m)
            u[0::2], w[0::2] = rng.normal(5.0, 1.5, m), rng.normal(0.0, 0.8, m)
            ends = np.cumsum(dur)
            if ends[-1] > tt[-1]:
                break
            m *= 2
        k = np.searchsorted(ends, tt, side="right")
        s = tt - (ends - dur)[k]
        x[p] = (np.cumsum(u * dur) - u * dur)[k] + u[k] * s
        z[p] = (np.cumsum(w * dur) - w * dur)[k] + w[k] * s
    return pd.DataFrame({"particle": np.repeat(np.arange(n), n_samples), "t": np.tile(t, n), "x": x.ravel(),
                         "z": z.ravel()})


# --------------------------------------------------------------------------- the fit itself
def test_second_bend_of_a_three_regime_power_law():
    """v ∝ t² to 2, t^1.2 to 50, t^0.6 beyond: t_c, t_g within 2 %, the three γ within 0.01;
    a curve with one bend has no global range and says why."""
    t = make_plan(20000, 0.1).lag_times[1:]
    v = np.where(t < 2, t ** 2, 4 * (t / 2) ** 1.2)
    v3 = np.where(t < 50, v, 4 * 25 ** 1.2 * (t / 50) ** 0.6)
    b = global_bend(t, v3)
    assert b["found"], b["reason"]
    assert b["t_c"] == pytest.approx(2.0, rel=0.02) and b["t_g"] == pytest.approx(50.0, rel=0.02)
    np.testing.assert_allclose(b["gammas"], (1.0, 0.6, 0.3), atol=0.01)
    assert b["n_beyond"] >= GLOBAL_MIN_BEYOND
    one = global_bend(t, v)
    assert not one["found"] and f"drop of at least {GLOBAL_MIN_DROP}" in one["reason"]
    late = global_bend(t, np.where(t < 600, v, 4 * 300 ** 1.2 * (t / 600) ** 0.2))  # 0.17 decade beyond
    assert not late["found"] and ("grid point" in late["reason"] or "last" in late["reason"])


# --------------------------------------------------------------------------- synthetic CTRW
def test_ctrw_with_heavy_tailed_rests_has_a_sub_diffusive_global_range():
    tracks = ctrw_release()
    res = exponents(tracks, n_origins=1)
    b = res["global_bend"]
    assert b["found"], b["reason"]
    assert res["windows_from"] == {"local": "crossover", "intermediate": "crossover", "global": "second bend"}
    t_c, t_g = b["t_c"], b["t_g"]
    assert 0.5 < t_c < 4.0  # ballistic flights of ~τ = 2 d/u*
    assert t_g > 10 * t_c and b["ci"][0] > 3 * t_c  # beyond the intermediate range's start
    # the windows: intermediate [3 t_c, t_g], global [t_g, longest lag]
    assert res["windows"]["local"][1] == pytest.approx(0.5 * t_c)
    assert res["windows"]["intermediate"] == pytest.approx((3 * t_c, t_g))
    assert res["windows"]["global"] == pytest.approx((t_g, res.curves["t"].iloc[-1]))
    g = res["global"]
    assert g["gamma_x"] < 0.45 and g["ci_x"][1] < 0.5  # clearly sub-diffusive
    assert res["intermediate"]["gamma_x"] > g["gamma_x"] + 0.1
    assert res["local"]["gamma_x"] == pytest.approx(1.0, abs=0.03)
    tab = res.table
    rows = tab[tab["range"] == "global"]
    assert set(rows["direction"]) == {"x", "z"} and (rows["windows_from"] == "second bend").all()
    assert (tab["t_g"] == t_g).all() and (tab["t_c"] == t_c).all()
    assert (tab["t_g_low"] < t_g).all() and (tab["t_g_high"] > t_g).all()
    # a global window given by the caller is used as given
    fixed = exponents(tracks, n_origins=1, ranges={"global": (100.0, 800.0)}, n_bootstrap=50)
    assert fixed["windows"]["global"] == (100.0, 800.0) and fixed["windows_from"]["global"] == "ranges"


@pytest.mark.parametrize("n_origins", [1, 8])
def test_control_walk_without_rests_has_no_global_range(n_origins):
    """The same flights back to back: ballistic then γ = ½, no second bend; the windows and
    the table are those of the two-range analysis (no t_g columns)."""
    res = exponents(ctrw_release(rests=False, seed=3), n_origins=n_origins)
    b = res["global_bend"]
    assert not b["found"] and b["reason"]
    assert "global" not in res and "global" not in res["windows"]
    assert res["windows_from"] == {"local": "crossover", "intermediate": "crossover"}
    assert res["windows"]["intermediate"][1] == pytest.approx(res.curves["t"].iloc[-1])
    assert res["windows"]["intermediate"][0] == pytest.approx(3 * res["crossover"]["t_c"])
    assert "t_g" not in res.table.columns and set(res.table["range"]) == {"local", "intermediate"}
    assert res["intermediate"]["gamma_x"] == pytest.approx(0.5, abs=0.06)


# --------------------------------------------------------------------------- saltation analyze
def test_analyze_tracks_file_shows_the_global_row(tmp_path, capsys, monkeypatch):
    """`saltation analyze ctrw.parquet --origins 1` (statistics from the release): the global
    rows in diffusion.csv, global_bend.csv, the printed lines, the report and the figure."""
    from saltation.analysis import report
    from saltation.cli import main

    figs = {}
    real = report._save

    def keep(fig, path):
        figs[Path(path).name] = [[ln.get_label() for ln in ax.get_lines()] for ax in fig.axes]
        return real(fig, path)

    monkeypatch.setattr(report, "_save", keep)
    tracks = ctrw_release()
    tracks.to_parquet(tmp_path / "ctrw.parquet")
    assert main(["analyze", str(tmp_path / "ctrw.parquet"), "--origins", "1"]) == 0
    printed = capsys.readouterr().out
    out = tmp_path / "ctrw_analysis"
    tab = pd.read_csv(out / "diffusion.csv")
    glob = tab[tab["range"] == "global"].set_index("direction")
    assert len(glob) == 2 and glob.loc["x", "gamma"] < 0.5 and np.isfinite(glob.loc["x", "t_g"])
    gb = pd.read_csv(out / "global_bend.csv").iloc[0]
    assert bool(gb["found"]) and gb["t_g"] == pytest.approx(glob.loc["x", "t_g"])
    assert "global" in printed and "t_g =" in printed
    page = (out / "report.html").read_text()
    assert "global" in page and "t_g" in page
    labels = figs["variance.png"][0]
    assert any(lab.startswith("global: γx") for lab in labels)
    assert any(lab.startswith("t_g =") for lab in labels)
