"""Sampling throughput: points per second for velocity + gradient + ∂u/∂t at random points
near the bed (y⁺ < 60), with 1 and 2 Numba threads, on a flow dataset.

    python benchmarks/bench_sampler.py [DATASET] [--points N] [--repeat R]

Prints one JSON object. Compile time is reported apart (first call)."""
from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np

from flowfields import open_dataset
from flowfields.sampler import sample_many


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset", nargs="?", default=None)
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    ds = open_dataset(args.dataset)
    f = ds.arrays
    lx, _, lz = ds.box
    rng = np.random.default_rng(0)
    n = args.points
    pts = np.column_stack([rng.uniform(0, lx, n), rng.uniform(0, min(60.0, ds.y[-1]), n), rng.uniform(0, lz, n)])
    u = np.empty((n, 3))
    g = np.empty((n, 3, 3))
    d = np.empty((n, 3))
    s = np.empty(n, dtype=np.int64)
    t0 = time.perf_counter()
    sample_many(f, pts[:10], 0.0, u[:10], g[:10], d[:10], s[:10])
    compile_s = time.perf_counter() - t0
    out = {"dataset": str(ds.path), "grid": list(ds.data.shape[1:4]), "snapshots": ds.n_snapshots,
           "storage": ds.meta["storage"]["dtype"], "points": n, "compile_s": round(compile_s, 3)}
    for threads in (1, 2):
        if threads > numba.config.NUMBA_NUM_THREADS:
            continue
        numba.set_num_threads(threads)
        times = []
        for _r in range(args.repeat):
            tp = rng.uniform(0, ds.times[-1] + ds.snapshot_interval if ds.n_snapshots > 1 else 1.0)
            t0 = time.perf_counter()
            sample_many(f, pts, tp, u, g, d, s)
            times.append(time.perf_counter() - t0)
        out[f"points_per_s_{threads}thread"] = round(n / min(times), 0)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
