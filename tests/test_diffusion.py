"""Diffusion exponents (SPEC §6) on synthetic processes whose exponents are known.

Each process is sampled as a tracks DataFrame (t in d/u*, x, z unwrapped in d) and fed to
``exponents``; the fitted γ must match the known value within the stated tolerance.
Tolerances are a few bootstrap standard errors of the ensemble sizes used here (the
95 % intervals printed by the fits are about ±0.02–0.03).
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from saltation.analysis.diffusion import MIN_PARTICLES, exponents, jump_duration_from_tracks
from saltation.analysis.variance import AnalysisError, VarianceAccumulator, make_plan, read_sums, variance_curves


def frame(x, z, dt, y=None):
    p, j = x.shape
    t = np.arange(j) * dt
    return pd.DataFrame({
        "particle": np.repeat(np.arange(p), j), "t": np.tile(t, p), "x": x.ravel(),
        "y": (np.ones_like(x) if y is None else y).ravel(), "z": z.ravel(),
    })


def fgn(n, hurst, size, rng):
    """Fractional Gaussian noise, exact (Davies & Harte 1987, circulant embedding):
    ``size`` independent series of ``n`` unit-variance increments with autocovariance
    γ(k) = ½(|k+1|^{2H} − 2|k|^{2H} + |k−1|^{2H})."""
    k = np.arange(n + 1, dtype=float)
    cov = 0.5 * ((k + 1) ** (2 * hurst) - 2 * k ** (2 * hurst) + np.abs(k - 1) ** (2 * hurst))
    row = np.concatenate([cov, cov[-2:0:-1]])  # length 2n, first row of the circulant
    lam = np.fft.fft(row).real
    assert lam.min() > -1e-9, "circulant embedding not non-negative"
    m = len(row)
    w = rng.standard_normal((size, m)) + 1j * rng.standard_normal((size, m))
    y = np.fft.fft(np.sqrt(np.clip(lam, 0, None) / m) * w, axis=1)
    return y.real[:, :n]


def test_fgn_generator_has_the_right_covariance():
    rng = np.random.default_rng(3)
    h = 0.75
    e = fgn(256, h, 4000, rng)
    lag1 = np.mean(e[:, :-1] * e[:, 1:])
    assert np.var(e) == pytest.approx(1.0, abs=0.02)
    assert lag1 == pytest.approx(0.5 * (2 ** (2 * h) - 2), abs=0.02)  # γ(1) = 2^{2H-1} − 1


WINDOWS = {"local": (0.1, 1.0), "intermediate": (5.0, 45.0)}


def test_ballistic_motion_gives_gamma_one():
    """X = u t with u varying between grains: ⟨X′²⟩ = var(u) t², γ = 1 (tolerance 0.005)."""
    rng = np.random.default_rng(1)
    t = np.arange(1001) * 0.1
    u, w = rng.normal(5.0, 1.0, 200), rng.normal(0.0, 0.7, 200)
    res = exponents(frame(u[:, None] * t, w[:, None] * t, 0.1), ranges=WINDOWS)
    for rng_name in ("local", "intermediate"):
        assert res[rng_name]["gamma_x"] == pytest.approx(1.0, abs=0.005)
        assert res[rng_name]["gamma_z"] == pytest.approx(1.0, abs=0.005)
    # the prefactor is the velocity variance: α = var(u)
    row = res.table.query("direction == 'x' and range == 'local'").iloc[0]
    assert row["alpha"] == pytest.approx(np.var(u, ddof=1), rel=0.05)


def test_brownian_motion_gives_gamma_half_with_bootstrap_interval():
    """Random walk, 300 grains: γ = 0.5 within 0.03; the 95 % interval holds 0.5."""
    rng = np.random.default_rng(2)
    x = np.cumsum(rng.normal(0, 1, (300, 1001)), axis=1)
    z = np.cumsum(rng.normal(0, 0.5, (300, 1001)), axis=1)
    res = exponents(frame(x, z, 0.1), ranges=WINDOWS)
    tab = res.table
    assert len(tab) == 4 and not tab[["gamma", "ci_low", "ci_high"]].isna().any().any()
    for _, r in tab.iterrows():
        assert r["gamma"] == pytest.approx(0.5, abs=0.03), r.to_dict()
        assert r["ci_low"] < r["gamma"] < r["ci_high"]
        assert r["ci_high"] - r["ci_low"] < 0.12
    assert tab["n_particles"].eq(300).all()


@pytest.mark.parametrize("hurst", [0.25, 0.5, 0.7, 0.85])
def test_fractional_brownian_motion_gives_its_hurst_exponent(hurst):
    """fBm (⟨X²⟩ = t^{2H}) generated exactly: γ = H within 0.03 (300 grains, 1024 samples)."""
    rng = np.random.default_rng(int(hurst * 100))
    x = np.cumsum(fgn(1024, hurst, 300, rng), axis=1)
    z = np.cumsum(fgn(1024, hurst, 300, rng), axis=1)
    res = exponents(frame(x, z, 1.0), ranges={"local": (1.0, 10.0), "intermediate": (20.0, 400.0)})
    for name in ("local", "intermediate"):
        assert res[name]["gamma_x"] == pytest.approx(hurst, abs=0.03)
        assert res[name]["gamma_z"] == pytest.approx(hurst, abs=0.03)


def hopping_grains(n=300, tau=4.0, dt=0.08, n_samples=6000, seed=5):
    """Saltation-like hops: each jump lasts T ~ U(0.8, 1.2)·τ with a streamwise velocity
    ~ N(5, 1.5) and a spanwise velocity ~ N(0, 0.8) held over the jump; the centre height
    is a parabola from the bed contact (y = 0.5) up to 0.5 + 2 d and back. Grains start at
    random phases. Ballistic below τ, normal diffusion (γ = ½) over many jumps."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * dt
    x, y, z = (np.empty((n, n_samples)) for _ in range(3))
    for p in range(n):
        start = -rng.uniform(0, 1.2 * tau)
        x0 = z0 = 0.0
        i = 0
        while i < n_samples:
            dur = rng.uniform(0.8, 1.2) * tau
            u, w = rng.normal(5.0, 1.5), rng.normal(0.0, 0.8)
            end = start + dur
            j = np.searchsorted(t, end, side="left")
            s = t[i:j] - start
            x[p, i:j], z[p, i:j] = x0 + u * s, z0 + w * s
            y[p, i:j] = 0.5 + 8.0 * (s / dur) * (1 - s / dur)
            x0, z0, start, i = x0 + u * dur, z0 + w * dur, end, j
    return frame(x, z, dt, y=y), tau


def test_two_regime_process_crossover_and_both_ranges():
    """Ballistic then diffusive: the windows come from the crossover t_c of ⟨X′²⟩ (within
    10 % of τ, its 95 % interval holding τ), the jump duration found from the bed contacts
    (within 5 % of τ) is reported beside it; the local range gives γ ≈ 1 (0.93–1.01: the
    fit reaches t_c/2, where some grains already changed jump) and the intermediate range
    γ = ½ within 0.05 with the automatic windows, 0.03 far from the crossover. Given
    jump_duration= sets the windows instead."""
    tracks, tau = hopping_grains()
    assert jump_duration_from_tracks(tracks) == pytest.approx(tau, rel=0.05)
    res = exponents(tracks)
    assert res["jump_duration"] == pytest.approx(tau, rel=0.05)
    assert res["jump_duration_from"] == "bed contacts in the tracks"
    cr = res["crossover"]
    assert cr["found"] and cr["direction"] == "x"
    assert cr["t_c"] == pytest.approx(tau, rel=0.10)
    assert cr["ci"][0] < tau < cr["ci"][1]
    assert res["windows_from"] == {"local": "crossover", "intermediate": "crossover"}
    assert res["windows"]["local"][1] == pytest.approx(0.5 * cr["t_c"])
    assert res["windows"]["intermediate"][0] == pytest.approx(3 * cr["t_c"])
    assert (res.table["t_c"] == cr["t_c"]).all() and (res.table["windows_from"] == "crossover").all()
    for d in ("x", "z"):
        assert 0.93 < res["local"][f"gamma_{d}"] < 1.01
        assert res["intermediate"][f"gamma_{d}"] == pytest.approx(0.5, abs=0.05)
    far = exponents(tracks, ranges={"intermediate": (10 * tau, 100.0)})
    assert far["windows_from"] == {"local": "crossover", "intermediate": "ranges"}
    for d in ("x", "z"):
        assert far["intermediate"][f"gamma_{d}"] == pytest.approx(0.5, abs=0.03)
    given = exponents(tracks, jump_duration=3.0)
    assert given["windows"]["local"][1] == pytest.approx(1.5) and given["windows"]["intermediate"][0] == pytest.approx(9.0)
    assert given["windows_from"]["local"] == "jump_duration" and given["jump_duration_from"] == "given"


def test_accumulator_fed_in_steps_equals_tracks_path():
    """The streaming accumulator (any number of groups) gives the same curves as tracks."""
    tracks, _ = hopping_grains(n=50, n_samples=800, seed=9)
    x = tracks["x"].to_numpy().reshape(50, 800)
    z = tracks["z"].to_numpy().reshape(50, 800)
    plan = make_plan(800, 0.08)
    acc = VarianceAccumulator(50, plan, n_groups=7)
    pos = np.zeros((50, 3))
    j = -1
    while (j := acc.next_sample(j)) is not None:
        pos[:, 0], pos[:, 2] = x[:, j], z[:, j]
        acc.sample(j, pos)
    vx, vz, n_or = variance_curves(acc.sums)
    ref = exponents(tracks, ranges={"local": (0.08, 2.0), "intermediate": (12.0, 30.0)})
    np.testing.assert_allclose(vx[1:], ref.curves["var_x"].to_numpy(), rtol=1e-10)
    np.testing.assert_allclose(vz[1:], ref.curves["var_z"].to_numpy(), rtol=1e-10)
    assert (n_or == len(plan.origins)).all()
    # direct check of one cell: origin 0, the largest lag
    _o, lag = plan.origins[0], plan.lags[-1]
    direct = np.mean([np.var(x[:, oo + lag] - x[:, oo], ddof=1) for oo in plan.origins])
    assert vx[-1] == pytest.approx(direct, rel=1e-10)


def test_variance_file_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    plan = make_plan(200, 0.1, n_origins=3)
    acc = VarianceAccumulator(30, plan, n_groups=4)
    for j in range(200):
        acc.sample(j, rng.normal(size=(30, 3)))
    acc.write(tmp_path / "variance.parquet")
    sums, lags, meta = read_sums(tmp_path / "variance.parquet")
    np.testing.assert_array_equal(sums, acc.sums)
    np.testing.assert_allclose(lags, plan.lag_times)
    assert meta["n_particles"] == 30 and meta["memory_bytes"] == acc.memory_bytes


# --------------------------------------------------------------------------- bad input
def test_no_tracks():
    with pytest.raises(AnalysisError, match="empty"):
        exponents(pd.DataFrame(columns=["particle", "t", "x", "y", "z"]), ranges=WINDOWS)
    with pytest.raises(AnalysisError, match="no tracks"):
        exponents(None)


def test_run_directory_without_tracks_or_variance(tmp_path):
    (tmp_path / "summary.json").write_text(json.dumps({"n_particles": 100}))
    with pytest.raises(AnalysisError, match="neither variance.parquet nor tracks.parquet.*output.variance = true"):
        exponents(tmp_path)


def test_too_few_particles():
    rng = np.random.default_rng(1)
    x = np.cumsum(rng.normal(size=(MIN_PARTICLES - 1, 500)), axis=1)
    with pytest.raises(AnalysisError, match=rf"{MIN_PARTICLES - 1} grain\(s\).*at least {MIN_PARTICLES}"):
        exponents(frame(x, x, 0.1), ranges=WINDOWS)


def test_too_short_run_says_how_long_would_do():
    tracks, tau = hopping_grains(n=20, n_samples=200, seed=2)  # 16 d/u* = 4 τ
    with pytest.raises(AnalysisError, match="intermediate.*too short.*at least") as err:
        exponents(tracks)
    assert "nan" not in str(err.value).lower()
    res = exponents(tracks, strict=False)  # the local range still fits
    assert "intermediate" in res.problems and "intermediate" not in res
    assert not res.table.isna().any().any() and set(res.table["range"]) == {"local"}


def test_range_with_too_few_points_says_what_sampling_would_do():
    rng = np.random.default_rng(4)
    x = np.cumsum(rng.normal(size=(50, 500)), axis=1)
    with pytest.raises(AnalysisError, match=r"local range \[0.1, 0.35\].*holds 3 lag.*at least 5.*every 0.07"):
        exponents(frame(x, x, 0.1), ranges={"local": (0.1, 0.35), "intermediate": (5.0, 20.0)})


def test_no_bed_contacts_and_no_ranges_asks_for_them():
    rng = np.random.default_rng(4)
    x = np.cumsum(rng.normal(size=(50, 500)), axis=1)
    with pytest.raises(AnalysisError, match="jump duration could not be found.*ranges="):
        exponents(frame(x, x, 0.1))


def test_bad_window():
    rng = np.random.default_rng(4)
    x = np.cumsum(rng.normal(size=(50, 500)), axis=1)
    with pytest.raises(AnalysisError, match="0 < t_min < t_max"):
        exponents(frame(x, x, 0.1), ranges={"local": (1.0, 0.5), "intermediate": (5.0, 20.0)})


# --------------------------------------------------------------------------- in a run
def test_run_writes_variance_and_exponents_reads_it(tmp_path):
    """A short LES run: variance.parquet from the run loop equals the tracks-based
    statistics when tracks are sampled on the same grid."""
    from saltation.case.schema import load_case
    from saltation.engine.simulation import run

    case = load_case("cases/default.toml", {"run.n_particles": 24, "run.duration": 1.0, "output.vtk": False})
    iv = case.variance_every * case.dt
    res = run("cases/default.toml", out=tmp_path, progress=False,
              **{"run.n_particles": 24, "run.duration": 1.0, "output.vtk": False, "output.tracks_interval": iv})
    assert (tmp_path / "variance.parquet").exists()
    v = res.summary["variance"]
    assert v["memory_bytes"] > 0 and v["sample_interval_particle"] == pytest.approx(0.1)
    wins = {"local": (0.1, 0.6), "intermediate": (3.0, 16.0)}
    a = exponents(tmp_path, ranges=wins)
    (tmp_path / "variance.parquet").rename(tmp_path / "v.bak")
    b = exponents(tmp_path, ranges=wins)
    assert a["source"] == "variance.parquet" and b["source"] == "tracks.parquet"
    np.testing.assert_allclose(a.curves[["var_x", "var_z"]], b.curves[["var_x", "var_z"]], rtol=1e-9)
    assert a["local"]["gamma_x"] == pytest.approx(b["local"]["gamma_x"], rel=1e-9)


def test_run_directory_and_its_tracks_dataframe_give_the_same_windows(tmp_path):
    """Issue 16: a run directory (variance.parquet, jumps.parquet) and the DataFrame of its
    tracks.parquet (contacts in y) used to set the windows from two different T_J. Both now
    take them from the crossover of ⟨X′²⟩: with the tracks sampled like the variances the
    curves are the same and so are t_c and the windows (to 1e-9: the curves agree to
    rounding); tracks sampled every 0.5 d/u* (the default) give a t_c inside the 95 %
    interval of the directory's and vice versa. The two T_J differ and are reported only."""
    from saltation.case.schema import load_case
    from saltation.engine.simulation import run

    # 60 grains: with 40 the sample's ⟨X′²⟩ showed no crossover (slope 1.97 → 1.79) once
    # bed impacts were second order in dt (flight/spheres._bed_impact); 60 and 80 show one
    over = {"run.n_particles": 60, "run.duration": 1.5, "output.vtk": False}
    case = load_case("cases/default.toml", over)
    iv = case.variance_every * case.dt
    run("cases/default.toml", out=tmp_path, progress=False, **over, **{"output.tracks_interval": iv})
    tracks = pd.read_parquet(tmp_path / "tracks.parquet")
    a = exponents(tmp_path, strict=False)
    b = exponents(tracks, strict=False)
    assert a["source"] == "variance.parquet" and b["source"] == "tracks"
    assert a["jump_duration_from"] == "jumps.parquet" and b["jump_duration_from"] == "bed contacts in the tracks"
    assert a["crossover"]["found"], a["crossover"]["reason"]
    assert a["windows_from"] == b["windows_from"] == {"local": "crossover", "intermediate": "crossover"}
    assert b["crossover"]["t_c"] == pytest.approx(a["crossover"]["t_c"], rel=1e-9)
    for name in ("local", "intermediate"):
        np.testing.assert_allclose(b["windows"][name], a["windows"][name], rtol=1e-9)
        if name in a:
            assert b[name]["gamma_x"] == pytest.approx(a[name]["gamma_x"], rel=1e-6)
    # tracks at the default 0.5 d/u*: every 5th sample
    t = np.sort(tracks["t"].unique())
    coarse = exponents(tracks[tracks["t"].isin(t[::5])], strict=False)
    ca, cc = a["crossover"], coarse["crossover"]
    assert cc["found"] and coarse["sample_interval"] == pytest.approx(5 * a["sample_interval"])
    assert ca["ci"][0] <= cc["t_c"] <= ca["ci"][1] and cc["ci"][0] <= ca["t_c"] <= cc["ci"][1]


def test_variance_survives_interrupt_and_resume(tmp_path):
    """A run stopped mid-way (checkpoint) and resumed writes the variance.parquet of the
    uninterrupted run, bit for bit; the sums travel in the run's checkpoint."""
    from saltation.case.schema import load_case, resolve_domain
    from saltation.engine.simulation import CHECKPOINT, RunInterrupted, Simulation, open_flow, run

    case = {"particle": {"diameter": 0.69e-3}, "flow": {"source": "loglaw", "tau_ratio": 1.79},
            "run": {"n_particles": 16, "duration": 0.8, "dt_particle": 0.02, "seed": 3, "threads": 1},
            "output": {"tracks": False, "vtk": False}}
    run(case, out=tmp_path / "ref", progress=False)
    c = resolve_domain(load_case(case))  # as run() does for an analytic flow
    with pytest.raises(RunInterrupted):
        Simulation(c, open_flow(c), tmp_path / "b", progress=False, stop_after_steps=610).run()
    with np.load(tmp_path / "b" / CHECKPOINT) as saved:
        assert saved["variance.sums"].sum() > 0
    run(case, out=tmp_path / "b", progress=False, resume=True)
    a = pd.read_parquet(tmp_path / "ref" / "variance.parquet")
    b = pd.read_parquet(tmp_path / "b" / "variance.parquet")
    assert a["n"].sum() > 0
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert not (tmp_path / "b" / CHECKPOINT).exists()
