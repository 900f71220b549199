"""The run's progress bar (tqdm on stderr).

On a terminal it redraws a few times a second; when stderr is a file or a pipe (a batch
job's log, a sweep worker) it writes a line at most every ``LOG_INTERVAL`` seconds, so
a long run does not fill its log with redraws.
"""
from __future__ import annotations

import contextlib
import json
import sys
import threading
import time
from pathlib import Path

LOG_INTERVAL = 30.0  # s between progress lines when stderr is not a terminal


def progress_bar(total: int, *, desc: str, enabled: bool, initial: int = 0):
    from tqdm import tqdm

    tty = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    return tqdm(total=total, initial=initial, desc=desc, unit="step", disable=not enabled, delay=2.0,
                mininterval=0.1 if tty else LOG_INTERVAL, file=sys.stderr)


# Cold compile of a run's kernels with an empty cache, measured on the 2-core development
# machine (`saltation run cases/default.toml` in a fresh NUMBA_CACHE_DIR; README).
COMPILE_ESTIMATE_S = {"spheres": 200.0, "composites": 280.0}
COMPILE_HEARTBEAT_S = 30.0  # a line this often while the compiler works


@contextlib.contextmanager
def compile_notice(enabled: bool, family: str = "spheres"):
    """Around the first kernel call of a run: when this installation's Numba cache has no
    compiled kernels for ``family`` yet, say so on stderr before (with the expected time),
    every COMPILE_HEARTBEAT_S while it lasts, and when it is done; the measured time is kept
    in the cache directory, so the next notice quotes it. Silent when the cache is warm."""
    import numba

    marker = Path(numba.config.CACHE_DIR) / f"compiled-{family}.json"
    if not enabled or marker.exists():
        yield
        return
    estimate = COMPILE_ESTIMATE_S.get(family, 200.0)
    print(f"saltation: compiling the {family} kernels, once per installation of this version "
          f"(~{estimate:.0f} s on a 2-core machine; later runs start at once)", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    done = threading.Event()

    def heartbeat():
        while not done.wait(COMPILE_HEARTBEAT_S):
            print(f"saltation: still compiling ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)

    beat = threading.Thread(target=heartbeat, daemon=True)
    beat.start()
    try:
        yield
    finally:
        done.set()
        beat.join()
    seconds = time.perf_counter() - t0
    print(f"saltation: kernels compiled in {seconds:.0f} s", file=sys.stderr, flush=True)
    try:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(json.dumps({"seconds": seconds}))
    except OSError:  # a read-only cache: the notice simply comes again
        pass
