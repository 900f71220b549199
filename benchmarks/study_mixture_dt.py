"""Time-step convergence of the natural mixture (bonded-sphere grains) with soft contacts.

Runs ``saltation.run`` on the shipped LES at τ*/τ*c = 1.79 (d = 0.69 mm), the natural
mixture at --conc % in a --domain box, soft contacts, --bed, one thread, for each seed in
--seeds (default 1) and each dt in --dts (d/u*), and prints per dt: counted jumps and the mean H (d), L (d), U (u*),
T (d/u*) with standard errors from a delete-one-grain jackknife (one grain's jumps are
correlated), grain–grain collisions and bed contacts per grain per d/u*, the largest
component overlap (Dn) and the wall time.

Jumps are compared under one definition for every dt — the coarsest dt's (bed/jumps.py:
duration ≥ that dt, height ≥ 0.01 d), after --spinup d/u* and each grain's first 10 — and
in two bands of larger hops, because the finest steps resolve micro-hops (0.01–0.03 d
high, a step or two long) that a coarse step merges into one bed-contact episode.

    PYTHONPATH=. python benchmarks/study_mixture_dt.py --out /tmp/saltation-studies/mixture_dt \
        [--dts 0.02 0.01 0.005] [--conc 2.07] [--duration 2.0] [--spinup 20] [--seeds 1 2 3] \
        [--off basset lift ...] [--shape sphere]

``--seeds``: the runs of every seed pooled (jumps; the jackknife over the grains of all
seeds) and each seed's collision rate with its ratio to the coarsest dt's; ``--off``: the
named [forces] switched off in every run, to find which force a dt dependence comes from;
``--shape``: another particle.shape in the same runs (``sphere``: the sphere engine).

A rerun skips the dts whose run directory holds a completed summary.json.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

import saltation
from saltation.case.schema import SHAPES, ForcesConfig

BANDS = ((None, None), (0.1, 0.05), (0.3, 0.1))  # (H ≥, T ≥); None: the coarsest dt's definition


def case(conc: float, domain, duration: float, dt: float, bed: str, shape: str = "mixture", seed: int = 1,
         off=()) -> dict:
    """The run's case; ``off``: [forces] switches set to false."""
    return {"particle": {"diameter": 0.69e-3, "shape": shape}, "flow": {"source": "les", "tau_ratio": 1.79},
            "collisions": {"model": "soft"}, "bed": {"model": bed}, "forces": {f: False for f in off},
            "run": {"concentration": conc / 100, "domain": list(domain), "duration": duration, "dt_particle": dt,
                    "seed": seed, "threads": 1},
            "output": {"tracks": False, "vtk": False}}


def jackknife(jumps: pd.DataFrame) -> dict:
    """Mean and standard error of H, L, U, T: delete-one-grain jackknife of Σx/Σn (NaN with
    fewer than two grains, e.g. a band no jump of a short run falls in)."""
    g = jumps.groupby("particle")
    n = g.size().to_numpy().astype(float)
    if len(n) < 2:
        return {key: (float("nan"), float("nan")) for key in ("H", "L", "U", "T")}
    out = {}
    for key, col in (("H", "height"), ("L", "length"), ("U", "velocity"), ("T", "duration")):
        tot = g[col].sum().to_numpy()
        loo = (tot.sum() - tot) / (n.sum() - n)
        k = len(n)
        out[key] = (tot.sum() / n.sum(), float(np.sqrt((k - 1) / k * ((loo - loo.mean()) ** 2).sum())))
    return out


# the on/off switches of [forces] (case/schema.py)
FORCES = tuple(f.name for f in dataclasses.fields(ForcesConfig) if isinstance(f.default, bool))


def run_dir(out: Path, dt: float, seed: int, off, shape: str = "mixture") -> Path:
    """One run's directory: dt<dt>, with _s<seed>, _no-<force> and a <shape>_ prefix where
    they differ from the default (so the runs of earlier versions of this study are found)."""
    tag = ("" if shape == "mixture" else f"{shape}_") + f"dt{dt:g}" + (f"_s{seed}" if seed != 1 else "")
    return out / (tag + "".join(f"_no-{f}" for f in sorted(off)))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="/tmp/saltation-studies/mixture_dt")
    ap.add_argument("--dts", type=float, nargs="+", default=[0.02, 0.01, 0.005])
    ap.add_argument("--conc", type=float, default=2.07, help="%%")
    ap.add_argument("--domain", type=float, nargs=3, default=[0.024, 0.012, 0.02], help="Lx Lz H (m)")
    ap.add_argument("--duration", type=float, default=2.0, help="s")
    ap.add_argument("--spinup", type=float, default=20.0, help="d/u*: jumps that start earlier are not counted")
    ap.add_argument("--bed", choices=("virtual", "packed"), default="virtual")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1],
                    help="run.seed values: jumps pooled, collision rates per seed and their ratio to the coarsest dt")
    ap.add_argument("--shape", default="mixture", choices=SHAPES,
                    help="particle.shape (sphere: the sphere engine, for comparison)")
    ap.add_argument("--off", nargs="*", default=[], choices=FORCES, metavar="FORCE",
                    help=f"[forces] switched off in every run (attribution of a dt dependence): {', '.join(FORCES)}")
    a = ap.parse_args(argv)
    runs = {}
    for dt in a.dts:
        for seed in a.seeds:
            out = run_dir(Path(a.out), dt, seed, a.off, a.shape)
            done = out / "summary.json"
            if not (done.exists() and json.loads(done.read_text()).get("status") == "completed"):
                t0 = time.perf_counter()
                saltation.run(case(a.conc, a.domain, a.duration, dt, a.bed, a.shape, seed, a.off), out=out,
                              progress=False, overwrite=True)
                print(f"dt = {dt:g}, seed {seed}: {time.perf_counter() - t0:.0f} s", flush=True)
            runs[dt, seed] = (json.loads(done.read_text()), pd.read_parquet(out / "jumps.parquet"))
    coarse = max(a.dts)
    off = f"; forces off: {', '.join(a.off)}" if a.off else ""
    name = "natural mixture" if a.shape == "mixture" else f"shape {a.shape}"
    print(f"\n{name}, C = {a.conc} %, domain {a.domain[0]} x {a.domain[1]} m, {a.bed} bed, soft contacts, "
          f"{a.duration} s, seeds {' '.join(map(str, a.seeds))}{off}; jumps starting after {a.spinup} d/u*, "
          f"first 10 per grain dropped")
    for h_min, t_min in BANDS:
        h_min, t_min = (0.01, coarse) if h_min is None else (h_min, t_min)
        print(f"\nH >= {h_min:g} d, T >= {t_min:g} d/u*")
        print(f"{'dt':>7s} {'jumps':>7s} {'H (d)':>16s} {'L (d)':>16s} {'U (u*)':>16s} {'T (d/u*)':>16s}")
        for dt in a.dts:
            parts = []
            for k, seed in enumerate(a.seeds):  # grains of different seeds are different grains
                j = runs[dt, seed][1]
                j = j[(~j["discarded"]) & (j["t_start"] >= a.spinup) & (j["height"] >= h_min)
                      & (j["duration"] >= t_min)]
                parts.append(j.assign(particle=j["particle"] + k * 10**9))
            j = pd.concat(parts)
            s = jackknife(j)
            print(f"{dt:7g} {len(j):7d} " + " ".join(f"{m:9.4f} ± {e:.4f}" for m, e in s.values()))
    print(f"\n{'dt':>7s} {'seed':>5s} {'n_sub':>6s} {'coll/grain/(d/u*)':>18s} {'ratio':>6s} {'bed/grain/(d/u*)':>17s} "
          f"{'max overlap':>12s} {'free s':>8s} {'contacts s':>11s}")
    for dt in a.dts:
        for seed in a.seeds:
            s = runs[dt, seed][0]
            c, t = s["collisions"], s["timing"]
            base = runs[coarse, seed][0]["collisions"]["per_particle_per_unit_time"]
            print(f"{dt:7g} {seed:5d} {c['soft']['substeps_per_step']:6d} {c['per_particle_per_unit_time']:18.3f} "
                  f"{c['per_particle_per_unit_time'] / base:6.3f} {c['bed_per_particle_per_unit_time']:17.3f} "
                  f"{c['overlap']['max_over_d']:12.4f} {t['free_flight_s']:8.1f} {t['particle_collisions_s']:11.1f}")
    print("ratio: the collision rate over that of the coarsest dt with the same seed")


if __name__ == "__main__":
    main()
