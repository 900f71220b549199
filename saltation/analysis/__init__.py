"""Analysis of run and sweep directories: diffusion exponents, jump and collision
statistics, figures and the HTML report (SPEC §6, §8, §9)."""
from . import diffusion, transport  # noqa: F401  (saltation.analysis.diffusion.exponents after `import saltation`)
from .variance import AnalysisError

__all__ = ["AnalysisError", "diffusion", "transport"]
