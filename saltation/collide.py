"""Grain–grain contacts inside the hydrodynamic step (SPEC §5): the contact phase of the
run loop's operator split (stepping.py).

Operator split
--------------
A hydrodynamic step of length Δt (d/u*) is done in three phases, in this order:

1. **free flight** (integrator.free_flight_particle): RK4 with the fluid forces, every
   grain on its own, from (x₀, u₀, ϖ₀) to (x₁, u₁, ϖ₁);
2. **contacts** (this module): the grains that can touch another one during the step are
   moved again through the step in ``n_sub`` sub-steps of h = Δt/n_sub, with the fluid
   force *held* at what the free flight gave it, plus the contact forces;
3. **bed** (integrator.bed_check_particle or packed_bed.packed_bed_check_particle).

Phase 2 is written as a correction to the free flight. Each grain's free-flight path in
the step is the cubic Hermite interpolant H(s), s = t/Δt ∈ [0, 1], through (x₀, u₀) and
(x₁, u₁) (spin: linear between ϖ₀ and ϖ₁); during the contact phase a grain is at
``H(s) + δx`` with velocity ``H'(s)/Δt + δu`` and spin ``ϖ(s) + δϖ``, and the deviations
obey ``dδu/dt = F_c/m``, ``dδx/dt = δu``, ``dδϖ/dt = T_c/I`` (F_c, T_c the contact force and
torque of contacts.py's LAMMPS-exact ``gran/hooke/history`` model, m = 1 the grain mass,
I = 0.1) — integrated by velocity Verlet (LAMMPS ``fix nve/sphere`` order: half kick,
drift, forces at the half-kicked velocities, half kick). Hence:

- a grain that touches nothing in the step keeps the RK4 result bit for bit (δ stays 0);
- for a grain in contact, ``(x, u, ϖ) = (x₁, u₁, ϖ₁) + (δx, δu, δϖ)``: the fluid force
  acts as in free flight (held over the step, the usual CFD–DEM assumption: the contact
  lasts ~3·10⁻³ d/u*, far shorter than the drag response time), the contact impulse adds
  on top; first-order splitting error O(Δt · |Δu_contact| · ∂a_fluid/∂u).

After the phase a grain that had a contact gets the fluid re-sampled at its new position
and its **Basset history restarted**, exactly as at a bed impact (history.py): a contact
changes the velocity by a finite amount in ~10⁻³ d/u*, which the Boussinesq–Basset
kernel (valid for smooth acceleration of a lone sphere) would turn into a spurious
long-lived force. A grain in a lasting contact (resting on another) restarts its history
every step, so it has none — appropriate for a grain that is not flying freely.

Contact mass: the grain's own mass (m = 1, I = 0.1, no added mass), as in the bed
rebound of SPEC §4; the dashpot is set from the restitution for that mass, so the
realised restitution is the case's e whatever the mass convention.

Which grains are sub-stepped, and from when (cost)
-------------------------------------------------
Only grains that can touch another grain in this step, and only from the earliest time
they can. With Δx = x₁ − x₀ the step's chord and b = Δt(|u₀ − ū| + |u₁ − ū|)/4 (ū = Δx/Δt)
a bound on how far the cubic bulges off it, two grains cannot touch before

    s_ij = (|x₀ᵢ − x₀ⱼ| − d − b_i − b_j) / |Δx_i − Δx_j|

(triangle inequality); a grain joins the sub-steps at the sub-step before min_j s_ij
(or at once when it is in contact now), with zero deviation — exact, since nothing has
acted on it yet. A grain that can touch no other grain in the step (s_ij > 1 for all its
list neighbours) is not sub-stepped at all and keeps the RK4 result and the hard bed. A
grain deflected by a contact can still reach a grain that had not joined: the force
kernel notices any contact with such a grain and *wakes* it at that sub-step (its
deviation is exactly zero until then), so no contact is missed on deflected paths
either. The cost of the phase is therefore n_sub × (grains close to a contact), not
n_sub × N; ``counters[3]`` counts the grain-sub-steps actually done.

The bed in the contact phase
----------------------------
A grain that is sub-stepped has its bed contacts inside the sub-steps, as soft contacts
with fixed bed spheres of diameter d (the pair model with a fixed partner: m_eff = m,
γ_n from the **bed** restitution, the bed friction, the same k_n and k_t): a position
correction after the phase (the hard rebound moves a grain by up to ~|Δu| Δt ≈ 0.1 d)
would put it into a neighbour it is touching, and the stiff spring would turn that
overlap into a spurious kick (½ k_n δ² at δ = 0.02 d is a relative speed of ~20 u*).
Packed bed: the real bed spheres (packed_bed.py), found through its cells. Virtual bed:
when the grain's bottom first goes below the bed top, a virtual bed sphere is placed
under it along a random normal (bed.virtual_bed_normal, the same counter-based draw as
the hard virtual bed) and kept until the contact ends. The first bed contact after at
least one step off the bed counts as a bed impact and closes a jump (SPEC §6); while the
contact lasts the next jump's start moves with the grain. Such a grain joins the
sub-steps no later than the time its bottom can reach the bed top. The other grains get
the hard-sphere rebound of SPEC §4 in phase 3; a grain ending the step below the bed top
may be moved by it by up to twice its reach, which the join test adds to its distance
margin, so that such a move never pushes it into a grain it was not sub-stepped with.
Known gap: a grain woken on a deflected path after its own free path went below the bed
top starts its soft bed contact with that overlap (rare; not counted).

Neighbour list (contacts.ContactList, skin s)
---------------------------------------------
Valid while no grain is more than s/2 from where the list was built. Before each
contact phase the bound ``max(|x₀ − x_ref|, |x₁ − x_ref|) + b`` is checked and the list
rebuilt at x₀ when it exceeds s/2 (with saltation speeds of ~10 u* and Δt = 0.02 d/u*
that is most steps: a rebuild is one counting sort and one cell sweep, cheap next to the
RK4 step). If a grain moves more than s/2 in one step, the skin is widened to 2.5× its
reach, up to what the cells allow (stepping.Stepper makes them wide enough for twice the
default skin, which covers 20 u*). A grain still faster, or deflected beyond the skin, is
counted in ``overruns``; after such a step the end positions are searched afresh for
pairs in contact that the list does not hold (``missed_contacts``, reported in
summary.json; the tests require zero).

Statistics (per grain, race-free): ``cl.collisions`` (contacts begun), ``cl.max_overlap``,
and here ``contact_substeps`` (sub-steps spent in each contact, summed) and
``overlap_sum`` (overlap summed over those sub-steps): mean contact duration in sub-steps
= Σ contact_substeps / Σ collisions, time-mean overlap = Σ overlap_sum / Σ contact_substeps.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .bed import virtual_bed_normal
from .cells import build_cells, min_image, stencil_cells
from .contacts import LEVER_RADIUS, ContactList, hard_sphere_collisions, normal_damping, rebuild
from .history import META_COUNT
from .rng import uniform2

__all__ = ["ContactPhase", "BedContext", "make_contact_phase", "make_bed_context", "soft_contact_phase",
           "hard_contact_phase"]

BED_SLOTS = 4  # bed spheres one grain can touch at once (3 in a hollow of the packed layer)
FREE = -1  # an empty bed-contact slot
VIRTUAL = -2  # a slot holding a virtual bed grain


class BedContext(NamedTuple):
    """The bed as the contact phase sees it: soft contacts with fixed bed spheres for the
    grains being sub-stepped (module docstring). Flat arrays only (parallel loops)."""
    params: np.ndarray  # (7,) packed (0/1), e, f, max tilt (rad), γ_n (m_eff = m), k_n, k_t
    ints: np.ndarray  # (2,) int64: seed, index of the current step
    t0: np.ndarray  # (1,) start time of the current step (d/u*)
    centres: np.ndarray  # packed bed (packed_bed.PackedBed, flattened)
    box: np.ndarray
    ncell: np.ndarray
    size: np.ndarray
    cell_start: np.ndarray
    cell_count: np.ndarray
    order: np.ndarray
    slot_id: np.ndarray  # (N, S) int64 bed sphere id, VIRTUAL or FREE
    slot_c: np.ndarray  # (N, S, 3) its centre, in the grain's unwrapped frame
    slot_shear: np.ndarray  # (N, S, 3) tangential spring
    in_bed: np.ndarray  # (N,) uint8 touching the bed at the last evaluation
    last_contact: np.ndarray  # (N,) int64 last step with bed contact (shared with packed_bed)


def make_bed_context(n, packed: bool, pb, restitution, friction, max_tilt, kn, kt, seed, last_contact):
    """BedContext for n grains; pb: a packed_bed.PackedBed (any, when not packed)."""
    gamma = normal_damping(restitution, kn, 1.0) if restitution > 0.0 else 2.0 * math.sqrt(kn)
    params = np.array([1.0 if packed else 0.0, restitution, friction, max_tilt, gamma, kn, kt])
    return BedContext(params, np.array([seed, 0], np.int64), np.zeros(1), pb.centres, pb.box, pb.ncell,
                      pb.size, pb.cell_start, pb.cell_count, pb.order, np.full((n, BED_SLOTS), FREE, np.int64),
                      np.zeros((n, BED_SLOTS, 3)), np.zeros((n, BED_SLOTS, 3)), np.zeros(n, np.uint8),
                      last_contact)


class ContactPhase(NamedTuple):
    active: np.ndarray  # (N,) uint8: sub-stepped in this step
    act: np.ndarray  # (N,) int64: ids of the active grains, n_act[0] of them
    n_act: np.ndarray  # (1,) int64
    wake: np.ndarray  # (N,) uint8: touched a grain that was not active
    touched: np.ndarray  # (N,) uint8: had a contact in this step
    reach: np.ndarray  # (N,) float64: D, how far the free-flight path gets from x₀
    dx: np.ndarray  # (N,3) deviations from the free-flight path
    dv: np.ndarray  # (N,3)
    dw: np.ndarray  # (N,3)
    P: np.ndarray  # (N,3) position, velocity, spin at the current sub-step (active rows)
    V: np.ndarray  # (N,3)
    W: np.ndarray  # (N,3)
    force: np.ndarray  # (N,3) contact force / torque at the last evaluation (active rows)
    torque: np.ndarray  # (N,3)
    x0pos: np.ndarray  # (N,3) start-of-step positions, for list rebuilds
    dev_max: np.ndarray  # (N,) largest |δx|² in this step
    ref_bound: np.ndarray  # (N,) bound on the free-flight path's distance from the list's reference
    nrm: np.ndarray  # (N,3) scratch: virtual bed normal
    margin: np.ndarray  # (N,) scratch: engagement reach incl. the bed-rebound margin
    start: np.ndarray  # (N,) earliest possible contact in the step (fraction s; inf: none)
    bed_overlap_max: np.ndarray  # (N,) largest overlap with a bed sphere (d)
    contact_substeps: np.ndarray  # (N,) int64 Σ sub-steps in contact (statistics)
    overlap_sum: np.ndarray  # (N,) float64 Σ overlap over those sub-steps (d)
    counters: np.ndarray  # (5,) int64: list rebuilds, overruns, wakes, sub-stepped grain-steps, missed


def make_contact_phase(n: int) -> ContactPhase:
    z3 = lambda: np.zeros((n, 3))  # noqa: E731
    return ContactPhase(
        np.zeros(n, np.uint8), np.zeros(n, np.int64), np.zeros(1, np.int64), np.zeros(n, np.uint8),
        np.zeros(n, np.uint8), np.zeros(n), z3(), z3(), z3(), z3(), z3(), z3(), z3(), z3(), z3(),
        np.zeros(n), np.zeros(n), z3(), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n, np.int64),
        np.zeros(n), np.zeros(5, np.int64),
    )


# ----------------------------------------------------------------------------- path


@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _hermite(x0, x1, v0, v1, s, dt):
    """Cubic Hermite position and velocity at s ∈ [0, 1] through (x0, v0), (x1, v1)."""
    s2 = s * s
    s3 = s2 * s
    h00 = 2.0 * s3 - 3.0 * s2 + 1.0
    h10 = s3 - 2.0 * s2 + s
    h01 = -2.0 * s3 + 3.0 * s2
    h11 = s3 - s2
    d00 = 6.0 * s2 - 6.0 * s
    d10 = 3.0 * s2 - 4.0 * s + 1.0
    d11 = 3.0 * s2 - 2.0 * s
    x = h00 * x0 + h01 * x1 + dt * (h10 * v0 + h11 * v1)
    v = d00 * (x0 - x1) / dt + d10 * v0 + d11 * v1
    return x, v


@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _set_path_inl(x0w, pos, vel, spin, j, s, dt, ph):
    """P, V, W of grain j at s: free-flight path plus its deviation."""
    for a in range(3):
        x, v = _hermite(x0w[j, a], pos[j, a], x0w[j, 3 + a], vel[j, a], s, dt)
        ph.P[j, a] = x + ph.dx[j, a]
        ph.V[j, a] = v + ph.dv[j, a]
        ph.W[j, a] = (1.0 - s) * x0w[j, 6 + a] + s * spin[j, a] + ph.dw[j, a]


@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _state_of(x0w, pos, vel, spin, j, s, dt, ph):
    """(x, v, ω) of neighbour j at s: from P/V/W when active, else its free-flight path."""
    if ph.active[j] != 0:
        return (ph.P[j, 0], ph.P[j, 1], ph.P[j, 2], ph.V[j, 0], ph.V[j, 1], ph.V[j, 2],
                ph.W[j, 0], ph.W[j, 1], ph.W[j, 2])
    x0, v0 = _hermite(x0w[j, 0], pos[j, 0], x0w[j, 3], vel[j, 0], s, dt)
    x1, v1 = _hermite(x0w[j, 1], pos[j, 1], x0w[j, 4], vel[j, 1], s, dt)
    x2, v2 = _hermite(x0w[j, 2], pos[j, 2], x0w[j, 5], vel[j, 2], s, dt)
    return (x0, x1, x2, v0, v1, v2,
            (1.0 - s) * x0w[j, 6] + s * spin[j, 0],
            (1.0 - s) * x0w[j, 7] + s * spin[j, 1],
            (1.0 - s) * x0w[j, 8] + s * spin[j, 2])


# ----------------------------------------------------------------------------- forces
# The per-grain kernels below allocate nothing and are compiled without reference
# counting (_nrt=False): a call passing the ~20 arrays of a ContactPhase otherwise costs
# ~40 atomic increments and decrements, more than the arithmetic (integrator.py).


@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _grain_force_inl(i, x0w, pos, vel, spin, model, box, per, nbr, nbr_count, shear, touch, collisions,
                 max_overlap, n_touch, s, dt, h, update, ph):
    """Contact force and torque on active grain i at sub-step position s (contacts.py's
    gran/hooke/history arithmetic, mirrored exactly so both grains of a pair compute
    negated vectors); h: the sub-step the tangential spring advances by. box, per: the
    contact grid's lengths and periodic flags; the other arrays are the ContactList's."""
    lx, ly, lz = box[0], box[1], box[2]
    px, py, pz = per[0], per[1], per[2]
    d = model.diameter
    d2 = d * d
    rad = 0.5 * d
    meff = 0.5 * model.mass
    kn, kt, mu = model.kn, model.kt, model.friction
    damp_n = meff * model.gamma_n
    damp_t = meff * model.gamma_t
    at_radius = model.lever == LEVER_RADIUS
    fx = 0.0
    fy = 0.0
    fz = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    touching = 0
    osum = 0.0
    xi, yi, zi = ph.P[i, 0], ph.P[i, 1], ph.P[i, 2]
    for k in range(nbr_count[i]):
        j = nbr[i, k]
        xj, yj, zj, vj0, vj1, vj2, wj0, wj1, wj2 = _state_of(x0w, pos, vel, spin, j, s, dt, ph)
        delx = min_image(xi - xj, lx, px)
        dely = min_image(yi - yj, ly, py)
        delz = min_image(zi - zj, lz, pz)
        rsq = delx * delx + dely * dely + delz * delz
        if rsq >= d2:
            if touch[i, k] != 0:
                touch[i, k] = 0
                shear[i, k, 0] = 0.0
                shear[i, k, 1] = 0.0
                shear[i, k, 2] = 0.0
            continue
        if ph.active[j] == 0:
            ph.wake[i] = 1
        touching += 1
        if touch[i, k] == 0:
            touch[i, k] = 1
            collisions[i] += 1
        if rsq == 0.0:
            continue
        r = math.sqrt(rsq)
        rinv = 1.0 / r
        rsqinv = 1.0 / rsq
        vr1 = ph.V[i, 0] - vj0
        vr2 = ph.V[i, 1] - vj1
        vr3 = ph.V[i, 2] - vj2
        vnnr = vr1 * delx + vr2 * dely + vr3 * delz
        vt1 = vr1 - delx * vnnr * rsqinv
        vt2 = vr2 - dely * vnnr * rsqinv
        vt3 = vr3 - delz * vnnr * rsqinv
        arm = rad if at_radius else 0.5 * r
        wr1 = arm * (ph.W[i, 0] + wj0) * rinv
        wr2 = arm * (ph.W[i, 1] + wj1) * rinv
        wr3 = arm * (ph.W[i, 2] + wj2) * rinv
        ccel = kn * (d - r) * rinv - damp_n * vnnr * rsqinv
        vtr1 = vt1 - (delz * wr2 - dely * wr3)
        vtr2 = vt2 - (delx * wr3 - delz * wr1)
        vtr3 = vt3 - (dely * wr1 - delx * wr2)
        sh = shear[i, k]
        if update:
            sh[0] += vtr1 * h
            sh[1] += vtr2 * h
            sh[2] += vtr3 * h
        shrmag = math.sqrt(sh[0] * sh[0] + sh[1] * sh[1] + sh[2] * sh[2])
        if update:
            rsht = (sh[0] * delx + sh[1] * dely + sh[2] * delz) * rsqinv
            sh[0] -= rsht * delx
            sh[1] -= rsht * dely
            sh[2] -= rsht * delz
        fs1 = -(kt * sh[0] + damp_t * vtr1)
        fs2 = -(kt * sh[1] + damp_t * vtr2)
        fs3 = -(kt * sh[2] + damp_t * vtr3)
        fs = math.sqrt(fs1 * fs1 + fs2 * fs2 + fs3 * fs3)
        fn = mu * abs(ccel * r)
        if fs > fn:
            if shrmag != 0.0:
                scale = fn / fs
                if kt > 0.0:
                    sh[0] = scale * (sh[0] + damp_t * vtr1 / kt) - damp_t * vtr1 / kt
                    sh[1] = scale * (sh[1] + damp_t * vtr2 / kt) - damp_t * vtr2 / kt
                    sh[2] = scale * (sh[2] + damp_t * vtr3 / kt) - damp_t * vtr3 / kt
                fs1 *= scale
                fs2 *= scale
                fs3 *= scale
            else:
                fs1 = 0.0
                fs2 = 0.0
                fs3 = 0.0
        fx += delx * ccel + fs1
        fy += dely * ccel + fs2
        fz += delz * ccel + fs3
        tor1 = rinv * (dely * fs3 - delz * fs2)
        tor2 = rinv * (delz * fs1 - delx * fs3)
        tor3 = rinv * (delx * fs2 - dely * fs1)
        tx -= arm * tor1
        ty -= arm * tor2
        tz -= arm * tor3
        osum += d - r
        if d - r > max_overlap[i]:
            max_overlap[i] = d - r
    ph.force[i, 0] = fx
    ph.force[i, 1] = fy
    ph.force[i, 2] = fz
    ph.torque[i, 0] = tx
    ph.torque[i, 1] = ty
    ph.torque[i, 2] = tz
    n_touch[i] = touching
    if touching > 0:
        ph.touched[i] = 1
        if update:
            ph.contact_substeps[i] += touching
            ph.overlap_sum[i] += osum


@njit(cache=True, error_model="numpy", _nrt=False)
def _set_path(x0w, pos, vel, spin, j, s, dt, ph):
    """_set_path_inl as a call (for parallel loops, which must not inline code that
    writes through a named tuple's arrays; integrator.py)."""
    _set_path_inl(x0w, pos, vel, spin, j, s, dt, ph)


@njit(cache=True, error_model="numpy", _nrt=False)
def _grain_force(i, x0w, pos, vel, spin, model, box, per, nbr, nbr_count, shear, touch, collisions,
                 max_overlap, n_touch, s, dt, h, update, ph):
    """_grain_force_inl as a call (see _set_path)."""
    _grain_force_inl(i, x0w, pos, vel, spin, model, box, per, nbr, nbr_count, shear, touch, collisions,
                     max_overlap, n_touch, s, dt, h, update, ph)

@njit(cache=True, inline="always", error_model="numpy", _nrt=False)
def _bed_force_inl(i, st, bc, ph, s, dt, h, update):
    """Soft contact of active grain i with the bed spheres it touches at sub-step s, added
    to ph.force[i] / ph.torque[i] (module docstring, "The bed in the contact phase").
    The spring–dashpot of the grain pairs with a fixed partner: m_eff = m, the bed's
    restitution (γ_n from it) and friction, the same k_n and k_t."""
    px = ph.P[i, 0]
    py = ph.P[i, 1]
    pz = ph.P[i, 2]
    used = 0
    for k in range(BED_SLOTS):
        if bc.slot_id[i, k] != FREE:
            used += 1
    if used == 0 and py >= 0.5:
        if update:
            bc.in_bed[i] = 0
        return
    packed = bc.params[0] != 0.0
    mu = bc.params[2]
    damp_n = bc.params[4]
    kn = bc.params[5]
    kt = bc.params[6]
    if update and py < 0.5:
        if packed:
            lx, lz = bc.box[0], bc.box[2]
            nx, nz = bc.ncell[0], bc.ncell[2]
            sx = px - lx * math.floor(px / lx)
            sz = pz - lz * math.floor(pz / lz)
            ix = min(int(sx / bc.size[0]), nx - 1)
            iz = min(int(sz / bc.size[2]), nz - 1)
            for a in range(-1, 2):
                for b in range(-1, 2):
                    c = ((ix + a) % nx) * nz + (iz + b) % nz
                    for q in range(bc.cell_start[c], bc.cell_start[c] + bc.cell_count[c]):
                        kb = bc.order[q]
                        ax = min_image(px - bc.centres[kb, 0], lx, 1)
                        ay = py - bc.centres[kb, 1]
                        az = min_image(pz - bc.centres[kb, 2], lz, 1)
                        if ax * ax + ay * ay + az * az >= 1.0:
                            continue
                        known = False
                        free = -1
                        for k in range(BED_SLOTS):
                            if bc.slot_id[i, k] == kb:
                                known = True
                            elif bc.slot_id[i, k] == FREE and free < 0:
                                free = k
                        if known or free < 0:
                            continue
                        bc.slot_id[i, free] = kb
                        bc.slot_c[i, free, 0] = px - ax
                        bc.slot_c[i, free, 1] = py - ay
                        bc.slot_c[i, free, 2] = pz - az
                        bc.slot_shear[i, free, 0] = 0.0
                        bc.slot_shear[i, free, 1] = 0.0
                        bc.slot_shear[i, free, 2] = 0.0
                        used += 1
        elif used == 0:
            # virtual bed: a bed grain of diameter d placed where the grain's bottom
            # crossed the bed top, its normal tilted at random (bed.virtual_bed_normal)
            nrm = ph.nrm[i]
            if ph.V[i, 1] < 0.0:
                xi1, xi2 = uniform2(bc.ints[0], i, st.impacts[i])
                virtual_bed_normal(ph.V[i], xi1, xi2, bc.params[3], nrm)
            else:
                nrm[0] = 0.0
                nrm[1] = 1.0
                nrm[2] = 0.0
            depth = 1.0 - (0.5 - py)
            bc.slot_id[i, 0] = VIRTUAL
            bc.slot_c[i, 0, 0] = px - depth * nrm[0]
            bc.slot_c[i, 0, 1] = py - depth * nrm[1]
            bc.slot_c[i, 0, 2] = pz - depth * nrm[2]
            bc.slot_shear[i, 0, 0] = 0.0
            bc.slot_shear[i, 0, 1] = 0.0
            bc.slot_shear[i, 0, 2] = 0.0
            used = 1
    if used == 0:
        if update:
            bc.in_bed[i] = 0
        return
    fx = 0.0
    fy = 0.0
    fz = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    nb = 0
    for k in range(BED_SLOTS):
        if bc.slot_id[i, k] == FREE:
            continue
        delx = px - bc.slot_c[i, k, 0]
        dely = py - bc.slot_c[i, k, 1]
        delz = pz - bc.slot_c[i, k, 2]
        rsq = delx * delx + dely * dely + delz * delz
        if rsq >= 1.0:
            bc.slot_id[i, k] = FREE
            continue
        nb += 1
        if rsq == 0.0:
            continue
        r = math.sqrt(rsq)
        rinv = 1.0 / r
        rsqinv = 1.0 / rsq
        vr1 = ph.V[i, 0]
        vr2 = ph.V[i, 1]
        vr3 = ph.V[i, 2]
        vnnr = vr1 * delx + vr2 * dely + vr3 * delz
        vt1 = vr1 - delx * vnnr * rsqinv
        vt2 = vr2 - dely * vnnr * rsqinv
        vt3 = vr3 - delz * vnnr * rsqinv
        arm = 0.5 * r  # contact point midway between equal spheres
        wr1 = arm * ph.W[i, 0] * rinv
        wr2 = arm * ph.W[i, 1] * rinv
        wr3 = arm * ph.W[i, 2] * rinv
        ccel = kn * (1.0 - r) * rinv - damp_n * vnnr * rsqinv
        vtr1 = vt1 - (delz * wr2 - dely * wr3)
        vtr2 = vt2 - (delx * wr3 - delz * wr1)
        vtr3 = vt3 - (dely * wr1 - delx * wr2)
        sh = bc.slot_shear[i, k]
        if update:
            sh[0] += vtr1 * h
            sh[1] += vtr2 * h
            sh[2] += vtr3 * h
            rsht = (sh[0] * delx + sh[1] * dely + sh[2] * delz) * rsqinv
            sh[0] -= rsht * delx
            sh[1] -= rsht * dely
            sh[2] -= rsht * delz
        fs1 = -kt * sh[0]
        fs2 = -kt * sh[1]
        fs3 = -kt * sh[2]
        fs = math.sqrt(fs1 * fs1 + fs2 * fs2 + fs3 * fs3)
        fn = mu * abs(ccel * r)
        if fs > fn:
            scale = fn / fs
            sh[0] *= scale
            sh[1] *= scale
            sh[2] *= scale
            fs1 *= scale
            fs2 *= scale
            fs3 *= scale
        fx += delx * ccel + fs1
        fy += dely * ccel + fs2
        fz += delz * ccel + fs3
        tx -= arm * rinv * (dely * fs3 - delz * fs2)
        ty -= arm * rinv * (delz * fs1 - delx * fs3)
        tz -= arm * rinv * (delx * fs2 - dely * fs1)
        if 1.0 - r > ph.bed_overlap_max[i]:
            ph.bed_overlap_max[i] = 1.0 - r
    ph.force[i, 0] += fx
    ph.force[i, 1] += fy
    ph.force[i, 2] += fz
    ph.torque[i, 0] += tx
    ph.torque[i, 1] += ty
    ph.torque[i, 2] += tz
    if nb > 0:
        ph.touched[i] = 1
    if update:
        step = bc.ints[1]
        t_now = bc.t0[0] + s * dt
        if nb > 0:
            if bc.in_bed[i] == 0:
                # a bed contact begins: an impact; it ends a jump if the grain was airborne
                st.impacts[i] += 1
                if bc.last_contact[i] < step - 1:
                    j = st.jump_buf_n[i]
                    if j < st.jump_buf.shape[1]:
                        st.jump_buf[i, j, 0] = st.jump_t0[i]
                        st.jump_buf[i, j, 1] = px - st.jump_x0[i]
                        st.jump_buf[i, j, 2] = st.jump_ymax[i] - 0.5
                        st.jump_buf[i, j, 3] = t_now - st.jump_t0[i]
                        st.jump_buf_n[i] = j + 1
                    st.jump_count[i] += 1
            # in contact: the next jump starts when it ends
            st.jump_t0[i] = t_now
            st.jump_x0[i] = px
            st.jump_ymax[i] = py
            bc.last_contact[i] = step
        bc.in_bed[i] = 1 if nb > 0 else 0


@njit(cache=True, error_model="numpy", _nrt=False)
def _bed_force(i, st, bc, ph, s, dt, h, update):
    """_bed_force_inl as a call (see _set_path)."""
    _bed_force_inl(i, st, bc, ph, s, dt, h, update)


@njit(cache=True, parallel=True)
def _forces(x0w, st, bc, model, cl, s, dt, h, update, ph, first, last):
    pos, vel, spin = st.pos, st.vel, st.spin
    box, per = cl.grid.box, cl.grid.periodic
    nbr, nbr_count, shear, touch = cl.nbr, cl.nbr_count, cl.shear, cl.touch
    collisions, max_overlap, n_touch = cl.collisions, cl.max_overlap, cl.n_touch
    act = ph.act
    for q in prange(first, last):
        i = act[q]
        _grain_force(i, x0w, pos, vel, spin, model, box, per, nbr, nbr_count, shear, touch, collisions,
                     max_overlap, n_touch, s, dt, h, update, ph)
        _bed_force(i, st, bc, ph, s, dt, h, update)


@njit(cache=True, error_model="numpy", _nrt=False)
def _wake_up(x0w, st, bc, model, cl, s, dt, h, update, ph, first):
    """Activate every non-active grain touched by an active one (their deviation is
    exactly zero until now) and give them their forces at this sub-step; repeat for the
    grains those touch. ``first``: active-list entries before it were evaluated."""
    pos, vel, spin = st.pos, st.vel, st.spin
    g = cl.grid
    d2 = model.diameter * model.diameter
    lo = first
    hi = ph.n_act[0]
    scan_from = 0
    while True:
        added = 0
        start = ph.n_act[0]
        for q in range(scan_from, hi):
            i = ph.act[q]
            if ph.wake[i] == 0:
                continue
            ph.wake[i] = 0
            for k in range(cl.nbr_count[i]):
                j = cl.nbr[i, k]
                if ph.active[j] != 0:
                    continue
                xj, yj, zj, _, _, _, _, _, _ = _state_of(x0w, pos, vel, spin, j, s, dt, ph)
                dxx = min_image(ph.P[i, 0] - xj, g.box[0], g.periodic[0])
                dyy = min_image(ph.P[i, 1] - yj, g.box[1], g.periodic[1])
                dzz = min_image(ph.P[i, 2] - zj, g.box[2], g.periodic[2])
                if dxx * dxx + dyy * dyy + dzz * dzz < d2:
                    for a in range(3):
                        ph.dx[j, a] = 0.0
                        ph.dv[j, a] = 0.0
                        ph.dw[j, a] = 0.0
                        ph.force[j, a] = 0.0
                        ph.torque[j, a] = 0.0
                    _set_path(x0w, pos, vel, spin, j, s, dt, ph)
                    ph.active[j] = 1
                    ph.dev_max[j] = 0.0
                    ph.act[ph.n_act[0]] = j
                    ph.n_act[0] += 1
                    added += 1
        if added == 0:
            break
        ph.counters[2] += added
        for q in range(start, ph.n_act[0]):
            _grain_force(ph.act[q], x0w, pos, vel, spin, model, g.box, g.periodic, cl.nbr, cl.nbr_count, cl.shear,
                         cl.touch, cl.collisions, cl.max_overlap, cl.n_touch, s, dt, h, update, ph)
            _bed_force(ph.act[q], st, bc, ph, s, dt, h, update)
        scan_from = start
        hi = ph.n_act[0]
    return lo


@njit(cache=True, parallel=True)
def _reach(x0w, pos, vel, dt, cl, ph):
    """D (reach of the free-flight path from x₀) per grain; returns the largest
    displacement bound from the list's reference positions."""
    n = pos.shape[0]
    box, per, ref = cl.grid.box, cl.grid.periodic, cl.ref_pos
    # arrays unpacked before the parallel loop: Numba 0.68 drops writes made in a prange
    # body through a named tuple's arrays (integrator.py)
    active, touched, wake, reach, worst = ph.active, ph.touched, ph.wake, ph.reach, ph.ref_bound
    for i in prange(n):
        active[i] = 0
        touched[i] = 0
        wake[i] = 0
        ch = 0.0
        b0 = 0.0
        b1 = 0.0
        r0 = 0.0
        r1 = 0.0
        for a in range(3):
            step = pos[i, a] - x0w[i, a]
            vbar = step / dt
            ch += step * step
            b0 += (x0w[i, 3 + a] - vbar) ** 2
            b1 += (vel[i, a] - vbar) ** 2
            e0 = min_image(x0w[i, a] - ref[i, a], box[a], per[a])
            e1 = min_image(pos[i, a] - ref[i, a], box[a], per[a])
            r0 += e0 * e0
            r1 += e1 * e1
        bulge = 0.25 * dt * (math.sqrt(b0) + math.sqrt(b1))
        reach[i] = math.sqrt(ch) + bulge
        worst[i] = math.sqrt(max(r0, r1)) + bulge
    return worst.max() if n > 0 else 0.0  # noqa: the reduction reads the filled array


@njit(cache=True)
def _engage(x0w, pos, model, cl, ph, bc):
    """active[i] = 1 when i can touch a list neighbour on the undeflected paths, or is in
    contact with a grain or the bed now. A grain that ends the step below the bed top will
    be moved by its (hard) bed rebound by up to twice its reach: that margin is added."""
    _margins(x0w, pos, ph.reach, ph.margin)
    _engage_kernel(x0w, pos, cl.grid.box, cl.grid.periodic, cl.nbr, cl.nbr_count, cl.n_touch, bc.in_bed,
                   bc.slot_id, ph.margin, ph.reach, model.diameter, ph.active, ph.start)


@njit(cache=True, parallel=True)
def _engage_kernel(x0w, pos, box, per, nbr, nbr_count, n_touch, in_bed, slot_id, margin, reach, d, active, start):
    """start[i]: the earliest step fraction s at which grain i can touch a grain or the
    bed on the undeflected paths (inf: not in this step); active[i] = 0 (none started).
    For a pair, |r(s)| ≥ |r₀| − s|Δx_i − Δx_j| − (b_i + b_j) with Δx the step's chord and
    b the bulge of the cubic off it (b = reach − |Δx|), so no contact before
    s = (|r₀| − d − b_i − b_j − bed margins)/|Δx_i − Δx_j|."""
    # every array an argument: Numba 0.68 dropped this loop's writes when they went to an
    # array taken from a named tuple inside the function
    lx, ly, lz = box[0], box[1], box[2]
    px, py, pz = per[0], per[1], per[2]
    for i in prange(x0w.shape[0]):
        active[i] = 0
        first = np.inf
        if n_touch[i] > 0 or in_bed[i] != 0:
            first = 0.0
        for slot in range(slot_id.shape[1]):
            if slot_id[i, slot] != FREE:
                first = 0.0
        cxi = pos[i, 0] - x0w[i, 0]
        cyi = pos[i, 1] - x0w[i, 1]
        czi = pos[i, 2] - x0w[i, 2]
        bi = reach[i] - math.sqrt(cxi * cxi + cyi * cyi + czi * czi)
        # when the bottom may reach the bed top (a grain that is sub-stepped has its bed
        # contact in the sub-steps, so it must join before that)
        bed_first = np.inf
        if min(x0w[i, 1], pos[i, 1]) - bi < 0.5:
            if pos[i, 1] < x0w[i, 1]:
                bed_first = min(1.0, max(0.0, (x0w[i, 1] - bi - 0.5) / (x0w[i, 1] - pos[i, 1])))
            else:
                bed_first = 0.0
        k = 0
        m = nbr_count[i]
        while first > 0.0 and k < m:
            j = nbr[i, k]
            k += 1
            dxx = min_image(x0w[i, 0] - x0w[j, 0], lx, px)
            dyy = min_image(x0w[i, 1] - x0w[j, 1], ly, py)
            dzz = min_image(x0w[i, 2] - x0w[j, 2], lz, pz)
            lim = d + margin[i] + margin[j]
            r2 = dxx * dxx + dyy * dyy + dzz * dzz
            if r2 >= lim * lim:
                continue
            cxj = pos[j, 0] - x0w[j, 0]
            cyj = pos[j, 1] - x0w[j, 1]
            czj = pos[j, 2] - x0w[j, 2]
            bj = reach[j] - math.sqrt(cxj * cxj + cyj * cyj + czj * czj)
            rel = math.sqrt((cxi - cxj) ** 2 + (cyi - cyj) ** 2 + (czi - czj) ** 2)
            gap = math.sqrt(r2) - d - bi - bj - (margin[i] - reach[i]) - (margin[j] - reach[j])
            if gap <= 0.0:
                first = 0.0
            elif rel > 0.0:
                first = min(first, gap / rel)
        if first > 1.0:
            start[i] = np.inf  # touches no grain in this step: free flight and the hard bed
        else:
            start[i] = min(first, bed_first)


@njit(cache=True, parallel=True)
def _margins(x0w, pos, reach, margin):
    # the hard bed pass moves a grain only when it ends the step with its bottom below the
    # bed top (y < 1/2), by at most twice its reach (integrator._bed_impact)
    for i in prange(x0w.shape[0]):
        margin[i] = reach[i] + (2.0 * reach[i] if pos[i, 1] < 0.5 else 0.0)


@njit(cache=True, error_model="numpy", _nrt=False)
def _substep_serial(x0w, st, bc, model, cl, ph, s_next, dt, h):
    """One sub-step (kick, drift, forces, wake-ups, kick) without parallel loops: for a
    few active grains a parallel launch costs more than the work."""
    pos, vel, spin = st.pos, st.vel, st.spin
    m = ph.n_act[0]
    inv_m = 1.0 / model.mass
    inv_i = 1.0 / model.inertia
    for q in range(m):
        i = ph.act[q]
        for a in range(3):
            ph.dv[i, a] += 0.5 * h * ph.force[i, a] * inv_m
            ph.dw[i, a] += 0.5 * h * ph.torque[i, a] * inv_i
            ph.dx[i, a] += h * ph.dv[i, a]
        dd = ph.dx[i, 0] ** 2 + ph.dx[i, 1] ** 2 + ph.dx[i, 2] ** 2
        if dd > ph.dev_max[i]:
            ph.dev_max[i] = dd
        _set_path_inl(x0w, pos, vel, spin, i, s_next, dt, ph)
    g = cl.grid
    for q in range(m):
        i = ph.act[q]
        _grain_force_inl(i, x0w, pos, vel, spin, model, g.box, g.periodic, cl.nbr, cl.nbr_count, cl.shear,
                         cl.touch, cl.collisions, cl.max_overlap, cl.n_touch, s_next, dt, h, True, ph)
        _bed_force_inl(i, st, bc, ph, s_next, dt, h, True)
    _wake_up(x0w, st, bc, model, cl, s_next, dt, h, True, ph, 0)
    for q in range(ph.n_act[0]):
        i = ph.act[q]
        for a in range(3):
            ph.dv[i, a] += 0.5 * h * ph.force[i, a] * inv_m
            ph.dw[i, a] += 0.5 * h * ph.torque[i, a] * inv_i


PARALLEL_FROM = 1 << 62  # active grains from which sub-steps run in parallel: never (below)


@njit(cache=True, parallel=True)
def _kick_drift(x0w, pos, vel, spin, model, ph, s_next, dt, h, first, last):
    inv_m = 1.0 / model.mass
    inv_i = 1.0 / model.inertia
    act, dv, dw, dx, force, torque, dev_max = ph.act, ph.dv, ph.dw, ph.dx, ph.force, ph.torque, ph.dev_max
    for q in prange(first, last):
        i = act[q]
        for a in range(3):
            dv[i, a] += 0.5 * h * force[i, a] * inv_m
            dw[i, a] += 0.5 * h * torque[i, a] * inv_i
            dx[i, a] += h * dv[i, a]
        m = dx[i, 0] ** 2 + dx[i, 1] ** 2 + dx[i, 2] ** 2
        if m > dev_max[i]:
            dev_max[i] = m
        _set_path(x0w, pos, vel, spin, i, s_next, dt, ph)


@njit(cache=True, parallel=True)
def _kick(model, ph, h, first, last):
    inv_m = 1.0 / model.mass
    inv_i = 1.0 / model.inertia
    act, dv, dw, force, torque = ph.act, ph.dv, ph.dw, ph.force, ph.torque
    for q in prange(first, last):
        i = act[q]
        for a in range(3):
            dv[i, a] += 0.5 * h * force[i, a] * inv_m
            dw[i, a] += 0.5 * h * torque[i, a] * inv_i


@njit(cache=True, parallel=True)
def _apply(st, x0w, cl, ph, skin_half):
    """End of the phase: deviations into the state of grains that had a contact; fluid
    re-sampled and Basset history restarted for them (module docstring). Returns the
    active grains whose path may have left the list's reach (overruns)."""
    over = np.zeros(ph.n_act[0], np.int64)
    act, bound, dev_max, touched, dx, dv, dw = ph.act, ph.ref_bound, ph.dev_max, ph.touched, ph.dx, ph.dv, ph.dw
    pos, vel, spin, fresh, meta, ymax = st.pos, st.vel, st.spin, st.fresh, st.hist_meta, st.jump_ymax
    for q in prange(ph.n_act[0]):
        i = act[q]
        if bound[i] + math.sqrt(dev_max[i]) > skin_half:
            over[q] = 1
        if touched[i] == 0:
            continue
        for a in range(3):
            pos[i, a] += dx[i, a]
            vel[i, a] += dv[i, a]
            spin[i, a] += dw[i, a]
        fresh[i] = 0
        meta[i, META_COUNT] = 0
        if pos[i, 1] > ymax[i]:  # the bed pass skips the grains sub-stepped here
            ymax[i] = pos[i, 1]
    return over.sum()


@njit(cache=True, error_model="numpy", _nrt=False)
def _start_grains(x0w, pos, vel, spin, ph, cand, ptr, before, s_now, dt):
    """Append the candidates cand[ptr:] with start < ``before`` (start ≤ 0 when
    ``before`` is 0) to the active list at step fraction s_now: zero deviation and force,
    on their free-flight path. Returns the new pointer."""
    while ptr < cand.shape[0]:
        i = cand[ptr]
        t = ph.start[i]
        if not (t < before or (before == 0.0 and t <= 0.0)):
            break
        ptr += 1
        if ph.active[i] != 0:  # woken earlier
            continue
        for a in range(3):
            ph.dx[i, a] = 0.0
            ph.dv[i, a] = 0.0
            ph.dw[i, a] = 0.0
            ph.force[i, a] = 0.0
            ph.torque[i, a] = 0.0
        ph.dev_max[i] = 0.0
        _set_path_inl(x0w, pos, vel, spin, i, s_now, dt, ph)
        ph.active[i] = 1
        ph.act[ph.n_act[0]] = i
        ph.n_act[0] += 1
    return ptr


@njit(cache=True)
def _with_skin(cl, skin):
    """The ContactList with a larger skin (cells unchanged: they must be wide enough)."""
    return ContactList(cl.grid, 1.0 + skin, skin, cl.cell_of, cl.cell_start,
                       cl.cell_count, cl.order, cl.ref_pos, cl.nbr, cl.nbr_count, cl.shear, cl.touch, cl.nbr2,
                       cl.nbr_count2, cl.shear2, cl.touch2, cl.n_touch, cl.collisions, cl.max_overlap, cl.builds)


@njit(cache=True)
def soft_contact_phase(st, x0w, model, cl, ph, bc, t0, step, dt, n_sub):
    """Phase 2 of the module docstring for all grains: the free flight (x₀ in ``x0w``
    (N, 9) = w.x0, x₁ in ``st``) of step ``step`` (from t0) corrected by soft contacts
    with grains and the bed in ``n_sub`` sub-steps. ``ph.active`` says afterwards which
    grains were sub-stepped (their bed is done; the bed pass must skip them). Returns the
    ContactList to keep (it may have been rebuilt)."""
    pos, vel, spin = st.pos, st.vel, st.spin
    bc.t0[0] = t0
    bc.ints[1] = step
    n = pos.shape[0]
    skin_half = 0.5 * cl.skin
    worst = _reach(x0w, pos, vel, dt, cl, ph)
    if worst > skin_half:
        for i in range(n):
            for a in range(3):
                ph.x0pos[i, a] = x0w[i, a]
        cl = rebuild(ph.x0pos, cl)
        ph.counters[0] += 1
        fastest = 0.0
        for i in range(n):
            ph.ref_bound[i] = ph.reach[i]  # the list is now built at x₀
            fastest = max(fastest, ph.reach[i])
        if fastest > skin_half:
            # a grain faster than the skin allows: grow the skin as far as the cells allow
            widest = min(cl.grid.size[0], min(cl.grid.size[1], cl.grid.size[2])) - model.diameter
            skin = min(2.5 * fastest, widest)
            if skin > cl.skin:
                cl = _with_skin(cl, skin)
                cl = rebuild(ph.x0pos, cl)
                skin_half = 0.5 * cl.skin
            for i in range(n):
                if ph.reach[i] > skin_half:  # still too fast: a contact might be missed
                    ph.counters[1] += 1
    _engage(x0w, pos, model, cl, ph, bc)
    # candidates, by the time they may first touch something (docstring: who is sub-stepped)
    n_cand = 0
    for i in range(n):
        if ph.start[i] <= 1.0:
            n_cand += 1
    ph.n_act[0] = 0
    if n_cand == 0:
        return cl
    cand = np.empty(n_cand, np.int64)
    key = np.empty(n_cand)
    m = 0
    for i in range(n):
        if ph.start[i] <= 1.0:
            cand[m] = i
            key[m] = ph.start[i]
            m += 1
    cand = cand[np.argsort(key, kind="mergesort")]
    h = dt / n_sub
    # set-up: forces at s = 0 of the grains in contact now, without advancing the
    # tangential springs (their state is that of the previous step's last sub-step)
    ptr = _start_grains(x0w, pos, vel, spin, ph, cand, 0, 0.0, 0.0, dt)
    _forces(x0w, st, bc, model, cl, 0.0, dt, h, False, ph, 0, ph.n_act[0])
    _wake_up(x0w, st, bc, model, cl, 0.0, dt, h, False, ph, 0)
    for k in range(n_sub):
        s_next = (k + 1) / n_sub
        # grains that may touch something before s_next join now (no force at s_k: they
        # cannot be touching anything yet)
        ptr = _start_grains(x0w, pos, vel, spin, ph, cand, ptr, s_next, k / n_sub, dt)
        m = ph.n_act[0]
        ph.counters[3] += m
        if m < PARALLEL_FROM:
            _substep_serial(x0w, st, bc, model, cl, ph, s_next, dt, h)
            continue
        _kick_drift(x0w, pos, vel, spin, model, ph, s_next, dt, h, 0, m)
        _forces(x0w, st, bc, model, cl, s_next, dt, h, True, ph, 0, m)
        _wake_up(x0w, st, bc, model, cl, s_next, dt, h, True, ph, 0)
        _kick(model, ph, h, 0, ph.n_act[0])
    over = _apply(st, x0w, cl, ph, skin_half)
    if over > 0:
        # a grain may have left the list's reach: look for pairs in contact now that the
        # list does not hold (an actual miss), with fresh cells
        ph.counters[1] += over
        ph.counters[4] += _missed_contacts(st.pos, cl)
    return cl


@njit(cache=True)
def _missed_contacts(pos, cl):
    """Pairs closer than d at ``pos`` that are not in each other's neighbour list."""
    g = cl.grid
    n = pos.shape[0]
    cell_of = np.empty(n, np.int64)
    start = np.empty(cl.cell_start.shape[0], np.int64)
    count = np.empty(cl.cell_count.shape[0], np.int64)
    order = np.empty(n, np.int64)
    build_cells(pos, g, cell_of, start, count, order)
    cells = np.empty(27, np.int64)
    missed = 0
    for i in range(n):
        m = stencil_cells(g, cell_of[i], cells)
        for c in range(m):
            for q in range(start[cells[c]], start[cells[c]] + count[cells[c]]):
                j = order[q]
                if j <= i:
                    continue
                dx = min_image(pos[i, 0] - pos[j, 0], g.box[0], g.periodic[0])
                dy = min_image(pos[i, 1] - pos[j, 1], g.box[1], g.periodic[1])
                dz = min_image(pos[i, 2] - pos[j, 2], g.box[2], g.periodic[2])
                if dx * dx + dy * dy + dz * dz >= 1.0:
                    continue
                listed = False
                for k in range(cl.nbr_count[i]):
                    if cl.nbr[i, k] == j:
                        listed = True
                if not listed:
                    missed += 1
    return missed


@njit(cache=True)
def hard_contact_phase(st, cl, restitution, friction, before):
    """Binary hard-sphere impulses at the end-of-flight positions (contacts.py); grains
    that collided restart their Basset history (their position is unchanged, so the
    fluid sample stays valid). ``before`` (N,) int64 scratch. Returns the collisions."""
    n = st.pos.shape[0]
    for i in range(n):
        before[i] = cl.collisions[i]
    count = hard_sphere_collisions(st.pos, st.vel, st.spin, cl, restitution, friction, 1.0)
    if count > 0:
        for i in range(n):
            if cl.collisions[i] != before[i]:
                st.hist_meta[i, META_COUNT] = 0
    return count
