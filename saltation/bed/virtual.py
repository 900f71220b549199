"""Bed rebound: hard-sphere impulse on a fixed bed grain (SPEC §4).

Impact model
------------
The grain (radius r = 1/2 in particle units, unit mass, I = (2/5) m r²) hits a
fixed bed sphere; ``n`` is the unit normal from the bed grain's centre to the
grain's centre.  With contact-point slip ``c = u + ω × (-r n)``, its tangential
part ``c_t = c - (c·n) n`` and ``u_n = u·n < 0``:

* normal:   u_n' = -e u_n
* sticking  if |c_t| ≤ (7/2) f (1+e) |u_n|:
  u_t' = u_t - (2/7) c_t,   ω' = ω + (5/(7r)) n × c_t   (leaves rolling, c_t' = 0)
* sliding   otherwise, ĉ_t = c_t/|c_t|:
  u_t' = u_t - f(1+e)|u_n| ĉ_t,   ω' = ω + (5/(2r)) f(1+e)|u_n| (n × ĉ_t)

:func:`rebound` applies exactly this, in place, and returns ``STICK``,
``SLIDE`` or ``NO_IMPACT`` (u_n ≥ 0: the grain is not approaching; nothing is
changed).  With e ≤ 1 and f ≥ 0 it never creates kinetic energy.

Virtual rough bed (Niño & García 1994 lineage)
----------------------------------------------
:func:`virtual_bed_normal` tilts the vertical by two random contact angles,
measured in the frame of the incoming grain: ``e1`` = horizontal direction of
the incoming velocity (x̂ if it has none), ``e3 = e1 × ŷ``.

    n ∝ -tan(θa) e1 + ŷ + tan(θb) e3

θa > 0 tilts the normal against the motion (the stoss face of a bed grain),
θa < 0 towards it (the lee face); θb is the cross-path tilt.

Geometric rule.  An incoming grain descending at angle β below the horizontal
(tan β = -u_y/|u_h|) can touch a face only if it approaches it:
u_in·n < 0 ⇔ θa > -β.  With a minimum incidence margin δ (default 2°) the
along-path angle is drawn uniformly in [max(-θmax, δ - β), θmax]; a grazing
grain (β → 0) therefore only meets stoss faces, a steeply falling one meets
both faces.  The cross-path tilt is then drawn with tan θb uniform in
±tan θb_max, tan²θa + tan²θb_max = tan²θmax, so the total tilt of n from the
vertical never exceeds θmax (default 30°, ``MAX_TILT``).  The draws are uniform
in these angles, not weighted by the exposed area of the bed grain: a
modelling choice in the spirit of Niño & García's random bed angles, not a
derived distribution.  In the along-path plane the
incidence angle is θa + β ≥ δ, hence u_in·n ≤ -|u_in| sin δ cos(tilt) < 0.
``xi1`` and ``xi2`` are uniform (0, 1) numbers supplied by the caller (see
``physics/rng.py``), so the draw is reproducible per particle.

Never into the bed.  On a tilted normal, u'·n ≥ 0 does not imply an upward
velocity: a grain sliding down a lee face leaves with u'_y < 0.  Physically it
strikes the bed beneath straight away.  :func:`bed_rebound` models exactly
that: if after the first impact u'_y < 0, a second impact on the horizontal
bed (n = ŷ) with the same e and f follows.  After it u''_y = -e u'_y ≥ 0, and
since each impact alone never creates energy neither does the pair.  The
grain's *position* (placing it at or above contact height) remains the
caller's job.
"""

import math
from typing import NamedTuple

import numpy as np
from numba import njit

NO_IMPACT = 0
STICK = 1
SLIDE = 2
SECOND_IMPACT = 4        # flag OR-ed into bed_rebound's code; branch = code & 3

MAX_TILT = math.radians(30.0)
# the bed parameter array every bed kernel takes (bed_parameters): restitution, friction,
# max tilt (rad), bed model (slot BED_MODEL: 0 virtual, flight.composites.BED_PACKED), then the jump
# thresholds (slots jumps.BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT)
BED_MODEL = 3


def bed_parameters(restitution, friction, max_tilt=MAX_TILT, *, model=0.0, min_jump_duration=0.0,
                   min_jump_height=0.0):
    """The bed parameter array of the kernels (slots above; bed/jumps.py for the last two:
    the shortest jump in d/u* and the lowest in d, from jumps.jump_thresholds)."""
    return np.array([restitution, friction, max_tilt, model, min_jump_duration, min_jump_height], np.float64)


def run_bed_parameters(case, coef, dt, model=0.0):
    """bed_parameters of a run: the case's e, f and tilt, the jump thresholds for its step
    dt (d/u*) and weight (coef: forces.make_coefficients)."""
    from ..physics.forces import ALPHA, TAU_STAR
    from .jumps import jump_thresholds

    t_min, h_min = jump_thresholds(dt, coef[TAU_STAR], coef[ALPHA])
    return bed_parameters(case.bed_restitution, case.bed_friction, case.bed.max_tilt_radians, model=model,
                          min_jump_duration=t_min, min_jump_height=h_min)
MIN_INCIDENCE = math.radians(2.0)
PARTICLE_RADIUS = 0.5    # particle units (d = 1)


# ------------------------------------------------------------------ coefficients
class BedCoefficients(NamedTuple):
    restitution: float
    friction: float
    source: str


_FIXED_SETS = {
    "schmeeckle-2001": (0.65, 0.10),
    "tsuji-1987": (0.80, 0.40),
}
DEFAULT_SET = "schmeeckle-2001"


def coefficient_set(name=DEFAULT_SET, tau_ratio=None, *, restitution=None, friction=None):
    """Restitution e and friction f of the bed impact (paper Table 2).

    name: 'schmeeckle-2001' (default: e=0.65, f=0.10), 'tsuji-1987' (0.80, 0.40),
    'nino-garcia-1994' (e = 0.75 - 0.25 τ*/τ*c, f = 0.89; needs ``tau_ratio``),
    or 'user' with ``restitution`` and ``friction``.
    Raises ValueError for e outside [0, 1] (rounding-level excursions are clipped)
    or f < 0.
    """
    key = (name or DEFAULT_SET).lower().replace("_", "-")
    if key in _FIXED_SETS:
        e, f = _FIXED_SETS[key]
    elif key in ("nino-garcia-1994", "nino-garcia"):
        if tau_ratio is None:
            raise ValueError("nino-garcia-1994 needs tau_ratio = tau*/tau*c")
        e = 0.75 - 0.25 * float(tau_ratio)
        f = 0.89
        key = "nino-garcia-1994"
    elif key == "user":
        if restitution is None or friction is None:
            raise ValueError("'user' needs restitution and friction")
        e, f = float(restitution), float(friction)
    else:
        raise ValueError(f"unknown bed coefficient set {name!r}; "
                         "use schmeeckle-2001, tsuji-1987, nino-garcia-1994 or user")
    if not (-1e-12 <= e <= 1.0 + 1e-12):
        raise ValueError(f"restitution e = {e:g} from {key} (tau_ratio={tau_ratio}) "
                         "is outside [0, 1]")
    e = min(max(e, 0.0), 1.0)
    if not f >= 0.0:
        raise ValueError(f"friction f = {f:g} must be >= 0")
    return BedCoefficients(e, f, key)


# ------------------------------------------------------------------ impulse
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _rebound(u, omega, n0, n1, n2, e, f, r):
    # the impulse of SPEC §4 for the unit normal (n0, n1, n2)
    un = u[0] * n0 + u[1] * n1 + u[2] * n2
    if un >= 0.0:
        return NO_IMPACT
    # contact slip c = u + ω × (-r n) = u - r (ω × n)
    c0 = u[0] - r * (omega[1] * n2 - omega[2] * n1)
    c1 = u[1] - r * (omega[2] * n0 - omega[0] * n2)
    c2 = u[2] - r * (omega[0] * n1 - omega[1] * n0)
    cn = c0 * n0 + c1 * n1 + c2 * n2
    ct0 = c0 - cn * n0
    ct1 = c1 - cn * n1
    ct2 = c2 - cn * n2
    ct = math.sqrt(ct0 * ct0 + ct1 * ct1 + ct2 * ct2)
    jn = (1.0 + e) * (-un)            # normal impulse per unit mass: u_n' = -e u_n
    u[0] += jn * n0
    u[1] += jn * n1
    u[2] += jn * n2
    if ct <= 3.5 * f * jn:
        # sticking: u_t' = u_t - (2/7) c_t ;  ω' = ω + (5/(7r)) n × c_t
        u[0] -= (2.0 / 7.0) * ct0
        u[1] -= (2.0 / 7.0) * ct1
        u[2] -= (2.0 / 7.0) * ct2
        k = 5.0 / (7.0 * r)
        omega[0] += k * (n1 * ct2 - n2 * ct1)
        omega[1] += k * (n2 * ct0 - n0 * ct2)
        omega[2] += k * (n0 * ct1 - n1 * ct0)
        return STICK
    # sliding: u_t' = u_t - f(1+e)|u_n| ĉ_t ;  ω' = ω + (5/(2r)) f(1+e)|u_n| n × ĉ_t
    jt = f * jn / ct
    u[0] -= jt * ct0
    u[1] -= jt * ct1
    u[2] -= jt * ct2
    k = 2.5 * jt / r
    omega[0] += k * (n1 * ct2 - n2 * ct1)
    omega[1] += k * (n2 * ct0 - n0 * ct2)
    omega[2] += k * (n0 * ct1 - n1 * ct0)
    return SLIDE


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def rebound(u, omega, n, e, f, r=PARTICLE_RADIUS):
    """Hard-sphere rebound on a fixed sphere, in place (SPEC §4).

    u, omega: velocity and spin (length 3, modified); n: unit normal from the bed
    grain centre to the grain centre; e: restitution; f: Coulomb friction;
    r: grain radius.  Returns STICK, SLIDE, or NO_IMPACT if u·n ≥ 0.
    """
    return _rebound(u, omega, n[0], n[1], n[2], e, f, r)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def bed_rebound(u, omega, n, e, f, r=PARTICLE_RADIUS):
    """Rebound on the bed grain with normal ``n``, followed, if the grain would
    still move downwards (u_y < 0), by a second impact on the horizontal bed
    (n = ŷ).  Guarantees u_y ≥ 0 on return when an impact happened.
    Returns the first impact's code, OR-ed with SECOND_IMPACT if the second one
    happened (branch of the first impact: ``code & 3``)."""
    code = _rebound(u, omega, n[0], n[1], n[2], e, f, r)
    if code != NO_IMPACT and u[1] < 0.0:
        # u_y'' = u_y' + (1+e)(-u_y') = -e u_y' >= 0 (exactly 0 for e = 0)
        _rebound(u, omega, 0.0, 1.0, 0.0, e, f, r)
        code |= SECOND_IMPACT
    return code


# ------------------------------------------------------------------ virtual bed
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def virtual_bed_normal(u_in, xi1, xi2, max_tilt, out, min_incidence=MIN_INCIDENCE):
    """Random contact normal on a virtual rough bed (rule in the module docstring).

    u_in: incoming velocity (length 3, should descend: u_y < 0); xi1, xi2:
    uniform (0, 1) numbers (along-path and cross-path angle); max_tilt: largest
    tilt of n from the vertical (radians, default MAX_TILT); out: the unit normal.
    Returns 1, or 0 when u_in does not descend onto the bed (u_y ≥ 0, or too
    flat to reach any face with the margin): then ``out`` is the vertical.
    """
    uh = math.sqrt(u_in[0] * u_in[0] + u_in[2] * u_in[2])
    if uh > 0.0:
        e1x = u_in[0] / uh
        e1z = u_in[2] / uh
    else:
        e1x = 1.0
        e1z = 0.0
    # e3 = e1 × ŷ = (-e1z, 0, e1x)
    e3x = -e1z
    e3z = e1x
    beta = math.atan2(-u_in[1], uh)          # descent angle below the horizontal
    lo = max(-max_tilt, min_incidence - beta)
    if u_in[1] >= 0.0 or lo > max_tilt:
        out[0] = 0.0
        out[1] = 1.0
        out[2] = 0.0
        return 0
    theta_a = lo + (max_tilt - lo) * xi1
    ta = math.tan(theta_a)
    tmax = math.tan(max_tilt)
    tb_max = math.sqrt(max(tmax * tmax - ta * ta, 0.0))
    tb = tb_max * (2.0 * xi2 - 1.0)
    nx = -ta * e1x + tb * e3x
    ny = 1.0
    nz = -ta * e1z + tb * e3z
    inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    out[0] = nx * inv
    out[1] = ny * inv
    out[2] = nz * inv
    return 1
