"""Temporal blocking of the contact phase (contacts/phase.py, "Blocks"): the sub-stepped grains
run block by block, and the result must be the one of a single sweep over all of them,
bit for bit, both when the blocks stay apart and when a deflected grain crosses into
another block (the phase is then redone with the two groups joined, and after
MERGED_PASSES such passes as one block)."""
import numba
import numpy as np
from test_collide_layout import run_contact_phase

from saltation.contacts import pairs as K
from saltation.contacts.phase import BLOCKS, MERGED_PASSES, PARALLEL_BLOCKS, REDONE_FAR, WAKES, WIDENED

TWO_THREADS = min(2, numba.config.NUMBA_NUM_THREADS)


def _run(pos0, vel0, block_members, box, skin, steps, dt, n_sub=128, block_slack=None, threads=1,
         parallel_members=None, near_slack=None):
    return run_contact_phase(pos0, vel0, steps, dt, n_sub, box, skin, 0.3, 0.3, block_members, block_slack,
                             threads, parallel_members, near_slack)


def _same(a, b):
    (sa, ca, _), (sb, cb, _) = a, b
    for name in ("pos", "vel", "spin", "impacts", "jump_count", "jump_buf_n"):
        np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name), err_msg=name)
    np.testing.assert_array_equal(ca.collisions, cb.collisions)
    np.testing.assert_array_equal(ca.max_overlap, cb.max_overlap)
    # the contact history, each pair's in its list entry (_near_pairs reorders the rows)
    np.testing.assert_array_equal(ca.nbr_count, cb.nbr_count)
    for i in range(len(ca.nbr_count)):
        m = ca.nbr_count[i]
        np.testing.assert_array_equal(ca.nbr[i, :m], cb.nbr[i, :m])
        np.testing.assert_array_equal(ca.touch[i, :m], cb.touch[i, :m], err_msg=f"touch of {i}")
        np.testing.assert_array_equal(ca.shear[i, :m], cb.shear[i, :m], err_msg=f"shear of {i}")


def _layer(lz, seed):
    # 300 grains in a 24 x 4 x lz d layer just over the bed top, drifting downstream
    pos, vel, _ = K.random_gas(300, (24.0, 4.0, lz), 1.0, seed, 3.0, 0.02)
    pos[:, 1] += 0.55
    vel[:, 0] += 4.0
    return (24.0, 8.0, lz), pos, vel


def test_blocks_give_the_single_sweep_result_in_a_dense_layer_over_the_bed():
    # 6.8 % solids in the layer: contacts between grains and with the bed (bed impacts write jump
    # records) in every step
    box, pos, vel = _layer(24.0, 3)
    blocked = _run(pos, vel, 1, box, 0.6, 5, 0.02)
    single = _run(pos, vel, 10 ** 9, box, 0.6, 5, 0.02)
    ph_b, ph_s = blocked[2], single[2]
    assert ph_s.counters[5] == 5  # one block per step
    assert ph_b.counters[5] > 10 * 5  # many blocks per step
    assert ph_b.counters[6] == ph_b.counters[7] == 0  # none redone: the blocks stayed apart
    assert ph_b.counters[3] == ph_s.counters[3] > 0  # the same grain-sub-steps
    assert blocked[1].collisions.sum() > 20 and blocked[0].impacts.sum() >= 3
    _same(blocked, single)


def test_giant_groups_are_cut_with_tighter_slacks_and_give_the_same_result():
    # a denser layer (13.6 % solids); groups of more than 10 members are cut with zero
    # slack (contacts/phase.py, "Blocks"): more blocks, crossings redone, the single sweep's result
    box, pos, vel = _layer(12.0, 5)
    default = _run(pos, vel, 1, box, 0.6, 5, 0.02)
    cut = _run(pos, vel, 1, box, 0.6, 5, 0.02, block_slack=(0.2, 0.05, 0.0, 0.0, 10))
    single = _run(pos, vel, 10 ** 9, box, 0.6, 5, 0.02)
    assert cut[2].counters[5] > default[2].counters[5]  # more, smaller blocks
    assert cut[2].counters[6] == 0  # never fell back to one block
    assert cut[1].collisions.sum() > 20
    _same(cut, single)
    _same(default, single)


def _cradle(row):
    # grain 1 knocks grain 0 into a row of resting grains 0.55 d apart, like Newton's
    # cradle, all within one step. Each row grain is touched from the side by a slow
    # partner, so that it is a candidate in a group of its own (row gaps > 2 x 0.25 d
    # slack); grain 1's list (cutoff 2 d) reaches 0 only
    x = [5.0 + 1.55 * k for k in range(row)]
    pos = [[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0]] + [[xi, 3.0, 5.0] for xi in x[1:]]
    pos += [[xi, 3.0, 5.0 + 1.02] for xi in x[1:]]
    vel = np.zeros((len(pos), 3))
    vel[1, 0] = 30.0
    vel[row + 1:, 2] = -0.5
    pos = np.array(pos)
    box = (24.0, 8.0, 12.0)
    return _run(pos, vel, 1, box, 1.0, 1, 0.1, 256), _run(pos, vel, 10 ** 9, box, 1.0, 1, 0.1, 256)


def test_a_grain_knocked_into_another_block_makes_the_phase_redo_with_the_groups_joined():
    # 0 is knocked into 2 (another block): the check finds the crossing, the pass is
    # redone with 0's and 2's groups joined; then 2 is knocked into 3: joined too
    blocked, single = _cradle(3)
    assert blocked[2].counters[7] == 2 and blocked[2].counters[6] == 0
    assert single[2].counters[6] == single[2].counters[7] == 0
    assert blocked[0].vel[3, 0] > 1.0  # the last grain of the row was hit
    _same(blocked, single)


def test_a_chain_of_crossings_ends_in_one_block():
    # a longer row: every pass finds one more crossing; after MERGED_PASSES passes with
    # joined groups the phase is redone as one block
    blocked, single = _cradle(MERGED_PASSES + 2)
    assert blocked[2].counters[7] == MERGED_PASSES and blocked[2].counters[6] == 1
    assert blocked[0].vel[MERGED_PASSES + 2, 0] > 1.0  # the last grain of the row
    _same(blocked, single)


def test_a_crossing_in_a_later_step_is_redone_too():
    # grain 1 knocks grain 0 into grain 2 over two shorter steps
    pos = np.array([[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0], [5.0 + 1.7, 3.0, 5.0]])
    vel = np.array([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    blocked = _run(pos, vel, 1, (12.0, 8.0, 12.0), 1.0, 2, 0.05)
    single = _run(pos, vel, 10 ** 9, (12.0, 8.0, 12.0), 1.0, 2, 0.05)
    assert blocked[2].counters[7] >= 1 and single[2].counters[7] == 0
    assert blocked[0].vel[2, 0] > 1.0  # grain 2 was hit
    _same(blocked, single)


# ----------------------------------------------------------------------------- threads
# On more than one thread a block of at least PARALLEL_MEMBERS candidates runs each part of
# its sub-steps over its members in parallel (contacts/phase._substep_part): the same bits as
# one thread and as a single sweep.


def test_blocks_on_two_threads_give_the_one_thread_and_single_sweep_result():
    box, pos, vel = _layer(12.0, 5)
    runs = {}
    for name, members, threads in (("two", 10 ** 9, TWO_THREADS), ("one", 10 ** 9, 1), ("blocked2", 1, TWO_THREADS),
                                   ("blocked1", 1, 1)):
        # blocks of 6 candidates or more run on all threads (the default is PARALLEL_MEMBERS)
        runs[name] = _run(pos, vel, members, box, 0.6, 5, 0.02, threads=threads, parallel_members=6)
    if TWO_THREADS > 1:
        c = runs["two"][2].counters
        # the single block of each pass in parallel: one pass per step, and again in a pass
        # redone without the near-pair filter (its blocks are not counted twice in BLOCKS)
        assert c[PARALLEL_BLOCKS] == c[BLOCKS] + c[REDONE_FAR] == 5 + c[REDONE_FAR]
        assert 0 < runs["blocked2"][2].counters[PARALLEL_BLOCKS] < runs["blocked2"][2].counters[BLOCKS]
    assert runs["one"][2].counters[PARALLEL_BLOCKS] == runs["blocked1"][2].counters[PARALLEL_BLOCKS] == 0
    assert runs["two"][1].collisions.sum() > 20 and runs["two"][0].impacts.sum() >= 3
    assert runs["two"][2].counters[WAKES] > 0  # wake-ups between the parallel parts
    for name in ("one", "blocked2", "blocked1"):
        _same(runs["two"], runs[name])
    for a, b in (("two", "one"), ("blocked2", "blocked1")):
        np.testing.assert_array_equal(runs[a][2].counters[:PARALLEL_BLOCKS], runs[b][2].counters[:PARALLEL_BLOCKS])


def test_two_threads_leave_a_large_block_on_one_thread_by_default():
    """Lanes have neither retirement nor the lists, which save more than a second thread
    gives ("Blocks on several threads"): a block is cut into lanes only from LANE_THREADS
    threads; on two, it is sub-stepped as on one — the same bits and the same counters,
    retired sub-steps included."""
    from saltation.contacts.phase import LANE_THREADS, PARALLEL_MEMBERS, RETIRED_SUBSTEPS, _lanes, make_contact_phase

    ph = make_contact_phase(4)
    assert LANE_THREADS == 3
    assert _lanes(2, PARALLEL_MEMBERS, ph) == 1 and _lanes(LANE_THREADS, PARALLEL_MEMBERS, ph) == LANE_THREADS
    assert _lanes(LANE_THREADS, PARALLEL_MEMBERS - 1, ph) == 1
    box, pos, vel = _layer(12.0, 5)
    runs = {t: _run(pos, vel, 10 ** 9, box, 0.6, 5, 0.02, threads=t, parallel_members=(6, LANE_THREADS))
            for t in (1, TWO_THREADS)}
    lanes = _run(pos, vel, 10 ** 9, box, 0.6, 5, 0.02, threads=TWO_THREADS, parallel_members=(6, 2))
    one, two = runs[1], runs[TWO_THREADS]
    _same(two, one)
    _same(lanes, one)
    np.testing.assert_array_equal(two[2].counters, one[2].counters)
    assert one[2].counters[RETIRED_SUBSTEPS] > 0 and two[2].counters[PARALLEL_BLOCKS] == 0
    if TWO_THREADS > 1:  # the test means something: cut into lanes on two, the block retires nobody
        assert lanes[2].counters[PARALLEL_BLOCKS] > 0 and lanes[2].counters[RETIRED_SUBSTEPS] == 0


def test_automatic_threads_share_soft_contacts_from_a_few_hundred_grains(tmp_path):
    # run.threads = 0: a run with soft contacts uses all cores from PARALLEL_MEMBERS grains
    # (a dilute run without contacts stays on one thread below SERIAL_BELOW)
    from saltation.case.schema import load_case, resolve_domain
    from saltation.contacts.phase import PARALLEL_MEMBERS
    from saltation.engine.simulation import Simulation, _les_box_m, open_flow

    most = numba.config.NUMBA_NUM_THREADS
    got = {}
    for model in ("soft", "off", "hard"):
        for n in (PARALLEL_MEMBERS - 1, PARALLEL_MEMBERS):
            case = load_case("cases/default.toml", {"collisions.model": model, "run.n_particles": n,
                                                    "run.threads": 0, "flow.source": "loglaw"})
            ds = open_flow(case)
            sim = Simulation(resolve_domain(case, _les_box_m(ds, case)), ds, tmp_path / f"{model}{n}",
                             progress=False)
            got[model, n] = sim.threads()
    assert got["soft", PARALLEL_MEMBERS] == most and got["soft", PARALLEL_MEMBERS - 1] == 1
    assert got["off", PARALLEL_MEMBERS] == got["hard", PARALLEL_MEMBERS] == 1


# ----------------------------------------------------------------------------- near pairs
# Row entries whose free-flight paths stay further apart than d + 2 NEAR_SLACK are not
# looked at in the sub-steps; afterwards every such pair of an active grain is checked with
# the deviations the sub-steps made, and the phase redone without the filter if one may
# have touched (contacts/phase.py, "Near pairs"). The same bits as without the filter.


def test_the_near_pair_filter_gives_the_unfiltered_result_and_redoes_when_a_far_pair_came_near():
    box, pos, vel = _layer(12.0, 5)
    plain = _run(pos, vel, 1, box, 0.6, 5, 0.02, near_slack=np.inf)
    default = _run(pos, vel, 1, box, 0.6, 5, 0.02)
    tight = _run(pos, vel, 1, box, 0.6, 5, 0.02, near_slack=0.0)  # any deviation toward a far pair fails
    assert plain[2].counters[REDONE_FAR] == 0
    assert tight[2].counters[REDONE_FAR] >= 1  # the check found far pairs that came near: redone
    assert plain[1].collisions.sum() > 20
    _same(default, plain)
    _same(tight, plain)
    for run in (default, tight):
        np.testing.assert_array_equal(run[2].counters[:3], plain[2].counters[:3])


def test_a_member_that_deviates_by_the_slack_widens_the_rows_instead_of_redoing_the_phase():
    # σ = 0.02 d: many grains deviate further within a step. Each is widened (it and its
    # partners look at every pair from then on), so no phase is redone for a far pair,
    # and the result is the unfiltered one, bit for bit (contacts/phase.py, "Widened rows")
    box, pos, vel = _layer(12.0, 5)
    plain = _run(pos, vel, 1, box, 0.6, 5, 0.02, near_slack=np.inf)
    narrow = _run(pos, vel, 1, box, 0.6, 5, 0.02, near_slack=0.02)
    assert plain[2].counters[WIDENED] == 0
    assert narrow[2].counters[WIDENED] >= 5
    assert narrow[2].counters[REDONE_FAR] == 0
    _same(narrow, plain)
    np.testing.assert_array_equal(narrow[2].counters[:3], plain[2].counters[:3])


def test_a_block_cut_into_lanes_widens_the_rows_too_instead_of_redoing_the_phase():
    # as above, with the block's sub-steps cut into lanes on two threads: the members that
    # reach the slack are widened between the drift and the forces, lane by lane
    box, pos, vel = _layer(12.0, 5)
    plain = _run(pos, vel, 1, box, 0.6, 5, 0.02, near_slack=np.inf)
    lanes = _run(pos, vel, 10 ** 9, box, 0.6, 5, 0.02, threads=TWO_THREADS, parallel_members=(6, 2),
                 near_slack=0.02)
    if TWO_THREADS > 1:
        assert lanes[2].counters[PARALLEL_BLOCKS] > 0
    assert lanes[2].counters[WIDENED] >= 5
    assert lanes[2].counters[REDONE_FAR] == 0
    _same(lanes, plain)
    np.testing.assert_array_equal(lanes[2].counters[:3], plain[2].counters[:3])


def test_near_entries_go_first_in_row_order_and_remember_their_list_entries():
    # one row at places 5..27 of the set's row arrays, 9 of its 23 entries near, listed as
    # _near_pairs lists them: the near ones from the front, the far ones from the back
    from saltation.contacts.phase import _near_first
    rng = np.random.default_rng(4)
    r0, r1, size = 5, 28, 40
    nbr = rng.integers(0, 1000, size).astype(np.int32)  # the set's dtypes (SubstepSet)
    image = rng.normal(size=(size, 3))
    touch = rng.integers(0, 2, size).astype(np.uint8)
    shear = rng.normal(size=(size, 3))
    is_near = np.zeros(r1 - r0, bool)
    is_near[rng.choice(r1 - r0, 9, replace=False)] = True
    order = np.concatenate([np.flatnonzero(is_near), np.flatnonzero(~is_near)]) + r0
    nx = np.arange(size, dtype=np.int32)
    nx[r0:r0 + 9] = order[:9]
    nx[r0 + 9:r1] = order[9:][::-1]
    before = [a.copy() for a in (nbr, image, touch, shear)]
    _near_first(nbr, image, touch, shear, nx, r0, r1, 9)
    np.testing.assert_array_equal(nx[r0:r1], order)  # where each place came from
    np.testing.assert_array_equal(nx[:r0], np.arange(r0))
    np.testing.assert_array_equal(nx[r1:], np.arange(r1, size))
    for got, old in zip((nbr, image, touch, shear), before, strict=True):
        np.testing.assert_array_equal(got[r0:r1], old[order])
        np.testing.assert_array_equal(got[:r0], old[:r0])  # other rows untouched
        np.testing.assert_array_equal(got[r1:], old[r1:])
