"""Cost of the run loop with grain contacts against N: wall time per step, particle-steps/s,
the free flight / bed / contacts split, and peak memory per grain (issue 4, "Scaling").

    python benchmarks/bench_scaling.py [--threads 1] [--contacts soft] [--bed virtual]
        [--fixed-c 0.0103] [--n-fixed-c 1000 5000 20000 50000 200000]
        [--n-fixed-domain 1000 3000 6500 13000 26000 52000 99000 125000]
        [--spinup 60] [--steps 20] [--json OUT]

Two series, each point in its own process (so peak RSS belongs to that point alone):

(a) fixed concentration ``--fixed-c`` (default 1.03 %): the bed area grows with N, the
    height stays the paper's 0.088 m (Lx : Lz kept at the paper's 0.176 : 0.028), so every
    point has the same grains per bed area and the same starting layer: the same
    physics per grain, only more of it (a weak-scaling test of linearity in N);
(b) fixed domain (the paper's [0.176, 0.088, 0.028] m, the shipped LES tiled over it):
    N = 1 000 … 99 000 are the paper's concentrations 0.04 … 3.94 %; 125 000 is 5 %, the
    one-way-coupling limit the case files accept.

Case: quartz d = 0.69 mm in water, τ*/τ*c = 1.79, all forces, shipped LES dataset,
dt = 0.02 d/u* (cases/default.toml), soft contacts with the case defaults (k_n from 1 %
overlap at 10 u*, 128 sub-steps per step). Every point first runs ``--spinup`` steps
(not timed: the grains start in a dense layer near the bed and need to spread into
saltation), then ``--steps`` timed steps. Timings are wall time of the stepping only
(stepping.Stepper.advance; its per-phase timers give the split); compile time is
excluded (warm-up on a small run in the same process first). Peak RSS: the process's
``ru_maxrss`` at the end minus its value after the warm-up (imports, dataset, compiled
code), divided by N.

The contact phase (contacts/phase.py) sub-steps only the grains that can touch something in the
step (column "sub-st.%": grain-sub-steps done / (N x sub-steps)); it copies them and their
list neighbours into compact, cell-ordered arrays once per step, runs the 128 sub-steps
on those and scatters the result back (contacts/phase.py, "Memory layout"), so the cost per
grain-sub-step should not grow with N. Column "ns/g-sub": contact-phase wall time per
grain-sub-step done (it also carries the phase's O(N) passes: reach, list rebuild,
engagement test, gather). The sub-stepped share depends on how far the grains have
spread from their initial layer; every point gets the same spin-up and timed steps, so
in series (a) the sub-stepped share should come out the same at every N.
Columns "blk/st" and "redo": blocks per step and contact phases redone (contacts/phase.py,
"Blocks": the sub-stepped grains run block by block while each block sits in cache).

Prints a table and one JSON object (also written to ``--json``). The machine may be
shared: the 1-minute load average is printed with every point, and ``cpu_per_step_ms``
/ ``wall_per_step_ms`` below 1 means the process did not have a core to itself.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import time

PAPER_DOMAIN = (0.176, 0.088, 0.028)


def case_tables(n, concentration=None, domain=None, contacts="soft", bed="virtual", threads=1):
    run = {"n_particles": int(n), "duration": 1.0, "dt_particle": 0.02, "seed": 7, "threads": threads}
    if concentration is not None:
        run["concentration"] = float(concentration)
    if domain is not None:
        run["domain"] = list(domain)
    return {
        "particle": {"diameter": 0.69e-3, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1e-6},
        "flow": {"source": "les", "tau_ratio": 1.79},
        "bed": {"model": bed},
        "collisions": {"model": contacts},
        "run": run,
        "output": {"tracks": False, "vtk": False},
    }


def bed_area_domain(n, concentration, d=0.69e-3):
    """[Lx, Lz, H] (m) holding n grains at the volume fraction: the paper's height H, its
    Lx : Lz, the bed area scaled (series (a))."""
    lx0, lz0, h = PAPER_DOMAIN
    area = n * math.pi / 6.0 * d ** 3 / (concentration * h)
    scale = math.sqrt(area / (lx0 * lz0))
    return (scale * lx0, scale * lz0, h)


def one_point(args) -> dict:
    """Runs in a child process: warm up, measure one (N, domain) point."""
    import numba

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_dense import build, steps  # noqa: E402 - the benchmarks' folder

    numba.set_num_threads(args.threads)

    # warm-up: compiled code and the dataset in memory, then the baseline RSS
    sim, ds, st, ws = build(case_tables(300, domain=(0.03, 0.015, 0.005), contacts=args.contacts, bed=args.bed),
                            out="/tmp/bench_scaling_unused")
    sim.stepper.advance(ds.arrays, st, ws, 0.0, 3, 0)
    del sim, st, ws
    base_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    domain = PAPER_DOMAIN if args.concentration is None else bed_area_domain(args.n, args.concentration)
    tables = case_tables(args.n, domain=domain, contacts=args.contacts, bed=args.bed, threads=args.threads)
    t0 = time.perf_counter()
    sim, ds, st, ws = build(tables, out="/tmp/bench_scaling_unused")
    setup_s = time.perf_counter() - t0
    f = ds.arrays
    stepper = sim.stepper
    done = steps(sim, f, st, ws, 0, args.spinup)
    stepper.timers[:] = 0.0
    counters0 = stepper.ph.counters.copy() if len(stepper.ph.counters) else None
    load = os.getloadavg()[0]
    c0 = time.process_time()
    t0 = time.perf_counter()
    timed = steps(sim, f, st, ws, done, args.steps)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    ff, pc, bd = (float(x) for x in stepper.timers)
    c = sim.case
    out = {
        "n": sim.n,
        "concentration_pct": 100.0 * c.concentration,
        "domain_d": [round(x / c.particle.diameter, 1) for x in c.domain],
        "threads": args.threads,
        "steps": timed,
        "wall_per_step_ms": 1e3 * wall / timed,
        "cpu_per_step_ms": 1e3 * cpu / timed,
        "particle_steps_per_s": sim.n * timed / wall,
        "us_per_particle_step": 1e6 * wall / (sim.n * timed),
        "free_flight_us": 1e6 * ff / (sim.n * timed),
        "bed_us": 1e6 * bd / (sim.n * timed),
        "contacts_us": 1e6 * pc / (sim.n * timed),
        "setup_s": setup_s,
        "peak_rss_bytes_per_particle": (peak_kb - base_kb) * 1024.0 / sim.n,
        "load_avg_1min": load,
    }
    if counters0 is not None:
        d = stepper.ph.counters - counters0
        n_sub = stepper.n_sub
        out["substepped_fraction"] = float(d[3]) / (n_sub * timed * sim.n)
        out["contacts_ns_per_grain_substep"] = 1e9 * pc / float(d[3]) if d[3] else None
        out["collisions_per_particle"] = float(stepper.cl.collisions.sum()) / sim.n
        out["missed_contacts"] = int(d[4])
        out["blocks_per_step"] = float(d[5]) / timed  # contacts/phase.py, "Blocks"
        out["phases_redone_unblocked"] = int(d[6])
        out["phases_redone_merged"] = int(d[7])
    return out


def run_point(n, concentration, args) -> dict:
    cmd = [sys.executable, __file__, "--one", str(n), "--threads", str(args.threads), "--contacts", args.contacts,
           "--bed", args.bed, "--spinup", str(args.spinup), "--steps", str(args.steps)]
    if concentration is not None:
        cmd += ["--concentration", repr(concentration)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        return {"n": n, "error": res.stderr.strip().splitlines()[-1] if res.stderr.strip() else f"rc {res.returncode}"}
    return json.loads(res.stdout.strip().splitlines()[-1])


def table(rows, title):
    head = (f"{'N':>7} {'C %':>6} {'ms/step':>9} {'p-steps/s':>10} {'us/p-step':>9} {'free fl.':>8} {'bed':>6} "
            f"{'contacts':>8} {'sub-st.%':>8} {'ns/g-sub':>8} {'blk/st':>6} {'redo':>4} {'coll/p':>7} {'RSS B/p':>8} "
            f"{'load':>5}")
    print(f"\n{title}\n{head}\n" + "-" * len(head))
    for r in rows:
        if "error" in r:
            print(f"{r['n']:>7} error: {r['error']}")
            continue
        print(f"{r['n']:>7} {r['concentration_pct']:>6.2f} {r['wall_per_step_ms']:>9.2f} {r['particle_steps_per_s']:>10.3g} "
              f"{r['us_per_particle_step']:>9.2f} {r['free_flight_us']:>8.2f} {r['bed_us']:>6.2f} {r['contacts_us']:>8.2f} "
              f"{100 * r.get('substepped_fraction', 0.0):>8.2f} {r.get('contacts_ns_per_grain_substep') or 0.0:>8.0f} "
              f"{r.get('blocks_per_step', 0.0):>6.0f} "
              f"{r.get('phases_redone_merged', 0) + r.get('phases_redone_unblocked', 0):>4d} "
              f"{r.get('collisions_per_particle', 0.0):>7.2f} "
              f"{r['peak_rss_bytes_per_particle']:>8.0f} {r['load_avg_1min']:>5.2f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--contacts", default="soft", choices=("soft", "hard", "off"))
    ap.add_argument("--bed", default="virtual", choices=("virtual", "packed"))
    ap.add_argument("--fixed-c", type=float, default=0.0103)
    ap.add_argument("--n-fixed-c", type=int, nargs="*", default=[1000, 5000, 20000, 50000, 200000])
    ap.add_argument("--n-fixed-domain", type=int, nargs="*", default=[1000, 3000, 6500, 13000, 26000, 52000, 99000, 125000])
    ap.add_argument("--spinup", type=int, default=60)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--json", default=None)
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--concentration", type=float, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one is not None:
        args.n = args.one
        print(json.dumps(one_point(args)))
        return
    t0 = time.perf_counter()
    fixed_c = [run_point(n, args.fixed_c, args) for n in args.n_fixed_c]
    table(fixed_c, f"(a) fixed concentration {100 * args.fixed_c:.2f} % (bed area grows), contacts {args.contacts}, "
                   f"bed {args.bed}, {args.threads} thread(s); times per particle-step in us")
    fixed_d = [run_point(n, None, args) for n in args.n_fixed_domain]
    table(fixed_d, "(b) fixed domain [0.176, 0.088, 0.028] m (concentration grows)")
    result = {"fixed_concentration": fixed_c, "fixed_domain": fixed_d, "wall_s": time.perf_counter() - t0,
              "cpu_count": os.cpu_count()}
    for name, rows in (("fixed_concentration", fixed_c), ("fixed_domain", fixed_d)):
        ok = [r for r in rows if "error" not in r]
        if len(ok) >= 2:
            import numpy as np

            slope = np.polyfit(np.log([r["n"] for r in ok]), np.log([r["wall_per_step_ms"] for r in ok]), 1)[0]
            result[f"{name}_loglog_slope_time_vs_N"] = float(slope)
    print(json.dumps(result, indent=1))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
