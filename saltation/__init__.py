"""saltation: saltating sand grains in stored LES channel flow.

``saltation.run(case, out=None, **overrides)`` runs one case (SPEC §9) and returns a
result with ``.summary``, ``.jumps`` and ``.tracks``; call it as often as you like in one
process (the run loop lives in ``saltation.engine.simulation``, so no submodule import can
replace this function). ``saltation.analysis.diffusion.exponents`` is reachable after
``import saltation``.
"""
__version__ = "0.1.0"

import flowfields  # noqa: E402,F401  (sets the versioned Numba cache before any kernel loads)

from .case import Case, CaseError, load_case  # noqa: E402


def __getattr__(name):
    """``saltation.analysis`` on first use (PEP 562): it imports pandas, which a plain
    ``import saltation`` (the command line's start) need not wait for."""
    if name == "analysis":
        import importlib

        return importlib.import_module(".analysis", __name__)
    raise AttributeError(f"module 'saltation' has no attribute {name!r}")


def run(case, out=None, progress=True, **overrides):
    """Run one case file (path) or dict of tables; overrides use "table.key" names.

    Keywords of :func:`saltation.engine.simulation.run` (``resume``, ``overwrite``) pass through."""
    from .engine.simulation import run as _run

    return _run(case, out=out, progress=progress, **overrides)


__all__ = ["run", "load_case", "Case", "CaseError", "analysis", "__version__"]
