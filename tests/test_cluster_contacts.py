"""Soft grain–grain contacts between bonded-sphere grains (saltation.contacts.composites):
the one-sphere grain is the sphere contact; an oblique frictional collision of two
asymmetric grains conserves linear and angular momentum; the cell search misses no pair
across cell and periodic boundaries; overlaps stay small in a dense mixture run."""
import math

import numpy as np
import pytest

from flowfields import profile_dataset
from saltation.bed.virtual import bed_parameters
from saltation.contacts import composites as ccm
from saltation.contacts.pairs import advance_granular, make_contact_list, make_contact_model
from saltation.flight import composites as clusters
from saltation.grains import shapes
from saltation.physics import history
from saltation.physics.forces import make_coefficients

R = 1.65
DT = 0.01
NW = 10
KN_SPHERE = 5e5  # m u*²/d² (sphere units): the case default order of magnitude
KN = KN_SPHERE * (1.0 + R) * math.pi / 6.0  # ρ u*² Dn (composite units)
BOX = (40.0, 60.0, 40.0)


def _vacuum():
    return make_coefficients(tau_star=1.0, R=R, re_star=10.0, Cm=0.0, weight=False, drag=False, lift=False,
                             magnus=False, added_mass=False, fluid_acceleration=False, basset=False)


def _state(comps, pos, vel, quat=None, omega=None):
    n = len(comps)
    q = np.tile([1.0, 0, 0, 0], (n, 1)) if quat is None else quat
    om = np.zeros((n, 3)) if omega is None else omega
    st = clusters.make_cluster_state(comps, pos, vel, q, om, 0.0, NW, R=R, Cm=0.0, re_star=10.0, spin_drag=False)
    return st, clusters.make_cluster_work(st)


def _run(st, w, cc, n_sub, steps, dt=DT, record=None):
    still = profile_dataset("still", y_top_plus=1e6)
    hc = history.make_history_coefficients(dt, NW)
    bed = bed_parameters(0.65, 0.1, 0.5)
    timers = np.zeros(2)
    for s in range(steps):
        _, cc = ccm.advance_clusters_contacts(still.arrays, _vacuum(), bed, 0, st, w, hc, s * dt, dt, 1, 1e9, cc,
                                              n_sub, timers, None)
        if record is not None:
            record(st, cc)
    return cc


def _rigid_momenta(st):
    """Total linear momentum and angular momentum about the origin (orbital + spin,
    rigid inertia R I_b Rᵀ Ω)."""
    p = (st.mass[:, None] * st.vel).sum(axis=0)
    L = np.zeros(3)
    for i in range(len(st.mass)):
        rot = clusters.quat_to_matrix_py(st.quat[i])
        L += st.mass[i] * np.cross(st.pos[i], st.vel[i]) + rot @ st.inertia[i] @ rot.T @ st.omega[i]
    return p, L


def _kinetic(st):
    ke = 0.0
    for i in range(len(st.mass)):
        rot = clusters.quat_to_matrix_py(st.quat[i])
        ke += 0.5 * st.mass[i] * st.vel[i] @ st.vel[i] + 0.5 * st.omega[i] @ (rot @ st.inertia[i] @ rot.T) @ st.omega[i]
    return ke


def test_one_sphere_grains_head_on_reproduce_the_sphere_contact():
    e, f = 0.65, 0.1
    one = shapes.Composite.from_spheres([[0, 0, 0]], [0.5])
    pos = np.array([[10.0, 5.0, 10.0], [11.05, 5.0, 10.0]])
    vel = np.array([[2.0, 0.0, 0.0], [-2.0, 0.0, 0.0]])
    st, w = _state([one, one], pos, vel)
    cc = ccm.make_cluster_contacts(st, ccm.contact_parameters(KN, e, f, skin=0.3, box=BOX))
    n_sub = ccm.substeps(st, KN, DT, 20)
    p0, _ = _rigid_momenta(st)
    cc = _run(st, w, cc, n_sub, 10)
    e_run = -(st.vel[0, 0] - st.vel[1, 0]) / (vel[0, 0] - vel[1, 0])
    assert e_run == pytest.approx(e, rel=0.02)
    p1, _ = _rigid_momenta(st)
    assert np.abs(p1 - p0).max() < 1e-13 * st.mass[0] * 2.0
    assert cc.collisions.tolist() == [1, 1]
    assert 0.0 < cc.max_overlap.max() < 0.01  # ≈ 0.0033 d at 4 u*
    # the sphere contact code (contacts/pairs.py), same stiffness, restitution, sub-step
    model = make_contact_model(KN_SPHERE, e, f)
    ps, vs, ws = pos.copy(), vel.copy(), np.zeros((2, 3))
    cl = make_contact_list(ps, BOX, (True, False, True), 1.0, 0.3)
    advance_granular(ps, vs, ws, np.zeros((2, 3)), np.zeros((2, 3)), model, cl, DT / n_sub, 10 * n_sub)
    assert np.abs(vs - st.vel).max() < 1e-9
    assert np.abs(ps - st.pos).max() < 1e-9


def test_oblique_frictional_collision_of_rod_and_blade_conserves_momenta():
    rod = shapes.build(1.9, 0.85, 0.75)
    blade = shapes.build(1.8, 1.0, 0.55)
    assert (rod.zingg_class, blade.zingg_class) == ("rod", "blade")
    rng = np.random.default_rng(3)
    quat = rng.normal(size=(2, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    pos = np.array([[10.0, 5.0, 10.0], [12.2, 5.4, 10.3]])
    vel = np.array([[3.0, 0.5, 0.2], [-2.0, -0.3, 0.1]])
    st, w = _state([rod, blade], pos, vel, quat=quat)
    cc = ccm.make_cluster_contacts(st, ccm.contact_parameters(KN, 0.65, 0.5, skin=0.3, box=BOX))
    dt = 0.005  # the contact spans a step boundary (the spinning grains carry it over)
    n_sub = ccm.substeps(st, KN, dt, 20)
    p0, L0 = _rigid_momenta(st)
    ke0 = _kinetic(st)
    scale_p = np.abs(st.mass[:, None] * st.vel).sum()
    scale_L = sum(st.mass[i] * np.linalg.norm(np.cross(st.pos[i], st.vel[i])) for i in range(2))
    worst = [0.0, 0.0]
    touched_steps = []

    def record(s, c):
        touched_steps.append(int(c.touched.sum()))
        p, L = _rigid_momenta(s)
        worst[0] = max(worst[0], np.abs(p - p0).max() / scale_p)
        worst[1] = max(worst[1], np.abs(L - L0).max() / scale_L)

    cc = _run(st, w, cc, n_sub, 120, dt=dt, record=record)
    assert cc.collisions.tolist() == [1, 1]  # they met (once)
    assert sum(t > 0 for t in touched_steps) >= 2  # the contact went on over a step boundary
    assert np.abs(st.omega).max() > 0.1  # the off-centre, frictional contact set them spinning
    assert worst[0] < 1e-12
    assert worst[1] < 1e-10
    assert _kinetic(st) < ke0  # dissipative (e < 1, friction)
    assert cc.max_overlap.max() < 0.02


def _random_grains(n, box, seed):
    rng = np.random.default_rng(seed)
    classes, axes = shapes.draw_axes(n, Dn=1.0, seed=seed)
    comps = [shapes.build(*a) for a in axes]
    pos = np.column_stack([rng.uniform(0, box[0], n), rng.uniform(0.5, 4.0, n), rng.uniform(0, box[2], n)])
    # some grains across the periodic boundaries (unwrapped coordinates, any image)
    pos[: n // 4, 0] += box[0] * rng.integers(-2, 3, n // 4)
    pos[n // 4: n // 2, 2] -= box[2] * rng.integers(-2, 3, n - n // 2 - n // 4)[: n // 2 - n // 4]
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    return comps, pos, quat


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_pair_missed_across_cells_and_periodic_boundaries(seed):
    box = (9.0, 5.0, 7.5)  # few cells: every grain is near a cell or periodic boundary
    comps, pos, quat = _random_grains(60, box, seed)
    st, w = _state(comps, pos, np.zeros((60, 3)), quat=quat)
    skin = 0.2
    cc = ccm.make_cluster_contacts(st, ccm.contact_parameters(KN, 0.65, 0.1, skin=skin, box=box))
    # a step with no motion: x0 = x1, so the list cutoff is (d_a + d_b)/2 + skin exactly
    w.x0[:, 0:3] = st.pos
    w.x0[:, 3:6] = st.vel
    w.x0[:, 6:10] = st.quat
    w.x0[:, 10:13] = st.omega
    sr, wr, cr = ccm.as_refs(st, w, cc)
    ccm.build_contact_list(sr, wr, cr, DT, None)
    cc = ccm.contacts_of(cr)
    brute = ccm.brute_force_pairs(st, box, skin)
    assert len(brute) > 20
    assert ccm.listed_pairs(cc) == brute
    # active grains: exactly those whose bounding spheres come within the skin of another
    rho = cc.rho
    act = np.zeros(60, bool)
    for i in range(60):
        for j in range(60):
            if i != j:
                d = st.pos[i] - st.pos[j]
                d[0] -= box[0] * np.floor(d[0] / box[0] + 0.5)
                d[2] -= box[2] * np.floor(d[2] / box[2] + 0.5)
                act[i] |= np.linalg.norm(d) < rho[i] + rho[j] + skin
    assert np.array_equal(cc.active.astype(bool), act)
    # forces of the listed contacts = the brute-force springs k_n δ n (grains at rest)
    ccm.component_forces(sr, cr, DT, 0.0)
    cp = ccm.grain_pose_centres(st)
    grain = np.repeat(np.arange(60), np.diff(st.cstart))
    force = np.zeros((60, 3))
    torque = np.zeros((60, 3))
    for a, b in ccm.brute_force_pairs(st, box, 0.0):
        d = cp[a] - cp[b]
        d[0] -= box[0] * np.floor(d[0] / box[0] + 0.5)
        d[2] -= box[2] * np.floor(d[2] / box[2] + 0.5)
        r = np.linalg.norm(d)
        n = d / r
        dl = 0.5 * (st.d_comp[a] + st.d_comp[b]) - r
        fa = KN * dl * n
        xc = cp[a] - (0.5 * st.d_comp[a] - 0.5 * dl) * n  # contact point, a's image
        i, j = grain[a], grain[b]
        force[i] += fa
        force[j] -= fa
        torque[i] += np.cross(xc - st.pos[i], fa)
        xj = cp[b] + (0.5 * st.d_comp[b] - 0.5 * dl) * n  # the same point, b's image
        torque[j] -= np.cross(xj - st.pos[j], fa)
    on = cc.active.astype(bool)
    assert np.abs(force).max() > 0  # there were contacts
    assert np.allclose(cc.force[on], force[on], rtol=1e-9, atol=1e-9 * np.abs(force).max())
    assert np.allclose(cc.torque[on], torque[on], rtol=1e-9, atol=1e-9 * np.abs(torque).max())
    assert np.all(force[~on] == 0)


def test_dense_mixture_on_the_virtual_bed_runs_with_small_overlaps(tmp_path):
    """The natural mixture at 1.03 % in a 0.024 × 0.012 m box with soft contacts on the
    virtual bed: with the bed in the free flight only, contacts pushed grains below the bed
    top and the lift-out made overlaps of 0.05–0.16 Dn and spun a grain until the RK4
    failed (non-finite at step 163 of this run). With the bed in the sub-steps it runs, and
    component overlaps stay within what the stiffness is set for (0.0036 Dn here)."""
    from saltation.engine.simulation import run

    case = {"particle": {"diameter": 0.69e-3, "shape": "mixture"},
            "flow": {"source": "les", "tau_ratio": 1.79},
            "collisions": {"model": "soft"},
            "run": {"concentration": 0.0103, "domain": [0.024, 0.012, 0.02], "duration": 0.12,
                    "dt_particle": 0.02, "seed": 1, "threads": 1},
            "output": {"vtk": False, "tracks": False}}
    s = run(case, out=tmp_path / "virtual", progress=False).summary
    assert s["status"] == "completed" and s["steps"] > 163
    c = s["collisions"]
    assert c["particle_particle"] >= 20 and c["bed"] >= 20
    assert c["overlap"]["max_over_d"] < 0.01


def test_dense_mixture_run_on_the_les_keeps_overlaps_small(tmp_path):
    """A few hundred composites at 3 % on the shipped LES with soft contacts: collisions
    happen, component overlaps stay ≲ a few % of Dn, the per-grain counts add up."""
    import pandas as pd

    from saltation.engine.simulation import run

    case = {"particle": {"diameter": 0.69e-3, "shape": "mixture"},
            "flow": {"source": "les", "tau_ratio": 1.79},
            "collisions": {"model": "soft"},
            "run": {"n_particles": 200, "concentration": 0.03, "duration": 0.1, "seed": 4, "threads": 1},
            "output": {"vtk": False}}
    res = run(case, out=tmp_path / "dense", progress=False)
    s = res.summary
    assert s["status"] == "completed"
    c = s["collisions"]
    # (the count over so short a run is a handful of events and chaotic: 13 here, 56 with
    # forces.wake_shielding = false; a few suffice for the overlap checks below)
    assert c["model"] == "soft" and c["particle_particle"] >= 5
    assert 0.0 < c["overlap"]["mean_over_d"] < c["overlap"]["max_over_d"] < 0.05
    grains = pd.read_parquet(tmp_path / "dense" / "particles.parquet")
    assert int(grains["collisions"].sum()) == 2 * c["particle_particle"]
    assert grains["max_overlap"].max() == pytest.approx(c["overlap"]["max_over_d"])
    assert s["timing"]["particle_collisions_s"] > 0
    assert (res.tracks["y"] > 0).all()


def test_mixture_contacts_same_bits_on_any_margin_and_thread_count(tmp_path):
    """The natural mixture at 2 % with soft contacts on the virtual bed: the default margin
    (contacts.composites.default_skin: 2 impact_speed dt, 0.4 Dn here) engages fewer grains
    than a wide one but gives the same jumps and end state; on two threads (the sub-step
    passes cut into one range per thread) the same bits as on one."""
    import pandas as pd

    from saltation.engine.simulation import run

    def go(name, threads, **collisions):
        case = {"particle": {"diameter": 0.69e-3, "shape": "mixture"},
                "flow": {"source": "les", "tau_ratio": 1.79},
                "collisions": {"model": "soft", **collisions},
                "run": {"concentration": 0.0207, "domain": [0.024, 0.012, 0.02], "duration": 0.1,
                        "seed": 1, "threads": threads},
                "output": {"vtk": False}}
        res = run(case, out=tmp_path / name, progress=False)
        return res.summary, pd.read_parquet(tmp_path / name / "particles.parquet"), res.jumps

    s1, p1, j1 = go("default", 1)
    assert s1["collisions"]["soft"]["skin_d"] == pytest.approx(ccm.default_skin(0.02, 10.0)) == pytest.approx(0.4)
    assert s1["collisions"]["particle_particle"] >= 100
    s2, p2, j2 = go("wide", 1, skin=0.96)
    eng1 = s1["collisions"]["contact_phase"]["engaged_grain_steps"]
    eng2 = s2["collisions"]["contact_phase"]["engaged_grain_steps"]
    assert eng1 < 0.8 * eng2
    s3, p3, j3 = go("two", 2)
    assert s3["collisions"]["contact_phase"]["engaged_grain_steps"] == eng1
    for p, j, s in ((p2, j2, s2), (p3, j3, s3)):
        pd.testing.assert_frame_equal(p, p1)
        pd.testing.assert_frame_equal(j, j1)
        assert s["collisions"]["particle_particle"] == s1["collisions"]["particle_particle"]


def _weight_only():
    return make_coefficients(tau_star=0.2, R=R, re_star=10.0, Cm=0.0, weight=True, drag=False, lift=False,
                             magnus=False, added_mass=False, fluid_acceleration=False, basset=False)


def _falling_pair(gap_z, closing=0.0):
    """A rod and a blade, turned at random, falling side by side onto the bed, their centres
    gap_z apart in z and closing in at ``closing`` (u*)."""
    rod, blade = shapes.build(1.9, 0.85, 0.75), shapes.build(1.8, 1.0, 0.55)
    rng = np.random.default_rng(5)
    quat = rng.normal(size=(2, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    pos = np.array([[10.0, 2.5, 10.0], [10.0, 2.5, 10.0 + gap_z]])
    vel = np.array([[1.0, -2.0, 0.3 + 0.5 * closing], [1.0, -2.0, 0.3 - 0.5 * closing]])
    omega = np.array([[0.0, 0.0, -2.0], [1.0, 0.0, -1.0]])
    return _state([rod, blade], pos, vel, quat=quat, omega=omega)


def _virtual_after(st, dt):
    """Contact state and bed array with the virtual bed in the sub-steps and after them."""
    cc = ccm.make_cluster_contacts(st, ccm.contact_parameters(KN, 0.65, 0.5, skin=0.3, box=BOX))
    cc = ccm.with_virtual_bed(cc, 0.65, 0.1, 0.5, (dt, 0.01), np.full(len(st.mass), -2, np.int64), 0)
    bed = bed_parameters(0.65, 0.1, 0.5, model=clusters.BED_VIRTUAL_AFTER, min_jump_duration=dt,
                         min_jump_height=0.01)
    return cc, bed


def test_with_contacts_every_virtual_bed_contact_is_soft_and_flight_above_it_unchanged():
    """Two grains far apart falling onto the virtual bed, with contacts and without: until
    the first one reaches the bed top they fly the same bits (the free flight, its bed
    check left to the pass after the contact phase, flight.composites.virtual_bed_pass).
    With contacts, a grain whose free path ends below the bed top is sub-stepped although
    no grain is near (``below``): its bed contact is soft (``bed_touch``), an impact as on
    the hard bed, no deeper than the stiffness allows, and it bounces on."""
    still = profile_dataset("still", y_top_plus=1e6)
    dt = 0.01
    hc = history.make_history_coefficients(dt, NW)
    st_a, w_a = _falling_pair(20.0)
    st_b, w_b = _falling_pair(20.0)
    bed0 = bed_parameters(0.65, 0.1, 0.5, min_jump_duration=dt, min_jump_height=0.01)
    cc, bed1 = _virtual_after(st_b, dt)
    n_sub = ccm.substeps(st_b, KN, dt, 20)
    timers = np.zeros(2)
    landed, soft, lowest = None, 0, []
    for s in range(300):
        clusters.advance_clusters(still.arrays, _weight_only(), bed0, 3, st_a, w_a, hc, s * dt, dt, 1, 1e9)
        _, cc = ccm.advance_clusters_contacts(still.arrays, _weight_only(), bed1, 3, st_b, w_b, hc, s * dt, dt, 1,
                                              1e9, cc, n_sub, timers, None)
        lowest.append(clusters.lowest_points(st_b).min())
        soft += int((cc.active & cc.bed_touch).sum())
        if landed is None:
            if st_a.impacts.any():
                landed = s
                assert cc.active[st_a.impacts > 0].all() and cc.bed_touch[st_a.impacts > 0].all()
                # (a tumbling grain may touch, leave and touch again within the step: two impacts)
                assert (st_b.impacts[st_a.impacts > 0] >= 1).all() and not st_b.impacts[st_a.impacts == 0].any()
            else:
                for name in ("pos", "vel", "quat", "omega", "jump_ymax"):
                    assert np.array_equal(getattr(st_a, name), getattr(st_b, name)), (s, name)
    assert landed is not None and landed > 50
    assert cc.collisions.sum() == 0  # never near each other
    assert soft >= 4 and st_b.impacts.min() >= 2 and st_b.jump_count.min() >= 1
    assert -0.01 < min(lowest)


def test_grains_sub_stepped_have_the_virtual_bed_in_the_sub_steps():
    """Two grains falling side by side, close enough to be sub-stepped together, onto the
    virtual bed: their first bed contacts are soft contacts in the sub-steps (a virtual bed
    sphere under each component that reaches the bed top: ``bed_touch``), counted as
    impacts there; they sink no deeper than the stiffness allows (≈ 0.0016 Dn at ~2 u*),
    bounce, drift apart and go on with the hard bed after the phase."""
    still = profile_dataset("still", y_top_plus=1e6)
    dt = 0.01
    hc = history.make_history_coefficients(dt, NW)
    st, w = _falling_pair(2.0)
    assert not ccm.brute_force_pairs(st, BOX)  # they start apart
    cc, bed = _virtual_after(st, dt)
    n_sub = ccm.substeps(st, KN, dt, 20)
    timers = np.zeros(2)
    lowest, soft_steps, soft_impacts = [], 0, 0
    for s in range(400):
        before = st.impacts.copy()
        _, cc = ccm.advance_clusters_contacts(still.arrays, _weight_only(), bed, 3, st, w, hc, s * dt, dt, 1, 1e9,
                                              cc, n_sub, timers, None)
        assert np.all(st.status == clusters.OK)
        lowest.append(clusters.lowest_points(st).min())
        soft = (cc.active & cc.bed_touch).astype(bool)
        if soft.any():
            soft_steps += 1
            soft_impacts += int((st.impacts - before)[soft].sum())
            assert cc.vslot.any() or not cc.in_bed[soft].any()
    assert soft_steps >= 2 and soft_impacts >= 2  # both landed soft, in the sub-steps
    assert st.impacts.min() >= 3 and st.jump_count.min() >= 2  # then bounced on (hard, apart)
    assert -0.01 < min(lowest)
    assert np.abs(st.vel).max() < 3.0  # bounced and damped, not launched


def test_fluid_response_makes_a_collision_independent_of_where_in_the_step_it_falls():
    """Two one-sphere grains colliding head-on in still water with drag, the same sub-step
    at Δt = 0.02 and 0.01 d/u*: the contact falls 0.0137 and 0.0037 d/u* before its step's
    end. The sub-steps hold the drag of the free path; without the fluid's response
    (contacts.composites._fluid_response) the end velocities differed by 2.8e-2 u*, with it
    by 2.7e-4."""
    coef = make_coefficients(tau_star=1.0, R=R, re_star=10.0, Cm=0.0, weight=False, drag=True, lift=False,
                             magnus=False, added_mass=False, fluid_acceleration=False, basset=False, spin=False)
    still = profile_dataset("still", y_top_plus=1e6)
    one = shapes.Composite.from_spheres([[0, 0, 0]], [0.5])

    def end_velocity(dt):
        st, w = _state([one, one], np.array([[10.0, 5.0, 10.0], [11.1037, 5.0, 10.0]]),
                       np.array([[2.0, 0.0, 0.0], [-2.0, 0.0, 0.0]]))
        cc = ccm.make_cluster_contacts(st, ccm.contact_parameters(KN, 0.65, 0.1, skin=0.3, box=BOX))
        hc = history.make_history_coefficients(dt, NW)
        bed = bed_parameters(0.65, 0.1, 0.5)
        for s in range(round(0.3 / dt)):
            _, cc = ccm.advance_clusters_contacts(still.arrays, coef, bed, 0, st, w, hc, s * dt, dt, 1, 1e9, cc,
                                                  round(256 * dt / 0.02), np.zeros(2), None)
        assert cc.collisions.tolist() == [1, 1]
        return st.vel[0, 0]

    v1, v2 = end_velocity(0.02), end_velocity(0.01)
    assert -0.95 < v1 < -0.85  # rebounded (e = 0.65 of 4 u*, less the drag)
    assert abs(v1 - v2) < 2e-3


def test_elastic_frictionless_collision_of_asymmetric_grains_conserves_energy():
    """e = 1, f = 0: the contact is a pure spring; the energy after an off-centre
    collision of a rod and a blade (which sets them spinning) equals the energy before
    to the integrator's accuracy — it would not if the contact-point velocities (from Ω)
    and the components' motion (from the orientation update) disagreed."""
    rod = shapes.build(1.9, 0.85, 0.75)
    blade = shapes.build(1.8, 1.0, 0.55)
    rng = np.random.default_rng(7)
    quat = rng.normal(size=(2, 4))
    quat /= np.linalg.norm(quat, axis=1)[:, None]
    pos = np.array([[10.0, 5.0, 10.0], [12.1, 5.5, 10.4]])
    vel = np.array([[3.0, 0.5, 0.2], [-2.0, -0.3, 0.1]])
    omega = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 0.0]])
    st, w = _state([rod, blade], pos, vel, quat=quat, omega=omega)
    cc = ccm.make_cluster_contacts(st, ccm.contact_parameters(KN, 1.0, 0.0, skin=0.3, box=BOX))
    dt = 0.005
    n_sub = ccm.substeps(st, KN, dt, 20)
    ke0 = _kinetic(st)
    w0 = st.omega.copy()
    cc = _run(st, w, cc, n_sub, 120, dt=dt)
    assert cc.collisions[0] >= 1 and cc.collisions[0] == cc.collisions[1]  # (spinning: they may meet again)
    assert cc.n_partners.sum() == 0  # and part
    assert np.abs(st.omega - w0).max() > 0.1  # the contact torque changed the spins
    assert _kinetic(st) == pytest.approx(ke0, rel=2e-3)  # splitting error ~1e-4–1e-3 (module docstring)
