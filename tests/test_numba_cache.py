"""The Numba cache recompiles what a change touches and nothing else
(flowfields/_numba_cache.py): a kernel's stamp is the hash of its module's import closure."""
from __future__ import annotations

import shutil
from pathlib import Path

import numba

from flowfields import _numba_cache as nc

ROOT = Path(__file__).resolve().parents[1]


def _module(name: str) -> Path:
    return ROOT / (name.replace(".", "/") + ".py")


def test_closure_follows_imports_transitively_and_stops_at_the_packages():
    stepping = set(nc.module_closure(_module("saltation.engine.stepping")))
    for dep in ("saltation.flight.spheres", "saltation.physics.forces", "saltation.physics.history", "flowfields.sampler"):
        assert _module(dep) in stepping, dep  # direct and indirect imports
    assert _module("saltation.cli") not in stepping
    assert _module("saltation.case.schema") not in stepping
    assert all(p.is_relative_to(ROOT) for p in stepping)


def test_an_edit_changes_the_stamps_of_the_modules_that_import_it_and_no_others(tmp_path):
    for pkg in nc.PACKAGES:
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("data", "__pycache__"))
    kernels = [p.relative_to(ROOT) for p in nc.kernel_sources(ROOT)]
    before = {k: nc.closure_stamp(tmp_path / k, tmp_path) for k in kernels}
    edited = Path("saltation/contacts/composites.py")  # composites only
    with open(tmp_path / edited, "a") as f:
        f.write("\n# an edit\n")
    after = {k: nc.closure_stamp(tmp_path / k, tmp_path) for k in kernels}
    changed = {k for k in kernels if before[k] != after[k]}
    assert edited in changed
    importers = {k for k in kernels if tmp_path / edited in nc.module_closure(tmp_path / k, tmp_path)}
    assert changed == importers
    for sphere_kernel in ("saltation/engine/stepping.py", "saltation/contacts/phase.py", "saltation/flight/spheres.py",
                          "flowfields/sampler.py"):
        assert Path(sphere_kernel) not in changed  # a sphere run loads everything from the cache
    # an edit to the command line changes no stamp at all
    with open(tmp_path / "saltation/cli.py", "a") as f:
        f.write("\n# an edit\n")
    assert {k: nc.closure_stamp(tmp_path / k, tmp_path) for k in kernels} == after


def test_numba_uses_the_closure_stamp_for_our_kernels():
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    locator = impl._locator_classes[0]
    assert locator.__name__ == "ClosureStampedLocator"
    from saltation.physics import forces

    py_file = forces.__file__
    loc = locator.from_function(forces.make_coefficients, py_file)
    assert loc is not None and loc.get_source_stamp() == nc.closure_stamp(Path(py_file))
    assert loc.get_cache_path().startswith(numba.config.CACHE_DIR)
    # a function outside the two packages is left to Numba's own locators
    assert locator.from_function(shutil.copy, shutil.__file__) is None


def test_every_import_form_of_the_package_layout_is_followed(tmp_path):
    """Relative and absolute imports of a submodule, with aliases and parenthesized lists."""
    for rel in ("saltation/__init__.py", "saltation/physics/__init__.py", "saltation/flight/__init__.py",
                "saltation/physics/history.py", "saltation/physics/spin.py", "saltation/flight/spheres.py"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    engine = tmp_path / "saltation/engine/run.py"
    engine.parent.mkdir()
    engine.write_text("from ..flight import spheres as integrator\n"
                      "from ..physics import (\n    spin,  # a comment\n)\n")
    peer = tmp_path / "tests/peers/loop.py"
    peer.parent.mkdir(parents=True)
    peer.write_text("from saltation.physics import history as h\n")
    assert nc._imports(tmp_path, engine) == {tmp_path / "saltation/flight/spheres.py",
                                             tmp_path / "saltation/physics/spin.py"}
    assert tmp_path / "saltation/physics/history.py" in nc._imports(tmp_path, peer)  # (and the package)
    # the real tree: a module imported under another name is in the closure
    assert _module("saltation.flight.composites") in nc.module_closure(_module("saltation.engine.composites"))


def test_a_kernel_in_tests_peers_is_stamped_with_its_closure():
    """tests/peers/sphere_advance.py calls the flight kernels: an edit to them must not leave
    it stale in the cache (Numba's own stamp would look at its file only)."""
    import sys

    from numba.core import caching

    sys.path.insert(0, str(ROOT / "tests" / "peers"))
    import sphere_advance

    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    locator = impl._locator_classes[0]
    py_file = sphere_advance.__file__
    loc = locator.from_function(sphere_advance.advance.py_func, py_file)
    assert loc is not None and loc.get_source_stamp() == nc.closure_stamp(Path(py_file))
    closure = nc.module_closure(Path(py_file).resolve())
    for dep in ("saltation.flight.spheres", "saltation.physics.forces", "flowfields.sampler"):
        assert _module(dep) in closure, dep
