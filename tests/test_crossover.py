"""The ballistic-to-intermediate crossover t_c found from ⟨X′²⟩(t) itself (issue 16):
tracks with no bed contacts (particle, t, x, z only: a flume, another model) get their
diffusion windows from it, and tracks files are read with their units.

The synthetic hops have independent streamwise and spanwise velocities per hop and
gamma-distributed durations T (shape k, mean τ); the asymptotes var(u) t² and
t var(u) E[T²]/E[T] meet at E[T²]/E[T] = τ (1 + 1/k), where t_c should lie (within 20 %:
the bend is gradual, and the finite record pulls the fit a little); local γ ≈ 1,
intermediate γ = ½ (independent hops).
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from saltation.analysis.diffusion import CROSSOVER_MIN_DROP, crossover, exponents, read_tracks_file
from saltation.analysis.variance import AnalysisError, make_plan


def hop_tracks(n=200, tau=4.0, shape=8.0, dt=0.1, n_samples=4000, seed=0):
    """Tracks (particle, t, x, z; no y) of grains hopping with durations T ~ Gamma(shape,
    τ/shape), streamwise velocity u ~ N(6, 2) and spanwise w ~ N(0, 0.8) held over each
    hop; grains start at random phases. Returns (tracks, E[T²]/E[T])."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * dt
    m = int(t[-1] / tau * 2 + 50)
    T = rng.gamma(shape, tau / shape, (n, m))
    u, w = rng.normal(6.0, 2.0, (n, m)), rng.normal(0.0, 0.8, (n, m))
    ends = -rng.uniform(0, 1, n)[:, None] * T[:, :1] + np.cumsum(T, axis=1)
    assert (ends[:, -1] > t[-1]).all()
    begins = ends - T
    x0, z0 = np.cumsum(u * T, axis=1) - u * T, np.cumsum(w * T, axis=1) - w * T
    x, z = np.empty((n, n_samples)), np.empty((n, n_samples))
    for p in range(n):
        k = np.searchsorted(ends[p], t, side="right")
        s = t - begins[p, k]
        x[p], z[p] = x0[p, k] + u[p, k] * s, z0[p, k] + w[p, k] * s
    tracks = pd.DataFrame({"particle": np.repeat(np.arange(n), n_samples), "t": np.tile(t, n),
                           "x": x.ravel(), "z": z.ravel()})
    return tracks, tau * (1 + 1 / shape)


# --------------------------------------------------------------------------- the fit itself
@pytest.mark.parametrize("t_c", [1.5, 3.0, 8.0])
def test_breakpoint_of_a_broken_power_law_whatever_the_lags(t_c):
    """v = t² up to t_c, then ∝ t^1.2: the breakpoint comes back within 2 % and the two γ
    within 0.01, from the lags of a 0.1 d/u* and of a 0.5 d/u* sampling alike (the fit
    weighs decades, not lags)."""
    found = []
    for dt, n in ((0.1, 2000), (0.5, 400)):
        t = make_plan(n, dt).lag_times[1:]
        v = np.where(t < t_c, t ** 2, t_c ** 2 * (t / t_c) ** 1.2)
        c = crossover(t, v)
        assert c["found"], c["reason"]
        assert c["t_c"] == pytest.approx(t_c, rel=0.02)
        assert c["gamma_before"] == pytest.approx(1.0, abs=0.01)
        assert c["gamma_after"] == pytest.approx(0.6, abs=0.01)
        assert c["var_c"] == pytest.approx(t_c ** 2, rel=0.05)
        found.append(c["t_c"])
    assert found[0] == pytest.approx(found[1], rel=0.03)


def test_no_crossover_in_a_straight_curve_or_at_its_end():
    t = make_plan(2000, 0.1).lag_times[1:]
    c = crossover(t, 3 * t ** 1.0)
    assert not c["found"] and c["t_c"] is None
    assert str(CROSSOVER_MIN_DROP) in c["reason"] or "end" in c["reason"] or "last" in c["reason"]
    late = crossover(t, np.where(t < 80, t ** 2, 80 ** 2 * (t / 80)))  # bends only after the scan's end
    assert not late["found"] and "last" in late["reason"]
    short = crossover(t[:2], t[:2] ** 2)  # 0.1–0.2 d/u*: 0.3 decade
    assert not short["found"] and "decade" in short["reason"]


# --------------------------------------------------------------------------- hop tracks, no y
@pytest.mark.parametrize("tau, shape, seed", [(2.0, 16.0, 1), (6.0, 4.0, 2)])
def test_hop_tracks_without_contacts_get_windows_from_the_crossover(tau, shape, seed):
    tracks, expected = hop_tracks(tau=tau, shape=shape, seed=seed)
    assert list(tracks.columns) == ["particle", "t", "x", "z"]
    res = exponents(tracks)
    cr = res["crossover"]
    assert res["jump_duration"] is None and res["jump_duration_from"] is None
    assert res["windows_from"] == {"local": "crossover", "intermediate": "crossover"}
    assert 0.8 * expected < cr["t_c"] < 1.2 * expected, (cr["t_c"], expected)
    lo, hi = cr["ci"]
    assert lo < cr["t_c"] < hi and hi / lo < 1.6 and cr["n_boot"] > 300
    assert res["windows"]["local"][1] == pytest.approx(0.5 * cr["t_c"])
    assert res["windows"]["intermediate"][0] == pytest.approx(3 * cr["t_c"])
    row = res.table.iloc[0]
    assert (row["t_c"], row["t_c_low"], row["t_c_high"]) == (cr["t_c"], lo, hi)
    for d in ("x", "z"):
        assert 0.93 < res["local"][f"gamma_{d}"] < 1.01
        assert res["intermediate"][f"gamma_{d}"] == pytest.approx(0.5, abs=0.05)
    assert res["crossover_z"]["found"] and res["crossover_z"]["direction"] == "z"
    assert 0.7 * expected < res["crossover_z"]["t_c"] < 1.3 * expected


def test_random_walk_without_contacts_has_no_crossover_and_says_what_to_give():
    rng = np.random.default_rng(7)
    x = np.cumsum(rng.normal(size=(60, 800)), axis=1)
    tracks = pd.DataFrame({"particle": np.repeat(np.arange(60), 800), "t": np.tile(np.arange(800) * 0.1, 60),
                           "x": x.ravel(), "z": x[::-1].ravel()})
    with pytest.raises(AnalysisError, match="no ballistic-to-intermediate crossover.*jump duration could not be found.*ranges="):
        exponents(tracks)
    res = exponents(tracks, strict=False)
    assert not res["crossover"]["found"] and set(res.problems) == {"local", "intermediate"}


def test_no_crossover_falls_back_to_the_jump_duration_of_the_contacts():
    """Ballistic grains (no bend within the record) whose centre touches the bed every
    4 d/u*: the windows come from T_J, and say so."""
    rng = np.random.default_rng(3)
    n, j, dt = 50, 1000, 0.1
    t = np.arange(j) * dt
    u = rng.normal(5.0, 1.0, n)[:, None]
    phase = rng.uniform(0, 4.0, n)[:, None]
    y = 0.5 + 2.0 * np.abs(np.sin(np.pi * (t + phase) / 4.0))
    tracks = pd.DataFrame({"particle": np.repeat(np.arange(n), j), "t": np.tile(t, n), "x": (u * t).ravel(),
                           "y": y.ravel(), "z": (0.3 * u * t).ravel()})
    res = exponents(tracks, strict=False)
    assert not res["crossover"]["found"]
    assert res["jump_duration"] == pytest.approx(4.0, rel=0.05)
    assert res["windows_from"]["local"].startswith("jump_duration (no crossover:")
    assert res["windows"]["local"][1] == pytest.approx(0.5 * res["jump_duration"])


# --------------------------------------------------------------------------- tracks files
def test_tracks_file_csv_parquet_and_units(tmp_path):
    tracks, _ = hop_tracks(n=40, n_samples=1500, seed=4)
    tracks["t"] = tracks["t"].round(3)
    tracks.to_csv(tmp_path / "a.csv", index=False, float_format="%.6g")  # times and positions with 6 digits
    back = read_tracks_file(tmp_path / "a.csv")
    steps = np.diff(np.unique(back["t"]))
    assert np.ptp(steps) < 1e-9  # snapped onto the grid
    si = tracks.assign(t=tracks["t"] * 0.0273, x=tracks["x"] * 0.69e-3, z=tracks["z"] * 0.69e-3)
    si.to_parquet(tmp_path / "si.parquet")
    conv = read_tracks_file(tmp_path / "si.parquet", diameter=0.69e-3, time_scale=0.0273)
    np.testing.assert_allclose(conv[["t", "x", "z"]], tracks[["t", "x", "z"]], rtol=1e-12, atol=1e-12)
    a, b = exponents(back, strict=False), exponents(conv, strict=False)
    assert b["crossover"]["t_c"] == pytest.approx(a["crossover"]["t_c"], rel=0.02)
    # seconds taken for d/u*: t_c scales with the unit (within 5 %: the fit's grid is fixed in log t, so the
    # unit change moves the curve against it), γ does not change
    raw = exponents(read_tracks_file(tmp_path / "si.parquet"), strict=False)
    assert raw["crossover"]["t_c"] == pytest.approx(b["crossover"]["t_c"] * 0.0273, rel=0.05)
    assert raw["crossover"]["gamma_after"] == pytest.approx(b["crossover"]["gamma_after"], abs=0.02)
    tracks.drop(columns=["z", "t"]).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(AnalysisError, match=r"lacks column\(s\) t, z: a tracks file needs particle.*t \(time, d/u\*\).*"
                                            r"x \(streamwise position, unwrapped, d\)"):
        read_tracks_file(tmp_path / "bad.csv")
    (tmp_path / "a.txt").write_text("particle,t,x,z\n")
    with pytest.raises(AnalysisError, match=r"\.csv or \.parquet"):
        read_tracks_file(tmp_path / "a.txt")
