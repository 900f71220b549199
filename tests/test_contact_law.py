"""The one soft contact law (physics/contact_law.py) that sphere pairs, bed spheres and
composite components share: it equals, to rounding, the LAMMPS gran/hooke/history
arithmetic the three former copies used (written here independently, in LAMMPS's form
with the unnormalised separation vector), and it obeys its own definitions (Coulomb
limit, spring kept in the tangent plane, no history advance without ``update``)."""
import math

import numpy as np
import pytest

from saltation.physics.contact_law import spring_dashpot


def lammps_hooke_history(delx, dely, delz, vr, wsum, arm, sh, dt, update, kn, kt, damp_n, damp_t, mu, d=1.0):
    """pair gran/hooke/history's per-pair force as LAMMPS writes it (ccel·del, shrmag,
    rsht), for a pair at separation del = x_i − x_j with lever arm ``arm``."""
    sh = np.array(sh, dtype=float)
    rsq = delx * delx + dely * dely + delz * delz
    r = math.sqrt(rsq)
    rinv, rsqinv = 1.0 / r, 1.0 / rsq
    vnnr = vr[0] * delx + vr[1] * dely + vr[2] * delz
    vt = [vr[0] - delx * vnnr * rsqinv, vr[1] - dely * vnnr * rsqinv, vr[2] - delz * vnnr * rsqinv]
    wr = [arm * w * rinv for w in wsum]
    ccel = kn * (d - r) * rinv - damp_n * vnnr * rsqinv
    vtr = [vt[0] - (delz * wr[1] - dely * wr[2]), vt[1] - (delx * wr[2] - delz * wr[0]),
           vt[2] - (dely * wr[0] - delx * wr[1])]
    if update:
        sh += np.array(vtr) * dt
    shrmag = float(np.linalg.norm(sh))
    if update:
        rsht = (sh[0] * delx + sh[1] * dely + sh[2] * delz) * rsqinv
        sh -= rsht * np.array([delx, dely, delz])
    fs = -(kt * sh + damp_t * np.array(vtr))
    fn = mu * abs(ccel * r)
    if np.linalg.norm(fs) > fn:
        if shrmag != 0.0:
            scale = fn / np.linalg.norm(fs)
            sh = scale * (sh + damp_t * np.array(vtr) / kt) - damp_t * np.array(vtr) / kt
            fs *= scale
        else:
            fs[:] = 0.0
    force = np.array([delx, dely, delz]) * ccel + fs
    return force, sh


def law_force(delx, dely, delz, vr, wsum, arm, sh, dt, update, kn, kt, damp_n, damp_t, mu, d=1.0):
    """The same contact through spring_dashpot, set up as contacts/pairs.py does."""
    r = math.sqrt(delx * delx + dely * dely + delz * delz)
    n = np.array([delx, dely, delz]) / r
    w = arm * np.asarray(wsum)
    v = np.asarray(vr) - np.cross(w, n)
    fn, f0, f1, f2, s0, s1, s2 = spring_dashpot(n[0], n[1], n[2], d - r, v[0], v[1], v[2], sh[0], sh[1], sh[2],
                                                 dt, update, kn, kt, damp_n, damp_t, mu)
    return fn * n + np.array([f0, f1, f2]), np.array([s0, s1, s2])


@pytest.mark.parametrize("damp_t", [0.0, 3.0])
@pytest.mark.parametrize("update", [True, False])
def test_equals_lammps_form_to_rounding(damp_t, update):
    rng = np.random.default_rng(7)
    kn, kt, damp_n, mu = 5.0e5, 5.0e5 * 2 / 7, 150.0, 0.3
    worst_f = worst_s = 0.0
    slid = stuck = 0
    for _ in range(2000):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        r = 1.0 - rng.uniform(1e-5, 1e-2)
        delx, dely, delz = r * n
        vr = rng.normal(scale=3.0, size=3)
        wsum = rng.normal(scale=10.0, size=3)
        sh = rng.normal(scale=rng.choice([1e-6, 1e-3]), size=3)
        args = (delx, dely, delz, vr, wsum, 0.5 * r, sh, 1e-4, update, kn, kt, damp_n, damp_t, mu)
        f_ref, s_ref = lammps_hooke_history(*args)
        f, s = law_force(*args)
        worst_f = max(worst_f, np.abs(f - f_ref).max() / np.abs(f_ref).max())
        worst_s = max(worst_s, np.abs(s - s_ref).max() / max(np.abs(s_ref).max(), 1e-300))
        fn = abs(np.dot(f_ref, n))
        ft = np.linalg.norm(f_ref - np.dot(f_ref, n) * n)
        if ft >= mu * fn * (1 - 1e-9):
            slid += 1
        else:
            stuck += 1
    assert slid > 20 and stuck > 20  # both branches (sliding, sticking) were exercised
    assert worst_f < 1e-11 and worst_s < 1e-9


def test_coulomb_limit_and_tangent_plane():
    n = np.array([0.0, 1.0, 0.0])
    # a fast sliding contact: |F_t| = μ |F_n|, the spring holds exactly that force
    fn, f0, f1, f2, s0, s1, s2 = spring_dashpot(*n, 1e-3, 5.0, -0.2, 1.0, 0.01, 0.02, 0.0, 1e-3, True,
                                                1e5, 3e4, 20.0, 0.0, 0.4)
    ft = np.array([f0, f1, f2])
    assert fn == pytest.approx(1e5 * 1e-3 + 20.0 * 0.2)
    assert np.linalg.norm(ft) == pytest.approx(0.4 * fn, rel=1e-12)
    assert ft[1] == 0.0 and s1 == 0.0  # ξ projected into the tangent plane
    np.testing.assert_allclose(-3e4 * np.array([s0, s1, s2]), ft, rtol=1e-12)
    # F_t opposes the slip
    assert ft[0] < 0.0 and ft[2] < 0.0


def test_no_history_advance_without_update():
    n = (1.0, 0.0, 0.0)
    out = spring_dashpot(*n, 1e-3, 0.0, 0.3, 0.0, 0.0, 1e-6, 0.0, 1e-3, False, 1e5, 3e4, 0.0, 0.0, 0.5)
    assert out[4:] == (0.0, 1e-6, 0.0)  # below the Coulomb limit: ξ untouched
    assert out[2] == pytest.approx(-3e4 * 1e-6)
