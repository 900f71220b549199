"""The cost of a case run the way users run it, against the stepper advanced directly.

    python benchmarks/bench_user_path.py [--cases cases/concentration_sweep_reduced.toml]
        [--concentrations 0.52 3.94] [--tau-ratio 1.79] [--duration 1.0] [--threads 1]

bench_dense.py times ``Stepper.advance`` in long chunks from a spun-up state. A user's run
(``saltation.run``, what ``saltation sweep`` calls for each case) goes through the run loop
instead: chunks that end wherever an output is due (the displacement variances of the
sweep cases want a sample every step or two), the jumps collected after each chunk,
checkpoints (every 5 % of the steps and every ``output.checkpoint_every`` s), Parquet and
JSON written at the end. For each concentration this runs the sweep's case both ways from
its initial state, one after the other in this process, and prints:

* the run's own timing (summary.json): wall, compile, kernel (inside the stepper) and the
  rest (the loop, outputs, checkpoints), and its chunks (advance calls);
* the same steps in one ``Stepper.advance`` call, and the ratio of the two kernel times;
* whether both end in the same state, bit for bit (particles.parquet against the direct
  run's arrays): the results may not depend on where the chunks end.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_dense  # noqa: E402  (the sweep's cases and the direct stepping)


def _user_run(tables, values, out, threads):
    """saltation.run of the case; returns (summary, final positions (N, 3) in d, advance calls)."""
    import pandas as pd

    import saltation
    from saltation.engine.simulation import Simulation

    calls = [0]
    advance = Simulation._advance

    def counted(self, *args):
        calls[0] += 1
        return advance(self, *args)

    Simulation._advance = counted  # counts the chunks; the call itself is the run loop's own
    try:
        result = saltation.run(tables, out=out, progress=False, overwrite=True,
                               **{**values, "run.threads": threads})
    finally:
        Simulation._advance = advance
    parts = pd.read_parquet(Path(out) / "particles.parquet")
    return result.summary, parts[["x", "y", "z"]].to_numpy(), calls[0] - 1  # less the compile call (0 steps)


def _direct_run(tables, values, threads):
    """The same case's steps in one Stepper.advance call; returns (seconds, steps, N, final positions)."""
    import numba

    numba.set_num_threads(threads)
    sim, ds, st, ws = bench_dense.build(tables, {**values, "run.threads": threads})
    sim.stepper.advance(ds.arrays, st, ws, 0.0, 0, 0)  # compiled or loaded, no step (as the run loop does)
    t0 = time.perf_counter()
    n = bench_dense.steps(sim, ds.arrays, st, ws, 0, sim.n_steps)
    return time.perf_counter() - t0, n, sim.n, st.pos.copy()


def compare(cases, concentration_pct, tau_ratio=1.79, duration=1.0, threads=1) -> dict:
    """One sweep case both ways (module docstring): the run's timing and chunks, both kernel
    costs, and whether both ended in the same state."""
    tables, values = bench_dense._sweep_case(cases, concentration_pct, tau_ratio)
    values = {**values, "run.duration": duration}
    with tempfile.TemporaryDirectory(prefix="bench_user_path_") as tmp:
        summary, pos_run, chunks = _user_run(tables, values, tmp, threads)
    direct_s, n_steps, n, pos_direct = _direct_run(tables, values, threads)
    t = summary["timing"]
    steps = summary["steps"]
    return {"concentration_pct": concentration_pct, "n": n, "steps": steps, "chunks": chunks,
            "wall_s": t["wall_s"], "compile_s": t["compile_s"], "kernel_s": t["kernel_s"],
            "rest_s": t["wall_s"] - t["compile_s"] - t["kernel_s"], "direct_s": direct_s,
            "kernel_us_per_gs": 1e6 * t["kernel_s"] / (n * steps), "direct_us_per_gs": 1e6 * direct_s / (n * n_steps),
            "same_end_state": bool(steps == n_steps and np.array_equal(pos_run, pos_direct))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=str(HERE.parent / "cases" / "concentration_sweep_reduced.toml"))
    ap.add_argument("--concentrations", type=float, nargs="+", default=[0.52, 3.94], help="%% (the sweep's)")
    ap.add_argument("--tau-ratio", type=float, default=1.79)
    ap.add_argument("--duration", type=float, default=1.0, help="s simulated (the reduced sweep's 1 s)")
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    print("| C % | N | steps | chunks | wall (s) | compile | kernel | rest | kernel µs/gs | direct µs/gs "
          "| kernel / direct | same end state |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for c in a.concentrations:
        r = compare(a.cases, c, a.tau_ratio, a.duration, a.threads)
        print(f"| {c:g} | {r['n']} | {r['steps']} | {r['chunks']} | {r['wall_s']:.2f} | {r['compile_s']:.2f} | "
              f"{r['kernel_s']:.2f} | {r['rest_s']:.2f} | {r['kernel_us_per_gs']:.2f} | {r['direct_us_per_gs']:.2f} | "
              f"{r['kernel_s'] / r['direct_s']:.3f} | {'yes' if r['same_end_state'] else 'NO'} |", flush=True)


if __name__ == "__main__":
    main()
