"""A grain's free-flight path inside one hydrodynamic step, as both contact phases see it
(contacts/phase.py for spheres, contacts/composites.py for bonded-sphere grains): the cubic
Hermite interpolant through the step's start and end positions and velocities, s = t/Δt
in [0, 1]."""
from __future__ import annotations

from numba import njit

__all__ = ["hermite_weights"]


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def hermite_weights(s):
    """Cubic Hermite basis at s and its derivatives: x(s) = h00 x₀ + h01 x₁ + Δt(h10 u₀ +
    h11 u₁), dx/ds = d00 (x₀ − x₁) + Δt(d10 u₀ + d11 u₁) (d01 = −d00)."""
    s2 = s * s
    s3 = s2 * s
    h00 = 2.0 * s3 - 3.0 * s2 + 1.0
    h10 = s3 - 2.0 * s2 + s
    h01 = -2.0 * s3 + 3.0 * s2
    h11 = s3 - s2
    d00 = 6.0 * s2 - 6.0 * s
    d10 = 3.0 * s2 - 4.0 * s + 1.0
    d11 = 3.0 * s2 - 2.0 * s
    return h00, h10, h01, h11, d00, d10, d11
