"""What a jump is, written once for every bed model and grain family (SPEC §6).

A jump is a free flight from one bed contact to the next. A contact that lasts (the
grain still touches the bed in the next step) or a re-touch so soon after the last
contact that the flight was never resolved is part of the *same* bed-contact episode,
not a new jump: the flight since the last contact closes a jump only if

* it lasted at least one hydrodynamic step, ``duration ≥ dt`` (a shorter one cannot be
  told from a contact that went on within the step), and
* the grain's bottom rose above the bed top by at least the contact resolution,
  ``H ≥ max(0.01, ½ (α/τ*) dt²)`` d: 1 % of d is the overlap the contact model allows
  (SPEC §5), and ½ (α/τ*) dt² is how far the grain falls in one step under its submerged
  weight (α/τ*: the weight acceleration of SPEC §2, particle units). A smaller rise is a
  grain chattering or sliding on the bed — a grain resting on the virtual bed in still
  water bounces every 2–5 steps to 0.001–0.007 d, numerically, for ever — not a hop.

Either way the next jump starts at this contact (``jump_t0``, ``jump_x0`` and the
highest point are reset by the caller), so the contact episode's end is where a jump
begins. With the two bounds U = L/T of a recorded jump is bounded by the grain's speed:
the micro-jumps of T ~ 1e-14 d/u* that gave U ~ 1e9 u* cannot occur.
"""
from numba import njit

# slots of the bed parameter array every bed kernel takes (bed.virtual.bed_parameters)
BED_MIN_JUMP_DURATION = 4
BED_MIN_JUMP_HEIGHT = 5


CONTACT_RESOLUTION = 0.01  # d: the largest contact overlap the contact stiffness is set for (SPEC §5)


def jump_thresholds(dt: float, tau_star: float, alpha: float) -> tuple[float, float]:
    """(shortest jump duration, lowest jump height) in d/u* and d for a step dt (d/u*)."""
    return float(dt), max(CONTACT_RESOLUTION, 0.5 * (alpha / tau_star) * dt * dt)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def close_jump(st, p, t_start, length, height, t_hit, min_duration, min_height):
    """A bed contact of grain p at t_hit ends the flight begun at t_start (length, height
    of the grain's bottom above the bed top, in d). Records a jump in ``st.jump_buf`` and
    counts it when the flight was one (module docstring); returns whether it was."""
    duration = t_hit - t_start
    if duration < min_duration or height < min_height:
        return False
    j = st.jump_buf_n[p]
    if j < st.jump_buf.shape[1]:
        st.jump_buf[p, j, 0] = t_start
        st.jump_buf[p, j, 1] = length
        st.jump_buf[p, j, 2] = height
        st.jump_buf[p, j, 3] = duration
        st.jump_buf_n[p] = j + 1
    st.jump_count[p] += 1
    return True
