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


def composites_resting(offsets, radii, pockets, bed_centres, domain_d, seed: int, gap: float = 1e-3):
    """Centres (N, 3) of N bonded-sphere grains placed on the packed bed (bed sphere
    diameter 1): grain i — component centres ``offsets[i]`` (k, 3) from its centre, in
    the world frame (its orientation applied), radii ``radii[i]`` (k,) — goes above the
    next hollow of ``pockets`` (bed.packed.hexagonal_pockets) in a random order (PCG64,
    the case seed), is lowered until its first component touches a bed sphere and is
    raised by ``gap``; the hollow is taken when the grain clears every grain placed by
    ``gap`` (minimum image in x, z), else the next one is tried. The grains then settle
    under their weight (tipping into a stable pose). Raises ValueError when the bed has
    room for fewer than N grains."""
    lx, lz = domain_d
    pockets = np.asarray(pockets, dtype=np.float64)
    bed = np.asarray(bed_centres, dtype=np.float64)
    order = np.random.default_rng(seed).permutation(len(pockets))
    n = len(offsets)
    out = np.zeros((n, 3))
    placed_c, placed_r = np.zeros((0, 3)), np.zeros(0)
    i = 0
    for k in order:
        if i == n:
            break
        off = np.asarray(offsets[i], dtype=np.float64)
        rad = np.asarray(radii[i], dtype=np.float64)
        x, z = pockets[k, 0], pockets[k, 2]
        dx = x + off[:, 0, None] - bed[None, :, 0]
        dz = z + off[:, 2, None] - bed[None, :, 2]
        dx -= lx * np.round(dx / lx)
        dz -= lz * np.round(dz / lz)
        reach = rad[:, None] + 0.5
        h2 = dx * dx + dz * dz
        under = h2 < reach * reach
        if not under.any():
            continue
        # the height at which each component would touch each bed sphere beneath it
        need = np.where(under, bed[None, :, 1] + np.sqrt(np.maximum(reach * reach - h2, 0.0)) - off[:, 1, None],
                        -np.inf)
        centre = np.array([x, need.max() + gap, z])
        comps = centre + off
        if len(placed_r):
            d = comps[:, None, :] - placed_c[None, :, :]
            d[..., 0] -= lx * np.round(d[..., 0] / lx)
            d[..., 2] -= lz * np.round(d[..., 2] / lz)
            if np.any(np.sqrt((d * d).sum(axis=2)) < rad[:, None] + placed_r[None, :] + gap):
                continue
        out[i] = centre
        placed_c = np.vstack([placed_c, comps])
        placed_r = np.concatenate([placed_r, rad])
        i += 1
    if i < n:
        raise ValueError(f"the packed bed of {lx:.4g} x {lz:.4g} d has room for {i} of these grains at rest "
                         f"in separate hollows, fewer than the {n} asked for")
    return out
