"""One Numba cache per source version.

Numba's on-disk cache (``cache=True``) checks only the timestamp of the file that holds
a kernel. A kernel that inlines or calls kernels from *other* files (the step in
saltation/stepping.py calls collide.py, packed_bed.py, integrator.py, forces.py, …) is
then reloaded stale after those files change: wrong machine code, silently. So every
kernel of both packages is cached under a directory named by a hash of all their
sources: any edit gives a fresh cache. ``NUMBA_CACHE_DIR``, when set, is the parent.
Must run before any ``@njit(cache=True)`` decorator executes (both packages' __init__).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

_done = False


def use_versioned_cache() -> str:
    global _done
    import numba

    if _done:
        return numba.config.CACHE_DIR
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha1()
    for pkg in ("flowfields", "saltation"):
        for p in sorted((root / pkg).rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "saltation-numba")
    numba.config.CACHE_DIR = os.path.join(base, h.hexdigest()[:16])
    _done = True
    return numba.config.CACHE_DIR
