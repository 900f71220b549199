"""Grain–grain contacts (saltation/contacts/pairs.py, SPEC §5): restitution, conservation laws,
Newton's third law and the symmetric tangential history, the hard-sphere impulse, no
missed contacts, counters, and the conversion from a case."""
import math

import numba
import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from saltation.case.schema import load_case
from saltation.contacts import pairs as C

BOX = (12.0, 12.0, 12.0)


def pair_state(offset, vel_i, vel_j, spin_i=(0, 0, 0), spin_j=(0, 0, 0), centre=(6.0, 6.0, 6.0)):
    c = np.asarray(centre, dtype=float)
    pos = np.array([c, c + np.asarray(offset, dtype=float)])
    vel = np.array([vel_i, vel_j], dtype=float)
    spin = np.array([spin_i, spin_j], dtype=float)
    return pos, vel, spin


def run_pair(model, pos, vel, spin, steps_per_contact=25, contacts=4.0, skin=0.1, periodic=(1, 1, 1)):
    """Advance a pair until well after the contact: time = contacts × contact duration
    plus the time to close the initial gap at the initial closing speed."""
    tc = C.contact_duration(model)
    dt = tc / steps_per_contact
    n = len(pos)
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    cl = C.make_contact_list(pos, BOX, periodic, model.diameter, skin)
    gap = np.linalg.norm(pos[1] - pos[0]) - model.diameter
    closing = max(1e-3, -np.dot(vel[1] - vel[0], (pos[1] - pos[0]) / np.linalg.norm(pos[1] - pos[0])))
    n_steps = int(math.ceil((contacts * tc + max(gap, 0.0) / closing) / dt))
    cl, _ = C.advance_granular(pos, vel, spin, force, torque, model, cl, dt, n_steps)
    return cl


def energy(vel, spin, model):
    return C.kinetic_energy_total(vel, spin, model)


def angular_momentum(pos, vel, spin, model, about):
    return model.mass * np.cross(pos - about, vel).sum(axis=0) + model.inertia * spin.sum(axis=0)


# --------------------------------------------------------------------------- restitution


@pytest.mark.parametrize("restitution, steps", [(0.65, 20), (0.65, 50), (0.9, 20), (0.3, 200)])
def test_head_on_collision_reproduces_restitution_and_conserves_momentum(restitution, steps):
    model = C.make_contact_model(kn=2.0e5, restitution=restitution, friction=0.1)
    pos, vel, spin = pair_state((1.005, 0, 0), (1.5, 0, 0), (-0.5, 0, 0))
    p0 = vel.sum(axis=0).copy()
    approach = vel[0, 0] - vel[1, 0]
    cl = run_pair(model, pos, vel, spin, steps_per_contact=steps)
    assert cl.collisions.tolist() == [1, 1]
    assert cl.n_touch.tolist() == [0, 0]  # separated again
    e = (vel[1, 0] - vel[0, 0]) / approach
    assert e == pytest.approx(restitution, rel=0.02)
    np.testing.assert_allclose(vel.sum(axis=0), p0, rtol=0, atol=1e-14)
    assert np.all(spin == 0.0) and np.all(vel[:, 1:] == 0.0)  # head-on: no tangential action


def test_restitution_error_shrinks_with_resolution():
    """The half-step velocity in the dashpot (LAMMPS/velocity-Verlet) costs O(dt): the
    error at 80 steps per contact is about a quarter of that at 20."""
    errs = []
    for steps in (20, 80):
        model = C.make_contact_model(kn=2.0e5, restitution=0.5, friction=0.0)
        pos, vel, spin = pair_state((1.001, 0, 0), (1.0, 0, 0), (-1.0, 0, 0))
        run_pair(model, pos, vel, spin, steps_per_contact=steps)
        errs.append(abs((vel[1, 0] - vel[0, 0]) / 2.0 - 0.5))
    assert 2.5 < errs[0] / errs[1] < 6.0


def test_normal_damping_formula_is_the_damped_oscillator_inverse():
    kn, m_eff = 3.0e4, 0.5
    for e in (0.1, 0.5, 0.65, 0.99, 1.0):
        g = C.normal_damping(e, kn, m_eff)
        wd = math.sqrt(kn / m_eff - g * g / 4.0)
        assert math.exp(-g * math.pi / (2.0 * wd)) == pytest.approx(e, rel=1e-12)
    with pytest.raises(ValueError):
        C.normal_damping(0.0, kn, m_eff)


def test_peak_overlap_matches_the_damped_oscillator_and_is_counted():
    model = C.make_contact_model(kn=5.0e5, restitution=0.65, friction=0.1)
    v0 = 10.0  # relative normal speed (u*): the case's design impact speed
    pos, vel, spin = pair_state((1.0 + 1e-9, 0, 0), (5.0, 0, 0), (-5.0, 0, 0))
    cl = run_pair(model, pos, vel, spin, steps_per_contact=200)
    beta = model.gamma_n / 2.0
    wd = math.sqrt(model.kn / (0.5 * model.mass) - beta * beta)
    t_peak = math.atan2(wd, beta) / wd
    delta_peak = v0 / wd * math.exp(-beta * t_peak) * math.sin(wd * t_peak)
    assert cl.max_overlap.max() == pytest.approx(delta_peak, rel=1e-3)
    assert delta_peak < 0.01  # the overlap rule of the case: ≲ 1 % of d at 10 u*
    stats = C.overlap_statistics(pos, cl)
    assert stats["contacts"] == 0 and stats["max_seen"] == pytest.approx(delta_peak, rel=1e-3)


# --------------------------------------------------------------------------- oblique, friction


@pytest.mark.parametrize("friction", [0.05, 0.4, 5.0])  # sliding, mixed, sticking
@pytest.mark.parametrize("gamma_t", [0.0, 40.0])
def test_oblique_collision_conserves_angular_momentum_about_the_contact_point(friction, gamma_t):
    model = C.make_contact_model(kn=1.0e5, restitution=0.7, friction=friction, gamma_t=gamma_t)
    pos, vel, spin = pair_state((1.0 + 1e-6, 0.4, -0.3), (1.0, -0.5, 0.3), (-1.0, 0.6, 0.2),
                                spin_i=(2.0, -1.0, 3.0), spin_j=(-0.5, 4.0, 1.0))
    contact_point = pos[1] + 0.5 * (pos[0] - pos[1])
    p0 = vel.sum(axis=0).copy()
    l0 = angular_momentum(pos, vel, spin, model, contact_point)
    l0_origin = angular_momentum(pos, vel, spin, model, np.zeros(3))
    e0 = energy(vel, spin, model)
    w0 = spin.copy()
    cl = run_pair(model, pos, vel, spin)
    assert cl.collisions.tolist() == [1, 1]
    # Both contact points and the centres moved; L about the fixed initial point is conserved
    # because the momentum is: round-off only, relative to m |v| d.
    scale = model.mass * np.abs(vel).max() * model.diameter
    np.testing.assert_allclose(vel.sum(axis=0), p0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(angular_momentum(pos, vel, spin, model, contact_point), l0, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(angular_momentum(pos, vel, spin, model, np.zeros(3)), l0_origin, rtol=0,
                               atol=1e-12 * scale * 10)
    # both grains got the same torque (equal spheres, same lever arm): equal spin change
    np.testing.assert_allclose(spin[0] - w0[0], spin[1] - w0[1], rtol=0, atol=1e-12)
    assert np.abs(spin - w0).max() > 1e-3  # friction did act
    assert energy(vel, spin, model) < e0


def test_lammps_lever_arm_drifts_angular_momentum_only_by_the_overlap():
    """LEVER_RADIUS (LAMMPS) puts the torque arm at d/2 while the centres are d − δ apart:
    the moment of the pair no longer cancels the torques; the drift is bounded by
    δmax × the tangential impulse (≤ m |Δv|)."""
    model = C.make_contact_model(kn=1.0e4, restitution=0.7, friction=0.5, lever=C.LEVER_RADIUS)
    pos, vel, spin = pair_state((1.0 + 1e-6, 0.4, 0.0), (1.0, -0.5, 0.0), (-1.0, 0.6, 0.0))
    v0 = vel.copy()
    l0 = angular_momentum(pos, vel, spin, model, np.zeros(3))
    cl = run_pair(model, pos, vel, spin)
    drift = np.abs(angular_momentum(pos, vel, spin, model, np.zeros(3)) - l0).max()
    bound = cl.max_overlap.max() * model.mass * np.abs(vel - v0).max() * 2.0
    assert 1e-9 < drift < bound


def test_newton_third_law_is_exact_and_history_antisymmetric_in_a_dense_gas():
    n = 400
    length = (n * math.pi / 6.0 / 0.3) ** (1.0 / 3.0)
    pos, vel, spin = C.random_gas(n, (length,) * 3, seed=3, speed=1.0)
    spin[:] = np.random.default_rng(1).normal(0.0, 2.0, (n, 3))
    model = C.make_contact_model(kn=2.0e4, restitution=0.6, friction=0.5, gamma_t=20.0)
    dt = C.contact_duration(model) / 30.0
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    cl = C.make_contact_list(pos, (length,) * 3, (1, 1, 1), 1.0, 0.2)
    p0 = vel.sum(axis=0).copy()
    cl, _ = C.advance_granular(pos, vel, spin, force, torque, model, cl, dt, 1500)
    assert cl.collisions.sum() > 200 and cl.n_touch.sum() > 10
    np.testing.assert_allclose(vel.sum(axis=0), p0, rtol=0, atol=1e-11)
    checked = 0
    for i in range(n):
        for k in range(cl.nbr_count[i]):
            if not cl.touch[i, k]:
                continue
            j = cl.nbr[i, k]
            (kk,) = np.nonzero(cl.nbr[j, :cl.nbr_count[j]] == i)[0]
            assert cl.touch[j, kk] == 1
            assert np.array_equal(cl.shear[j, kk], -cl.shear[i, k])  # bit for bit
            checked += 1
    assert checked == cl.n_touch.sum() > 10
    # pair forces cancel exactly: every contact force of grain 0's partners, one pair at a time
    for i in np.nonzero(cl.n_touch == 1)[0][:20]:
        k = int(np.nonzero(cl.touch[i, :cl.nbr_count[i]])[0][0])
        j = cl.nbr[i, k]
        if cl.n_touch[j] != 1:
            continue
        assert np.array_equal(force[i], -force[j])
        assert np.array_equal(torque[i], torque[j])


def test_contact_forces_of_an_isolated_pair_are_exactly_opposite():
    model = C.make_contact_model(kn=1.0e4, restitution=0.5, friction=0.3, gamma_t=10.0)
    pos, vel, spin = pair_state((0.98, 0.11, -0.07), (0.3, -1.1, 0.7), (-0.9, 0.2, 0.1),
                                spin_i=(1.0, 2.0, -3.0), spin_j=(0.5, -0.2, 0.3))
    n = (pos[0] - pos[1]) / np.linalg.norm(pos[0] - pos[1])
    cl = C.make_contact_list(pos, BOX, (1, 1, 1), 1.0, 0.1)
    force = np.zeros((2, 3))
    torque = np.zeros((2, 3))
    for _ in range(5):  # history grows, projected, possibly truncated
        C.contact_forces(pos, vel, spin, model, cl, 1e-3, True, force, torque)
        assert np.array_equal(force[0], -force[1])
        assert np.array_equal(torque[0], torque[1])
        assert np.array_equal(cl.shear[0, 0], -cl.shear[1, 0])
        assert abs(torque[0] @ n) < 1e-12 * np.abs(torque).max()  # torque ⟂ n
        assert abs(cl.shear[0, 0] @ n) < 1e-15  # history lies in the tangent plane
    assert np.abs(cl.shear[0, 0]).max() > 0.0


# --------------------------------------------------------------------------- energy


@settings(max_examples=60, deadline=None)
@given(
    restitution=st.one_of(st.floats(0.05, 0.99), st.just(1.0)),
    friction=st.one_of(st.just(0.0), st.floats(0.0, 2.0)),
    gamma_t=st.one_of(st.just(0.0), st.floats(0.0, 50.0)),
    kt_ratio=st.floats(0.05, 1.0),
    lever=st.sampled_from([C.LEVER_CONTACT_POINT, C.LEVER_RADIUS]),
    impact=st.tuples(st.floats(-0.9, 0.9), st.floats(-0.9, 0.9)),
    rel_vel=st.tuples(st.floats(0.1, 5.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)),
    spins=st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6),
)
def test_a_contact_never_creates_energy(restitution, friction, gamma_t, kt_ratio, lever, impact, rel_vel, spins):
    """For e ≤ 0.99 the kinetic energy after the contact never exceeds that before. For
    e = 1 (no dashpot) the discrete onset of the contact (the overlap at the first step
    inside is up to |v| dt) can add a little: at most (π/n)² with n steps per contact."""
    steps = 25
    model = C.make_contact_model(kn=1.0e4, restitution=restitution, friction=friction, kt_ratio=kt_ratio,
                                 gamma_t=gamma_t, lever=lever)
    b = np.array([0.0, impact[0], impact[1]])
    assume(np.linalg.norm(b) < 0.95)
    offset = np.array([math.sqrt(1.0 - b @ b) + 1e-6, b[1], b[2]])
    v = np.array(rel_vel)
    pos, vel, spin = pair_state(offset, 0.5 * v, -0.5 * v, spins[:3], spins[3:])
    e0 = energy(vel, spin, model)
    cl = run_pair(model, pos, vel, spin, steps_per_contact=steps)
    assume(cl.collisions[0] == 1)
    e1 = energy(vel, spin, model)
    if restitution <= 0.99:
        assert e1 <= e0 * (1.0 + 1e-12)
    else:
        assert e1 <= e0 * (1.0 + (math.pi / steps) ** 2)


# --------------------------------------------------------------------------- hard spheres


unit_vectors = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
    lambda v: 0.1 < math.sqrt(sum(x * x for x in v)))
vectors = st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3)


@settings(max_examples=400, deadline=None)
@given(vi=vectors, vj=vectors, wi=vectors, wj=vectors, n=unit_vectors,
       restitution=st.floats(0.0, 1.0), friction=st.floats(0.0, 3.0))
@example(vi=[0.0, 0.0, 0.0], vj=[0.0, 0.0, 0.0], wi=[0.0, 0.0, 0.0], wj=[0.0, 0.0, 1.0], n=(1.0, 1.0, 0.0),
         restitution=0.0, friction=0.0)  # un = -1e-17 by numpy's cross product, 0 in the kernel
def test_hard_sphere_impulse_conserves_momentum_and_never_creates_energy(vi, vj, wi, wj, n, restitution, friction):
    model = C.make_contact_model(kn=1.0, restitution=1.0, friction=0.0)  # m = 1, I = 0.1, d = 1
    n = np.array(n) / np.linalg.norm(n)
    vel = np.array([vi, vj], dtype=float)
    spin = np.array([wi, wj], dtype=float)
    r = 0.5
    slip = vel[0] - vel[1] - r * np.cross(spin[0] + spin[1], n)
    un = slip @ n
    p0 = vel.sum(axis=0)
    # angular momentum about the contact point (centres at ±r n from it)
    centres = np.array([r * n, -r * n])
    l0 = angular_momentum(centres, vel, spin, model, np.zeros(3))
    e0 = energy(vel, spin, model)
    applied = C.binary_impulse(vel[0], vel[1], spin[0], spin[1], n, restitution, friction, 1.0)
    scale = 1e-12 * (1.0 + np.abs(vel).max() + np.abs(spin).max())
    if abs(un) > scale:  # a grazing pair with un at round-off (-1e-17) may go either way
        assert applied == (un < 0.0)
    np.testing.assert_allclose(vel.sum(axis=0), p0, rtol=0, atol=scale)
    np.testing.assert_allclose(angular_momentum(centres, vel, spin, model, np.zeros(3)), l0, rtol=0, atol=scale)
    assert energy(vel, spin, model) <= e0 * (1.0 + 1e-12) + 1e-12
    if applied:
        slip1 = vel[0] - vel[1] - r * np.cross(spin[0] + spin[1], n)
        assert slip1 @ n == pytest.approx(-restitution * un, rel=1e-9, abs=1e-9)
        ct0 = slip - un * n
        ct1 = slip1 - (slip1 @ n) * n
        if np.linalg.norm(ct0) <= 3.5 * friction * (1 + restitution) * abs(un):
            assert np.linalg.norm(ct1) < 1e-9 * (1 + np.linalg.norm(ct0))  # sticks: rolls off
        else:  # slides: slip reduced along its own direction, never reversed
            assert ct1 @ ct0 >= -1e-12 and np.linalg.norm(ct1) <= np.linalg.norm(ct0) + 1e-12


def test_hard_sphere_collisions_in_a_gas():
    n = 300
    length = (n * math.pi / 6.0 / 0.1) ** (1.0 / 3.0)
    pos, vel, spin = C.random_gas(n, (length,) * 3, seed=4)
    cl = C.make_contact_list(pos, (length,) * 3, (1, 1, 1), 1.0, 0.0)
    model = C.make_contact_model(kn=1.0, restitution=0.8, friction=0.3)
    p0 = vel.sum(axis=0).copy()
    e_prev = energy(vel, spin, model)
    total = 0
    dt = 0.01
    for _ in range(300):
        pos += dt * vel
        total += C.hard_sphere_collisions(pos, vel, spin, cl, 0.8, 0.3, 1.0)
        e = energy(vel, spin, model)
        assert e <= e_prev * (1.0 + 1e-13)
        e_prev = e
    assert total > 50 and cl.collisions.sum() == 2 * total
    np.testing.assert_allclose(vel.sum(axis=0), p0, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- neighbours


def brute_force_contacts(pos, box, periodic, d):
    dd = pos[:, None, :] - pos[None, :, :]
    for a in range(3):
        if periodic[a]:
            dd[..., a] -= box[a] * np.round(dd[..., a] / box[a])
    r2 = (dd**2).sum(-1)
    i, j = np.nonzero(np.triu(r2 < d * d, 1))
    return set(zip(i.tolist(), j.tolist()))


def touching_pairs(cl):
    out = set()
    for i in range(len(cl.nbr_count)):
        for k in range(cl.nbr_count[i]):
            if cl.touch[i, k]:
                j = int(cl.nbr[i, k])
                out.add((min(i, j), max(i, j)))
    return out


@settings(max_examples=150, deadline=None)
@given(
    n=st.integers(2, 50),
    box=st.tuples(st.floats(2.7, 6.0), st.floats(2.7, 6.0), st.floats(2.7, 6.0)),
    periodic=st.tuples(st.booleans(), st.booleans(), st.booleans()),
    skin=st.sampled_from([0.0, 0.1, 0.3]),
    seed=st.integers(0, 2**32 - 1),
)
def test_no_contact_missed_across_cell_and_periodic_boundaries(n, box, periodic, skin, seed):
    rng = np.random.default_rng(seed)
    b = np.array(box)
    pos = rng.uniform(0.0, 1.0, (n, 3)) * b
    for a in range(3):  # crowd the faces, put some exactly on them, unwrap some images
        faces = rng.random(n) < 0.4
        pos[faces, a] = rng.choice([0.0, 0.2, b[a] - 0.3, np.nextafter(b[a], 0), b[a]], int(faces.sum()))
        if periodic[a]:
            pos[:, a] += rng.integers(-2, 3, n) * b[a] * (rng.random(n) < 0.3)
    vel = rng.normal(0.0, 1.0, (n, 3))
    spin = np.zeros((n, 3))
    model = C.make_contact_model(kn=1.0e3, restitution=0.8, friction=0.2)
    cl = C.make_contact_list(pos, box, periodic, 1.0, skin)
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    C.contact_forces(pos, vel, spin, model, cl, 1e-3, False, force, torque)
    expected = brute_force_contacts(pos, b, periodic, 1.0)
    assert touching_pairs(cl) == expected
    assert cl.collisions.sum() == 2 * len(expected)
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-9 * (1 + np.abs(force).max()))


def test_verlet_skin_keeps_every_contact_and_matches_rebuilding_every_step():
    n = 300
    length = (n * math.pi / 6.0 / 0.15) ** (1.0 / 3.0)
    model = C.make_contact_model(kn=2.0e4, restitution=0.7, friction=0.4)
    dt = C.contact_duration(model) / 30.0
    runs = {}
    for skin in (0.0, 0.3):
        pos, vel, spin = C.random_gas(n, (length,) * 3, seed=9, speed=2.0)
        cl = C.make_contact_list(pos, (length,) * 3, (1, 1, 1), 1.0, skin)
        force = np.zeros((n, 3))
        torque = np.zeros((n, 3))
        for _ in range(10):
            cl, _ = C.advance_granular(pos, vel, spin, force, torque, model, cl, dt, 60)
            assert touching_pairs(cl) == brute_force_contacts(pos, (length,) * 3, (1, 1, 1), 1.0)
        runs[skin] = (pos, vel, spin, cl.builds[0], cl.collisions.sum())
    assert runs[0.3][3] < runs[0.0][3] / 5  # far fewer builds with a skin
    assert runs[0.3][4] == runs[0.0][4] > 0
    # same physics, different summation order: agree to round-off-grown-by-chaos level
    np.testing.assert_allclose(runs[0.3][1], runs[0.0][1], atol=1e-8)


def test_capacity_grows_without_changing_the_result():
    n = 200
    length = (n * math.pi / 6.0 / 0.3) ** (1.0 / 3.0)
    model = C.make_contact_model(kn=2.0e4, restitution=0.7, friction=0.4)
    dt = C.contact_duration(model) / 30.0
    out = []
    for capacity in (1, 64):
        pos, vel, spin = C.random_gas(n, (length,) * 3, seed=2)
        cl = C.make_contact_list(pos, (length,) * 3, (1, 1, 1), 1.0, 0.3, capacity=capacity)
        cl, _ = C.advance_granular(pos, vel, spin, np.zeros((n, 3)), np.zeros((n, 3)), model, cl, dt, 300)
        out.append((vel, spin, cl.nbr.shape[1]))
    assert out[0][2] > 1
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_results_do_not_depend_on_the_thread_count():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one Numba thread only")
    n = 300
    length = (n * math.pi / 6.0 / 0.2) ** (1.0 / 3.0)
    model = C.make_contact_model(kn=2.0e4, restitution=0.7, friction=0.4, gamma_t=10.0)
    dt = C.contact_duration(model) / 30.0
    out = []
    before = numba.get_num_threads()
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            pos, vel, spin = C.random_gas(n, (length,) * 3, seed=6)
            cl = C.make_contact_list(pos, (length,) * 3, (1, 1, 1), 1.0, 0.2)
            cl, ke = C.advance_granular(pos, vel, spin, np.zeros((n, 3)), np.zeros((n, 3)), model, cl, dt, 400,
                                        record_every=100)
            out.append((pos, vel, spin, ke))
    finally:
        numba.set_num_threads(before)
    for a, b in zip(out[0], out[1]):
        assert np.array_equal(a, b)


# --------------------------------------------------------------------------- stepper, case


def test_free_grain_with_external_acceleration_follows_the_parabola():
    model = C.make_contact_model(kn=1.0e4, restitution=0.7, friction=0.4)
    pos = np.array([[1.0, 2.0, 3.0]])
    vel = np.array([[0.5, 1.0, -0.2]])
    spin = np.array([[0.0, 0.0, 1.0]])
    acc = np.array([[0.0, -2.0, 0.1]])
    cl = C.make_contact_list(pos, (5.0, 50.0, 5.0), (1, 0, 1), 1.0, 0.1)
    dt, n = 1e-3, 1000
    x0, v0 = pos.copy(), vel.copy()
    C.advance_granular(pos, vel, spin, np.zeros((1, 3)), np.zeros((1, 3)), model, cl, dt, n, acc_ext=acc)
    t = dt * n
    np.testing.assert_allclose(pos, x0 + v0 * t + 0.5 * acc * t * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(vel, v0 + acc * t, rtol=0, atol=1e-12)
    assert spin[0, 2] == 1.0


def test_energy_record_starts_with_the_initial_state():
    n = 100
    length = (n * math.pi / 6.0 / 0.1) ** (1.0 / 3.0)
    pos, vel, spin = C.random_gas(n, (length,) * 3, seed=1)
    model = C.make_contact_model(kn=2.0e4, restitution=0.7, friction=0.4)
    e0 = C.kinetic_energy(vel, spin, model)
    cl = C.make_contact_list(pos, (length,) * 3, (1, 1, 1), 1.0, 0.2)
    cl, ke = C.advance_granular(pos, vel, spin, np.zeros((n, 3)), np.zeros((n, 3)), model, cl, 1e-3, 500,
                                record_every=100)
    assert ke.shape == (6, 2)
    assert ke[0] == pytest.approx(e0, rel=1e-14)
    assert ke[-1] == pytest.approx(C.kinetic_energy(vel, spin, model), rel=1e-14)
    assert np.all(np.diff(ke.sum(axis=1)) <= 1e-12)  # dissipative gas cools


def test_contact_model_from_case_matches_the_overlap_rule():
    case = load_case({
        "particle": {"diameter": 0.69e-3, "density": 2650.0},
        "fluid": {"density": 1000.0, "viscosity": 1.0e-6},
        "flow": {"source": "loglaw", "tau_ratio": 1.79},
        "collisions": {"model": "soft", "restitution": 0.65, "friction": 0.1},
        "run": {"duration": 1.0},
    })
    model = C.contact_model_from_case(case)
    c = case.collisions
    # undamped contact of two grains at impact_speed peaks at max_overlap (particle units)
    assert c.impact_speed * math.sqrt(0.5 / model.kn) == pytest.approx(c.max_overlap, rel=1e-12)
    assert model.kt == pytest.approx(c.tangential_stiffness_ratio * model.kn)
    assert (model.restitution, model.friction, model.mass, model.inertia) == (0.65, 0.1, 1.0, 0.1)
    undamped = math.pi * math.sqrt(0.5 / model.kn)
    assert undamped * case.time_scale == pytest.approx(case.contact_duration, rel=1e-12)
    # the damped contact is longer: never more sub-steps than the case's (undamped) rule
    assert 1 <= C.contact_substeps(model, case.dt_particle) <= case.contact_substeps
    assert C.contact_duration(model) / (case.dt_particle / C.contact_substeps(model, case.dt_particle)) >= 20.0
