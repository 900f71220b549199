"""A grain's free-flight path inside one hydrodynamic step: the cubic Hermite interpolant
through the step's start and end positions and velocities, s = t/Δt in [0, 1]. Both
contact phases move grains as deviations from it (contacts/phase.py for spheres,
contacts/composites.py for bonded-sphere grains), and the beds find a grain's impact on
it (flight/spheres._bed_impact, bed/packed.packed_bed_check_particle)."""
from __future__ import annotations

from numba import njit

__all__ = ["hermite_weights", "hermite_point", "first_below", "first_inside", "PLANE", "SPHERE"]

# samples of the step scanned for the first crossing before it is bisected (first_inside)
CROSSING_SCAN = 8
CROSSING_BISECTIONS = 40  # the crossing to 2⁻⁴⁰ of an eighth of the step


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


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def hermite_point(x0, x1, u0, u1, s, dt):
    """Position and velocity at s of the cubic Hermite through (x0, u0) and (x1, u1) over dt."""
    h00, h10, h01, h11, d00, d10, d11 = hermite_weights(s)
    return h00 * x0 + h01 * x1 + dt * (h10 * u0 + h11 * u1), d00 * (x0 - x1) / dt + d10 * u0 + d11 * u1


PLANE, SPHERE = 0, 1  # the surfaces first_inside finds a path's entry into


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def _inside(kind, x0, x1, u0, u1, s, dt, centre, reach):
    """Whether the path is inside the surface at s: below the plane y = centre[1]
    (PLANE), or within ``reach`` of ``centre`` (SPHERE)."""
    if kind == PLANE:
        return hermite_point(x0[1], x1[1], u0[1], u1[1], s, dt)[0] < centre[1]
    r2 = 0.0
    for i in range(3):
        a = hermite_point(x0[i], x1[i], u0[i], u1[i], s, dt)[0] - centre[i]
        r2 += a * a
    return r2 < reach * reach


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def first_inside(kind, x0, x1, u0, u1, dt, centre, reach):
    """The first s in (0, 1] at which the Hermite path through (x0, u0), (x1, u1) (3-vectors)
    enters the surface (``_inside``), for a path that starts outside and ends inside: the
    first of CROSSING_SCAN equal parts of the step that ends inside, bisected. (A cubic can
    cross three times; the scan finds the first unless two crossings share a part, ≤ Δt/8
    apart.)"""
    lo = 0.0
    hi = 1.0
    for i in range(1, CROSSING_SCAN + 1):
        s = i / CROSSING_SCAN
        if _inside(kind, x0, x1, u0, u1, s, dt, centre, reach):
            hi = s
            break
        lo = s
    for _ in range(CROSSING_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if _inside(kind, x0, x1, u0, u1, mid, dt, centre, reach):
            hi = mid
        else:
            lo = mid
    return hi


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def first_below(y0, y1, v0, v1, dt, level):
    """The first s in (0, 1] at which the Hermite height through (y0, v0), (y1, v1) comes
    down to ``level``, for y0 ≥ level > y1 (``first_inside`` for a plane)."""
    return first_inside(PLANE, (0.0, y0, 0.0), (0.0, y1, 0.0), (0.0, v0, 0.0), (0.0, v1, 0.0), dt,
                        (0.0, level, 0.0), 0.0)
