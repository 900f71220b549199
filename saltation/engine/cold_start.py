"""A first run's compile on two cores.

With an empty Numba cache, a sphere run with soft contacts spends most of its first minute
compiling. The step (stepping.advance_split) calls three kernel trees: the free flight, the
soft contact phase (the larger one) and the bed. When this installation has not compiled
the step for the run's argument types yet, :func:`compile_elsewhere` compiles the contact
phase in a helper process while this process compiles the other two; the step then loads
the contact phase from the shared cache instead of compiling it. The compiled code is the
same either way (same compiler, same types, same flags), so results do not change: only
the first run's wall time does (``benchmarks/bench_compile.py``).

Nothing depends on the helper: if it fails, is killed or is slower than expected, the
step compiles whatever the cache lacks, as it always did. ``SALTATION_SERIAL_COMPILE=1``
turns the helper off; it is also off on one CPU.

Run as ``python -m saltation.engine.cold_start JOBS_FILE``, it is the helper: it compiles
each (module, kernel name, argument types) of the pickled list, in order, and Numba saves
each in the cache.
"""
from __future__ import annotations

import importlib
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

HELPER_TIMEOUT_S = 900.0  # a helper still compiling after this long is stopped


def is_cached(dispatcher, sig) -> bool:
    """Whether Numba's cache holds ``dispatcher`` compiled for ``sig`` (the types of a call).
    Reads the kernel's cache index only (no code is loaded). Unknown (a Numba without these
    internals, an unreadable index): True, so that nothing extra is started."""
    try:
        cache = dispatcher._cache
        key = cache._index_key(sig, dispatcher.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # noqa: BLE001  (Numba internals: any failure means "don't know")
        return True


def helper_wanted() -> bool:
    """Two or more CPUs and not turned off by SALTATION_SERIAL_COMPILE."""
    return (os.cpu_count() or 1) >= 2 and os.environ.get("SALTATION_SERIAL_COMPILE", "") in ("", "0")


def compile_elsewhere(jobs: list) -> subprocess.Popen | None:
    """Start a helper process that compiles each (kernel, argument types) of ``jobs``, in
    order, into the shared cache; None when it cannot be started."""
    root = str(Path(__file__).resolve().parents[2])  # the folder holding the saltation package
    env = dict(os.environ)  # NUMBA_CACHE_DIR too: the helper's cache is this process's (flowfields/_numba_cache)
    env["PYTHONPATH"] = os.pathsep.join([root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    path = None
    try:
        fd, path = tempfile.mkstemp(prefix="saltation-jobs-", suffix=".pkl")
        with os.fdopen(fd, "wb") as f:
            pickle.dump([(k.py_func.__module__, k.py_func.__name__, sig) for k, sig in jobs], f)
        return subprocess.Popen([sys.executable, "-m", __name__, path], env=env,
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except Exception:  # noqa: BLE001  (no helper: this process compiles it)
        if path is not None:
            _remove(path)
        return None


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def finish(helper: subprocess.Popen | None, wait: bool = True) -> None:
    """Wait for the helper (up to HELPER_TIMEOUT_S), or stop it (``wait=False``: this
    process was interrupted)."""
    if helper is None:
        return
    try:
        if wait:
            helper.wait(timeout=HELPER_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pass
    finally:
        if helper.poll() is None:
            helper.kill()
            helper.wait()
        _remove(helper.args[-1])  # the jobs file


def typed(*values) -> tuple:
    """The Numba types of a call's arguments (what the dispatcher compiles for)."""
    import numba

    return tuple(numba.typeof(v) for v in values)


def compile_split(step, step_args: tuple, jobs) -> None:
    """Unless ``step`` (a kernel) is cached for ``step_args``, or the helper is not wanted:
    ``jobs()`` gives (elsewhere, here), two lists of (kernel, argument types); compile those
    of ``elsewhere`` in a helper process and those of ``here`` in this one, each list in
    order, then wait for the helper. The two lists should share no callee (one of the two
    processes would compile it again: slower, not wrong), and the types must be those the
    step calls each kernel with (or the step compiles it again). ``jobs`` is called only
    then (making the types may call a small kernel)."""
    if not helper_wanted() or is_cached(step, typed(*step_args)):
        return
    elsewhere, here = jobs()
    helper = compile_elsewhere(elsewhere)
    compiled = False
    try:
        for kernel, sig in here:
            kernel.compile(sig)
        compiled = True
    finally:
        finish(helper, wait=compiled)


def main(argv: list[str]) -> int:
    (path,) = argv
    with open(path, "rb") as f:
        jobs = pickle.load(f)
    for module, name, sig in jobs:
        getattr(importlib.import_module(module), name).compile(sig)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
