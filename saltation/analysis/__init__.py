"""Analysis of run and sweep directories: diffusion exponents, jump and collision
statistics, figures and the HTML report (SPEC §6, §8, §9)."""
from .variance import AnalysisError

__all__ = ["AnalysisError"]
