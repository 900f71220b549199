"""Cost of soft contacts between bonded-sphere grains (the natural mixture) against spheres
in the same box at the same concentration, through ``saltation.run`` as a user runs it.

    python benchmarks/bench_mixture_contacts.py [--concentrations 1.03 2.07] [--threads 1 2]
        [--domain 0.024 0.012 0.02] [--spinup 0.2] [--window 0.2] [--shapes mixture sphere]

Each case (default: the shipped LES at τ*/τ*c = 1.79, d = 0.69 mm, soft contacts, virtual
bed, dt = 0.02 d/u*, seed 1) is run twice in this process: for ``--spinup`` seconds and
for ``--spinup`` + ``--window`` seconds. The figures are the difference of the two runs'
timers and counters (summary.json "timing", "collisions.contact_phase"), so they are those
of the window after the spin-up, not of the first steps (kernels compiled before, by a
short run of the same case). Printed per case: grains, free flight (spheres: with their bed pass; the
composites' bed is in their free flight) and contact phase in µs per grain-step and their
ratio, contact sub-steps per step, the engaged fraction (grains sub-stepped in a step / N;
composites only: the sphere phase joins grains within the step, contacts/phase.py), ns per
grain-sub-step done, and a hash of the jumps of
the longer run, which must be the same on every thread count.
"""
from __future__ import annotations

import argparse
import hashlib
import tempfile
import time

import pandas as pd

import saltation


def _case(shape, conc, domain, duration, threads):
    return {"particle": {"diameter": 0.69e-3, "shape": shape}, "flow": {"source": "les", "tau_ratio": 1.79},
            "collisions": {"model": "soft"},
            "run": {"concentration": conc / 100, "domain": list(domain), "duration": duration,
                    "dt_particle": 0.02, "seed": 1, "threads": threads},
            "output": {"tracks": False, "vtk": False}}


def _run(case):
    out = tempfile.mkdtemp(prefix="bench_mixture_")
    t0 = time.perf_counter()
    res = saltation.run(case, out=out, progress=False)
    s = res.summary
    cp = s["collisions"].get("contact_phase", {})
    jumps = pd.read_parquet(f"{out}/jumps.parquet")
    # the sphere engine times its bed pass apart; the composites' bed is in their free flight
    return {"wall": time.perf_counter() - t0, "free": s["timing"]["free_flight_s"] + s["timing"].get("bed_s", 0.0),
            "contacts": s["timing"]["particle_collisions_s"], "steps": s["steps"], "n": s["n_particles"],
            "n_sub": s["collisions"]["soft"]["substeps_per_step"],
            "gss": cp.get("substepped_grain_substeps", 0), "engaged": cp.get("engaged_grain_steps", -1),
            "hash": hashlib.sha1(pd.util.hash_pandas_object(jumps).values.tobytes()).hexdigest()[:12]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concentrations", type=float, nargs="+", default=[1.03, 2.07], help="%%")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--domain", type=float, nargs=3, default=[0.024, 0.012, 0.02], help="Lx Lz H (m)")
    ap.add_argument("--spinup", type=float, default=0.2, help="s before the window")
    ap.add_argument("--window", type=float, default=0.2, help="s timed")
    ap.add_argument("--shapes", nargs="+", default=["mixture", "sphere"])
    a = ap.parse_args(argv)
    rows = []
    for shape in a.shapes:
        for conc in a.concentrations:
            saltation.run(_case(shape, conc, a.domain, 0.005, 1), out=tempfile.mkdtemp(), progress=False)  # compile
            for thr in a.threads:
                r0 = _run(_case(shape, conc, a.domain, a.spinup, thr))
                r1 = _run(_case(shape, conc, a.domain, a.spinup + a.window, thr))
                gs = r1["n"] * (r1["steps"] - r0["steps"])
                gss = r1["gss"] - r0["gss"]
                free, cont = r1["free"] - r0["free"], r1["contacts"] - r0["contacts"]
                rows.append((shape, conc, thr, r1["n"], 1e6 * free / gs, 1e6 * cont / gs, cont / free, r1["n_sub"],
                             (r1["engaged"] - r0["engaged"]) / gs if r1["engaged"] >= 0 else float("nan"),
                             1e9 * cont / max(gss, 1), r1["hash"]))
                print(f"{shape} {conc} % {thr} thr.: done ({r0['wall'] + r1['wall']:.0f} s)", flush=True)
    print(f"\nwindow {a.window} s after a {a.spinup} s spin-up, domain {a.domain} m, dt 0.02 d/u*, soft contacts")
    head = ("shape", "C %", "thr", "N", "free us/g-st", "contacts us/g-st", "cont/free", "n_sub", "engaged",
            "ns/g-sub", "jumps hash")
    print(("{:>8} {:>5} {:>3} {:>5} {:>12} {:>16} {:>9} {:>5} {:>7} {:>8} {:>12}").format(*head))
    for r in rows:
        print(f"{r[0]:>8} {r[1]:>5} {r[2]:>3} {r[3]:>5} {r[4]:>12.2f} {r[5]:>16.2f} {r[6]:>9.1f} {r[7]:>5} "
              f"{r[8]:>7.2f} {r[9]:>8.0f} {r[10]:>12}")
    for shape in a.shapes:
        for conc in a.concentrations:
            hashes = {r[10] for r in rows if r[0] == shape and r[1] == conc}
            if len(hashes) > 1:
                print(f"WARNING: {shape} at {conc} %: the jumps differ between thread counts")
    for conc in a.concentrations:
        for thr in a.threads:
            m = [r for r in rows if r[0] == "mixture" and r[1] == conc and r[2] == thr]
            s = [r for r in rows if r[0] == "sphere" and r[1] == conc and r[2] == thr]
            if m and s:
                print(f"C = {conc} %, {thr} thr.: mixture / spheres per grain-step: contact phase "
                      f"{m[0][5] / s[0][5]:.1f}x, whole step {(m[0][4] + m[0][5]) / (s[0][4] + s[0][5]):.1f}x")


if __name__ == "__main__":
    main()
