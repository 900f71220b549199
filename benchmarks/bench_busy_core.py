"""A run on all cores while another process holds one of them (flowfields/_openmp.py).

Runs ``cases/default.toml`` for ``--duration`` s in a fresh process per setting — one
thread, and all threads with libgomp's spin (GOMP_SPINCOUNT=300000), with this package's
default (GOMP_SPINCOUNT unset: 300) and with OMP_WAIT_POLICY=passive — first on the idle
machine, then with a busy loop (``while True: pass``) on one core, and prints each run's
wall time less its compiling (summary.json ``timing``: the steps and the outputs). Warm
kernel cache assumed (run ``saltation run cases/default.toml`` once first). No timing is
asserted anywhere.

    python benchmarks/bench_busy_core.py [--duration 1.0] [--rounds 2]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "default.toml"
SETTINGS = {  # name -> (Numba threads or None: all, environment)
    "one thread": (1, {}),
    "libgomp's spin (300000)": (None, {"GOMP_SPINCOUNT": "300000"}),
    "default (300)": (None, {}),
    "OMP_WAIT_POLICY=passive": (None, {"OMP_WAIT_POLICY": "passive"}),
}
RUN = """
import json, sys, tempfile, saltation
with tempfile.TemporaryDirectory() as d:
    r = saltation.run(sys.argv[1], out=d, progress=False, **{"run.duration": float(sys.argv[2])})
t = r.summary["timing"]
print(json.dumps({"wall_s": t["wall_s"] - t["compile_s"], "threads": t.get("threads")}))
"""


def one_run(threads, env, duration):
    e = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY", "NUMBA_NUM_THREADS")}
    e.update(env)
    if threads:
        e["NUMBA_NUM_THREADS"] = str(threads)
    out = subprocess.run([sys.executable, "-c", RUN, str(CASE), str(duration)], env=e, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=1.0, help="simulated seconds of the default case")
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args()
    results = {}
    for machine in ("idle", "one core busy"):
        busy = None
        if machine != "idle":
            busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        try:
            for r in range(a.rounds):
                for name, (threads, env) in SETTINGS.items():
                    x = one_run(threads, env, a.duration)
                    results.setdefault((machine, name), []).append(x["wall_s"])
                    print(f"[{machine}, {name}, round {r + 1}: {x['wall_s']:.2f} s on {x['threads']} thread(s)]",
                          file=sys.stderr, flush=True)
        finally:
            if busy is not None:
                busy.kill()
    print(f"\n{CASE.name}, {a.duration:g} s simulated, {os.cpu_count()} CPUs: wall time less compiling (s), "
          f"{a.rounds} runs each")
    print(f"{'setting':<26} {'idle':>16} {'one core busy':>16}")
    for name in SETTINGS:
        cells = [" ".join(f"{v:.2f}" for v in results[(m, name)]) for m in ("idle", "one core busy")]
        print(f"{name:<26} {cells[0]:>16} {cells[1]:>16}")


if __name__ == "__main__":
    main()
