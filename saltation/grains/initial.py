"""Initial conditions of the grains (paper §3.3).

The paper places each grain in a randomly chosen near-bed cell with initial linear and
angular velocities drawn at random "within the range of the experimental values" of
Niño & García (1998). Their tables are not available to us, so the ranges below are the
order of magnitude of saltation take-off velocities reported in that lineage (grain
velocities of a few u*, take-off angles of 20–50°, topspin of order u*/d). They only set
where each grain starts: the first 10 jumps of every grain are discarded (paper §3.2).

In particle units (d, u*, u*/d), uniform draws:

* position: x in [0, Lx), z in [0, Lz), centre height y in [0.6, 2.0] d above the bed top;
* velocity: u in [1, 4], v in [0.5, 2], w in [-0.5, 0.5] u*;
* spin: ϖ_z in [-2, 0] (topspin), ϖ_x, ϖ_y in [-0.5, 0.5] u*/d.

With ``release_height`` (settling experiments) every grain starts at rest at that height.
With ``run.start = "rest"`` (bed load, SPEC §7) every grain starts at rest in a hollow
of the packed bed (``initial_conditions_resting``).
Draws come from numpy's PCG64 seeded with the case seed: same seed, same grains.
"""
from __future__ import annotations

import numpy as np

Y_RANGE = (0.6, 2.0)
U_RANGE = (1.0, 4.0)
V_RANGE = (0.5, 2.0)
W_RANGE = (-0.5, 0.5)
SPIN_Z_RANGE = (-2.0, 0.0)
SPIN_XY_RANGE = (-0.5, 0.5)


def initial_conditions(n: int, domain_d, seed: int, release_height=None):
    """(pos, vel, spin), each (n, 3), in particle units. domain_d = (Lx, Lz) in d."""
    rng = np.random.default_rng(seed)
    lx, lz = domain_d
    pos = np.column_stack([rng.uniform(0, lx, n), rng.uniform(*Y_RANGE, n), rng.uniform(0, lz, n)])
    vel = np.column_stack([rng.uniform(*U_RANGE, n), rng.uniform(*V_RANGE, n), rng.uniform(*W_RANGE, n)])
    spin = np.column_stack([rng.uniform(*SPIN_XY_RANGE, n), rng.uniform(*SPIN_XY_RANGE, n), rng.uniform(*SPIN_Z_RANGE, n)])
    if release_height is not None:
        pos[:, 1] = release_height
        vel[:] = 0.0
        spin[:] = 0.0
    return pos, vel, spin


SOLID_FRACTION_AT_START = 0.15  # largest solid fraction of the starting layer when grains collide


def initial_conditions_apart(n: int, domain_d, seed: int, release_height=None, min_gap=0.02):
    """As ``initial_conditions``, but no two grains closer than d (1 + min_gap) (minimum
    image in x, z): for runs with grain–grain contacts, where overlapping starts would be
    violent. Centres are placed by random sequential insertion in a layer from the usual
    lowest start height (or ``release_height``) up, at least as tall as the usual band and
    tall enough to hold the grains at a solid fraction of SOLID_FRACTION_AT_START;
    velocities and spins are drawn as in ``initial_conditions``."""
    from ..contacts.pairs import random_gas

    lx, lz = domain_d
    pos, vel, spin = initial_conditions(n, domain_d, seed, release_height)
    band = max(Y_RANGE[1] - Y_RANGE[0], n * (np.pi / 6.0) / (lx * lz * SOLID_FRACTION_AT_START), 1.0 + min_gap)
    placed, _, _ = random_gas(n, (lx, band, lz), 1.0, seed, 0.0, min_gap)
    bottom = Y_RANGE[0] if release_height is None else release_height
    pos[:, 0] = placed[:, 0]
    pos[:, 2] = placed[:, 2]
    pos[:, 1] = bottom + placed[:, 1]
    return pos, vel, spin


def initial_conditions_resting(n: int, pockets, domain_d, seed: int, min_gap: float = 0.0):
    """(pos, vel, spin) of n grains at rest, each in its own hollow of the packed bed
    (``pockets``: (P, 3) resting centres, bed.packed.hexagonal_pockets), hollows drawn in
    a random order (PCG64, the case seed) and taken when no grain already placed is closer
    than d (1 + min_gap) (minimum image in x, z; neighbours may touch, as in the second
    layer of a close packing). Raises ValueError when the bed has room for fewer than n
    such grains (one per bed sphere at most; random filling takes about 0.45–0.7)."""
    lx, lz = domain_d
    pockets = np.asarray(pockets, dtype=np.float64)
    order = np.random.default_rng(seed).permutation(len(pockets))
    taken = []
    limit = (1.0 + min_gap) ** 2 * (1.0 - 1e-9)
    for k in order:
        p = pockets[k]
        if taken:
            q = pockets[taken]
            dx = q[:, 0] - p[0]
            dz = q[:, 2] - p[2]
            dx -= lx * np.round(dx / lx)
            dz -= lz * np.round(dz / lz)
            if np.min(dx * dx + (q[:, 1] - p[1]) ** 2 + dz * dz) < limit:
                continue
        taken.append(k)
        if len(taken) == n:
            break
    if len(taken) < n:
        raise ValueError(f"the packed bed of {lx:.4g} x {lz:.4g} d has room for {len(taken)} grains at rest "
                         f"in separate hollows, fewer than the {n} asked for")
    pos = pockets[np.array(taken)].copy()
    return pos, np.zeros((n, 3)), np.zeros((n, 3))
