"""Saltation throughput: particle-steps per second of the RK4 grain kernel, all forces on
(Basset included), grains saltating over an LES dataset with virtual-bed impacts.

    python benchmarks/bench_saltation.py [DATASET] [--synthetic DIR] [--n 1000,10000,100000]
                                         [--threads 1,2] [--work 2e6] [--repeat 3]
                                         [--no-breakdown] [--fresh-cache]

DATASET: a flow dataset folder (default: the shipped one, ``flowfields.open_dataset()``).
``--synthetic DIR`` writes (once) and uses an int16 synthetic channel of the shipped
dataset's shape (48 × 30 × 48 cells × 80 snapshots, Re_τ = 395) — for machines where the
shipped data are not there yet.

Case: ``cases/default.toml`` (d = 0.69 mm quartz in water, τ*/τ*c = 1.79, dt = 0.02 d/u*,
virtual bed). Grains start as in ``saltation/grains/initial.py`` (near the bed, take-off-like
velocities); a population of ``--spinup-grains`` is first run for ``--spinup`` d/u* so
that it is mid-saltation (grains at every phase of their jumps, bed impacts included),
then tiled to N grains with random streamwise/spanwise shifts. The kernel
``advance`` (tests/peers/sphere_advance.py) is driven directly. Each figure is the best of ``--repeat``
timings of about ``--work`` particle-steps (wall clock; the process CPU time is given
too, a steadier figure on a shared machine); compile time (the first call: a full
compile with ``--fresh-cache``, else mostly a load from Numba's cache) is reported apart.

Breakdown (1 thread, N = --breakdown-n), in µs per particle-step: the whole step, then
each part of its work run alone on the same grains — the four fluid samples of a step
(``physics.fluid.fluid_at_grain``: centre with gradient, top and bottom), the four force and
spin evaluations, the Basset closure — and the rest (RK4 bookkeeping, state traffic,
NaN checks, bed impacts) by difference; then the whole step with lift off, Basset off,
both off, in a steady single-snapshot log-law flow and in still fluid.

Prints one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

if "--fresh-cache" in sys.argv:  # must precede the first numba import
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="bench_saltation_numba_")

import numba  # noqa: E402
import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flowfields import open_dataset, profile_dataset  # noqa: E402
from flowfields.dataset import DatasetError, write_dataset  # noqa: E402
from saltation.bed.virtual import run_bed_parameters  # noqa: E402
from saltation.case.schema import load_case, resolve_domain  # noqa: E402
from saltation.engine.simulation import _les_box_m  # noqa: E402
from saltation.flight.spheres import GrainState, make_state, make_workspace  # noqa: E402
from saltation.grains.initial import initial_conditions  # noqa: E402
from saltation.physics import history  # noqa: E402
from saltation.physics.fluid import fluid_at_grain  # noqa: E402
from saltation.physics.forces import (  # noqa: E402
    BASSET_PREFACTOR,
    ON_LIFT,
    R_SUBMERGED,
    RE_STAR,
    fluid_acceleration,
    make_coefficients,
)
from saltation.physics.history import history_end_step  # noqa: E402
from saltation.physics.spin import spin_rate  # noqa: E402

sys.path.insert(0, str(ROOT / "tests" / "peers"))
from sphere_advance import advance  # noqa: E402  (tests/peers: the flight-and-bed loop without contacts)

CASE = ROOT / "cases" / "default.toml"


# ---------------------------------------------------------------------- synthetic flow
def synthetic_channel(path, nx=48, ny=30, nz=48, nt=80, re_tau=395.0, dt_plus=4.0, seed=0):
    """An int16 dataset of the shipped one's shape: Reichardt mean profile plus smooth
    random fluctuations (a few Fourier modes advected at the local mean velocity),
    r.m.s. ~ 2 u⁺ away from the wall, zero at it. Only for timing."""
    path = Path(path)
    if (path / "meta.json").exists():
        return path
    from flowfields.analytic import reichardt

    rng = np.random.default_rng(seed)
    lx, lz = 2.0 * np.pi * re_tau, np.pi * re_tau
    x = (np.arange(nx) + 0.5) * lx / nx
    z = (np.arange(nz) + 0.5) * lz / nz
    eta = np.linspace(-1.0, 0.0, ny + 1)
    faces = re_tau * (1.0 + np.tanh(2.5 * eta) / np.tanh(2.5))
    y = 0.5 * (faces[1:] + faces[:-1])
    y = y * (0.5 / y[0]) ** (1.0 - y / re_tau)  # first centre at y⁺ = 0.5
    y = np.maximum.accumulate(y + 1e-9 * np.arange(ny))
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    mean = reichardt(Y)
    damp = np.minimum(Y / 15.0, 1.0)
    u = np.empty((nt, nx, ny, nz, 3), dtype=np.float64)
    modes = []
    for _ in range(12):
        kx = 2 * np.pi * rng.integers(1, 5) / lx
        kz = 2 * np.pi * rng.integers(1, 7) / lz
        ky = np.pi * rng.uniform(0.5, 3.0) / re_tau
        modes.append((kx, ky, kz, rng.uniform(0, 2 * np.pi, 3), rng.normal(0, 0.8, 3)))
    for n in range(nt):
        t = n * dt_plus
        fl = np.zeros((nx, ny, nz, 3))
        for kx, ky, kz, ph, amp in modes:
            arg = kx * (X - 0.8 * mean * t) + kz * Z + ky * Y
            for c in range(3):
                fl[..., c] += amp[c] * np.sin(arg + ph[c])
        u[n] = fl * damp[..., None]
        u[n, ..., 0] += mean
    write_dataset(path, x, y, z, u, re_tau, np.arange(nt) * dt_plus,
                  {"synthetic": True, "generator": "benchmarks/bench_saltation.py"}, dtype="int16")
    return path


# ---------------------------------------------------------------------- set-up
def make_case(dataset_path):
    overrides = {"flow.dataset": str(dataset_path)} if dataset_path is not None else None
    case = load_case(CASE, overrides)
    ds = open_dataset(case.flow.dataset)
    case = resolve_domain(case, _les_box_m(ds, case))
    return case, ds


class Setup:
    """Coefficients and a mid-saltation population for one flow."""

    def __init__(self, case, ds, **force_switches):
        self.case = case
        self.ds = ds
        self.f = ds.arrays
        self.re_star = case.shear_reynolds
        fc = case.forces
        sw = dict(weight=fc.weight, drag=fc.drag, lift=fc.lift, magnus=fc.magnus,
                  added_mass=fc.added_mass, fluid_acceleration=fc.fluid_acceleration, basset=fc.basset)
        sw.update(force_switches)
        self.coef = make_coefficients(
            tau_star=case.shields_number, R=case.submerged_specific_gravity, re_star=self.re_star,
            slope=case.flow.slope_radians, Cm=fc.added_mass_coefficient, C_L=fc.lift_coefficient,
            C_Omega=fc.magnus_coefficient, **sw)
        self.dt = case.dt_particle
        self.bed = run_bed_parameters(case, self.coef, self.dt)
        self.n_window = fc.basset_window
        self.hc = history.make_history_coefficients(self.dt, self.n_window)
        self.top = float(ds.y[-1]) / self.re_star
        self.seed = int(case.run.seed)
        d = case.particle.diameter
        lx, lz, _ = case.domain
        self.domain_d = (lx / d, lz / d)

    def run_steps(self, st, ws, t0, n_steps):
        """advance() n_steps, emptying the jump buffers whenever they fill."""
        done = 0
        while done < n_steps:
            k = advance(self.f, self.coef, self.bed, self.seed, st, ws, self.hc,
                        t0 + done * self.dt, self.dt, n_steps - done, self.top)
            st.jump_buf_n[:] = 0
            if np.any(st.status != 0):
                raise RuntimeError(f"a grain became non-finite: {np.nonzero(st.status)[0][:5]}")
            done += k
        return t0 + done * self.dt

    def spun_up(self, n0, duration):
        """n0 grains from grains/initial.py, run for `duration` d/u*: (state, t)."""
        pos, vel, spin = initial_conditions(n0, self.domain_d, self.seed)
        st = make_state(pos, vel, spin, 0.0, self.n_window)
        ws = make_workspace(n0)
        t = self.run_steps(st, ws, 0.0, int(round(duration / self.dt)))
        return st, t

    def tiled(self, st0, n):
        """n grains: copies of the spun-up population shifted at random in x and z."""
        n0 = len(st0.pos)
        reps = -(-n // n0)
        st = GrainState(*(np.concatenate([a] * reps)[:n].copy() for a in st0))
        rng = np.random.default_rng(12345)
        shift_x = np.repeat(np.r_[0.0, rng.uniform(0, self.domain_d[0], reps - 1)], n0)[:n]
        shift_z = np.repeat(np.r_[0.0, rng.uniform(0, self.domain_d[1], reps - 1)], n0)[:n]
        st.pos[:, 0] += shift_x
        st.pos[:, 2] += shift_z
        st.jump_x0[:] += shift_x
        st.fresh[:] = 0  # the fluid cache is per grain: sample afresh
        st.jump_buf_n[:] = 0
        return st


def time_advance(setup, st0, t0, n, threads, work, repeat):
    """Best particle-steps/s of `repeat` timings of ~`work` particle-steps at n grains."""
    numba.set_num_threads(threads)
    steps = max(int(work // n), 5)
    best = np.inf
    best_cpu = np.inf
    impacts = 0
    for _ in range(repeat):
        st = setup.tiled(st0, n)
        ws = make_workspace(n)
        t = setup.run_steps(st, ws, t0, 1)  # refill the per-grain fluid cache, untimed
        i0 = int(st.impacts.sum())
        cpu = time.process_time()
        tic = time.perf_counter()
        setup.run_steps(st, ws, t, steps)
        best = min(best, time.perf_counter() - tic)
        best_cpu = min(best_cpu, time.process_time() - cpu)
        impacts = int(st.impacts.sum()) - i0
    ps = n * steps
    return {"particle_steps_per_s": round(ps / best),
            "us_per_particle_step_per_thread": round(best * threads / ps * 1e6, 3),
            "cpu_us_per_particle_step": round(best_cpu / ps * 1e6, 3),
            "steps": steps, "bed_impacts_per_1000_particle_steps": round(1000 * impacts / ps, 2)}


# ---------------------------------------------------------------------- components alone
# Each kernel below repeats one part of a step's work for every grain, on the grains'
# current data, and nothing else (serial: 1 thread). Compiled like step_particle
# (_nrt=False), so they call the same compiled flow and physics kernels.
@njit(_nrt=False)
def _sample_stages(f, re_star, pos, vel, t, dt, n_steps, lift, uf, grad, dudt, vort, top, bot):
    # the 4 new fluid samples of a step (stages 2-4 and the step end) at straight-line
    # positions: centre with gradient, top and bottom velocity (with lift)
    n = pos.shape[0]
    for s in range(n_steps):
        for p in range(n):
            for stage in range(4):
                h = 0.5 * dt if stage < 2 else dt
                x = pos[p, 0] + (s * dt + h) * vel[p, 0]
                y = max(pos[p, 1] + h * vel[p, 1], 0.5)
                z = pos[p, 2] + (s * dt + h) * vel[p, 2]
                fluid_at_grain(f, re_star, x, y, z, t + s * dt + h, lift, uf[p], grad[p], dudt[p], vort[p],
                               top[p], bot[p])


@njit(_nrt=False)
def _force_stages(coef, x, n_steps, uf, grad, dudt, vort, top, bot, acc, dspin):
    # the 4 right-hand-side evaluations of a step: forces and spin rate
    n = x.shape[0]
    for _s in range(n_steps):
        for p in range(n):
            up = x[p, 3:6]
            spin = x[p, 6:9]
            for _stage in range(4):
                fluid_acceleration(up, uf[p], grad[p], dudt[p], vort[p], spin, top[p], bot[p], coef, acc[p])
                spin_rate(spin, vort[p], coef[R_SUBMERGED], coef[RE_STAR], dspin[p])


@njit(_nrt=False)
def _history_steps(coef, hc, dt, n_steps, vel, uf, hist_i, slip, meta, tail):
    # the Basset closure of a step (history.history_end_step)
    n = vel.shape[0]
    for _s in range(n_steps):
        for p in range(n):
            history_end_step(vel[p], uf[p], hist_i[p], coef[BASSET_PREFACTOR], dt, slip[p], meta[p], tail[p],
                             hc.window_weights, hc.tail_weight, hc.tail_decay, hc.tail_c_old, hc.tail_c_new,
                             hist_i[p], hc.tail_time)


def _best_cpu(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        tic = time.process_time()
        fn()
        best = min(best, time.process_time() - tic)
    return best


def time_components(setup, st0, t0, n, work, repeat):
    """CPU us per particle-step of the flow sampling, the force/spin evaluations and the
    history closure, each alone (1 thread), on a mid-saltation population."""
    numba.set_num_threads(1)
    steps = max(int(work // n), 5)
    st = setup.tiled(st0, n)
    w = make_workspace(n)
    setup.run_steps(st, w, t0, 1)  # real fluid samples in the workspace
    fl = (w.uf, w.grad, w.dudt, w.vort, w.uf_top, w.uf_bot)
    lift = setup.coef[ON_LIFT] != 0.0
    x = np.concatenate([st.pos, st.vel, st.spin], axis=1)
    hist = [a.copy() for a in (st.vel, w.uf, st.hist_i, st.hist_slip, st.hist_meta, st.hist_tail)]
    jobs = {
        "flow_sampling": lambda k: _sample_stages(setup.f, setup.coef[RE_STAR], st.pos, st.vel, t0, setup.dt, k,
                                                  lift, *fl),
        "forces_and_spin": lambda k: _force_stages(setup.coef, x, k, *fl, w.acc, w.dspin),
        "basset_history": lambda k: _history_steps(setup.coef, setup.hc, setup.dt, k, *hist),
    }
    out = {}
    for name, job in jobs.items():
        job(1)  # compile
        out[name] = round(_best_cpu(lambda job=job: job(steps), repeat) / (n * steps) * 1e6, 3)
    return out


# ---------------------------------------------------------------------- main
def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dataset", nargs="?", default=None)
    ap.add_argument("--synthetic", metavar="DIR", default=None,
                    help="write (if absent) and use a synthetic int16 dataset of the shipped shape")
    ap.add_argument("--n", default="1000,10000,100000")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--work", type=float, default=2e6, help="particle-steps per timing")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--spinup", type=float, default=20.0, help="d/u* of spin-up before timing")
    ap.add_argument("--spinup-grains", type=int, default=2000)
    ap.add_argument("--breakdown-n", type=int, default=10000)
    ap.add_argument("--no-breakdown", action="store_true")
    ap.add_argument("--fresh-cache", action="store_true",
                    help="compile everything into a new, empty Numba cache (cold compile time)")
    args = ap.parse_args()

    path = args.dataset
    if args.synthetic:
        path = synthetic_channel(args.synthetic)
    try:
        case, ds = make_case(path)
    except DatasetError as exc:
        sys.exit(f"{exc}\n(no dataset: try --synthetic DIR for a synthetic one of the shipped shape)")
    sizes = [int(float(v)) for v in args.n.split(",")]
    thread_list = [t for t in (int(v) for v in args.threads.split(",")) if t <= numba.config.NUMBA_NUM_THREADS]

    setup = Setup(case, ds)
    out = {
        "dataset": str(ds.path), "grid": list(ds.data.shape[1:4]), "snapshots": ds.n_snapshots,
        "storage": ds.meta["storage"]["dtype"], "case": str(CASE.relative_to(ROOT)),
        "re_star": round(setup.re_star, 3), "dt_particle": setup.dt, "basset_window": setup.n_window,
        "forces": "all on", "cpu_count": os.cpu_count(), "load_avg_1min_at_start": os.getloadavg()[0],
        "numba": numba.__version__, "threading_layer": None,
        "numba_cache": "fresh (cold compile)" if args.fresh_cache else "project cache (as found)",
    }
    # compile: the first call of every kernel (cache=True: a warm cache makes this small)
    numba.set_num_threads(thread_list[0])
    tic = time.perf_counter()
    pos, vel, spin = initial_conditions(4, setup.domain_d, 0)
    st = make_state(pos, vel, spin, 0.0, setup.n_window)
    setup.run_steps(st, make_workspace(4), 0.0, 2)
    out["compile_s"] = round(time.perf_counter() - tic, 3)
    out["threading_layer"] = numba.threading_layer()

    tic = time.perf_counter()
    numba.set_num_threads(max(thread_list))
    st0, t0 = setup.spun_up(args.spinup_grains, args.spinup)
    out["spinup"] = {"grains": args.spinup_grains, "duration_d_u": args.spinup, "wall_s": round(time.perf_counter() - tic, 2),
                     "mean_jumps_per_grain": round(float(st0.jump_count.mean()), 2),
                     "mean_height_d": round(float(st0.pos[:, 1].mean()), 3)}
    table = {}
    for n in sizes:
        for th in thread_list:
            table[f"N={n},threads={th}"] = time_advance(setup, st0, t0, n, th, args.work, args.repeat)
    out["throughput"] = table

    if not args.no_breakdown:
        nb = args.breakdown_n
        bd = {"N": nb, "threads": 1, "unit": "CPU us per particle-step (best of --repeat)"}
        row = table.get(f"N={nb},threads=1") or time_advance(setup, st0, t0, nb, 1, args.work, args.repeat)
        total = row["cpu_us_per_particle_step"]
        bd["step_all_forces"] = total
        parts = time_components(setup, st0, t0, nb, args.work, args.repeat)
        bd.update(parts)
        bd["rest"] = round(total - sum(parts.values()), 3)
        bd["rest_is"] = "RK4 stage bookkeeping, state copies, NaN checks, bed impacts, jump records"
        ablations = {}
        for label, sw in (("lift_off", {"lift": False}), ("basset_off", {"basset": False}),
                          ("lift_and_basset_off", {"lift": False, "basset": False})):
            s2 = Setup(case, ds, **sw)
            ablations[label] = time_advance(s2, st0, t0, nb, 1, args.work, args.repeat)["cpu_us_per_particle_step"]
        for label, kind in (("steady_loglaw_flow", "loglaw"), ("still_fluid", "still")):
            flow = profile_dataset(kind, y_top_plus=1000.0 * setup.re_star)
            s2 = Setup(case, ds)
            s2.ds, s2.f, s2.top = flow, flow.arrays, float(flow.y[-1]) / setup.re_star
            ablations[label] = time_advance(s2, st0, t0, nb, 1, args.work, args.repeat)["cpu_us_per_particle_step"]
        bd["whole_step_with"] = ablations
        out["breakdown"] = bd
    out["load_avg_1min_at_end"] = os.getloadavg()[0]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
