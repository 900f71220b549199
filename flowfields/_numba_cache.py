"""A Numba cache that recompiles exactly what a source change touches.

Numba's on-disk cache (``cache=True``) stamps a kernel with the source of the file that
defines it, and nothing else. A kernel that calls kernels from *other* files (the step in
the engine calls the contact phase, the bed, the free flight, the forces, …) has their
machine code linked into its own, so after a change to one of those files Numba would
reload it stale: wrong machine code, silently. Here every kernel's stamp is a hash of
its module *and of every module of the two packages it imports, transitively* (a global
constant read by a kernel is frozen into its machine code too): a change to a module
recompiles the kernels of that module and of the modules that import it, and loads the
rest from the cache. An edit to a module no kernel module imports (the command line, the
case schema, the run loop, the writers, the analysis) recompiles nothing.

The cache lives in ``$NUMBA_CACHE_DIR/kernels`` (default ``~/.cache/saltation-numba``).
``use_versioned_cache()`` must run before any ``@njit(cache=True)`` decorator executes
(both packages' ``__init__`` call it).
"""
from __future__ import annotations

import functools
import hashlib
import os
import re
from pathlib import Path

_done = False
PACKAGES = ("flowfields", "saltation")
# kernels outside the packages that call theirs (tests/peers, tests, benchmarks) get the same stamp
STAMPED = PACKAGES + ("tests", "benchmarks")
ROOT = Path(__file__).resolve().parents[1]
_KERNEL = re.compile(r"^\s*@(numba\.)?(njit|jit|vectorize|guvectorize)\b", re.M)
# in-package imports: "from .x import", "from ..x import", "from . import x, y", "from saltation.x import"
_FROM = re.compile(r"^\s*from\s+(\.+)([\w.]*)\s+import\s+(\([^)]*\)|[^\n]+)", re.M)
_ABS = re.compile(r"^\s*(?:from|import)\s+((?:flowfields|saltation)(?:\.\w+)*)", re.M)
# "from saltation.physics import history": a submodule named after "import"
_ABS_FROM = re.compile(r"^\s*from\s+((?:flowfields|saltation)(?:\.\w+)*)\s+import\s+(\([^)]*\)|[^\n]+)", re.M)


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
            name = (name.split() or [""])[0]  # "composites as clusters": composites
            sub = _module_file(root, f"{target}.{name}") if name and target else None
            if sub is not None:  # "from . import history": the submodule
                found.add(sub)
            elif name and target:  # a name defined in the module (or package) itself
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
    for mod, names in _ABS_FROM.findall(text):
        for name in re.sub(r"#.*|[()]", " ", names).split(","):
            name = (name.split() or [""])[0]
            sub = _module_file(root, f"{mod}.{name}") if name else None
            if sub is not None:
                found.add(sub)
    return found


def kernel_sources(root: Path | None = None) -> list[Path]:
    """The kernel modules of both packages and everything of theirs they import."""
    root = root or Path(__file__).resolve().parents[1]
    every = [p for pkg in PACKAGES for p in sorted((root / pkg).rglob("*.py"))]
    return _closure([p for p in every if _KERNEL.search(p.read_text(encoding="utf-8"))], root)


def module_closure(path: Path, root: Path | None = None) -> list[Path]:
    """``path`` and every module of the two packages it imports, transitively."""
    return _closure([path], root or ROOT)


def _closure(start: list[Path], root: Path) -> list[Path]:
    seen, todo = set(start), list(start)
    while todo:
        for f in _imports(root, todo.pop()):
            if f not in seen:
                seen.add(f)
                todo.append(f)
    return sorted(seen)


def _hash_sources(paths: list[Path], root: Path) -> str:
    """A hash of the files' paths (relative to root) and contents."""
    h = hashlib.sha1()
    for p in paths:
        h.update(p.relative_to(root).as_posix().encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def closure_stamp(path: Path, root: Path | None = None) -> str:
    """The cache stamp of the kernels defined in ``path``: a hash of its import closure."""
    root = root or ROOT
    return _hash_sources(module_closure(path, root), root)


@functools.cache
def _closure_stamp(py_file: str) -> str:
    return closure_stamp(Path(py_file).resolve())


def kernel_version() -> str:
    """A hash of every kernel module and what they import (names the compile notice's marker)."""
    return _hash_sources(kernel_sources(ROOT), ROOT)[:16]


def _locator_class():
    """Numba's locator for $NUMBA_CACHE_DIR, with the stamp of a kernel of our packages
    replaced by the hash of its module's import closure (module docstring)."""
    from numba.core import caching

    base = getattr(caching, "UserProvidedCacheLocator", None) or caching._UserProvidedCacheLocator

    class ClosureStampedLocator(base):
        def get_source_stamp(self):
            return _closure_stamp(self._py_file)

        @classmethod
        def from_function(cls, py_func, py_file):
            path = Path(py_file).resolve()
            if not path.is_relative_to(ROOT) or path.relative_to(ROOT).parts[0] not in STAMPED:
                return None  # not ours: Numba's own locators decide
            return super().from_function(py_func, py_file)

    return caching, ClosureStampedLocator


def use_versioned_cache() -> str:
    global _done
    import numba

    if _done:
        return numba.config.CACHE_DIR
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "saltation-numba")
    numba.config.CACHE_DIR = os.path.join(base, "kernels")
    caching, locator = _locator_class()
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    impl._locator_classes = [locator] + [c for c in impl._locator_classes if c.__name__ != locator.__name__]
    _done = True
    return numba.config.CACHE_DIR
