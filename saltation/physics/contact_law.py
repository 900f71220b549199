"""The one soft contact law (SPEC §5): linear spring–dashpot normal force, tangential
spring with history and Coulomb limit (Cundall & Strack 1979; the "hooke/history" form of
Silbert et al. 2001, eqs. 1–3, as LAMMPS ``pair gran/hooke/history`` evaluates it).

Every soft contact calls it — sphere pairs (contacts/pairs.py, contacts/phase.py), a grain
on a bed sphere (contacts/phase.py, the partner fixed) and the component spheres of
bonded-sphere grains (contacts/composites.py) — the way one ``GranularModel`` serves
LAMMPS's pairs and walls. The callers own the geometry (which spheres touch, where the
contact point lies, the lever arms of the torque) and the bookkeeping; this function owns
the force:

    F_n = k_n δ − c_n v_n                              (normal, along n, j → i)
    ξ  += v_t h,   ξ −= (ξ·n) n                        (tangential spring, kept in the
                                                          tangent plane; only if ``update``)
    F_t = −k_t ξ − c_t v_t,   |F_t| ≤ μ |F_n|          (Coulomb: on sliding ξ is shortened
                                                          so that the spring holds the limit)

with δ the overlap, v = v_i − v_j the relative velocity of the contact point (spin
included), v_n = v·n, v_t = v − v_n n, h the (sub-)step the spring advances by. The
dashpot c_n = m_eff γ_n comes from the restitution (contacts/pairs.normal_damping); c_t is
an optional tangential dashpot (0 in the saltation runs, LAMMPS's γ_t in the peer tests).

All in the caller's units. Returns (F_n, F_t x, y, z, ξ x, y, z): the caller adds
F_n n + F_t to grain i (and the opposite to j, if it is free) and stores ξ.
"""
import math

from numba import njit


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def spring_dashpot(n0, n1, n2, overlap, vr0, vr1, vr2, sh0, sh1, sh2, h, update, kn, kt, c_n, c_t, mu):
    """Contact force of the law above for unit normal n, overlap δ > 0, contact-point
    relative velocity vr and tangential spring ξ = sh (module docstring)."""
    vn = vr0 * n0 + vr1 * n1 + vr2 * n2
    vt0 = vr0 - vn * n0
    vt1 = vr1 - vn * n1
    vt2 = vr2 - vn * n2
    fn = kn * overlap - c_n * vn
    if update:
        sh0 += vt0 * h
        sh1 += vt1 * h
        sh2 += vt2 * h
    # |ξ| before the projection decides whether a spring exists (LAMMPS's shrmag)
    shrmag = math.sqrt(sh0 * sh0 + sh1 * sh1 + sh2 * sh2)
    if update:
        sn = sh0 * n0 + sh1 * n1 + sh2 * n2
        sh0 -= sn * n0
        sh1 -= sn * n1
        sh2 -= sn * n2
    ft0 = -(kt * sh0 + c_t * vt0)
    ft1 = -(kt * sh1 + c_t * vt1)
    ft2 = -(kt * sh2 + c_t * vt2)
    ftm = math.sqrt(ft0 * ft0 + ft1 * ft1 + ft2 * ft2)
    lim = mu * abs(fn)
    if ftm > lim:
        if shrmag != 0.0:
            scale = lim / ftm
            if kt > 0.0:
                # the spring that, with the dashpot, gives exactly the Coulomb limit
                sh0 = scale * (sh0 + c_t * vt0 / kt) - c_t * vt0 / kt
                sh1 = scale * (sh1 + c_t * vt1 / kt) - c_t * vt1 / kt
                sh2 = scale * (sh2 + c_t * vt2 / kt) - c_t * vt2 / kt
            ft0 *= scale
            ft1 *= scale
            ft2 *= scale
        else:
            ft0 = 0.0
            ft1 = 0.0
            ft2 = 0.0
    return fn, ft0, ft1, ft2, sh0, sh1, sh2


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def sphere_contact_velocity(n0, n1, n2, arm, dv0, dv1, dv2, ws0, ws1, ws2):
    """Relative velocity of the contact point of sphere i against sphere j (or a fixed
    bed sphere): dv − arm (ω_i + ω_j) × n, with dv = v_i − v_j, ws = ω_i + ω_j, n from j
    to i and the contact point ``arm`` from each centre."""
    w0 = arm * ws0
    w1 = arm * ws1
    w2 = arm * ws2
    return dv0 - (w1 * n2 - w2 * n1), dv1 - (w2 * n0 - w0 * n2), dv2 - (w0 * n1 - w1 * n0)


@njit(cache=True, no_cfunc_wrapper=True, inline="always", error_model="numpy", _nrt=False)
def lever_torque(n0, n1, n2, arm, f0, f1, f2):
    """arm n × F: the torque on sphere i is minus this (contact point −arm n from its centre)."""
    return arm * (n1 * f2 - n2 * f1), arm * (n2 * f0 - n0 * f2), arm * (n0 * f1 - n1 * f0)
