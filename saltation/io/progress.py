"""The run's progress bar (tqdm on stderr).

On a terminal it redraws a few times a second; when stderr is a file or a pipe (a batch
job's log, a sweep worker) it writes a line at most every ``LOG_INTERVAL`` seconds, so
a long run does not fill its log with redraws.
"""
from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

from numba import njit, objmode

LOG_INTERVAL = 30.0  # s between progress lines when stderr is not a terminal


@njit(cache=True, no_cfunc_wrapper=True)
def wall_clock():
    """time.perf_counter() (s) read from compiled code: the run loops' timers."""
    with objmode(t="float64"):
        t = time.perf_counter()
    return t


def progress_bar(total: int, *, desc: str, enabled: bool, initial: int = 0):
    from tqdm import tqdm

    tty = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    return tqdm(total=total, initial=initial, desc=desc, unit="step", disable=not enabled, delay=2.0,
                mininterval=0.1 if tty else LOG_INTERVAL, file=sys.stderr)


# Cold compile of a run's kernels with an empty cache on a 2-core machine,
# `benchmarks/bench_compile.py` (its compile_s; part of the kernels in a helper process,
# engine/cold_start.py). On a 2-vCPU Intel Xeon VM (2026-12-06): spheres
# (cases/default.toml: the LES, soft contacts, virtual bed) 97 s with outputs off and 121 s
# with the case's outputs (a 0.01 s run), the README's first run 197 s; composites (the same
# with particle.shape = "mixture") 94 s with outputs off. The code of 04e23be compiled the
# spheres in 75 s there (the contact phase has grown since); an Intel Rocket Lake compiled
# that code in 37-45 s.
COMPILE_ESTIMATE_S = {"spheres": 120.0, "composites": 120.0}
COMPILE_HEARTBEAT_S = 30.0  # a line this often while the compiler works


class compile_notice:  # noqa: N801  (used as a context manager, like a function)
    """Around a run's set-up and first kernel call: when this installation's Numba cache has
    no compiled kernels for ``family`` yet, say so on stderr at the start (with the expected
    time) and every COMPILE_HEARTBEAT_S while it lasts; ``done()`` (called after the first
    kernel call, or on leaving the block without an error) says how long it took and keeps
    that in the cache directory, so later runs stay silent. Silent when the cache is warm
    or ``enabled`` is false (--quiet)."""

    def __init__(self, enabled: bool, family: str = "spheres"):
        import numba

        from flowfields._numba_cache import kernel_version

        self.family = family
        # one marker per version of the kernel sources: after a change, the notice comes again
        self.marker = Path(numba.config.CACHE_DIR) / f"compiled-{family}-{kernel_version()}.json"
        self.active = bool(enabled) and not self.marker.exists()
        self._done = threading.Event()
        self._beat = None

    def __enter__(self):
        if self.active:
            estimate = COMPILE_ESTIMATE_S.get(self.family, 200.0)
            print(f"saltation: compiling the {self.family} kernels, once per installation of this version "
                  f"(~{estimate:.0f} s on a 2-core machine; later runs start at once)", file=sys.stderr, flush=True)
            self._t0 = time.perf_counter()
            self._beat = threading.Thread(target=self._heartbeat, daemon=True)
            self._beat.start()
        return self

    def _heartbeat(self):
        while not self._done.wait(COMPILE_HEARTBEAT_S):
            print(f"saltation: still compiling ({time.perf_counter() - self._t0:.0f} s)", file=sys.stderr, flush=True)

    def _stop(self):
        self._done.set()
        if self._beat is not None:
            self._beat.join()
            self._beat = None

    def done(self):
        """The kernels are compiled: report the time and remember it (once)."""
        if not self.active or self._done.is_set():
            return
        self._stop()
        seconds = time.perf_counter() - self._t0
        print(f"saltation: kernels compiled in {seconds:.0f} s", file=sys.stderr, flush=True)
        try:
            self.marker.parent.mkdir(parents=True, exist_ok=True)
            self.marker.write_text(json.dumps({"seconds": seconds}))
        except OSError:  # a read-only cache: the notice simply comes again
            pass

    def __exit__(self, kind, value, tb):
        if kind is None:
            self.done()
        else:  # interrupted or failed while compiling: stop the heartbeat, remember nothing
            self._stop()
        return False
