"""Temporal blocking of the contact phase (collide.py, "Blocks"): the sub-stepped grains
run block by block, and the result must be the one of a single sweep over all of them,
bit for bit, both when the blocks stay apart and when a deflected grain crosses into
another block (the phase is then redone as one block)."""
import numpy as np

from saltation import contacts as K
from test_collide_layout import run_contact_phase


def _run(pos0, vel0, block_members, box, skin, steps, dt):
    return run_contact_phase(pos0, vel0, steps, dt, 128, box, skin, 0.3, 0.3, block_members)


def _same(a, b):
    (sa, ca, _), (sb, cb, _) = a, b
    for name in ("pos", "vel", "spin", "impacts", "jump_count", "jump_buf_n"):
        np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name), err_msg=name)
    np.testing.assert_array_equal(ca.collisions, cb.collisions)
    np.testing.assert_array_equal(ca.max_overlap, cb.max_overlap)


def test_blocks_give_the_single_sweep_result_in_a_dense_layer_over_the_bed():
    # 300 grains in a 24 x 4 x 24 d layer just over the bed top (5.5 % solids): contacts
    # between grains and with the bed (bed impacts write jump records) in every step
    box = (24.0, 8.0, 24.0)
    pos, vel, _ = K.random_gas(300, (24.0, 4.0, 24.0), 1.0, 3, 3.0, 0.02)
    pos[:, 1] += 0.55
    vel[:, 0] += 4.0
    blocked = _run(pos, vel, 1, box, 0.6, 5, 0.02)
    single = _run(pos, vel, 10 ** 9, box, 0.6, 5, 0.02)
    ph_b, ph_s = blocked[2], single[2]
    assert ph_s.counters[5] == 5  # one block per step
    assert ph_b.counters[5] > 10 * 5  # many blocks per step
    assert ph_b.counters[6] == 0  # none redone: the blocks stayed apart
    assert ph_b.counters[3] == ph_s.counters[3] > 0  # the same grain-sub-steps
    assert blocked[1].collisions.sum() > 20 and blocked[0].impacts.sum() >= 3
    _same(blocked, single)


def test_a_grain_knocked_into_another_block_makes_the_phase_redo_as_one_block():
    # grain 1 knocks grain 0 into grain 2; 2 is too far from 0's free-flight path to be
    # grouped with it (0.7 d gap > 2 x 0.25 d slack), so with one group per block the
    # blocked pass misses 0-2, the check finds the crossing and the phase is redone
    pos = np.array([[5.0, 3.0, 5.0], [5.0 - 1.05, 3.0, 5.0], [5.0 + 1.7, 3.0, 5.0]])
    vel = np.array([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    blocked = _run(pos, vel, 1, (12.0, 8.0, 12.0), 1.0, 2, 0.05)
    single = _run(pos, vel, 10 ** 9, (12.0, 8.0, 12.0), 1.0, 2, 0.05)
    assert blocked[2].counters[6] >= 1 and single[2].counters[6] == 0
    assert blocked[0].vel[2, 0] > 1.0  # grain 2 was hit
    _same(blocked, single)
