"""The fluid as a grain sees it: flow samples converted to particle units (SPEC §1).

Particle units: length d, velocity u*, time d/u*. The flow dataset is in wall units, so
with Re* = u* d/ν a point x (in d) sits at x⁺ = x·Re*, a time t (in d/u*) at t⁺ = t·Re*;
velocities are the same number in both (u*), gradients and ∂u/∂t scale by Re*.
The particle's y is measured from the bed top, which is the LES wall (y⁺ = 0).
"""
from __future__ import annotations

from numba import njit

from flowfields.sampler import ABOVE_TOP, sample_column, sample_point, vorticity_from_gradient


@njit(cache=True, error_model="numpy", _nrt=False)
def fluid_at_grain(f, re_star, x, y, z, t, with_lift, uf, grad, dudt, vort, uf_top, uf_bot, with_gradient=True):
    """Fluid velocity, gradient, ∂u/∂t and vorticity at the grain centre, and (with_lift)
    the fluid velocity at its top and bottom (y ± 1/2, zero below the bed; SPEC §2 lift).
    Without lift uf_top and uf_bot are not written (the lift term does not read them);
    without gradient (no Magnus, added mass, fluid acceleration or spin law: drag, weight
    and lift need the velocity alone) grad, dudt and vort are not written either.

    The three heights share one vertical of the flow: x, z and time are located once
    (``sampler.sample_column``). Returns 1 if the centre lies above the stored flow (the
    top value is used), else 0."""
    xp = x * re_star
    yp = y * re_star
    zp = z * re_star
    tp = t * re_star
    if with_lift:
        status = sample_column(f, xp, yp, zp, tp, (y + 0.5) * re_star, (y - 0.5) * re_star,
                               uf, grad, dudt, uf_top, uf_bot, with_gradient)
    else:
        status = sample_point(f, xp, yp, zp, tp, uf, grad, dudt, with_gradient)
    if with_gradient:
        for i in range(3):
            dudt[i] *= re_star
            for j in range(3):
                grad[i, j] *= re_star
        vorticity_from_gradient(grad, vort)
    return 1 if status == ABOVE_TOP else 0


def flow_top_in_d(dataset, re_star: float) -> float:
    """Top of the stored flow in grain diameters above the bed top."""
    return float(dataset.y[-1]) / re_star
