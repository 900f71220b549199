"""The fluid as a grain sees it: flow samples converted to particle units (SPEC §1).

Particle units: length d, velocity u*, time d/u*. The flow dataset is in wall units, so
with Re* = u* d/ν a point x (in d) sits at x⁺ = x·Re*, a time t (in d/u*) at t⁺ = t·Re*;
velocities are the same number in both (u*), gradients and ∂u/∂t scale by Re*.
The particle's y is measured from the bed top, which is the LES wall (y⁺ = 0).
"""
from __future__ import annotations

from numba import njit

from flowfields.dataset import DatasetError
from flowfields.sampler import (
    ABOVE_TOP,
    BELOW_WALL,
    gather_cell,
    locate_xzt,
    sample_column,
    sample_point,
    velocity_in_cell,
    vorticity_from_gradient,
    wall_normal,
)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
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


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def locate_grain(f, re_star, x, y, z, t):
    """Where a grain centre (particle units) lies in the flow data (a compiled call, not
    inlined: inlined with ``gather_at`` and ``grain_velocity`` at every RK4 stage of
    flight.spheres._weight_drag_flight it made that function take 4 minutes to compile):
    (i0, i1, wx, j0, j1, wy, k0, k1, wz, n0, n1, wt, below_wall, sublayer, y⁺).
    With ``grain_velocity`` it gives the velocity ``fluid_at_grain`` gives (same
    arithmetic), split so that a caller can keep the gathered cell (sampler.gather_cell)."""
    yp = y * re_star
    i0, i1, wx, k0, k1, wz, n0, n1, wt = locate_xzt(f, x * re_star, z * re_star, t * re_star)
    status, j0, j1, wy, _, sublayer = wall_normal(f, yp)
    return i0, i1, wx, j0, j1, wy, k0, k1, wz, n0, n1, wt, status == BELOW_WALL, sublayer, yp


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def gather_at(f, loc):
    """The gathered cell (sampler.gather_cell) of a ``locate_grain`` result."""
    return gather_cell(f, loc[9], loc[10], loc[11], loc[0], loc[1], loc[3], loc[4], loc[6], loc[7])


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False, inline="always")
def same_cell(a, b):
    """Two ``locate_grain`` results at the same time share their gathered cell."""
    return a[0] == b[0] and a[3] == b[3] and a[6] == b[6]


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def grain_velocity(f, loc, nodes):
    """Fluid velocity (u*) at a located grain centre from its gathered cell; zero below
    the bed top (as ``fluid_at_grain``)."""
    if loc[12]:
        return 0.0, 0.0, 0.0
    return velocity_in_cell(f, nodes, loc[2], loc[5], loc[8], loc[14], loc[13])


# A rough-bed dataset serves grains whose d⁺ = Re* lies within 20 % of its bed grain's d⁺:
# Colebrook's ΔU⁺ changes by (1/κ)·0.3k/(1 + 0.3k)·ln(1.2) ≈ 0.4 u⁺ over that range at
# k⁺ ≈ 20 (about 5 % of u⁺ one diameter above the bed), below the spread of the mean
# near-bed velocity between published sand-bed profiles (ΔU⁺ ≈ 4–7, SPEC §3); the Niño &
# García stages (Re* = 17.5–21.4 for d = 0.69 mm) then fit one dataset.
BED_TOLERANCE = 0.20
BED_MODES = ("auto", "smooth", "rough")


class BedMismatch(DatasetError):
    """The flow dataset's bed does not fit the run (the message says which one to make)."""


def check_bed(dataset, re_star: float, bed: str = "auto", where: str = "") -> None:
    """Refuse a run whose grains do not fit the dataset's bed (SPEC §3 rough bed).

    bed = "rough" requires a rough-bed dataset, "smooth" a smooth-wall one, "auto" takes
    the dataset as it is. Over a rough bed the grain's Re* must lie within BED_TOLERANCE
    of the bed grain's d⁺."""
    if bed not in BED_MODES:
        raise ValueError(f"flow.bed = {bed!r} is not allowed; use one of {', '.join(BED_MODES)}")
    info = getattr(dataset, "bed", None)
    name = where or str(getattr(dataset, "path", "") or "the flow dataset")
    make = ("saltation flow generate --bed porous --bed-d-plus {dp:.1f} --out DATASET "
            "(then [flow] dataset = \"DATASET\")")
    if bed == "rough" and not info:
        raise BedMismatch(f"flow.bed = \"rough\" but {name} has no bed metadata (meta.json \"bed\"): it is a "
                          f"smooth-wall LES; make a rough-bed dataset with: " + make.format(dp=re_star))
    if bed == "smooth" and info:
        raise BedMismatch(f"flow.bed = \"smooth\" but {name} is a rough-bed dataset (bed grain d+ = "
                          f"{info['d_plus']:.2f}); choose a smooth-wall dataset or flow.bed = \"rough\"")
    if info:
        dp = float(info["d_plus"])
        if abs(re_star / dp - 1.0) > BED_TOLERANCE:
            raise BedMismatch(
                f"this run's grains have Re* = u* d/nu = {re_star:.2f}, but {name} was made for a bed of grains with "
                f"d+ = {dp:.2f} (runs within {100 * BED_TOLERANCE:.0f} %: Re* {dp * (1 - BED_TOLERANCE):.2f}-"
                f"{dp * (1 + BED_TOLERANCE):.2f}); the near-bed flow over other grains differs. Make the right "
                f"dataset with: " + make.format(dp=re_star))


def flow_top_in_d(dataset, re_star: float) -> float:
    """Top of the stored flow in grain diameters above the bed top."""
    return float(dataset.y[-1]) / re_star
