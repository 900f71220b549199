"""Jump statistics of a run (SPEC §6), one function for every grain family.

Rows come from the jump recorder (writers.JumpWriter.collect): particle, jump index,
length L (d), height H (d), velocity U = L/T (u*), duration T (d/u*). Each grain's first
DISCARDED_JUMPS jumps are dropped (initial-condition memory, Moreno-Casas et al. 2022
§3.2). Mean and standard deviation as the paper reports them; beside them the median
and the transport-weighted velocity ΣL/ΣT (the mean grain velocity over all flight
time), which a few unusual jumps cannot move — bed/jumps.py bounds T from below, so
U = L/T is bounded by the grain's speed, and the two means agree within the spread.
"""
from __future__ import annotations

import numpy as np

DISCARDED_JUMPS = 10
ROW_COLUMNS = ("particle", "jump", "length", "height", "velocity", "duration")
_P, _J, _L, _H, _U, _T = range(6)


def counted_jumps(rows: np.ndarray) -> np.ndarray:
    """The rows (an (n, 6) array of ROW_COLUMNS) the statistics use, ordered by (particle,
    jump): the result does not depend on when jumps were collected."""
    counted = rows[rows[:, _J] >= DISCARDED_JUMPS]
    return counted[np.lexsort((counted[:, _J], counted[:, _P]))]


def jump_statistics(rows: np.ndarray) -> dict:
    """summary.json's "jumps" block: count, recorded, H/L/U/T mean, std and median, the
    velocity ΣL/ΣT, the shortest counted duration."""
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, len(ROW_COLUMNS))
    counted = counted_jumps(rows)
    out = {"count": int(len(counted)), "recorded": int(len(rows)), "discarded_first_per_particle": DISCARDED_JUMPS}
    for key, col in (("H", _H), ("L", _L), ("U", _U), ("T", _T)):
        v = counted[:, col]
        out[f"{key}_mean"] = float(v.mean()) if len(v) else None
        out[f"{key}_std"] = (float(v.std(ddof=1)) if len(v) > 1 else 0.0) if len(v) else None
        out[f"{key}_median"] = float(np.median(v)) if len(v) else None
    total_t = counted[:, _T].sum()
    out["U_flight_weighted"] = float(counted[:, _L].sum() / total_t) if total_t > 0 else None
    out["T_shortest"] = float(counted[:, _T].min()) if len(counted) else None
    out["units"] = "H, L in d; U in u*; T in d/u*"
    return out


def empty_rows() -> np.ndarray:
    return np.zeros((0, len(ROW_COLUMNS)))
