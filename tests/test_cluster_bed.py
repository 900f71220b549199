"""Bonded-sphere grains on the packed bed (saltation.bed.packed_composites): rebound along the real
normal, no overlap left, no energy created, and a full run through saltation.run."""
import math

import numpy as np
import pytest

from flowfields import profile_dataset
from saltation.bed import packed_composites as cluster_bed
from saltation.bed.packed import make_packed_bed
from saltation.bed.virtual import bed_parameters
from saltation.flight import composites as clusters
from saltation.grains import shapes
from saltation.physics import history
from saltation.physics.forces import make_coefficients

DT = 0.01
NW = 10
RE_STAR = 10.0
R = 1.65
TAU_STAR = 1.0


def _vacuum(weight):
    # no fluid forces, no added mass: a rigid body under (optionally) its submerged weight
    return make_coefficients(tau_star=TAU_STAR, R=R, re_star=RE_STAR, weight=weight, drag=False, lift=False,
                             magnus=False, added_mass=False, fluid_acceleration=False, basset=False, spin=False)


def _setup(comps, pos, vel, quat=None, omega=None):
    n = len(comps)
    q = np.tile([1.0, 0, 0, 0], (n, 1)) if quat is None else np.asarray(quat, float)
    om = np.zeros((n, 3)) if omega is None else np.asarray(omega, float)
    st = clusters.make_cluster_state(comps, pos, vel, q, om, 0.0, NW, R=R, Cm=0.0, re_star=RE_STAR,
                                     spin_drag=False)
    return st, clusters.make_cluster_work(st)


def _run(st, w, coef, bed, pb, n_steps, check=None):
    flow = profile_dataset("still", y_top_plus=1e6)
    hc = history.make_history_coefficients(DT, NW)
    last = np.full(st.pos.shape[0], -2, np.int64)
    hits = 0
    for s in range(n_steps):
        clusters.advance_clusters(flow.arrays, coef, bed, 0, st, w, hc, s * DT, DT, 1, 1e30)
        hits += cluster_bed.packed_bed_pass(flow.arrays, coef, hc, st, w, s * DT, DT, s, bed, pb, last,
                                            np.zeros(len(last), np.uint8))
        if check is not None:
            check(s)
    return hits


def _unit_sphere():
    return shapes.Composite.from_spheres([[0.0, 0.0, 0.0]], [0.5])  # radius ½: d = Dn


@pytest.mark.parametrize("offset", [0.0, 0.3, 0.55])
def test_sphere_rebounds_elastically_along_the_real_normal(offset):
    # a one-sphere grain (d = Dn) flying straight (no weight) at a bed sphere, e = 1, f = 0:
    # v' = v − 2 (v·n) n with n the normal at the exact hit point (the path is a line)
    pb = make_packed_bed(6.0, 6.0)
    c = pb.centres[np.argmin(np.hypot(pb.centres[:, 0] - 3.0, pb.centres[:, 2] - 3.0))]
    v = np.array([0.3, -2.0, 0.1])
    start = np.array([c[0] + offset, 1.2, c[2]])
    st, w = _setup([_unit_sphere()], [start], [v])
    bed = bed_parameters(1.0, 0.0, math.radians(30.0), model=clusters.BED_PACKED)
    hits = _run(st, w, _vacuum(False), bed, pb, 80)
    assert hits == 1
    # the hit: the first bed sphere the line meets, |start + s v − c| = 1 (reach ½ + ½)
    s_hit, a = math.inf, None
    for cj in pb.centres:
        aj = start - cj
        b = aj @ v
        disc = b * b - (v @ v) * (aj @ aj - 1.0)
        if disc > 0.0:
            sj = (-b - math.sqrt(disc)) / (v @ v)
            if 0.0 < sj < s_hit:
                s_hit, a = sj, aj
    n = (a + s_hit * v)
    n /= np.linalg.norm(n)
    expect = v - 2.0 * (v @ n) * n
    np.testing.assert_allclose(st.vel[0], expect, atol=1e-12)
    np.testing.assert_allclose(st.omega[0], 0.0, atol=1e-12)  # impulse through the centre
    # and the position is where the reflected line puts it (exact back-tracking)
    t_end = 80 * DT
    np.testing.assert_allclose(st.pos[0], start + s_hit * v + (t_end - s_hit) * expect, atol=1e-10)
    assert st.jump_count[0] == 1


def test_dropped_composites_never_overlap_the_bed_and_create_no_energy():
    # rods, blades, disks and equants dropped under their weight at random orientations onto
    # the bed with friction: at the end of every step no component is inside a bed sphere,
    # the energy (kinetic + potential of the submerged weight) never rises, and they settle
    rng = np.random.default_rng(3)
    comps = [shapes.build(*a).scaled(1.0 / shapes.build(*a).nominal_diameter)
             for a in [(3.0, 1.0, 0.9), (2.2, 1.8, 0.7), (2.0, 1.1, 0.5), (1.2, 1.0, 0.8)]]
    n = len(comps)
    pos = np.array([[2.0 + 4.0 * i, 2.5, 4.0] for i in range(n)])
    vel = np.column_stack([rng.uniform(-1, 1, n), np.full(n, -3.0), rng.uniform(-1, 1, n)])
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    st, w = _setup(comps, pos, vel, quat=q, omega=rng.normal(size=(n, 3)))
    pb = make_packed_bed(16.0, 8.0, cluster_bed.cut_for(st))
    bed = bed_parameters(0.6, 0.5, math.radians(30.0), model=clusters.BED_PACKED)
    g_eff = st.volume / TAU_STAR / st.mass  # submerged weight / rigid mass (Cm = 0)

    def energy():
        e = np.zeros(n)
        for p in range(n):
            rot = clusters.quat_to_matrix_py(st.quat[p])
            ob = rot.T @ st.omega[p]
            e[p] = 0.5 * st.mass[p] * st.vel[p] @ st.vel[p] + 0.5 * ob @ st.inertia[p] @ ob \
                + st.mass[p] * g_eff[p] * st.pos[p, 1]
        return e

    prev = [energy()]
    gaps = []

    def check(s):
        gaps.append(cluster_bed.min_bed_gap(st, pb))
        e = energy()
        # RK4 in free flight keeps the energy to ~1e-10; impulses only remove it
        assert np.all(e <= prev[0] + 1e-8 * np.abs(prev[0]) + 1e-9)
        prev[0] = e

    e0 = energy()
    hits = _run(st, w, _vacuum(True), bed, pb, 1500, check)
    assert hits > 4 * n  # every grain bounced several times
    assert min(gaps) > -1e-9  # never inside a bed sphere
    assert np.all(st.impacts > 1)
    ke = 0.5 * st.mass * (st.vel ** 2).sum(axis=1)
    # most of the energy is gone (a grain may still roll across the hollows)
    assert np.all(ke < 0.15 * (e0 - energy() + ke))
    # on the bed: lowest points in the hollows (below the spheres' tops, above their
    # centres) or close above them
    low = clusters.lowest_points(st)
    assert np.all(low > -0.5) and np.all(low < 0.25)


def test_mixture_run_on_the_packed_bed(tmp_path):
    from saltation.engine.simulation import run

    case = {"particle": {"diameter": 0.69e-3, "shape": "mixture"},
            "flow": {"source": "les", "tau_ratio": 2.43},
            "bed": {"model": "packed"},
            "collisions": {"model": "off"},
            "run": {"n_particles": 20, "duration": 0.3, "seed": 2, "threads": 1},
            "output": {"vtk": False}}
    res = run(case, out=tmp_path / "packed", progress=False)
    s = res.summary
    assert s["status"] == "completed"
    assert s["collisions"]["bed_model"] == "packed" and s["collisions"]["bed"] > 20
    assert s["timing"]["bed_s"] > 0
    assert s["jumps"]["recorded"] > 20
    assert (res.tracks["y"] > 0).all()
