"""Fluid forces on a saltating grain in free flight (SPEC §2, paper eqs. 1-13).

Everything is per unit *virtual* particle mass (ρp + Cm ρ)·πd³/6 and in particle
units (length d, velocity u*, time d/u*; SPEC §1).  With the slip velocity
``u_r = u_p - u_f`` and ``U_r = |u_r|``:

=====================  =====================================================
submerged weight       a_sw = (α/τ*) (sin θ, -cos θ, 0)            θ: bed slope
drag                   a_dr = -(3/4) α C_D U_r u_r,  C_D = Yen (1992) of
                       Re_p = U_r Re*
lift (y only)          a_lf = (3/4) α C_L (|u_r|²_top - |u_r|²_bot) ŷ,
                       slip with the fluid velocity at y ± 1/2
Magnus                 a_mg = (3/4) α C_Ω (ϖ_p - ½ ω_f) × u_r
added mass             a_am = α Cm (∂u_f/∂t + (u_p·∇) u_f)
fluid acceleration     a_fa = α (∂u_f/∂t + (u_f·∇) u_f)
=====================  =====================================================

with α = 1/(1 + R + Cm).  The Basset history term lives in ``physics/history.py`` and
the spin equation in ``physics/spin.py``.

Conventions: ``grad_uf[i, j] = ∂u_i/∂x_j``; all vectors are float64 arrays of
length 3; vorticity and spin are in units u*/d.  The caller evaluates the fluid
velocity at the top and bottom of the grain (``uf_top``, ``uf_bot`` at y ± 1/2)
and passes zero where that point is below the bed (y - 1/2 < 0).

Coefficients travel in one float64 array ``coef`` indexed by the module-level
constants below (build it with :func:`make_coefficients`).  Each term has an
on/off switch (1.0 / 0.0).  Every term is written once, as an ``_add_*``
function that adds its contribution to an output vector; the sum
(:func:`fluid_acceleration`) and the per-term breakdown
(:func:`fluid_acceleration_terms`, for ablation and diagnostics tables) both
call those, so the formulas exist in one place only.
"""

import math

import numpy as np
from numba import njit

# ---------------------------------------------------------------- coefficient layout
ALPHA = 0            # α = 1/(1 + R + Cm)
TAU_STAR = 1         # Shields number τ*
RE_STAR = 2          # grain shear Reynolds number Re* = u* d / ν
SLOPE = 3            # bed slope θ (radians, positive = bed descending in +x)
CM = 4               # added-mass coefficient
CL = 5               # lift coefficient
C_OMEGA = 6          # Magnus coefficient C_Ω
R_SUBMERGED = 7      # submerged specific gravity R = ρp/ρ - 1
SIN_SLOPE = 8        # sin θ (precomputed)
COS_SLOPE = 9        # cos θ (precomputed)
BASSET_PREFACTOR = 10  # 9α/√(π Re*), used by physics/history.py (a_bs = -prefactor · I)
ON_WEIGHT = 11
ON_DRAG = 12
ON_LIFT = 13
ON_MAGNUS = 14
ON_ADDED_MASS = 15
ON_FLUID_ACC = 16
ON_BASSET = 17       # not used here; carried for the integrator's convenience
ON_SPIN = 18         # free-flight spin law (physics/spin.py); not used here
N_COEF = 19

# ---------------------------------------------------------------- term rows
TERM_WEIGHT = 0
TERM_DRAG = 1
TERM_LIFT = 2
TERM_MAGNUS = 3
TERM_ADDED_MASS = 4
TERM_FLUID_ACC = 5
N_TERMS = 6
TERM_NAMES = ("weight", "drag", "lift", "magnus", "added_mass", "fluid_acceleration")

# below this slip Reynolds number C_D is evaluated at the limit value (Stokes)
RE_P_MIN = 1.0e-12


def make_coefficients(*, tau_star, R=1.65, Rp=None, re_star=None, slope=0.0,
                      Cm=0.5, C_L=0.2, C_Omega=1.0,
                      weight=True, drag=True, lift=True, magnus=True,
                      added_mass=True, fluid_acceleration=True, basset=True, spin=True):
    """Build the ``coef`` array for the force kernels.

    Parameters
    ----------
    tau_star : Shields number τ* = u*²/(g R d).
    R : submerged specific gravity ρp/ρ - 1 (1.65 quartz in water).
    Rp, re_star : give one: explicit particle Reynolds number √(gRd³)/ν, or the
        shear Reynolds number Re* = √τ*·Rp.  Both may be given if consistent.
    slope : bed slope θ in radians.
    Cm, C_L, C_Omega : added-mass, lift and Magnus coefficients.
    weight … basset : on/off switches of the terms; spin: the free-flight spin law
        (physics/spin.py) — off, the spin changes only at contacts.
    """
    if tau_star is None or not tau_star > 0:
        raise ValueError(f"tau_star must be > 0, got {tau_star!r}")
    if Rp is None and re_star is None:
        raise ValueError("give Rp or re_star")
    if re_star is None:
        re_star = math.sqrt(tau_star) * Rp
    elif Rp is not None:
        expect = math.sqrt(tau_star) * Rp
        if abs(expect - re_star) > 1e-9 * max(abs(re_star), 1.0):
            raise ValueError(f"re_star={re_star} inconsistent with sqrt(tau_star)*Rp={expect}")
    if not re_star > 0:
        raise ValueError(f"re_star must be > 0, got {re_star!r}")
    if not R > -1.0:
        raise ValueError(f"R must be > -1, got {R!r}")
    if Cm < 0:
        raise ValueError(f"Cm must be >= 0, got {Cm!r}")
    alpha = 1.0 / (1.0 + R + Cm)
    coef = np.zeros(N_COEF)
    coef[ALPHA] = alpha
    coef[TAU_STAR] = tau_star
    coef[RE_STAR] = re_star
    coef[SLOPE] = slope
    coef[CM] = Cm
    coef[CL] = C_L
    coef[C_OMEGA] = C_Omega
    coef[R_SUBMERGED] = R
    coef[SIN_SLOPE] = math.sin(slope)
    coef[COS_SLOPE] = math.cos(slope)
    coef[BASSET_PREFACTOR] = 9.0 * alpha / math.sqrt(math.pi * re_star)
    coef[ON_WEIGHT] = float(bool(weight))
    coef[ON_DRAG] = float(bool(drag))
    coef[ON_LIFT] = float(bool(lift))
    coef[ON_MAGNUS] = float(bool(magnus))
    coef[ON_ADDED_MASS] = float(bool(added_mass))
    coef[ON_FLUID_ACC] = float(bool(fluid_acceleration))
    coef[ON_BASSET] = float(bool(basset))
    coef[ON_SPIN] = float(bool(spin))
    return coef


# ---------------------------------------------------------------- drag law
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def yen_drag_coefficient(re_p):
    """Yen (1992) sphere drag coefficient:
    C_D = 24/Re (1 + 0.15√Re + 0.017 Re) - 0.208/(1 + 10⁴ Re^-1/2).
    Re below RE_P_MIN is evaluated at RE_P_MIN (C_D ~ 24/Re diverges at 0)."""
    re = max(re_p, RE_P_MIN)
    sre = math.sqrt(re)
    return 24.0 / re * (1.0 + 0.15 * sre + 0.017 * re) - 0.208 / (1.0 + 1.0e4 / sre)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def drag_factor(slip_speed, re_star):
    """C_D(Re_p)·U_r with Re_p = U_r Re*, written without the 1/U_r singularity:
    (24/Re*)(1 + 0.15√Re_p + 0.017 Re_p) - 0.208 U_r √Re_p/(√Re_p + 10⁴).
    Finite (= 24/Re*) at zero slip; identical to yen_drag_coefficient·U_r."""
    re = slip_speed * re_star
    sre = math.sqrt(re)
    return (24.0 / re_star) * (1.0 + 0.15 * sre + 0.017 * re) \
        - 0.208 * slip_speed * sre / (sre + 1.0e4)


# ---------------------------------------------------------------- the terms
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def weight_components(coef):
    """(α/τ*) sin θ and (α/τ*) cos θ: a_sw = (α/τ*)(sin θ, -cos θ, 0)."""
    g = coef[ALPHA] / coef[TAU_STAR]
    return g * coef[SIN_SLOPE], g * coef[COS_SLOPE]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_weight(coef, out):
    # a_sw = (α/τ*)(sin θ, -cos θ, 0)
    if coef[ON_WEIGHT] == 0.0:
        return
    gx, gy = weight_components(coef)
    out[0] += gx
    out[1] -= gy


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def drag_per_slip(r0, r1, r2, coef):
    """k of a_dr = k u_r with u_r = u_p - u_f = (r0, r1, r2): k = -(3/4) α C_D U_r."""
    ur = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    return -0.75 * coef[ALPHA] * drag_factor(ur, coef[RE_STAR])


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_drag(up, uf, coef, out):
    # a_dr = -(3/4) α C_D U_r u_r
    if coef[ON_DRAG] == 0.0:
        return
    r0 = up[0] - uf[0]
    r1 = up[1] - uf[1]
    r2 = up[2] - uf[2]
    k = drag_per_slip(r0, r1, r2, coef)
    out[0] += k * r0
    out[1] += k * r1
    out[2] += k * r2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def weight_and_drag(coef, up0, up1, up2, uf0, uf1, uf2):
    """``fluid_acceleration`` when weight and drag are the only terms switched on, on
    scalars (flight/spheres.py's fast path): the same operations in the same order."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    if coef[ON_WEIGHT] != 0.0:
        gx, gy = weight_components(coef)
        a0 += gx
        a1 -= gy
    if coef[ON_DRAG] != 0.0:
        r0 = up0 - uf0
        r1 = up1 - uf1
        r2 = up2 - uf2
        k = drag_per_slip(r0, r1, r2, coef)
        a0 += k * r0
        a1 += k * r1
        a2 += k * r2
    return a0, a1, a2


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_lift(up, uf_top, uf_bot, coef, out):
    # a_lf,y = (3/4) α C_L (|u_p - u_f(y+1/2)|² - |u_p - u_f(y-1/2)|²)
    if coef[ON_LIFT] == 0.0:
        return
    t0 = up[0] - uf_top[0]
    t1 = up[1] - uf_top[1]
    t2 = up[2] - uf_top[2]
    b0 = up[0] - uf_bot[0]
    b1 = up[1] - uf_bot[1]
    b2 = up[2] - uf_bot[2]
    top2 = t0 * t0 + t1 * t1 + t2 * t2
    bot2 = b0 * b0 + b1 * b1 + b2 * b2
    out[1] += 0.75 * coef[ALPHA] * coef[CL] * (top2 - bot2)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_magnus(up, uf, vort_f, spin_p, coef, out):
    # a_mg = (3/4) α C_Ω (ϖ_p - ½ ω_f) × u_r
    if coef[ON_MAGNUS] == 0.0:
        return
    s0 = spin_p[0] - 0.5 * vort_f[0]
    s1 = spin_p[1] - 0.5 * vort_f[1]
    s2 = spin_p[2] - 0.5 * vort_f[2]
    r0 = up[0] - uf[0]
    r1 = up[1] - uf[1]
    r2 = up[2] - uf[2]
    k = 0.75 * coef[ALPHA] * coef[C_OMEGA]
    out[0] += k * (s1 * r2 - s2 * r1)
    out[1] += k * (s2 * r0 - s0 * r2)
    out[2] += k * (s0 * r1 - s1 * r0)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_material_acceleration(dudt_f, grad_uf, v, k, out):
    # out += k (∂u_f/∂t + (v·∇) u_f),  (v·∇)u_i = Σ_j v_j ∂u_i/∂x_j
    for i in range(3):
        out[i] += k * (dudt_f[i] + grad_uf[i, 0] * v[0] + grad_uf[i, 1] * v[1]
                       + grad_uf[i, 2] * v[2])


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_added_mass(up, grad_uf, dudt_f, coef, out):
    # a_am = α Cm (∂u_f/∂t + (u_p·∇) u_f): fluid acceleration along the grain path
    if coef[ON_ADDED_MASS] == 0.0:
        return
    _add_material_acceleration(dudt_f, grad_uf, up, coef[ALPHA] * coef[CM], out)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _add_fluid_acc(uf, grad_uf, dudt_f, coef, out):
    # a_fa = α (∂u_f/∂t + (u_f·∇) u_f): pressure gradient of the undisturbed flow
    if coef[ON_FLUID_ACC] == 0.0:
        return
    _add_material_acceleration(dudt_f, grad_uf, uf, coef[ALPHA], out)


# ---------------------------------------------------------------- public kernels
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def fluid_acceleration(up, uf, grad_uf, dudt_f, vort_f, spin_p, uf_top, uf_bot,
                       coef, out):
    """Sum of all switched-on non-history terms (weight, drag, lift, Magnus, added
    mass, fluid acceleration) written into ``out`` (length 3)."""
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    _add_weight(coef, out)
    _add_drag(up, uf, coef, out)
    _add_lift(up, uf_top, uf_bot, coef, out)
    _add_magnus(up, uf, vort_f, spin_p, coef, out)
    _add_added_mass(up, grad_uf, dudt_f, coef, out)
    _add_fluid_acc(uf, grad_uf, dudt_f, coef, out)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def fluid_acceleration_terms(up, uf, grad_uf, dudt_f, vort_f, spin_p, uf_top, uf_bot,
                             coef, terms):
    """Each term separately: ``terms`` has shape (N_TERMS, 3), rows TERM_WEIGHT …
    TERM_FLUID_ACC (names in TERM_NAMES).  Switched-off terms are zero rows.
    ``terms.sum(axis=0)`` equals :func:`fluid_acceleration`."""
    for k in range(N_TERMS):
        for i in range(3):
            terms[k, i] = 0.0
    _add_weight(coef, terms[TERM_WEIGHT])
    _add_drag(up, uf, coef, terms[TERM_DRAG])
    _add_lift(up, uf_top, uf_bot, coef, terms[TERM_LIFT])
    _add_magnus(up, uf, vort_f, spin_p, coef, terms[TERM_MAGNUS])
    _add_added_mass(up, grad_uf, dudt_f, coef, terms[TERM_ADDED_MASS])
    _add_fluid_acc(uf, grad_uf, dudt_f, coef, terms[TERM_FLUID_ACC])
