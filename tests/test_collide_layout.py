"""The contact phase's compact layout (contacts/phase.py, "Memory layout"): a grain woken on a
deflected path gets its neighbour row from the grain arrays, its own neighbours joining
the compact set; the set grows without losing its contents; bystanders change nothing."""
import numba
import numpy as np

from saltation.bed.packed import make_packed_bed
from saltation.contacts import pairs as K
from saltation.contacts.phase import (
    ACTIVE,
    RETIRED,
    RETIRED_SUBSTEPS,
    SUBSTEPPED,
    WAKES,
    _candidates_first,
    _force_again,
    _grow,
    _make_set,
    _rest_of_path,
    _set_path,
    _set_place,
    _state_of,
    empty_substep_set,
    make_bed_context,
    make_contact_phase,
    soft_contact_phase,
    substep_view,
)
from saltation.flight.spheres import make_state, make_workspace


def run_contact_phase(pos0, vel0, steps=3, dt=0.02, n_sub=128, box=(12.0, 8.0, 12.0), skin=0.6, friction=0.2,
                      bed_friction=0.1, block_members=None, block_slack=None, threads=1,
                      parallel_members=None, near_slack=None, retire_backoff=None):
    """Straight-line free flight plus the contact phase for ``steps`` steps (virtual bed) on
    ``threads`` Numba threads; returns the state, the list and the phase."""
    n = len(pos0)
    model = K.make_contact_model(5e5, 0.9, friction)
    st = make_state(pos0, vel0, np.zeros((n, 3)), 0.0, 4)
    ws = make_workspace(n)
    cl = K.make_contact_list(st.pos, box, (True, False, True), 1.0, skin)
    ph = make_contact_phase(n)
    if block_members is not None:
        ph.block_members[0] = block_members
    if block_slack is not None:
        ph.block_slack[:] = block_slack
    if parallel_members is not None:  # (candidates, threads); candidates alone: lanes from two threads on
        ph.parallel_members[:] = parallel_members if isinstance(parallel_members, tuple) else (parallel_members, 2)
    if near_slack is not None:
        ph.near_slack[0] = near_slack
    if retire_backoff is not None:
        ph.retire_backoff[0] = retire_backoff
    bc = make_bed_context(n, False, make_packed_bed(3.0, 3.0), 0.65, bed_friction, 0.5, model.kn, model.kt, 0,
                          np.full(n, -2, np.int64))
    cs = empty_substep_set()
    numba.set_num_threads(threads)
    for s in range(steps):
        ws.x0[:, 0:3] = st.pos
        ws.x0[:, 3:6] = st.vel
        ws.x0[:, 6:9] = st.spin
        st.pos[:] += dt * st.vel
        cl, cs = soft_contact_phase(st, ws.x0, model, cl, ph, bc, s * dt, s, dt, n_sub, cs, threads)
        assert (ph.loc == -1).all()  # the set is released after each phase
    return st, cl, ph


def test_woken_grain_brings_its_neighbours_and_a_bystander_changes_nothing():
    pos3 = np.array([[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0], [5.0 + 1.0 + 0.1, 3.0, 5.0]])
    vel3 = np.array([[0.0, 0.0, 0.0], [12.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    # grain 3: a list neighbour of grain 2 only (1.3 d to its side), never touched
    pos4 = np.vstack([pos3, [[6.1, 3.0, 6.3]]])
    vel4 = np.vstack([vel3, [[0.0, 0.0, 0.0]]])
    st3, cl3, ph3 = run_contact_phase(pos3, vel3)
    st4, cl4, ph4 = run_contact_phase(pos4, vel4)
    assert 3 in cl4.nbr[2, :cl4.nbr_count[2]] and 3 not in cl4.nbr[0, :cl4.nbr_count[0]]
    assert ph3.counters[2] >= 1 and ph4.counters[2] >= 1  # grain 2 was woken
    assert st3.vel[2, 0] > 1.0
    np.testing.assert_array_equal(st4.pos[:3], st3.pos)
    np.testing.assert_array_equal(st4.vel[:3], st3.vel)
    np.testing.assert_array_equal(st4.spin[:3], st3.spin)
    np.testing.assert_array_equal(cl4.collisions[:3], cl3.collisions)
    assert cl4.collisions[3] == 0 and np.all(st4.vel[3] == 0.0)
    np.testing.assert_allclose(st4.vel.sum(axis=0), vel4.sum(axis=0), atol=1e-9)


def test_the_compact_set_grows_without_losing_its_contents():
    ref = _make_set(3, 5)
    cs = substep_view(ref)  # the set's arrays, seen from Python
    cs.n[0], cs.n_rows[0] = 3, 5
    cs.gid[:3] = [7, 2, 9]
    cs.path[:3] = np.arange(54.0).reshape(3, 18)
    cs.nbr[:5] = [1, 2, 0, 2, 0]
    cs.shear[:5] = np.arange(15.0).reshape(5, 3)
    cs.slot_c[:3] = np.arange(36.0).reshape(3, 4, 3)
    big_ref = _grow(ref, 10, 4)
    big = substep_view(big_ref)
    assert big.gid.shape[0] >= 10 and big.queue.shape[0] == big.gid.shape[0] and big.nbr.shape[0] == 5
    assert big.n[0] == 3 and big.n_rows[0] == 5
    np.testing.assert_array_equal(big.gid[:3], [7, 2, 9])
    np.testing.assert_array_equal(big.path[:3], cs.path[:3])
    np.testing.assert_array_equal(big.nbr[:5], cs.nbr[:5])
    np.testing.assert_array_equal(big.shear[:5], cs.shear[:5])
    np.testing.assert_array_equal(big.slot_c[:3], cs.slot_c[:3])
    assert substep_view(_grow(big_ref, 2, 2)).gid.shape[0] == big.gid.shape[0]  # room enough: kept


def test_a_grain_hitting_the_bed_beside_an_unlisted_grain_is_a_candidate():
    """Grain 0 falls onto the bed (its hard rebound could move it by twice its reach, 0.4 d)
    1.58 d from grain 1, which stands still: by the margins they may meet, so grain 0 is
    sub-stepped with the soft bed, whether the list (skin 0.5: cutoff 1.5 d) holds the pair
    or not (skin 0.8). Fails when only the list's rows are searched."""
    pos0 = np.array([[5.0, 0.6, 5.0], [6.55, 0.9, 5.0]])
    vel0 = np.array([[0.0, -10.0, 0.0], [0.0, 0.0, 0.0]])
    out = {}
    for skin in (0.5, 0.8):
        st, cl, ph = run_contact_phase(pos0, vel0, steps=1, skin=skin)
        listed = 1 in cl.nbr[0, :cl.nbr_count[0]]
        out[skin] = (listed, ph.active.copy(), st.pos.copy(), st.vel.copy())
    assert not out[0.5][0] and out[0.8][0]  # the pair is listed with the wider skin only
    for skin in (0.5, 0.8):
        listed, active, pos, vel = out[skin]
        assert active[0] == 1 and active[1] == 0
        assert vel[0, 1] > 0.0  # rebounded off the (soft) bed
        np.testing.assert_array_equal(pos, out[0.5][2])
        np.testing.assert_array_equal(vel, out[0.5][3])


def _gas(n, seed):
    """n grains at random, not overlapping, between 0.6 d and 3 d above the bed, moving
    at up to 8 u* in every direction: a dense, colliding layer."""
    rng = np.random.default_rng(seed)
    pos = []
    while len(pos) < n:
        p = rng.uniform([0.0, 0.6, 0.0], [12.0, 3.0, 12.0])
        if all(np.linalg.norm(p - q) > 1.02 for q in pos):
            pos.append(p)
    return np.array(pos), rng.uniform(-8.0, 8.0, (n, 3))


def test_retired_grains_give_the_same_bits():
    """A grain that touches nothing and is sure to stay so unforced retires for the rest of
    the step (contacts/phase.py, "Retired members"): the same positions, velocities, spins,
    contact springs and counts as when no grain retires, and many grain-sub-steps retired.
    Fails when a grain retires that a deflected neighbour or the bed then reaches."""
    pos0, vel0 = _gas(150, 3)
    runs = {}
    for backoff in (0.0, 8.0, 1.0):
        st, cl, ph = run_contact_phase(pos0, vel0, steps=8, retire_backoff=backoff)
        runs[backoff] = (st, cl, ph)
    st0, cl0, ph0 = runs[0.0]
    assert ph0.counters[RETIRED_SUBSTEPS] == 0
    assert ph0.counters[SUBSTEPPED] > 50_000 and cl0.collisions.sum() > 500 and ph0.counters[WAKES] > 50
    for backoff in (8.0, 1.0):
        st, cl, ph = runs[backoff]
        assert ph.counters[RETIRED_SUBSTEPS] > 0.2 * ph.counters[SUBSTEPPED]
        for a, b in ((st.pos, st0.pos), (st.vel, st0.vel), (st.spin, st0.spin), (cl.shear, cl0.shear),
                     (cl.touch, cl0.touch), (cl.collisions, cl0.collisions), (cl.max_overlap, cl0.max_overlap)):
            np.testing.assert_array_equal(a, b)
        same = np.arange(ph.counters.shape[0]) != RETIRED_SUBSTEPS
        np.testing.assert_array_equal(ph.counters[same], ph0.counters[same])


def test_a_retired_member_reads_as_if_it_were_active():
    """A retired member keeps only its position in cur (_set_place, "Retired members"); a
    touch (_state_of), _quiet_until beside it (_rest_of_path) and its being forced again
    (_force_again) work out its velocity and spin from its path and deviation: the same
    bits as the cur _set_path gives an active one with the same path and deviation."""
    rng = np.random.default_rng(5)
    cs = substep_view(_make_set(2, 1))
    cs.path[0] = rng.normal(size=18)
    cs.path[1] = cs.path[0]
    cs.dev[0] = 1e-3 * rng.normal(size=9)
    cs.dev[1] = cs.dev[0]
    cs.active[:] = (ACTIVE, RETIRED)
    cs.retired[0] = 0
    s, dt, h = 47 / 128, 0.02, 0.02 / 128
    _set_path(cs, 0, s, dt)
    cs.cur[1] = np.nan  # what _set_place leaves stale is never read
    _set_place(cs, 1, s, dt)
    np.testing.assert_array_equal(cs.cur[1, :3], cs.cur[0, :3])
    assert np.isnan(cs.cur[1, 3:]).all()
    np.testing.assert_array_equal(_state_of(cs, 1, s, dt), _state_of(cs, 0, s, dt))
    for c in range(3):
        np.testing.assert_array_equal(_rest_of_path(cs, 1, s, dt, c), _rest_of_path(cs, 0, s, dt, c))
    _force_again(cs, 1, s, dt, h, 8.0)
    assert cs.active[1] == ACTIVE
    np.testing.assert_array_equal(cs.cur[1], cs.cur[0])


def test_each_block_and_lane_is_numbered_candidates_first():
    """_candidates_first ("Memory layout"): in a block the candidates (start ≤ 1) take its
    first set indices, then the members that are only neighbours, each group in its old
    order; a block cut into lanes (as many candidates and threads as ph.parallel_members:
    _substep_part) is renumbered so within each lane's range, so that each lane
    keeps its members. The blocks' ranges are left alone."""
    rng = np.random.default_rng(3)
    n = 40
    gid = rng.permutation(n)[:14]  # members in cell order → grain
    start = np.full(n, np.inf)
    start[gid[[1, 3, 4, 5]]] = (0.0, 0.25, 0.5, 1.0)  # block 0: members 0..5, 4 candidates
    start[gid[[8, 12]]] = (0.0, 0.75)  # block 1: members 6..13, 2 candidates
    start[gid[[2, 10]]] = 1.5  # not candidates (start > 1)
    mstart = np.array([0, 6, 14])
    new = np.concatenate([rng.permutation(6), 6 + rng.permutation(8)])  # cell order → set index
    ph = make_contact_phase(n)
    ph.parallel_members[:] = (3, 2)  # lanes from 3 candidates and 2 threads
    cand = start[gid] <= 1.0
    for threads, ranges in ((1, ((0, 6), (6, 14))), (2, ((0, 3), (3, 6), (6, 14)))):  # block 0 in 2 lanes
        got = _candidates_first(new, mstart, gid, start, threads, ph)
        for lo, hi in ranges:
            members = np.flatnonzero((new >= lo) & (new < hi))
            by_old = members[np.argsort(new[members])]  # in their old order
            want = np.concatenate([by_old[cand[by_old]], by_old[~cand[by_old]]])
            np.testing.assert_array_equal(got[want], np.arange(lo, hi))
        if threads == 2:  # the test means something: lane 0 holds one candidate of 4
            assert cand[new < 3].sum() == 1


def test_a_pair_many_box_lengths_apart_unwrapped_touches_as_in_the_box():
    """Positions along a periodic axis are unwrapped (a saltating grain laps the box a few
    hundred times in 200 s more than one resting on the bed): a pair's periodic shift for
    the step (SubstepSet.image, cells.image_shift) must hold that many laps. Grain 0 is 300
    box lengths downstream of where it is in the reference run; grain 1 runs into it. The
    same collision, the same velocities after it (to the rounding of the larger x)."""
    pos = np.array([[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0]])
    vel = np.array([[0.0, 0.0, 0.0], [12.0, 0.0, 0.0]])
    ref = run_contact_phase(pos.copy(), vel.copy(), steps=2)
    lapped = pos.copy()
    lapped[0, 0] += 300 * 12.0  # the helper's box is 12 d long in x
    got = run_contact_phase(lapped, vel.copy(), steps=2)
    assert ref[1].collisions.sum() == 2  # both grains count the one collision
    assert got[1].collisions.sum() == ref[1].collisions.sum()
    np.testing.assert_allclose(got[0].vel, ref[0].vel, rtol=0, atol=1e-9)
    assert abs(got[0].vel[1, 0] - 12.0) > 1.0  # the collision did change grain 1's velocity
