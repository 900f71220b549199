"""saltation: saltating sand grains in stored LES channel flow.

``saltation.run(case, out=None, **overrides)`` runs one case (SPEC §9) and returns a
result with ``.summary``, ``.jumps`` and ``.tracks``.
"""
__version__ = "0.1.0"

import flowfields  # noqa: E402,F401  (sets the versioned Numba cache before any kernel loads)


def run(case, out=None, progress=True, **overrides):
    """Run one case file (path) or dict of tables; overrides use "table.key" names."""
    from .run import run as _run

    return _run(case, out=out, progress=progress, **overrides)


__all__ = ["run", "__version__"]
