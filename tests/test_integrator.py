"""The RK4 grain integrator: settling, zero slip, convergence, bed, reproducibility, NaN."""
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

from flowfields.dataset import in_memory_dataset
from saltation.bed.virtual import bed_parameters
from saltation.case.schema import load_case
from saltation.engine.simulation import Simulation, SimulationError, run
from saltation.flight.spheres import make_state, make_workspace
from saltation.physics import history
from saltation.physics.forces import make_coefficients, yen_drag_coefficient

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
from sphere_advance import advance  # noqa: E402  (tests/peers: the flight-and-bed loop without contacts)


def uniform_flow(u=(0.0, 0.0, 0.0), y_top=1e6):
    y = np.array([1e-3, y_top])
    data = np.zeros((1, 2, 2, 2, 3), dtype=np.float32)
    data[...] = np.asarray(u, dtype=np.float32)
    return in_memory_dataset([0.0, 1e4], y, [0.0, 1e4], data, re_tau=y_top, times_plus=[0.0])


def integrate(flow, coef, pos, vel, spin, dt, n_steps, n_window=20, bed=(0.65, 0.1, 0.5), seed=0):
    st = make_state(np.atleast_2d(pos), np.atleast_2d(vel), np.atleast_2d(spin), 0.0, n_window)
    ws = make_workspace(len(st.pos))
    hc = history.make_history_coefficients(dt, n_window)
    done = advance(flow.arrays, coef, np.asarray(bed, dtype=float), seed, st, ws, hc, 0.0, dt, n_steps, 1e300)
    assert done == n_steps
    return st


def yen_terminal_velocity(rp):
    """Independent root-find in particle units of still water (τ* = 1, Re* = Rp): weight
    α/τ* balances drag (3/4) α C_D(w Rp) w² → (3/4) C_D w² = 1."""
    return brentq(lambda w: 0.75 * yen_drag_coefficient(w * rp) * w * w - 1.0, 1e-6, 10.0)


@pytest.mark.parametrize("diameter", [0.2e-3, 0.69e-3, 2.0e-3])
def test_terminal_settling_velocity_matches_yen_root_find(diameter, tmp_path):
    case = {
        "particle": {"diameter": diameter, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1e-6},
        "flow": {"source": "still"},
        "forces": {"basset": False},
        "run": {"n_particles": 1, "duration": 1.0, "dt_particle": 0.02, "release_height": 5000.0},
        "output": {"tracks": True, "vtk": False},
    }
    c = load_case(case)
    # still water: velocity scale √(gRd), so the run lasts 40 response-time-ish units
    res = run(case, out=tmp_path / "run", progress=False, **{"run.duration": 60.0 * c.time_scale})
    tr = res.tracks
    w = -tr.loc[tr["t"].idxmax(), "v"]
    assert w == pytest.approx(yen_terminal_velocity(c.particle_reynolds), rel=0.01)


def test_terminal_velocity_with_basset_history_approaches_the_same_value():
    """The history force decays as t^-1/2 at steady fall: still within 1 % after a long fall."""
    rp = 72.9
    coef = make_coefficients(tau_star=1.0, R=1.65, re_star=rp)
    st = integrate(uniform_flow(), coef, [0, 1e5, 0], [0, 0, 0], [0, 0, 0], dt=0.05, n_steps=40000, n_window=50)
    assert -st.vel[0, 1] == pytest.approx(yen_terminal_velocity(rp), rel=0.01)


def test_grain_at_zero_slip_in_uniform_flow_stays_at_zero_slip():
    coef = make_coefficients(tau_star=0.057, R=1.65, re_star=17.5, weight=False)
    u = (5.0, 0.3, -0.7)
    st = integrate(uniform_flow(u), coef, [0, 100.0, 0], u, [0, 0, 0], dt=0.02, n_steps=500)
    np.testing.assert_allclose(st.vel[0], u, rtol=0, atol=1e-6)  # float32 flow storage
    np.testing.assert_allclose(st.spin[0], 0.0, atol=1e-12)


def test_rk4_is_fourth_order_without_history():
    """Grain launched into a linear shear flow (exactly represented by the trilinear
    interpolant, so the right-hand side is smooth): error ratio ≈ 16 per halving."""
    y = np.array([1e-3, 1e3])
    data = np.zeros((1, 2, 2, 2, 3), dtype=np.float32)
    data[0, :, :, :, 0] = (0.02 * y)[None, :, None]  # u⁺ = 0.02 y⁺: 0.35 u*/d at Re* = 17.5
    flow = in_memory_dataset([0.0, 1e5], y, [0.0, 1e5], data, re_tau=1e3, times_plus=[0.0])
    coef = make_coefficients(tau_star=0.057, R=1.65, re_star=17.5, basset=False)
    T = 4.0

    def end(dt):
        # spin relative to ½ω_f stays below Re_r = 1 (one branch of the C_ω table: smooth)
        st = integrate(flow, coef, [0, 30.0, 0], [9.0, 1.0, 0.5], [0.0, 0.0, -0.2], dt, int(round(T / dt)))
        return np.concatenate([st.pos[0], st.vel[0], st.spin[0]])

    ref = end(0.005)
    errs = [np.abs(end(dt) - ref).max() for dt in (0.16, 0.08, 0.04)]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    print("RK4 errors", errs, "orders", orders)
    assert np.all(orders > 3.6), (errs, orders)
    assert errs[-1] > 1e-12  # a real error, not round-off


def test_no_grain_ends_below_the_bed_and_jumps_are_recorded(tmp_path):
    res = run("cases/loglaw.toml", out=tmp_path / "r", progress=False,
              **{"run.n_particles": 40, "run.duration": 0.5, "output.vtk": False, "run.seed": 3})
    tr = res.tracks
    assert tr["y"].min() >= 0.5 - 1e-12
    jumps = res.jumps
    assert len(jumps) > 40
    assert (jumps["duration"] > 0).all() and (jumps["height"] >= 0).all()
    np.testing.assert_allclose(jumps["velocity"], jumps["length"] / jumps["duration"])
    # every jump ends at a bed contact; contacts within one contact episode (bed/jumps.py) end none
    bed = res.summary["collisions"]["bed"]
    assert len(jumps) <= bed and len(jumps) > 0.8 * bed
    assert jumps["duration"].min() >= res.summary["dt_particle"]


def test_same_seed_and_threads_reproduce_a_run_bit_for_bit(tmp_path):
    over = {"run.n_particles": 30, "run.duration": 0.3, "output.vtk": False, "run.threads": 2}
    a = run("cases/loglaw.toml", out=tmp_path / "a", progress=False, **over)
    b = run("cases/loglaw.toml", out=tmp_path / "b", progress=False, **over)
    assert a.tracks.equals(b.tracks)
    assert a.jumps.equals(b.jumps)
    c = run("cases/loglaw.toml", out=tmp_path / "c", progress=False, **over, **{"run.seed": 99})
    assert not a.tracks.equals(c.tracks)


def test_nan_stops_the_run_naming_particle_step_and_state(tmp_path, monkeypatch):
    import json

    import saltation.grains.initial as ini
    from saltation.case.schema import resolve_domain

    case = resolve_domain(load_case("cases/loglaw.toml", {"run.n_particles": 5, "run.duration": 0.2, "output.vtk": False}))
    y = np.geomspace(0.05, 2e4, 100)
    data = np.zeros((1, 2, len(y), 2, 3), dtype=np.float32)
    data[0, :, :, :, 0] = 10.0
    data[0, :, 60:, :, 0] = np.nan  # poisoned above y⁺ ≈ 170 (≈ 10 d)
    flow = in_memory_dataset([0.0, 1e4], y, [0.0, 1e4], data, re_tau=2e4, times_plus=[0.0])
    monkeypatch.setattr(ini, "Y_RANGE", (20.0, 21.0))  # start the grains in the poisoned layer
    with pytest.raises(SimulationError, match=r"particle \d+ became non-finite during step \d+.*position"):
        Simulation(case, flow, tmp_path / "nan", progress=False).run()
    # what was written so far is kept
    assert (tmp_path / "nan" / "tracks.parquet").exists()
    assert json.loads((tmp_path / "nan" / "summary.json").read_text())["status"] == "failed"


def _shear_flow(rate=0.02):
    y = np.array([1e-3, 1e3])
    data = np.zeros((1, 2, 2, 2, 3), dtype=np.float32)
    data[0, :, :, :, 0] = (rate * y)[None, :, None]
    return in_memory_dataset([0.0, 1e5], y, [0.0, 1e5], data, re_tau=1e3, times_plus=[0.0])


def test_spin_law_off_keeps_the_spin_and_the_velocity_only_sample_moves_the_grain_alike():
    """[forces] spin = false: no rotational drag, so in free flight the spin stays what it
    was; with Magnus, added mass and fluid acceleration also off the kernel samples the
    velocity without its gradient — the translation must be that of the gradient path."""
    flow = _shear_flow()
    kw = dict(tau_star=0.057, R=1.65, re_star=17.5, magnus=False, added_mass=False, fluid_acceleration=False)
    spin0 = [0.0, 0.0, -2.0]
    on = integrate(flow, make_coefficients(**kw), [0, 50.0, 0], [1.0, 0.5, 0], spin0, dt=0.02, n_steps=300)
    off = integrate(flow, make_coefficients(**kw, spin=False), [0, 50.0, 0], [1.0, 0.5, 0], spin0, dt=0.02,
                    n_steps=300)
    assert on.impacts[0] == 0 and off.impacts[0] == 0
    np.testing.assert_array_equal(off.spin[0], spin0)
    # the spin law relaxes ϖ toward ½ ω_f = -0.175 u*/d (shear 0.35 u*/d): it did move
    assert abs(on.spin[0, 2] - spin0[2]) > 0.1
    np.testing.assert_allclose(off.pos[0], on.pos[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(off.vel[0], on.vel[0], rtol=1e-12, atol=1e-12)


def test_spin_key_reaches_the_kernel(tmp_path):
    from saltation.case.schema import resolve_domain
    from saltation.engine.simulation import _les_box_m, open_flow
    from saltation.physics.forces import ON_SPIN

    assert load_case("cases/default.toml").forces.spin is True
    for value in (True, False):
        case = load_case("cases/default.toml", {"forces.spin": value, "flow.source": "loglaw"})
        ds = open_flow(case)
        sim = Simulation(resolve_domain(case, _les_box_m(ds, case)), ds, tmp_path / str(value), progress=False)
        assert sim.coef[ON_SPIN] == float(value)


def test_weight_and_drag_fast_path_matches_the_general_body_to_round_off():
    """With weight and drag the only forces the integrator takes its scalar fast path
    (one gathered fluid cell per time level, reused by the stages in the same cell);
    lift switched on with C_L = 0 adds exactly nothing but forces the general body.
    Through the real LES, across cells, periodic boundaries and bed impacts, the two
    must agree to round-off (the general body's sampler forms fused multiply-adds that
    the inlined one does not: ~1 ulp per step; measured after 400 steps: 2e-13 d in
    position, 1e-13 u* in velocity) with the same bed impacts."""
    from flowfields import open_dataset

    ds = open_dataset()
    re_star = 17.45
    kw = dict(tau_star=0.0573, R=1.65, re_star=re_star, magnus=False, added_mass=False,
              fluid_acceleration=False, basset=False, spin=False)
    fast = make_coefficients(**kw, lift=False)
    general = make_coefficients(**kw, lift=True, C_L=0.0)
    rng = np.random.default_rng(5)
    n = 200  # three full chunks of the parallel loop and a partial one
    lx, lz = ds.box[0] / re_star, ds.box[2] / re_star
    pos = np.column_stack([rng.uniform(0, lx, n), rng.uniform(0.6, 3.0, n), rng.uniform(0, lz, n)])
    vel = np.column_stack([rng.uniform(0, 12, n), rng.uniform(-2, 2, n), rng.uniform(-1, 1, n)])
    spin = rng.normal(0, 1, (n, 3))
    out = []
    for coef in (fast, general):
        st = make_state(pos, vel, spin, 0.0, 10)
        ws = make_workspace(n)
        hc = history.make_history_coefficients(0.02, 10)
        done = 0
        while done < 400:
            done += advance(ds.arrays, coef, bed_parameters(0.65, 0.1, 0.5), 7, st, ws, hc, done * 0.02, 0.02,
                            400 - done, 1e300)
            st.jump_buf_n[:] = 0
        out.append(st)
    a, b = out
    assert a.impacts.sum() > 200 and a.pos[:, 0].max() > lx  # bed impacts, grains crossed the period
    for name in ("impacts", "jump_count", "status"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("pos", "vel", "spin"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-10, err_msg=name)
