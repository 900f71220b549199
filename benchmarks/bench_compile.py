"""Compile time of a first run, and what an edit costs afterwards.

    python benchmarks/bench_compile.py [--cases default,mixture] [--edits saltation/cli.py,...]

Works on a copy of the two packages in a temporary folder (so the edits below never touch
the repository), each case in a fresh Numba cache directory, each run a fresh Python
process. For each case:
  cold    the first run with an empty cache (import, set-up, compile, a few steps;
          ``run.duration`` cut to 0.01 s, outputs off);
  warm    the same again (everything loaded from the cache);
  edit:F  after appending a comment to module F of the copy (one per --edits, in turn):
          only the kernels of F and of the modules importing F recompile.
Each figure: ``process_wall_s`` (the whole process) and the run's own ``compile_s``
(set-up and the first kernel call). ``mixture`` is the default case with particle.shape =
"mixture" (bonded-sphere grains). Prints one JSON object; seconds on this machine.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = {
    "default": {},
    "mixture": {"particle.shape": "mixture"},
}
RUN = """
import json, sys, saltation
over = json.loads(sys.argv[1])
res = saltation.run("cases/default.toml", out=sys.argv[2], progress=False, overwrite=True, **over)
print(json.dumps(res.summary["timing"]))
"""


EDITS = "saltation/cli.py,saltation/contacts/composites.py,saltation/physics/forces.py"


def copy_sources(dest: Path) -> Path:
    """The two packages and the cases, copied (the flow data linked, not copied)."""
    for pkg in ("saltation", "flowfields"):
        shutil.copytree(ROOT / pkg, dest / pkg, ignore=shutil.ignore_patterns("__pycache__", "data"))
    (dest / "flowfields" / "data").symlink_to(ROOT / "flowfields" / "data")
    shutil.copytree(ROOT / "cases", dest / "cases")
    return dest


def first_run(overrides: dict, cache: str, out: str, src: Path) -> dict:
    over = {"run.duration": 0.01, "output.vtk": False, "output.tracks": False, **overrides}
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(src))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", RUN, json.dumps(over), out], cwd=src, env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(proc.stderr[-3000:])
    timing = json.loads(proc.stdout.strip().splitlines()[-1])
    return {"process_wall_s": round(wall, 1), "compile_s": round(timing["compile_s"], 1)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default="default,mixture")
    ap.add_argument("--edits", default=EDITS, help="comma-separated module files; empty: none")
    args = ap.parse_args()
    result = {"machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]}}
    for name in args.cases.split(","):
        with tempfile.TemporaryDirectory() as tmp:
            src = copy_sources(Path(tmp) / "src")
            cache, out = os.path.join(tmp, "numba"), os.path.join(tmp, "run")
            row = {"cold": first_run(CASES[name], cache, out, src)}
            row["warm"] = first_run(CASES[name], cache, out, src)
            for edit in [e for e in args.edits.split(",") if e]:
                with open(src / edit, "a") as f:
                    f.write("\n# an edit (bench_compile.py)\n")
                row[f"edit:{edit}"] = first_run(CASES[name], cache, out, src)
            result[name] = row
        print(json.dumps({name: result[name]}), file=sys.stderr, flush=True)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
