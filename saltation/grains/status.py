"""Per-grain status codes and the jump record layout, shared by every grain family
(flight/spheres.py, flight/composites.py and the kernels that read their state)."""

OK = 0  # integrating
NOT_FINITE = 1  # the grain's state became non-finite: it is stopped and the run fails

JUMP_FIELDS = 4  # columns of a jump record (bed/jumps.close_jump): t_start, length, height, duration
