"""Analytic mean-velocity profiles (SPEC §3), sampled onto the same grid type as LES data.

Steady, no fluctuations: the fast sanity-check sources. All in wall units.
"""
from __future__ import annotations

import numpy as np

from .dataset import FlowDataset, in_memory_dataset

KAPPA = 0.41
B_SMOOTH = 5.5  # SPEC §3 log-law intercept


def log_law(y_plus, kappa=KAPPA, b=B_SMOOTH):
    """Smooth-wall log law u⁺ = ln(y⁺)/κ + B, joined to u⁺ = y⁺ where they cross (y⁺ ≈ 11)."""
    y = np.asarray(y_plus, dtype=float)
    y_cross = _log_law_crossing(kappa, b)
    with np.errstate(divide="ignore"):
        return np.where(y < y_cross, y, np.log(np.maximum(y, 1e-300)) / kappa + b)


def _log_law_crossing(kappa, b):
    """y⁺ where y⁺ = ln(y⁺)/κ + B (Newton from 11)."""
    y = 11.0
    for _ in range(50):
        f = y - np.log(y) / kappa - b
        y -= f / (1.0 - 1.0 / (kappa * y))
    return y


def rough_log_law(y_plus, ks_plus):
    """Rough-wall log law u⁺ = 2.5 ln(30 y/k_s), zero below y = k_s/30 (SPEC §3)."""
    y = np.asarray(y_plus, dtype=float)
    return np.where(y > ks_plus / 30.0, 2.5 * np.log(np.maximum(30.0 * y / ks_plus, 1.0)), 0.0)


def reichardt(y_plus, kappa=KAPPA):
    """Reichardt (1951) smooth-wall composite profile, continuous from y⁺ = 0."""
    y = np.asarray(y_plus, dtype=float)
    return np.log1p(kappa * y) / kappa + 7.8 * (1.0 - np.exp(-y / 11.0) - (y / 11.0) * np.exp(-y / 3.0))


PROFILES = ("loglaw", "rough", "composite", "still")


def profile_dataset(profile: str, y_top_plus: float = 2000.0, ks_plus: float | None = None, ny: int = 400) -> FlowDataset:
    """A steady dataset holding an analytic profile on a stretched y grid.

    The grid is geometric from y⁺ = 0.05 to y_top_plus (ny points), two planes in x and z
    (periodic, uniform), one snapshot. Interpolation error of the piecewise-linear profile
    is below 0.1 % for ny = 400."""
    if profile not in PROFILES:
        raise ValueError(f"flow profile {profile!r} is not one of {PROFILES}")
    if y_top_plus <= 1.0:
        raise ValueError(f"y_top_plus must exceed 1 wall unit, got {y_top_plus}")
    y = np.geomspace(0.05, y_top_plus, ny)
    if profile == "loglaw":
        ux = log_law(y)
    elif profile == "rough":
        if ks_plus is None or ks_plus <= 0:
            raise ValueError("the rough log law needs a positive roughness height ks_plus (wall units)")
        ux = rough_log_law(y, ks_plus)
    elif profile == "composite":
        ux = reichardt(y)
    else:
        ux = np.zeros_like(y)
    u = np.zeros((1, 2, ny, 2, 3), dtype=np.float32)
    u[0, :, :, :, 0] = ux[None, :, None]
    return in_memory_dataset(
        x=[0.0, 1000.0],
        y=y,
        z=[0.0, 1000.0],
        u_plus=u,
        re_tau=y_top_plus,
        times_plus=[0.0],
        meta_extra={"kind": f"analytic:{profile}", "provenance": {"profile": profile, "ks_plus": ks_plus}},
    )
