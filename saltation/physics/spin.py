"""Particle spin in free flight (SPEC §2, paper eq. 13 with its dropped factor).

Torque on a sphere rotating relative to the fluid (Dennis, Singh & Ingham 1980,
as tabulated for saltation by Lukerchenko et al. 2009):

    T = -(ρ/2) (d/2)⁵ C_ω |ω_r| ω_r,     ω_r = ω_p - ½ ω_f,
    C_ω = C1/√Re_r + C2/Re_r + C3 Re_r,  Re_r = d²|ω_r|/(4ν).

With I = π ρp d⁵/60 this gives, in particle units (spin in u*/d, time d/u*,
Re_r = |ϖ_r| Re*/4):

    dϖ_p/dt = -(15 / (16π (1+R))) C_ω |ϖ_r| ϖ_r.

The first table row (C_ω = 16π/Re_r) is the Stokes torque 8πμa³ω_r.  The
product C_ω|ϖ_r| = (4/Re*)(C1 √Re_r + C2 + C3 Re_r²) is finite at zero relative
spin, so :func:`spin_rate` never divides by |ϖ_r|.
"""

import math

import numpy as np
from numba import njit

# Re_r upper bounds of the rows and (C1, C2, C3) per row
SPIN_TABLE_RE = np.array([1.0, 10.0, 20.0, 50.0, np.inf])
SPIN_TABLE_C = np.array([
    [0.0, 16.0 * math.pi, 0.0],
    [0.0, 16.0 * math.pi, 0.0418],
    [5.32, 37.2, 0.0],
    [6.44, 32.2, 0.0],
    [6.45, 32.1, 0.0],
])


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _spin_row(re_r):
    if re_r < 1.0:
        return 0
    if re_r < 10.0:
        return 1
    if re_r < 20.0:
        return 2
    if re_r < 50.0:
        return 3
    return 4


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def spin_coefficient(re_r):
    """Rotational drag coefficient C_ω(Re_r) (table of SPEC §2). Diverges as
    16π/Re_r at Re_r → 0; Re_r is floored at 1e-300 to stay finite."""
    re = max(re_r, 1.0e-300)
    k = _spin_row(re)
    return SPIN_TABLE_C[k, 0] / math.sqrt(re) + SPIN_TABLE_C[k, 1] / re \
        + SPIN_TABLE_C[k, 2] * re


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def spin_rate(spin_p, vort_f, R, re_star, out):
    """dϖ_p/dt into ``out`` (length 3), particle units.

    spin_p: particle spin ϖ_p; vort_f: fluid vorticity ω_f (both u*/d);
    R: submerged specific gravity; re_star: u* d/ν.
    """
    r0 = spin_p[0] - 0.5 * vort_f[0]
    r1 = spin_p[1] - 0.5 * vort_f[1]
    r2 = spin_p[2] - 0.5 * vort_f[2]
    wr = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    re_r = 0.25 * wr * re_star
    k = _spin_row(re_r)
    # C_ω |ϖ_r| = (4/Re*)(C1 √Re_r + C2 + C3 Re_r²)
    cw_wr = (4.0 / re_star) * (SPIN_TABLE_C[k, 0] * math.sqrt(re_r) + SPIN_TABLE_C[k, 1]
                               + SPIN_TABLE_C[k, 2] * re_r * re_r)
    g = -15.0 / (16.0 * math.pi * (1.0 + R)) * cw_wr
    out[0] = g * r0
    out[1] = g * r1
    out[2] = g * r2
