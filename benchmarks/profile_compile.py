"""Where a cold compile goes: seconds per kernel and signature, and per compiler stage.

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/profile_compile.py [CASE.toml]
        [--set particle.shape=mixture ...] [--top 30] [--json OUT]

Runs CASE (default ``cases/default.toml``) for 0.01 s without outputs, in this process,
and records every Numba compilation with a compile-event listener (``numba.core.event``):
for each kernel its signatures and its *exclusive* seconds (its own compile, without the
kernels it compiled on the way; that includes re-optimising and emitting the callees
Numba links into it). Beside it, the time in Numba's compiler passes and in LLVM's
stages. Run it with an empty cache: a warm cache compiles nothing. Everything compiles in this
process (SALTATION_SERIAL_COMPILE=1: no helper for the contact phase). A kernel listed with
more than one signature was compiled more than once (see ARCHITECTURE.md, "What a kernel
compiles, and how often").
"""
from __future__ import annotations

import argparse
import collections
import functools
import json
import os
import tempfile
import time
from pathlib import Path

import numba.core.codegen as codegen
from numba.core import compiler_machinery, event

ROOT = Path(__file__).resolve().parents[1]


class _Exclusive:
    """Exclusive seconds of nested timed sections (a stack of child totals)."""

    def __init__(self):
        self.stack: list[float] = []
        self.seconds: dict[str, float] = collections.defaultdict(float)

    def timed(self, key, fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            self.stack.append(0.0)
            try:
                return fn(*args, **kwargs)
            finally:
                dt = time.perf_counter() - t0
                child = self.stack.pop()
                self.seconds[key if isinstance(key, str) else key(*args)] += dt - child
                if self.stack:
                    self.stack[-1] += dt
        return wrapper


class _Kernels(event.Listener):
    """Exclusive seconds per (kernel, signature) from Numba's compile events."""

    def __init__(self):
        self.stack: list[list] = []
        self.records: list[tuple[str, str, float]] = []

    def on_start(self, ev):
        self.stack.append([time.perf_counter(), 0.0])

    def on_end(self, ev):
        t0, child = self.stack.pop()
        dt = time.perf_counter() - t0
        if self.stack:
            self.stack[-1][1] += dt
        fn = ev.data["dispatcher"].py_func
        self.records.append((f"{fn.__module__}.{fn.__qualname__}", str(ev.data["args"]), dt - child))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("case", nargs="?", default=str(ROOT / "cases" / "default.toml"))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a case override, e.g. particle.shape=mixture (repeatable)")
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--json", default=None, help="write every record here")
    args = ap.parse_args()
    # every kernel in this process, where the listener sees it (no helper process for the
    # contact phase: saltation/engine/cold_start.py)
    os.environ["SALTATION_SERIAL_COMPILE"] = "1"

    stages = _Exclusive()
    codegen.CPUCodeLibrary._optimize_functions = stages.timed(
        "LLVM function passes", codegen.CPUCodeLibrary._optimize_functions)
    codegen.CPUCodeLibrary._optimize_final_module = stages.timed(
        "LLVM module passes", codegen.CPUCodeLibrary._optimize_final_module)
    codegen.JITCodeLibrary._finalize_specific = stages.timed(
        "LLVM machine code", codegen.JITCodeLibrary._finalize_specific)
    codegen.CPUCodeLibrary.add_ir_module = stages.timed("LLVM IR parsing", codegen.CPUCodeLibrary.add_ir_module)
    compiler_machinery.PassManager._runPass = stages.timed(
        lambda self, index, pss, state: f"Numba pass {pss.name()}", compiler_machinery.PassManager._runPass)
    kernels = _Kernels()
    event.register("numba:compile", kernels)

    import saltation

    over = {"run.duration": 0.01, "output.vtk": False, "output.tracks": False}
    for item in args.set:
        key, value = item.split("=", 1)
        over[key] = json.loads(value) if value[:1] in "0123456789-[{tf\"" else value
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        res = saltation.run(args.case, out=out, progress=False, overwrite=True, **over)
        wall = time.perf_counter() - t0

    per = collections.defaultdict(lambda: [0, 0.0])
    for name, _, s in kernels.records:
        per[name][0] += 1
        per[name][1] += s
    print(f"run {wall:.1f} s, compile {res.summary['timing']['compile_s']:.1f} s; "
          f"{len(per)} kernels, {len(kernels.records)} signatures, "
          f"{sum(s for *_, s in kernels.records):.1f} s exclusive in all")
    print(f"\n{'s':>7} {'sigs':>4}  kernel (exclusive seconds, top {args.top})")
    for name, (n, s) in sorted(per.items(), key=lambda kv: -kv[1][1])[:args.top]:
        print(f"{s:7.1f} {n:4d}  {name}")
    print(f"\n{'s':>7}  stage (exclusive seconds, top 12)")
    for key, s in sorted(stages.seconds.items(), key=lambda kv: -kv[1])[:12]:
        print(f"{s:7.1f}  {key}")
    if args.json:
        Path(args.json).write_text(json.dumps(kernels.records))


if __name__ == "__main__":
    main()
