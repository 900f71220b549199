"""One Numba cache per version of the kernel sources.

Numba's on-disk cache (``cache=True``) checks only the timestamp of the file that holds
a kernel. A kernel that inlines or calls kernels from *other* files (the step in
saltation/stepping.py calls collide.py, packed_bed.py, integrator.py, forces.py, …) is
then reloaded stale after those files change: wrong machine code, silently. So every
kernel of both packages is cached under a directory named by a hash of the sources that
can reach compiled code: the modules that define kernels (``@njit``) and every module of
the two packages they import, transitively (a global constant read by a kernel is frozen
into its machine code). An edit to any other module (the command line, the case schema,
the run loop, the writers, the analysis) keeps the cache. ``NUMBA_CACHE_DIR``, when set,
is the parent. Must run before any ``@njit(cache=True)`` decorator executes (both
packages' __init__).
"""
from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

_done = False
PACKAGES = ("flowfields", "saltation")
_KERNEL = re.compile(r"^\s*@(numba\.)?(njit|jit|vectorize|guvectorize)\b", re.M)
# in-package imports: "from .x import", "from ..x import", "from . import x, y", "from saltation.x import"
_FROM = re.compile(r"^\s*from\s+(\.+)([\w.]*)\s+import\s+(\([^)]*\)|[^\n]+)", re.M)
_ABS = re.compile(r"^\s*(?:from|import)\s+((?:flowfields|saltation)(?:\.\w+)*)", re.M)


def _module_file(root: Path, dotted: str) -> Path | None:
    base = root.joinpath(*dotted.split("."))
    for cand in (base.with_suffix(".py"), base / "__init__.py"):
        if cand.is_file():
            return cand
    return None


def _imports(root: Path, path: Path) -> set[Path]:
    """Files of the two packages that ``path`` imports (relative or absolute)."""
    text = path.read_text(encoding="utf-8")
    pkg = path.relative_to(root).with_suffix("").parts[:-1]  # the importing module's package
    found = set()
    for dots, mod, names in _FROM.findall(text):
        up = pkg[: len(pkg) - (len(dots) - 1)] if len(dots) > 1 else pkg
        target = ".".join(up + tuple(p for p in mod.split(".") if p))
        for name in re.sub(r"#.*|[()]", " ", names).split(","):
            sub = _module_file(root, f"{target}.{name.strip()}") if name.strip() and target else None
            if sub is not None:  # "from . import history": the submodule
                found.add(sub)
            elif name.strip() and target:  # a name defined in the module (or package) itself
                f = _module_file(root, target)
                if f is not None:
                    found.add(f)
    for dotted in _ABS.findall(text):
        parts = dotted.split(".")
        for k in range(len(parts), 0, -1):
            f = _module_file(root, ".".join(parts[:k]))
            if f is not None:
                found.add(f)
                break
    return found


def kernel_sources(root: Path | None = None) -> list[Path]:
    """The kernel modules of both packages and everything of theirs they import."""
    root = root or Path(__file__).resolve().parents[1]
    every = [p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))]
    todo = [p for p in every if _KERNEL.search(p.read_text(encoding="utf-8"))]
    seen = set(todo)
    while todo:
        for f in _imports(root, todo.pop()):
            if f not in seen:
                seen.add(f)
                todo.append(f)
    return sorted(seen)


def use_versioned_cache() -> str:
    global _done
    import numba

    if _done:
        return numba.config.CACHE_DIR
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha1()
    for p in kernel_sources(root):
        h.update(p.relative_to(root).as_posix().encode())
        h.update(p.read_bytes())
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "saltation-numba")
    numba.config.CACHE_DIR = os.path.join(base, h.hexdigest()[:16])
    _done = True
    return numba.config.CACHE_DIR
