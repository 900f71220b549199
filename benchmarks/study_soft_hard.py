"""Soft against hard grain contacts on the reduced paper domain (issue 19, item 3).

    python benchmarks/study_soft_hard.py [--concentrations 0.0012 0.0052 0.0207 0.0394]
        [--seeds 1] [--duration 1.0] [--scale 1.0] [--out /tmp/saltation-studies/soft_hard]

For each concentration and seed, one run with ``collisions.model = "soft"`` and one with
``"hard"`` (the reduced sweep's physics: d = 0.69 mm quartz, the shipped LES at
τ*/τ*c = 1.79, virtual bed, e = 0.65, f = 0.10, dt = 0.02 d/u*, domain of
cases/concentration_sweep_reduced.toml × ``scale`` in x and z). Prints, per run: jump
statistics (H, L in d; U and its spread in u*; jumps counted), the instantaneous velocity
spreads of the grains at the end (u*), their mean centre height (d), grain–grain
collisions, and the overlaps of the end state (pairs closer than d: mean, 99th
percentile and largest overlap, in d). Writes results.json under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

import saltation
from saltation.contacts.cells import make_grid, neighbour_pairs

D = 0.69e-3
REDUCED = (0.02933, 0.01467, 0.028)  # m: Lx, Lz, H of cases/concentration_sweep_reduced.toml


def tables(model, conc, duration, scale, seed):
    return {
        "particle": {"diameter": D, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1e-6},
        "flow": {"source": "les", "tau_ratio": 1.79},
        "bed": {"model": "virtual", "coefficients": "schmeeckle-2001"},
        "collisions": {"model": model, "restitution": 0.65, "friction": 0.10},
        "run": {"concentration": conc, "domain": [REDUCED[0] * scale, REDUCED[1] * scale, REDUCED[2]],
                "duration": duration, "dt_particle": 0.02, "seed": seed, "threads": 1},
        "output": {"tracks": True, "tracks_interval": duration, "vtk": False},
    }


def end_overlaps(pos, lx, lz):
    """Overlaps (d) of the pairs closer than d in the end state (periodic x, z)."""
    p = pos.copy()
    p[:, 0] %= lx
    p[:, 2] %= lz
    ly = max(p[:, 1].max() + 2.0, 4.0)
    p[:, 1] = np.clip(p[:, 1], 0.0, ly - 1e-9)
    pairs = neighbour_pairs(p, make_grid((lx, ly, lz), 1.0, (True, False, True)), 1.0)
    sep = p[pairs[:, 0]] - p[pairs[:, 1]]
    sep[:, 0] -= lx * np.round(sep[:, 0] / lx)
    sep[:, 2] -= lz * np.round(sep[:, 2] / lz)
    return 1.0 - np.linalg.norm(sep, axis=1)


def one(model, conc, seed, args) -> dict:
    out = Path(args.out) / f"{model}_c{conc}_s{seed}"
    t0 = time.perf_counter()
    saltation.run(tables(model, conc, args.duration, args.scale, seed), out=out, progress=False, overwrite=True)
    wall = time.perf_counter() - t0
    s = json.loads((out / "summary.json").read_text())
    tr = pd.read_parquet(out / "tracks.parquet")
    last = tr[tr.t == tr.t.max()]
    pos = last[["x", "y", "z"]].to_numpy()
    vel = last[["u", "v", "w"]].to_numpy()
    ov = end_overlaps(pos, REDUCED[0] * args.scale / D, REDUCED[1] * args.scale / D)
    j = s["jumps"]
    return {"model": model, "concentration_pct": 100 * conc, "seed": seed, "n": s["n_particles"], "wall_s": wall,
            "H": j["H_mean"], "L": j["L_mean"], "U": j["U_mean"], "U_std": j["U_std"], "jumps": j["count"],
            "u_std": vel[:, 0].std(), "v_std": vel[:, 1].std(), "w_std": vel[:, 2].std(), "y_mean": pos[:, 1].mean(),
            "collisions": s["collisions"]["particle_particle"], "pairs_touching": len(ov),
            "overlap_mean": float(ov.mean()) if len(ov) else 0.0,
            "overlap_p99": float(np.percentile(ov, 99)) if len(ov) else 0.0,
            "overlap_max": float(ov.max()) if len(ov) else 0.0}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concentrations", type=float, nargs="+", default=[0.0012, 0.0052, 0.0207, 0.0394])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--duration", type=float, default=1.0, help="s simulated")
    ap.add_argument("--scale", type=float, default=1.0, help="x and z of the reduced domain times this")
    ap.add_argument("--out", default="/tmp/saltation-studies/soft_hard")
    args = ap.parse_args()
    rows = []
    print(f"{'C %':>6} {'seed':>4} {'model':>5} {'N':>5} {'H/d':>6} {'L/d':>6} {'U/u*':>6} {'σU':>5} "
          f"{'jumps':>6} {'σu':>5} {'ȳ/d':>5} {'coll':>8} {'touch':>5} {'ov99':>6} {'ovmax':>6} {'wall s':>7}")
    for conc in args.concentrations:
        for seed in args.seeds:
            for model in ("soft", "hard"):
                r = one(model, conc, seed, args)
                rows.append(r)
                print(f"{r['concentration_pct']:6.2f} {seed:4d} {model:>5} {r['n']:5d} {r['H']:6.3f} {r['L']:6.2f} "
                      f"{r['U']:6.2f} {r['U_std']:5.2f} {r['jumps']:6d} {r['u_std']:5.2f} {r['y_mean']:5.2f} "
                      f"{r['collisions']:8d} {r['pairs_touching']:5d} {r['overlap_p99']:6.3f} {r['overlap_max']:6.3f} "
                      f"{r['wall_s']:7.1f}", flush=True)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "results.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
