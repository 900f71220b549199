"""Contact-kernel throughput against LAMMPS: particle-steps per second of a granular gas.

    python benchmarks/bench_contacts_lammps.py [--n 100000] [--solid-fraction 0.04]
        [--steps 4000] [--skin 0.3] [--threads 1 2] [--lmp lmp] [--keep DIR]

Set-up (the same for both codes): N equal spheres (d = 1, m = 1) at the given solid
fraction in a periodic cube, no gravity, Gaussian velocities σ = 1 per component;
soft contacts with the case defaults in particle units — k_n = 5·10⁵ (overlap ≤ 1 % d at
10 u*), k_t = (2/7) k_n, e = 0.65 (γ_n from ``normal_damping``), γ_t = 0, f = 0.10 —
dt = t_c/20 (SPEC §5's coarsest resolution), a neighbour skin of 0.3 d checked every
step. LAMMPS: serial ``lmp`` (one MPI rank), ``pair_style gran/hooke/history`` +
``fix nve/sphere``, ``neighbor SKIN bin``, ``neigh_modify delay 0 every 1 check yes``;
its speed is its own "Loop time" (set-up and file reading excluded). Ours:
``contacts.pairs.advance_granular`` (velocity Verlet, contact forces, neighbour list with the
same skin and criterion) on 1 and 2 Numba threads, timed after a warm-up (compile time
reported apart).

Ours runs on the grains in their given (random) memory order on 1 and 2 threads, and
once more on 1 thread after renumbering the grains in cell order (LAMMPS sorts its atoms
spatially by default, every 1000 steps; our kernels never reorder the caller's arrays).

Prints one JSON object: particle-steps/s for LAMMPS and for each of our runs (wall
clock, and per CPU-second: LAMMPS's loop time × its reported CPU use, our process CPU
time), the ratios to LAMMPS (``ratio_1thread_vs_lammps``: ours on one thread, unsorted,
against one LAMMPS rank, wall clock), neighbour-list builds and collisions of both, and
the machine load (the 2 cores may be shared: read ``load_*`` and ``busy_processes``
before comparing numbers from different runs; the CPU-second rates are less sensitive
to a busy neighbour, the 2-thread run is very sensitive to it).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from saltation.contacts import pairs as C

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "peers"))
from lammps_gas import gas_input, write_gas_data  # noqa: E402  (tests/peers: a test and benchmark helper)


def run_lammps(lmp, workdir, model, dt, steps, skin):
    (workdir / "in.gas").write_text(gas_input(model, dt, steps, steps, skin))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    subprocess.run([lmp, "-in", "in.gas", "-log", "log.gas", "-screen", "none"], cwd=workdir, check=True, env=env)
    wall = time.perf_counter() - t0
    log = (workdir / "log.gas").read_text()
    loop = float(re.search(r"Loop time of ([0-9.eE+-]+) on 1 procs", log).group(1))
    builds = int(re.search(r"Neighbor list builds = (\d+)", log).group(1))
    cpu = re.search(r"([0-9.]+)% CPU use", log)
    return {"loop_s": loop, "wall_s": round(wall, 3), "builds": builds,
            "cpu_use_percent": float(cpu.group(1)) if cpu else None,
            "version": re.search(r"LAMMPS \(([^)]*)\)", log).group(1)}


def busy_processes():
    """Other processes using more than half a core right now (ps), for the record."""
    try:
        out = subprocess.run(["ps", "-eo", "pcpu,comm", "--sort=-pcpu"], capture_output=True, text=True,
                             check=True).stdout.splitlines()[1:8]
    except (OSError, subprocess.CalledProcessError):
        return []
    rows = [line.split(None, 1) for line in out]
    return [f"{name.strip()} {pc}%" for pc, name in rows if float(pc) > 50.0 and "python" not in name]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--solid-fraction", type=float, default=0.04)
    ap.add_argument("--steps", type=int, default=4000)
    ap.add_argument("--skin", type=float, default=0.3)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--lmp", default="lmp")
    ap.add_argument("--keep", default=None, help="directory for the LAMMPS files (default: a temporary one)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    n = args.n
    length = (n * math.pi / 6.0 / args.solid_fraction) ** (1.0 / 3.0)
    model = C.make_contact_model(kn=5.0e5, restitution=0.65, friction=0.10, gamma_t=0.0, lever=C.LEVER_RADIUS)
    dt = C.contact_duration(model) / 20.0
    pos0, vel0, spin0 = C.random_gas(n, (length,) * 3, seed=args.seed, speed=1.0)
    out = {
        "n_particles": n, "solid_fraction": args.solid_fraction, "box": length, "steps": args.steps,
        "dt": dt, "contact_duration": C.contact_duration(model), "skin": args.skin,
        "kn": model.kn, "kt": model.kt, "gamma_n": model.gamma_n, "gamma_t": model.gamma_t,
        "friction": model.friction, "load_before": os.getloadavg(), "busy_processes": busy_processes(),
        "cpu_count": os.cpu_count(),
    }

    lmp = shutil.which(args.lmp)
    if lmp is None:
        out["lammps"] = None
    else:
        work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_lammps_"))
        work.mkdir(parents=True, exist_ok=True)
        write_gas_data(work / "data.gas", pos0, vel0, spin0, length)
        res = run_lammps(lmp, work, model, dt, args.steps, args.skin)
        res["particle_steps_per_s"] = round(n * args.steps / res["loop_s"])
        if res["cpu_use_percent"]:
            res["particle_steps_per_cpu_s"] = round(n * args.steps / (res["loop_s"] * res["cpu_use_percent"] / 100.0))
        out["lammps"] = res
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    # ours: compile + warm-up on a copy, then timed runs from the same initial state
    p, v, w = pos0.copy(), vel0.copy(), spin0.copy()
    t0 = time.perf_counter()
    cl = C.make_contact_list(p, (length,) * 3, (True, True, True), 1.0, args.skin)
    C.advance_granular(p, v, w, np.zeros((n, 3)), np.zeros((n, 3)), model, cl, dt, 5)
    out["compile_and_warmup_s"] = round(time.perf_counter() - t0, 3)
    ours = {}
    runs = [(t, False) for t in args.threads] + [(1, True)]
    for threads, sort in runs:
        if threads > numba.config.NUMBA_NUM_THREADS:
            continue
        numba.set_num_threads(threads)
        p, v, w = pos0.copy(), vel0.copy(), spin0.copy()
        cl = C.make_contact_list(p, (length,) * 3, (True, True, True), 1.0, args.skin)
        if sort:  # grains renumbered in cell order once (LAMMPS sorts atoms every 1000 steps)
            o = cl.order.copy()
            p, v, w = p[o].copy(), v[o].copy(), w[o].copy()
            cl = C.make_contact_list(p, (length,) * 3, (True, True, True), 1.0, args.skin)
        builds0 = int(cl.builds[0])
        t0 = time.perf_counter()
        c0 = time.process_time()
        cl, _ = C.advance_granular(p, v, w, np.zeros((n, 3)), np.zeros((n, 3)), model, cl, dt, args.steps)
        el = time.perf_counter() - t0
        cpu = time.process_time() - c0
        ours[f"{threads}_thread" + ("_sorted" if sort else "")] = {
            "seconds": round(el, 3), "particle_steps_per_s": round(n * args.steps / el),
            "cpu_seconds": round(cpu, 3), "particle_steps_per_cpu_s": round(n * args.steps / cpu),
            "builds": int(cl.builds[0]) - builds0, "collisions": int(cl.collisions.sum() // 2),
            "max_overlap_d": float(cl.max_overlap.max()),
        }
    out["ours"] = ours
    lam = out.get("lammps")
    if lam:
        for key, run in ours.items():
            run["ratio_vs_lammps"] = round(run["particle_steps_per_s"] / lam["particle_steps_per_s"], 3)
            if key.startswith("1_thread") and lam.get("particle_steps_per_cpu_s"):
                run["cpu_ratio_vs_lammps"] = round(run["particle_steps_per_cpu_s"] / lam["particle_steps_per_cpu_s"], 3)
        if "1_thread" in ours:
            out["ratio_1thread_vs_lammps"] = ours["1_thread"]["ratio_vs_lammps"]
    out["load_after"] = os.getloadavg()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
