"""Memory and cost of the streaming displacement-variance accumulator at paper scale.

Paper run (SPEC §8): 99 000 grains, 200 s simulated at τ*/τ*c = 1.79 (d/u* = 0.0273 s,
so 7330 d/u*), variances sampled every 0.1 d/u* (the default output.variance_interval).
Prints JSON: memory of the accumulator, samples it needs (kernel chunk ends), seconds
per needed sample, and that cost per d/u* of run. No timing is asserted anywhere.

    python benchmarks/bench_variance.py [--n 99000] [--duration 7330] [--samples 60]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from saltation.analysis.variance import VarianceAccumulator, make_plan


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=99_000, help="grains")
    ap.add_argument("--duration", type=float, default=7330.0, help="run length in d/u*")
    ap.add_argument("--dt", type=float, default=0.1, help="sampling interval in d/u*")
    ap.add_argument("--origins", type=int, default=8)
    ap.add_argument("--samples", type=int, default=60, help="needed samples to time")
    a = ap.parse_args()

    n_samples = int(a.duration / a.dt) + 1
    plan = make_plan(n_samples, a.dt, n_origins=a.origins)
    acc = VarianceAccumulator(a.n, plan)
    due = sorted(acc._due)
    rng = np.random.default_rng(0)
    pos = rng.normal(size=(a.n, 3))
    acc.sample(due[0], pos)  # warm-up (first origin)
    picks = due[1 : 1 + a.samples]
    t0 = time.perf_counter()
    for j in picks:
        acc.sample(j, pos)
    per = (time.perf_counter() - t0) / len(picks)
    print(json.dumps({
        "n_particles": a.n, "run_d_u*": a.duration, "sample_interval_d_u*": a.dt,
        "origins": len(plan.origins), "lags": len(plan.lags), "groups": acc.n_groups,
        "max_lag_d_u*": plan.max_lag_time,
        "memory_MB": acc.memory_bytes / 1e6,
        "memory_reference_positions_MB": acc.ref.nbytes / 1e6, "memory_group_sums_MB": acc.sums.nbytes / 1e6,
        "needed_samples": len(due), "of_samples": n_samples,
        "s_per_needed_sample": per, "total_s_for_run": per * len(due),
    }, indent=1))


if __name__ == "__main__":
    main()
