"""grains/refs.py: a StructRef over a state tuple's arrays, and the tuple back (as_tuple)."""
from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
import pytest
from numba import njit

from saltation.flight.spheres import GrainState, GrainStateRef, Workspace, make_state
from saltation.grains.refs import as_tuple


@njit
def _round_trip(st):
    """Through a StructRef and back; writes through both; the tuple's own fields."""
    ref = GrainStateRef(*st)
    ref.pos[0, 1] = 2.5  # through the StructRef
    back = as_tuple(ref, GrainState)
    back.vel[1, 2] = -1.0  # through the tuple made from it
    return back.pos[0, 1], back.impacts.shape[0], back.jump_buf.shape[2]


def test_a_state_goes_through_a_structref_and_back_over_the_same_arrays():
    st = make_state(np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), 0.0, 10)
    y, n, fields = _round_trip(st)
    assert y == 2.5 and n == 3 and fields == st.jump_buf.shape[2]
    assert st.pos[0, 1] == 2.5 and st.vel[1, 2] == -1.0  # the caller's arrays were written


class _Other(NamedTuple):
    pos: np.ndarray


@njit
def _wrong_tuple(st):
    return as_tuple(GrainStateRef(*st), _Other)


def test_as_tuple_refuses_a_tuple_with_other_fields():
    st = make_state(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3)), 0.0, 10)
    with pytest.raises(numba.core.errors.TypingError, match="are not those of _Other"):
        _wrong_tuple(st)


def test_as_tuple_refuses_something_that_is_not_a_structref():
    @njit
    def f(w):
        return as_tuple(w, Workspace)

    from saltation.flight.spheres import make_workspace
    with pytest.raises(numba.core.errors.TypingError):
        f(make_workspace(2))
