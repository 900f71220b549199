"""Rigid bonded-sphere grains (saltation.flight.composites): the one-sphere grain is the sphere
integrator; torque-free rotation conserves L and energy; shear exerts a torque; bed
impacts never create energy."""
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from flowfields import open_dataset, profile_dataset
from saltation.bed.virtual import bed_parameters
from saltation.flight import composites as clusters
from saltation.flight import spheres as integrator
from saltation.grains import shapes
from saltation.physics import history
from saltation.physics.forces import make_coefficients

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
from sphere_advance import advance  # noqa: E402  (tests/peers: the flight-and-bed loop without contacts)

DT = 0.01
NW = 10
BED = bed_parameters(0.65, 0.1, math.radians(30.0))


def _cluster(comps, pos, vel, omega, coef, quat=None, spin_drag=True):
    n = len(comps)
    q = np.tile([1.0, 0, 0, 0], (n, 1)) if quat is None else quat
    st = clusters.make_cluster_state(comps, pos, vel, q, omega, 0.0, NW, R=1.65, Cm=coef[4],
                                     re_star=coef[2], spin_drag=spin_drag)
    return st, clusters.make_cluster_work(st)


def test_one_sphere_grain_is_the_sphere_integrator():
    ds = open_dataset()
    re_star = 10.0
    coef = make_coefficients(tau_star=0.06, R=1.65, re_star=re_star)
    hc = history.make_history_coefficients(DT, NW)
    rng = np.random.default_rng(0)
    n = 3
    pos = np.column_stack([rng.uniform(0, 50, n), rng.uniform(0.6, 2, n), rng.uniform(0, 50, n)])
    vel = np.column_stack([rng.uniform(1, 4, n), rng.uniform(0.5, 2, n), rng.uniform(-.5, .5, n)])
    spin = np.column_stack([rng.uniform(-.5, .5, n), rng.uniform(-.5, .5, n), rng.uniform(-2, 0, n)])
    st = integrator.make_state(pos, vel, spin, 0.0, NW)
    w = integrator.make_workspace(n)
    top = float(ds.y[-1]) / re_star
    advance(ds.arrays, coef, BED, 0, st, w, hc, 0.0, DT, 800, top)
    one = shapes.Composite.from_spheres([[0, 0, 0]], [0.5])
    cst, cw = _cluster([one] * n, pos, vel, spin, coef)
    clusters.advance_clusters(ds.arrays, coef, BED, 0, cst, cw, hc, 0.0, DT, 800, top)
    assert st.impacts.sum() >= 5  # bed impacts were part of the comparison
    assert np.array_equal(st.impacts, cst.impacts)
    # the two rebound formulas (bed.virtual vs the rigid-body impulse) differ in rounding:
    # ~2e-9 after the first impact, amplified by each later one (30 here). Measured:
    # 7.8e-7 in x, 3.3e-6 in u with the second-order impact (flight/spheres._bed_impact),
    # 5.9e-8 and 9.2e-8 with the linear one it replaced
    assert np.abs(st.pos - cst.pos).max() < 1e-5
    assert np.abs(st.vel - cst.vel).max() < 1e-5
    assert np.abs(st.spin - cst.omega).max() < 1e-5
    m = st.jump_buf_n.min()
    start, length, height, duration = 0, 1, 2, 3  # jump_buf columns
    for col in (start, length, duration):
        assert np.allclose(st.jump_buf[:, :m, col], cst.jump_buf[:, :m, col], atol=1e-6)
    # the height: a composite's is also sampled inside each step (highest_on_path), a
    # sphere's at the steps' ends only, which can miss the apex by up to the fall under the
    # submerged weight (≤ 1/τ* per unit mass) in half a step
    extra = cst.jump_buf[:, :m, height] - st.jump_buf[:, :m, height]
    assert extra.min() > -1e-6 and extra.max() < 0.5 / 0.06 * (DT / 2) ** 2, extra
    assert extra.max() > 1e-6  # (the inside samples did find higher points)


def _free_coef():
    return make_coefficients(tau_star=1.0, R=1.65, re_star=10.0, Cm=0.0, weight=False, drag=False, lift=False,
                             magnus=False, added_mass=False, fluid_acceleration=False, basset=False)


def test_torque_free_rotation_conserves_momentum_and_energy():
    still = profile_dataset("still", y_top_plus=1e6)
    coef = _free_coef()
    # asymmetric: equant sub-type 4 has three distinct principal moments and a
    # non-diagonal tensor in its geometric frame
    g = shapes.build(1.0, 0.8, 0.6).scaled(1.0 / (0.48 ** (1 / 3)))
    st, w = _cluster([g], [[0, 50, 0]], [[0.3, 0, 0]], [[1.0, 2.0, 0.5]], coef,
                     quat=np.array([[0.9, 0.1, 0.3, 0.2]]), spin_drag=False)
    hc = history.make_history_coefficients(DT, NW)

    def invariants():
        rot = clusters.quat_to_matrix_py(st.quat[0])
        iw = rot @ st.inertia[0] @ rot.T
        o = st.omega[0]
        return iw @ o, 0.5 * o @ iw @ o

    l0, e0 = invariants()
    clusters.advance_clusters(still.arrays, coef, BED, 0, st, w, hc, 0.0, DT, 2000, 1e9)
    l1, e1 = invariants()
    assert np.allclose(l1, l0, rtol=1e-7, atol=1e-10)
    assert e1 == pytest.approx(e0, rel=1e-7)
    assert not np.allclose(st.omega[0], [1.0, 2.0, 0.5], atol=1e-2)  # it does tumble
    assert np.allclose(st.pos[0], [0.3 * 20.0, 50, 0])


def test_shear_flow_turns_a_rod():
    # a vertical rod (long axis along y) in the log-law flow near the bed: the top sphere
    # sees a faster flow; torque about z must be negative (same sense as the vorticity)
    re_star = 20.0
    flow = profile_dataset("loglaw", y_top_plus=1000 * re_star)
    coef = make_coefficients(tau_star=1.0, R=1.65, re_star=re_star, weight=False, lift=False,
                             magnus=False, basset=False)
    rod = shapes.build(3.0, 1.0, 0.9)
    rod = rod.scaled(1.0 / rod.nominal_diameter)
    half = math.sqrt(0.5)
    q = np.array([[half, 0, 0, half]])  # body x → world y
    st, w = _cluster([rod], [[0, 3.0, 0]], [[0, 0, 0]], [[0, 0, 0]], coef, quat=q)
    hc = history.make_history_coefficients(DT, NW)
    clusters.advance_clusters(flow.arrays, coef, BED, 0, st, w, hc, 0.0, DT, 5, 1e9)
    assert st.omega[0, 2] < -1e-3
    assert abs(st.omega[0, 0]) < 1e-9 and abs(st.omega[0, 1]) < 1e-9
    # the same grain's centre velocity follows the flow
    assert st.vel[0, 0] > 0


def test_bed_impacts_never_create_energy():
    still = profile_dataset("still", y_top_plus=1e6)
    coef = make_coefficients(tau_star=1.0, R=1.65, re_star=10.0, drag=False, lift=False, magnus=False,
                             added_mass=False, fluid_acceleration=False, basset=False)
    rng = np.random.default_rng(4)
    comps = [shapes.build(*a).scaled(1.0 / np.prod(a) ** (1 / 3)) for a in
             [(1.0, 0.9, 0.3), (1.0, 0.5, 0.2), (1.0, 0.4, 0.35), (1.0, 0.8, 0.6), (1.0, 0.95, 0.7)]]
    n = len(comps)
    q = rng.normal(size=(n, 4))
    st, w = _cluster(comps, np.column_stack([np.arange(n) * 10.0, np.full(n, 3.0), np.zeros(n)]),
                     rng.uniform(-1, 1, (n, 3)) - [0, 1, 0], rng.uniform(-2, 2, (n, 3)), coef, quat=q)
    hc = history.make_history_coefficients(DT, NW)

    def energy():
        e = np.zeros(n)
        for p in range(n):
            rot = clusters.quat_to_matrix_py(st.quat[p])
            iw = rot @ st.inertia[p] @ rot.T
            # the added mass enters the free-flight inertia: count it in the energy
            m_eff = st.mmat[p, 0, 0]
            e[p] = 0.5 * m_eff * st.vel[p] @ st.vel[p] + 0.5 * st.omega[p] @ iw @ st.omega[p] \
                + st.volume[p] / coef[1] * st.pos[p, 1]
        return e

    e0 = energy()
    clusters.advance_clusters(still.arrays, coef, BED, 3, st, w, hc, 0.0, DT, 1500, 1e9)
    assert st.impacts.min() >= 1
    assert np.all(energy() <= e0 * (1 + 1e-6) + 1e-9)
    assert np.all(clusters.lowest_points(st) >= -1e-2)


def test_wake_factor_tandem_side_by_side_and_size():
    # two touching unit spheres, slip of the grain along −x (fluid moves +x relative to it)
    d = np.array([1.0, 1.0])
    rw = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]])
    ur = (-1.0, 0.0, 0.0)  # u_k − u_f
    lead = clusters.wake_factor(0, 2, 0, rw, d, *ur, 1.0, 0.5, 6.0)
    trail = clusters.wake_factor(0, 2, 1, rw, d, *ur, 1.0, 0.5, 6.0)
    assert lead == 1.0 and trail == pytest.approx(0.5, abs=1e-14)
    # 4 diameters apart: the deficit decays as exp(−(L/d − 1)/λ)
    far = np.array([[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    assert clusters.wake_factor(0, 2, 1, far, d, *ur, 1.0, 0.5, 6.0) == pytest.approx(1 - 0.5 * math.exp(-0.5))
    # side by side (offset across the slip by one diameter): no shielding
    side = np.array([[0.0, -0.5, 0.0], [0.0, 0.5, 0.0]])
    assert clusters.wake_factor(0, 2, 1, side, d, *ur, 1.0, 0.5, 6.0) == 1.0
    assert clusters.wake_factor(0, 2, 0, side, d, *ur, 1.0, 0.5, 6.0) == 1.0
    # half a radius off the axis: lateral overlap 1 − (0.25/1)² of the frontal disks
    off = np.array([[-0.5, 0.0, 0.0], [0.5, 0.25, 0.0]])
    assert clusters.wake_factor(0, 2, 1, off, d, *ur, 1.0, 0.5, 6.0) == pytest.approx(1 - 0.5 * (1 - 0.0625))
    # a small sphere behind a big one is fully covered; a big one behind a small one partly
    d2 = np.array([2.0, 1.0])
    rw2 = np.array([[-0.75, 0.0, 0.0], [0.75, 0.0, 0.0]])
    assert clusters.wake_factor(0, 2, 1, rw2, d2, *ur, 1.0, 0.5, 6.0) == pytest.approx(0.5)
    d3 = np.array([1.0, 2.0])  # leader d = 1 at L = 1.5: 0.5 diameters beyond contact
    expect = 1 - 0.5 * 0.25 * math.exp(-0.5 / 6.0)
    assert clusters.wake_factor(0, 2, 1, rw2, d3, *ur, 1.0, 0.5, 6.0) == pytest.approx(expect)
    # no slip: no wake
    assert clusters.wake_factor(0, 2, 1, rw, d, 0.0, 0.0, 0.0, 0.0, 0.5, 6.0) == 1.0
