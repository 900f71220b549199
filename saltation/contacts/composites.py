"""Grain–grain contacts between bonded-sphere grains (SPEC §5 on composites; issue 6
item 2): soft contacts between the component spheres of *different* grains, summed into
each grain's force and torque, sub-stepped inside the hydrodynamic step.

Units: those of flight/composites.py (length Dn, velocity u*, time Dn/u*, mass ρ Dn³ with ρ the
fluid density, force ρ u*² Dn², torque ρ u*² Dn³). The rigid mass of grain i is
m_i = (1+R) V_i (``ClusterState.mass``), its rigid inertia I_i (body frame).

Contact law (per pair of component spheres a ∈ grain i, b ∈ grain j ≠ i)
-----------------------------------------------------------------------
Centres x_a, x_b (minimum image in x and z), r = |x_a − x_b|, n = (x_a − x_b)/r,
overlap δ = (d_a + d_b)/2 − r > 0. Contact point: the middle of the overlap,
x_c = x_a − (d_a/2 − δ/2) n (= x_b + (d_b/2 − δ/2) n); for two unit spheres this is the
midpoint of contacts/pairs.py's LEVER_CONTACT_POINT. The same point serves both grains, so the
force pair has no net moment and the total angular momentum (orbital + spin) is
conserved to round-off.

- contact-point velocities u_i = v_i + Ω_i × (x_c − x_i), u_j likewise; v_r = u_i − u_j,
  v_n = v_r·n, v_t = v_r − v_n n;
- normal force on i (linear spring–dashpot, Cundall & Strack 1979, no clamping as in
  contacts/pairs.py): F_n = (k_n δ − c_n v_n) n with c_n = 2 √(m_eff k_n) |ln e| / √(ln² e + π²),
  m_eff = m_i m_j / (m_i + m_j) the grains' reduced rigid mass (contacts.pairs.normal_damping
  written for a pair of unequal grains). A central impact then rebounds with exactly the
  case's e; an off-centre one feels a smaller point-effective mass (rotation) and
  rebounds a little more elastically — the usual choice for clumped-sphere DEM;
- tangential spring (history per component pair, as contacts/pairs.py / LAMMPS
  gran/hooke/history): ξ ← ξ + v_t h, ξ ← ξ − (ξ·n) n, F_t = −k_t ξ; Coulomb limit
  |F_t| ≤ f |F_n| (F_t scaled to it and ξ = −F_t/k_t). Normal and tangential force are
  the one law every soft contact uses (physics/contact_law.spring_dashpot), with c_t = 0;
- on grain i: F += F_n + F_t, T += (x_c − x_i) × (F_n + F_t); on j the negatives.

k_n, k_t, e and f are the case's [collisions] values, the same as the sphere runs
(contacts.pairs.contact_model_from_case): k_n(ρ u*² units) = k_n(sphere units) · (1+R) π/6,
because the sphere code's mass unit is the grain mass ρp (π/6) d³ = (1+R)(π/6) ρ d³. A
one-sphere composite of d = Dn is therefore the sphere contact exactly.

Sub-steps: n_sub = ⌈steps_per_contact · Δt / t_c,min⌉ with t_c,min = π √(μ_min / k_n)
the shortest (undamped) contact of the run: μ_min is half the smallest point-effective
mass 1/(1/m + (c×n)·I⁻¹(c×n)) over the grains, their component surface points c and
directions n (200 directions; ``substeps``). That is the worst case — a tip of the
lightest rod hit sideways — so typical contacts get more sub-steps than asked for.

Scheme inside the hydrodynamic step (operator split after the free flight, as contacts/phase.py)
-----------------------------------------------------------------------------------------
1. Free flight (flight.composites.step_grain, RK4 + the virtual bed) takes every grain from its
   start state (x₀, v₀, q₀, Ω₀) (``ClusterWork.x0``) to (x₁, v₁, q₁, Ω₁).
2. **Engagement**: with D_i = |x₁ − x₀| + Δt(|v₀ − ū| + |v₁ − ū|)/4 a bound on how far the
   centre's free path (cubic Hermite, below) gets from x₀, and ρ_i the grain's bounding
   radius (max |r_k| + d_k/2), grains i and j can touch in the step only if
   |x₀ᵢ − x₀ⱼ| < ρ_i + ρ_j + D_i + D_j + s (s: the skin, a margin for contact-deflected
   paths). Found through a cell list of the grains; those grains are *active*.
3. The active grains are moved again through the step in n_sub sub-steps h = Δt/n_sub
   as **deviations from their free-flight path**: centre x = H(σ) + δx, velocity
   H'(σ)/Δt + δv (H the Hermite cubic through (x₀, v₀), (x₁, v₁), σ = t/Δt), orientation
   Q = q_f(σ) ⊗ δq (q_f the slerp from q₀ to q₁, δq a body-frame rotation), angular
   velocity Ω_f(σ) + δΩ (Ω_f linear from Ω₀ to Ω₁), with δΩ = I_w(Q)⁻¹ δL and
   dδv/dt = F_c/m, dδL/dt = T_c, dδq/dt = ½ (R_fᵀ δΩ) ⊗ δq (exact kinematics for the
   composition Q = q_f ⊗ δq), dδx/dt = δv. Velocity Verlet in LAMMPS order (half kick,
   drift, contact forces at the half-kicked velocities, half kick), a set-up force
   evaluation at σ = 0 that does not advance ξ. The fluid force and torque act as in
   free flight (held over the step); the contact acts on the rigid mass and rigid
   inertia (no added mass: as the bed rebound, flight/composites.py, and the sphere contacts).
   Integrating δL (world frame) rather than δΩ makes the kicks conserve total angular
   momentum exactly; the gyroscopic change of the free rotation is in the RK4 path.
   Component candidates come from a neighbour list of the active grains' component
   spheres, built at σ = 0 through a cell list (cells ≥ d_max + 2 m_max + s, periodic in
   x and z, clamped in y like contacts/cells.py) with the pair cutoff (d_a + d_b)/2 + m_a + m_b + s,
   m_a = D_i + |r_a| φ_i the reach of component a (φ_i the slerp angle). A grain whose
   deviation (|δx| + ρ_i ∫|δΩ| dt) exceeds s/2 is counted in ``overruns`` and the list is
   rebuilt at the current sub-step (history carried over by partner id).
4. A grain that touched another one gets (x₁ + δx, v₁ + δv, q₁ ⊗ δq, Ω₁ + I_w⁻¹ δL), plus
   the fluid's response to the change ("Fluid response"), its fluid re-sampled and its
   Basset history restarted (as contacts/phase.py and a bed impact: a contact is an
   impulsive velocity change). The others keep the RK4 result bit for bit.

Accuracy: within a contact the scheme is velocity Verlet (second order in h); the split
with the free flight adds a first-order error in Δt where the free path turns the
grain — its orientation is the slerp between the RK4 end orientations while its
angular velocity is taken linear in time. Measured on an elastic (e = 1), frictionless
off-centre collision of a spinning rod and blade: kinetic energy after/before − 1 =
1e-4 to 1e-3 at Δt = 0.0025–0.01 d/u*, either sign, and not reduced by more sub-steps
(it is 0 to round-off for grains that do not spin; angular and linear momentum are
conserved to round-off whatever the spin).

Fluid response
--------------
The sub-steps hold the fluid force of the free path: after a contact the grain flies on to
the step's end with the fluid force of its old velocity and spin, where that of the new
ones would have acted — an error first order in Δt (contacts/fluid_response.py for
spheres: a grain leaving the bed keeps the drag of its descent). A grain that touched
something (a grain or the bed) gets, after the phase, M⁻¹ (W(new) − W(free)) τ added to its
velocity and angular velocity: W the fluid's force and torque (flight.composites._rhs: drag,
lift, Magnus, spin drag, added mass, with the fluid sampled at the free path's end and the
history held) at its new and at its free-flight end velocity and spin, both at the free
path's end pose (the secant of the force law), M the generalized mass with added mass (no
gyroscopic terms: the free rotation from the new spin is not the fluid's), and τ = (δx · δv)/|δv|²
clamped to [0, Δt] the time since the contact (exact for one impulsive contact, where
δx = δv τ). Its position would move by ½ Δa τ², left alone so that no grain is pushed into
a neighbour. The Basset history restarts as before (its slip step dated at the step's
end, not at the contact as for spheres).

Cost
----
The sub-step passes go over the active grains in ranges: one call of a kernel compiled
without reference counting (``_nrt=False``) per range, the per-grain kernels (pose, kick
and drift, forces) inlined into it (_move_grains, _force_kick_grains); on one thread the
whole sub-step loop is one call (_substep_range) that returns only when a grain overruns
the list's skin; on more, each pass is cut into one range per thread. Called once per
grain and sub-step, a per-grain kernel was passed the three tuples (~60 arrays, some
500 words pushed on the stack) and, from a reference-counted caller, an atomic increment
and decrement of every array: 80–90 % of the phase. The natural mixture at 2.07 % in a
0.024 × 0.012 m box (693 grains, 0.1 s, one thread): contact phase 89.95 s → 4.03 s, the
same bits (benchmarks/bench_mixture_contacts.py compares it with spheres in the same
box). The margin s of the engagement test and the list (``default_skin``) is the
farthest a contact can deflect a grain within one step, 2 v_impact Δt (0.4 Dn at the
defaults): the list is built afresh every step, so it need not cover a step's travel,
as the sphere list must. Still, every engaged grain is sub-stepped through the whole step
with n_sub set by the lightest point-effective mass (421 sub-steps per 0.02 step against
128 for spheres): at 2.07 % the phase is ~27× the spheres' per grain-step (the whole step
~20×); the sphere phase's joining late and retiring (contacts/phase.py) are not done here.

The packed bed (bed.model = "packed", ``with_packed_bed``)
----------------------------------------------------------
A grain that is sub-stepped has its bed contacts inside the sub-steps, as for spheres
(contacts/phase.py, "The bed in the contact phase"): the bed spheres (diameter 1, fixed)
are partners in its components' neighbour rows (ids −1 − j, found through the bed's
cells, same cutoff and skin, their tangential springs carried over by id like any
other), with the one contact law and a fixed partner: m_eff = m_i (the rigid mass), the
dashpot from the **bed** restitution, the bed friction, the same k_n and k_t; the
contact point is again the middle of the overlap. A grain resting or rolling on the bed
(a bed contact in the last step, or touching it at the last evaluation) whose path's
lowest point can reach the bed top (``_path_bottom``) is made active, so it keeps its
soft bed contacts from step to step instead of the hard rebound and push-out of
bed/packed_composites.py, which would make it bounce in its hollow every step. That
pass skips every active grain. Jumps as there: the first bed contact after at least
one step off the bed is a bed impact and ends a jump; while the contact lasts, the next
jump's start moves with the grain.

The virtual bed (bed.model = "virtual", ``with_virtual_bed``)
--------------------------------------------------------------
With contacts the free flight leaves the virtual bed alone (bed[BED_MODEL] =
flight.composites.BED_VIRTUAL_AFTER), as the sphere engine does (contacts/phase.py, "The
bed in the contact phase"). A grain that is sub-stepped has its bed contacts inside the
sub-steps: when a component's bottom first goes below the bed top, a virtual bed sphere of
diameter 1 is placed under it along a normal drawn as the hard virtual bed draws it
(bed.virtual.virtual_bed_normal from the component centre's velocity, its own
counter-based draw; vertical if the component does not descend), touching the component
with its depth below the bed top as overlap, and kept until that contact ends; the contact
law and the jump bookkeeping are the packed bed's. Every grain whose free path can reach
the bed top is sub-stepped (``ClusterContacts.below``), whether or not it can reach another
grain: the lowest component bottom of its start or end pose, less the centre's bulge
(D_i − chord) and the sag of a component's arc about the slerp axis, ρ_i (1 − cos φ_i/2),
is below the bed top. A tumbling grain whose tip dips into the bed within the step and
leaves it by the step's end is among them. So every bed contact of a run with contacts
is soft, and which grains have it does not depend on the engagement margin or the list's
skin. The other grains' free paths stay above the bed top; the free flight's bed check
still runs for them after the phase (flight.composites.virtual_bed_pass: it keeps their
highest point for the jump height, and would rebound a grain whose end pose lay below
the bed top by a rounding). A grain resting on the bed is therefore
sub-stepped every step (as on the packed bed); the cost of a dilute run with contacts
rises by the sub-steps of the grains at the bed in each step.
Before (the bed in the free flight only), contacts pushed grains up to 0.3 Dn below the
bed top within a step and the next free flight lifted them out into their neighbours:
component overlaps of 0.05–0.16 Dn in one step, spins of 150–220 u*/Dn, and a free-flight
RK4 that diverged (non-finite after 0.09 s at 1.03 % and 0.33 s at 2.07 % in a
0.024 × 0.012 m box, Δt = 0.02), with jump statistics that differed by ~24 % between
Δt = 0.01 and 0.005 where it ran (CHANGELOG).

Known fault, as in contacts/phase.py ("The bed in the contact phase"): a component kept
on its virtual bed sphere can slide off it and sink below the bed top (a rod settling in
still water: 0.37 Dn), and the sphere placed after that contact ends throws the grain
out (155 u* in one step). Not fixed (README, "Known fault").

Known gap: a grain deflected by more than the engagement margin s towards a grain that was
not active is not stopped (``overruns`` counts the steps where that was possible;
``missed_contacts`` — brute-force check at the end of such a step — the pairs in contact
that the list did not hold).

Statistics (per grain, race-free): grain–grain collisions begun (a pair of grains that
goes from no touching component pair to at least one; Σ/2 = collisions), the largest
component overlap (in Dn), Σ overlap and Σ sub-steps over component contacts (time-mean
overlap).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..bed.jumps import close_jump
from ..bed.packed import BED_CENTRE_Y, bed_cell, bed_offset
from ..bed.virtual import BED_MODEL, virtual_bed_normal
from ..flight.composites import (
    BED_VIRTUAL_AFTER,
    CHUNK,
    OK,
    ClusterState,
    ClusterStateRef,
    ClusterWork,
    ClusterWorkRef,
    _lowest,
    _quat_to_matrix,
    _rhs,
    body_loads,
    chunk_range,
    free_flight_pass,
    highest_on_path,
    solve_generalized_mass,
    state_row,
    virtual_bed_pass,
)
from ..flight.path import hermite_weights
from ..grains.refs import as_tuple, struct_ref
from ..io.progress import wall_clock
from ..physics.contact_law import spring_dashpot
from ..physics.history import history_mark_impact
from ..physics.rng import uniform2
from .cells import axis_index, axis_span, grid_shape, min_image, sort_points, stencil_cell

__all__ = ["ClusterContacts", "compile_jobs", "make_cluster_contacts", "with_packed_bed", "with_virtual_bed", "contact_parameters", "substeps", "contact_phase",
           "build_contact_list", "as_refs", "contacts_of",
           "advance_clusters_contacts", "component_forces", "brute_force_pairs", "listed_pairs",
           "point_effective_masses", "DEFAULT_SKIN", "default_skin"]

PARALLEL_FROM = 128  # active grains from which the sub-step passes run in parallel (launch cost)
PARTNERS = 16  # grains one grain can touch at once (statistics; more are not counted as new)
DEFAULT_SKIN = 0.3  # Dn: engagement margin and list skin of contact_parameters' callers that give none


def default_skin(dt: float, impact_speed: float) -> float:
    """Engagement margin and list skin s (Dn) of a run whose case gives none: the farthest a
    contact can deflect a grain within one step, |δx| ≤ Δv Δt with Δv ≤ (1 + e) v_n ≤ 2 v_n
    and v_n ≤ ``impact_speed`` (u*; the overlap rule's speed, at the 99.9th percentile of
    real contacts' approach speeds: docs/studies/stiffness_dt.md), at least 0.1 Dn. The list
    is built afresh every step, so unlike the sphere list (engine/stepping.default_skin,
    kept across steps) it need not cover a step's travel: that is in each grain's reach."""
    return max(0.1, 2.0 * impact_speed * dt)


# slots of ClusterContacts.counters (engine/composites.py reports them by these names)
LIST_BUILDS = 0  # component neighbour-list builds
OVERRUNS = 1  # grains that moved further than the list's skin allowed
SUBSTEPPED = 2  # grain-sub-steps done
ENGAGED = 3  # engaged grain-steps
N_COUNTERS = 4
PERIODIC = (1, 0, 1)  # x and z periodic, y clamped (contacts/cells.py)


class ClusterContacts(NamedTuple):
    """Contact state of a run of composites (module docstring); K components, N grains."""
    par: np.ndarray  # (8,) k_n, k_t, ζ = 2|ln e|/√(ln²e+π²), f, skin, Lx, Ly, Lz
    grain_of: np.ndarray  # (K,) int64
    rho: np.ndarray  # (N,) bounding radius (Dn)
    rnorm: np.ndarray  # (K,) |r_k| (Dn)
    nbr: np.ndarray  # (K, C) int64 partner components
    nbr_count: np.ndarray  # (K,) int64
    shear: np.ndarray  # (K, C, 3) tangential spring ξ
    nbr2: np.ndarray  # spare buffers for the next build
    nbr_count2: np.ndarray
    shear2: np.ndarray
    partners: np.ndarray  # (N, P) int64 grains touched at the last evaluation
    n_partners: np.ndarray  # (N,) int64
    new_partners: np.ndarray  # (N, P) scratch
    active: np.ndarray  # (N,) uint8
    act: np.ndarray  # (N,) int64 active ids, n_act[0] of them
    n_act: np.ndarray  # (1,) int64
    touched: np.ndarray  # (N,) uint8: had a contact in this step
    reach: np.ndarray  # (N,) D_i
    phi: np.ndarray  # (N,) slerp angle of the step
    x1: np.ndarray  # (N, 13) end of the free flight
    dx: np.ndarray  # (N, 3) deviations
    dv: np.ndarray  # (N, 3)
    dL: np.ndarray  # (N, 3)
    dq: np.ndarray  # (N, 4)
    dev: np.ndarray  # (N,) deviation bound since the last list build
    P: np.ndarray  # (N, 3) pose at the current sub-step
    V: np.ndarray  # (N, 3)
    Om: np.ndarray  # (N, 3)
    dOm: np.ndarray  # (N, 3) Ω − Ω_f
    rot: np.ndarray  # (N, 3, 3)
    iw: np.ndarray  # (N, 3, 3) world inverse rigid inertia
    cp: np.ndarray  # (K, 3) world component centres
    force: np.ndarray  # (N, 3) contact force
    torque: np.ndarray  # (N, 3) contact torque about the centre of mass
    collisions: np.ndarray  # (N,) int64 grain–grain collisions begun
    max_overlap: np.ndarray  # (N,) largest component overlap (Dn)
    overlap_sum: np.ndarray  # (N,) Σ overlap over component-contact sub-steps
    contact_substeps: np.ndarray  # (N,) int64 Σ component-contact sub-steps
    counters: np.ndarray  # (N_COUNTERS,) int64
    # the packed bed's spheres as fixed partners (module docstring, "The packed bed")
    bed_centres: np.ndarray  # (M, 3) bed sphere centres (Dn); (0, 3) without a packed bed
    bed_par: np.ndarray  # (5,) ζ_bed, f_bed, shortest jump duration, lowest jump height (bed/jumps.py), max tilt
    step_t: np.ndarray  # (2,) start time t and length Δt of the step being taken (Dn/u*)
    step_index: np.ndarray  # (1,) int64 global index of that step
    last_contact: np.ndarray  # (N,) int64 last step with bed contact (shared with bed/packed_composites.py)
    in_bed: np.ndarray  # (N,) uint8 touching a bed sphere at the last evaluation
    bed_touch: np.ndarray  # (N,) uint8 touched a bed sphere in this step
    # the virtual bed in the sub-steps (module docstring, "The virtual bed", ``with_virtual_bed``):
    # one bed sphere under each component that reached the bed top; (0,) without
    vslot: np.ndarray  # (K,) uint8 component touches its virtual bed sphere
    vcentre: np.ndarray  # (K, 3) that sphere's centre (Dn)
    vshear: np.ndarray  # (K, 3) its tangential spring ξ
    bed_seed: np.ndarray  # (1,) int64 run.seed: the normals' draws (physics/rng.py)
    below: np.ndarray  # (N,) uint8 on the virtual bed: the free path can reach the bed top (_reach_one)


ClusterContactsRefType, ClusterContactsRef = struct_ref(ClusterContacts, __name__)  # grains/refs.py


# The contact phase's kernels take the three tuples as StructRefs (one pointer each,
# grains/refs.py): the step makes them once and carries three pointers. The parallel ones
# loop over chunks of grains (flight.composites.CHUNK); each chunk (and each serial kernel)
# reads them as tuples again (as_tuple), so that the per-grain functions below see tuples,
# as the hot loops must.
@njit(cache=True, no_cfunc_wrapper=True)
def as_refs(st, w, cc):
    """The three tuples as StructRefs over the same arrays (grains/refs.py)."""
    return ClusterStateRef(*st), ClusterWorkRef(*w), ClusterContactsRef(*cc)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _views(sr, wr, cr):
    """The three StructRefs as tuples again, for a chunk of grains."""
    return as_tuple(sr, ClusterState), as_tuple(wr, ClusterWork), as_tuple(cr, ClusterContacts)


def point_effective_masses(st, n_dir: int = 200) -> np.ndarray:
    """Smallest point-effective mass 1/(1/m + (c×n)·I⁻¹(c×n)) of each grain over its
    component surface points c = r_k + (d_k/2) n and n_dir directions n (ρ Dn³)."""
    k = np.arange(n_dir) + 0.5
    th = np.arccos(1.0 - 2.0 * k / n_dir)
    ph = math.pi * (1.0 + 5.0**0.5) * k
    dirs = np.column_stack([np.cos(ph) * np.sin(th), np.sin(ph) * np.sin(th), np.cos(th)])
    out = np.zeros(len(st.mass))
    for p in range(len(st.mass)):
        a, b = st.cstart[p], st.cstart[p + 1]
        c = st.r_body[a:b, None, :] + 0.5 * st.d_comp[a:b, None, None] * dirs[None, :, :]
        cn = np.cross(c, dirs[None, :, :])
        q = np.einsum("kni,ij,knj->kn", cn, st.inertia_inv[p], cn)
        out[p] = 1.0 / (1.0 / st.mass[p] + q.max())
    return out


def damping_factor(restitution: float) -> float:
    """ζ with c_n = ζ √(m_eff k_n) giving restitution e (contacts.pairs.normal_damping)."""
    if not 0.0 < restitution <= 1.0:
        raise ValueError(f"restitution {restitution!r} must be in (0, 1] for a spring–dashpot")
    le = math.log(restitution)
    return 2.0 * abs(le) / math.sqrt(le * le + math.pi**2)


def contact_parameters(kn, restitution, friction, kt_ratio=2.0 / 7.0, skin=DEFAULT_SKIN, box=(1e6, 60.0, 1e6)):
    """The ``par`` array (k_n, k_t in ρ u*² units; box (Lx, Ly, Lz) in Dn, x, z periodic)."""
    if kn <= 0.0 or friction < 0.0 or kt_ratio < 0.0 or skin <= 0.0:
        raise ValueError("kn and skin must be positive; friction and kt_ratio non-negative")
    return np.array([kn, kt_ratio * kn, damping_factor(restitution), friction, skin, *map(float, box)])


def substeps(st, kn: float, dt: float, steps_per_contact: int = 20) -> int:
    """Sub-steps per hydrodynamic step so that the shortest contact of the run (two of
    the lightest point-effective masses, undamped) spans ≥ steps_per_contact."""
    mu = point_effective_masses(st).min()
    tc = math.pi * math.sqrt(0.5 * mu / kn)
    return max(1, math.ceil(steps_per_contact * dt / tc - 1e-9))


def make_cluster_contacts(st, par, capacity: int = 32) -> ClusterContacts:
    """Contact state for a ClusterState ``st`` (flight.composites.make_cluster_state)."""
    n = st.pos.shape[0]
    kt = st.r_body.shape[0]
    grain_of = np.repeat(np.arange(n), np.diff(st.cstart)).astype(np.int64)
    rnorm = np.linalg.norm(st.r_body, axis=1)
    rho = np.array([(rnorm[a:b] + 0.5 * st.d_comp[a:b]).max() for a, b in zip(st.cstart[:-1], st.cstart[1:])])
    par = np.asarray(par, dtype=np.float64)
    lx, lz = par[5], par[7]
    need = 2.0 * (st.d_comp.max() + par[4])
    if n > 1 and min(lx, lz) < 2.0 * need:
        raise ValueError(f"the particle domain {lx:.4g} × {lz:.4g} Dn is too small for grain–grain contacts "
                         f"of components up to {st.d_comp.max():.3g} Dn with skin {par[4]:.3g} Dn "
                         f"(needs ≥ {2 * need:.4g} Dn in x and z)")
    c = max(1, int(capacity))
    z3 = lambda m: np.zeros((m, 3))  # noqa: E731
    return ClusterContacts(
        par, grain_of, rho, rnorm,
        np.zeros((kt, c), np.int64), np.zeros(kt, np.int64), np.zeros((kt, c, 3)),
        np.zeros((kt, c), np.int64), np.zeros(kt, np.int64), np.zeros((kt, c, 3)),
        np.zeros((n, PARTNERS), np.int64), np.zeros(n, np.int64), np.zeros((n, PARTNERS), np.int64),
        np.zeros(n, np.uint8), np.zeros(n, np.int64), np.zeros(1, np.int64), np.zeros(n, np.uint8),
        np.zeros(n), np.zeros(n), np.zeros((n, 13)), z3(n), z3(n), z3(n), np.zeros((n, 4)), np.zeros(n),
        z3(n), z3(n), z3(n), z3(n), np.zeros((n, 3, 3)), np.zeros((n, 3, 3)), z3(kt), z3(n), z3(n),
        np.zeros(n, np.int64), np.zeros(n), np.zeros(n), np.zeros(n, np.int64), np.zeros(N_COUNTERS, np.int64),
        np.zeros((0, 3)), np.zeros(5), np.zeros(2), np.zeros(1, np.int64), np.full(n, -2, np.int64),
        np.zeros(n, np.uint8), np.zeros(n, np.uint8),
        np.zeros(0, np.uint8), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(1, np.int64), np.zeros(n, np.uint8))


def with_packed_bed(cc: ClusterContacts, pb, restitution: float, friction: float, jump_limits,
                    last_contact) -> ClusterContacts:
    """The contact state with the packed bed's spheres (bed.packed.PackedBed ``pb``) as
    fixed partners of the sub-steps: bed restitution and friction, the jump thresholds
    (shortest duration, lowest height; bed/jumps.py) and the engine's ``last_contact``
    array (N,) int64, which the hard bed pass shares."""
    return cc._replace(bed_centres=np.ascontiguousarray(pb.centres), bed_par=_bed_par(restitution, friction, jump_limits),
                       last_contact=last_contact)


def _bed_par(restitution, friction, jump_limits, max_tilt=0.0):
    """ClusterContacts.bed_par: ζ_bed, f_bed, the jump thresholds, the largest tilt (rad)."""
    return np.array([damping_factor(restitution), float(friction), float(jump_limits[0]), float(jump_limits[1]),
                     float(max_tilt)])


def with_virtual_bed(cc: ClusterContacts, restitution: float, friction: float, max_tilt: float, jump_limits,
                     last_contact, seed: int) -> ClusterContacts:
    """The contact state with the virtual bed in the sub-steps (module docstring, "The
    virtual bed"): bed restitution, friction and largest tilt of the normal (rad), the jump
    thresholds (bed/jumps.py), the engine's ``last_contact`` array (N,) int64, which the
    hard pass after the phase (flight.composites.virtual_bed_pass) shares, and run.seed.
    The free flight must then leave the bed to that pass (bed[BED_MODEL] =
    flight.composites.BED_VIRTUAL_AFTER)."""
    k = cc.grain_of.shape[0]
    return cc._replace(bed_par=_bed_par(restitution, friction, jump_limits, max_tilt), last_contact=last_contact, vslot=np.zeros(k, np.uint8),
                       vcentre=np.zeros((k, 3)), vshear=np.zeros((k, 3)),
                       bed_seed=np.array([int(seed)], np.int64))


# ----------------------------------------------------------------------------- small kernels
@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _qmul(a0, a1, a2, a3, b0, b1, b2, b3):
    return (a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3, a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
            a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1, a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0)


# ----------------------------------------------------------------------------- engagement
@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _reach(sr, wr, cr, dt):
    """D_i (Hermite path bound) and the slerp angle φ_i of every grain; x1 saved.
    (Parallel bodies are separate functions: writes through a NamedTuple's attribute
    directly in a prange body can be lost.)"""
    n = sr.pos.shape[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, wv, cv = _views(sr, wr, cr)
        for p in range(*chunk_range(c, n)):
            _reach_one(sv, wv, cv, p, dt)


@njit(cache=True, no_cfunc_wrapper=True)
def _reach_one(st, w, cc, p, dt):
    x0 = w.x0[p]
    x1 = cc.x1[p]
    state_row(st, p, x1)
    chord = 0.0
    b0 = 0.0
    b1 = 0.0
    for i in range(3):
        d = x1[i] - x0[i]
        chord += d * d
    chord = math.sqrt(chord)
    for i in range(3):
        ub = (x1[i] - x0[i]) / dt
        b0 += (x0[3 + i] - ub) ** 2
        b1 += (x1[3 + i] - ub) ** 2
    reach = chord + 0.25 * dt * (math.sqrt(b0) + math.sqrt(b1))
    cc.reach[p] = reach
    dot = abs(x0[6] * x1[6] + x0[7] * x1[7] + x0[8] * x1[8] + x0[9] * x1[9])
    cc.phi[p] = 2.0 * math.acos(min(1.0, dot))
    if cc.vslot.shape[0] > 0:
        # virtual bed: a grain whose free path can reach the bed top is sub-stepped, with its
        # bed contact soft (module docstring, "The virtual bed"). A component's bottom lies
        # above the chord between its ends less the centre's bulge (reach − chord) and the
        # sag of its arc about the slerp axis, |r| (1 − cos φ/2) ≤ ρ (1 − cos φ/2)
        low0, _ = _lowest(st, w, p, x0[0], x0[1], x0[2], x0[6], x0[7], x0[8], x0[9])
        low1, _ = _lowest(st, w, p, x1[0], x1[1], x1[2], x1[6], x1[7], x1[8], x1[9])
        sag = (reach - chord) + cc.rho[p] * (1.0 - math.cos(0.5 * cc.phi[p]))
        cc.below[p] = 1 if min(low0, low1) - sag < 0.0 else 0


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _engage_pass(pos, ok, rho, reach, skin, box, n, size, start, count, order, ids, active):
    for q in prange(ids.shape[0]):
        i = ids[q]
        ix = axis_index(pos[i, 0], n[0], size[0], box[0], 1)
        iy = axis_index(pos[i, 1], n[1], size[1], box[1], 0)
        iz = axis_index(pos[i, 2], n[2], size[2], box[2], 1)
        hit = 0
        for s in range(27):
            c = stencil_cell(ix, iy, iz, n, PERIODIC, s)
            if c < 0:
                continue
            for m in range(start[c], start[c] + count[c]):
                j = ids[order[m]]
                if j == i:
                    continue
                dx = min_image(pos[i, 0] - pos[j, 0], box[0], 1)
                dy = pos[i, 1] - pos[j, 1]
                dz = min_image(pos[i, 2] - pos[j, 2], box[2], 1)
                lim = rho[i] + rho[j] + reach[i] + reach[j] + skin
                if dx * dx + dy * dy + dz * dz < lim * lim:
                    hit = 1
                    break
            if hit:
                break
        active[i] = hit


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _path_bottom(w, cc, p):
    """A lower bound of grain p's lowest point on its free path in the step: the lower
    end minus the Hermite bulge (D_i − chord) and the bounding radius ρ_i."""
    chord = 0.0
    for i in range(3):
        chord += (cc.x1[p, i] - w.x0[p, i]) ** 2
    return min(w.x0[p, 1], cc.x1[p, 1]) - (cc.reach[p] - math.sqrt(chord)) - cc.rho[p]


@njit(cache=True, no_cfunc_wrapper=True)
def _engage(sr, wr, cr):
    """Mark the active grains (module docstring, step 2) and list them in cc.act; forget
    the partners and list rows of the others (they touch nothing) and start the active
    ones' deviations at zero. Returns their number."""
    st, w, cc = _views(sr, wr, cr)
    n = st.pos.shape[0]
    box = cc.par[5:8]
    skin = cc.par[4]
    m = 0
    for p in range(n):
        if st.status[p] == OK:
            m += 1
    ids = np.empty(m, np.int64)
    m = 0
    rmax = 0.0
    dmax = 0.0
    for p in range(n):
        if st.status[p] == OK:
            ids[m] = p
            m += 1
            rmax = max(rmax, cc.rho[p])
            dmax = max(dmax, cc.reach[p])
    cut = min(2.0 * (rmax + dmax) + skin, 0.5 * min(box[0], box[2]))
    pos = np.ascontiguousarray(w.x0[:, 0:3])  # C layout: sort_points compiles once (as for cc.cp)
    gn, size = grid_shape(box, cut)
    start, count, order = sort_points(pos, ids, box, gn, size, PERIODIC)
    cc.active[:] = 0
    if 2.0 * (rmax + dmax) + skin > 0.5 * min(box[0], box[2]):
        cc.counters[OVERRUNS] += 1  # cells capped at half the box: counted as an overrun
    _engage_pass(pos, st.status, cc.rho, cc.reach, skin, box, gn, size, start, count, order, ids, cc.active)
    if cc.vslot.shape[0] > 0:
        # on the virtual bed every bed contact is soft: a grain whose path can reach the bed
        # top is sub-stepped, whether or not it can reach another grain (module docstring)
        for q in range(m):
            if cc.below[ids[q]] != 0:
                cc.active[ids[q]] = 1
    if cc.bed_centres.shape[0] > 0:
        # a grain resting or rolling on the packed bed (bed contact in the last step) whose
        # path can reach the bed again keeps its soft bed contacts (module docstring)
        step = cc.step_index[0]
        for q in range(m):
            p = ids[q]
            if cc.in_bed[p] != 0 or (cc.last_contact[p] >= step - 1 and _path_bottom(w, cc, p) < 0.0):
                cc.active[p] = 1
    k = 0
    for p in range(n):
        if cc.active[p]:
            cc.act[k] = p
            k += 1
        else:
            cc.n_partners[p] = 0
            cc.in_bed[p] = 0
            for a in range(st.cstart[p], st.cstart[p + 1]):
                cc.nbr_count[a] = 0
            if cc.vslot.shape[0] > 0:  # its bed contacts are the hard pass's now
                for a in range(st.cstart[p], st.cstart[p + 1]):
                    cc.vslot[a] = 0
    cc.n_act[0] = k
    for q in range(k):
        p = cc.act[q]
        cc.touched[p] = 0
        cc.bed_touch[p] = 0
        for i in range(3):
            cc.dx[p, i] = 0.0
            cc.dv[p, i] = 0.0
            cc.dL[p, i] = 0.0
        cc.dq[p, 0] = 1.0
        cc.dq[p, 1] = 0.0
        cc.dq[p, 2] = 0.0
        cc.dq[p, 3] = 0.0
    return k


# ----------------------------------------------------------------------------- neighbour list
@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _list_pass(cp, comps, grain_of, dcomp, creach, skin, box, n, size, start, count, order, nbr, cnt):
    cap = nbr.shape[1]
    most = np.zeros(comps.shape[0], np.int64)
    for q in prange(comps.shape[0]):
        a = comps[q]
        ga = grain_of[a]
        ix = axis_index(cp[a, 0], n[0], size[0], box[0], 1)
        iy = axis_index(cp[a, 1], n[1], size[1], box[1], 0)
        iz = axis_index(cp[a, 2], n[2], size[2], box[2], 1)
        k = 0
        for s in range(27):
            c = stencil_cell(ix, iy, iz, n, PERIODIC, s)
            if c < 0:
                continue
            for m in range(start[c], start[c] + count[c]):
                b = comps[order[m]]
                if grain_of[b] == ga:
                    continue
                dx = min_image(cp[a, 0] - cp[b, 0], box[0], 1)
                dy = cp[a, 1] - cp[b, 1]
                dz = min_image(cp[a, 2] - cp[b, 2], box[2], 1)
                lim = 0.5 * (dcomp[a] + dcomp[b]) + creach[a] + creach[b] + skin
                if dx * dx + dy * dy + dz * dz < lim * lim:
                    if k < cap:
                        nbr[a, k] = b
                    k += 1
        cnt[a] = k
        most[q] = k
    return most.max() if comps.shape[0] > 0 else 0


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _bed_list_pass(cp, comps, dcomp, creach, skin, pb, nbr, cnt):
    """Append to the row of each listed component the packed bed's spheres (ids −1 − j,
    diameter 1) within the pair cutoff ½(d_a + 1) + m_a + s, found through the bed's
    cells (bed.packed.PackedBed ``pb``, x and z periodic, one layer): as many cells around
    the component as the cutoff needs, each once. Only reads go through ``pb``: the
    writes are to plain arrays (a prange body's writes through a named tuple can be
    lost). Returns the longest row."""
    cap = nbr.shape[1]
    nx, nz = pb.ncell[0], pb.ncell[2]
    most = np.zeros(comps.shape[0], np.int64)
    for q in prange(comps.shape[0]):
        a = comps[q]
        k = cnt[a]
        lim = 0.5 * (dcomp[a] + 1.0) + creach[a] + skin
        if cp[a, 1] - BED_CENTRE_Y < lim:
            ix, iz = bed_cell(pb, cp[a, 0], cp[a, 2])
            x_lo, x_n = axis_span(ix, nx, True, int(math.ceil(lim / pb.size[0])))
            z_lo, z_n = axis_span(iz, nz, True, int(math.ceil(lim / pb.size[2])))
            for i in range(x_n):
                for j in range(z_n):
                    c = ((x_lo + i) % nx) * nz + (z_lo + j) % nz
                    for m in range(pb.cell_start[c], pb.cell_start[c] + pb.cell_count[c]):
                        j_bed = pb.order[m]
                        dx, dy, dz = bed_offset(pb, j_bed, cp[a, 0], cp[a, 1], cp[a, 2])
                        if dx * dx + dy * dy + dz * dz < lim * lim:
                            if k < cap:
                                nbr[a, k] = -1 - j_bed
                            k += 1
        cnt[a] = k
        most[q] = k
    return most.max() if comps.shape[0] > 0 else 0


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _transfer(comps, nbr, cnt, shear, nbr2, cnt2, shear2):
    for q in prange(comps.shape[0]):
        a = comps[q]
        for k in range(cnt2[a]):
            b = nbr2[a, k]
            shear2[a, k, 0] = 0.0
            shear2[a, k, 1] = 0.0
            shear2[a, k, 2] = 0.0
            for m in range(cnt[a]):
                if nbr[a, m] == b:
                    shear2[a, k, 0] = shear[a, m, 0]
                    shear2[a, k, 1] = shear[a, m, 1]
                    shear2[a, k, 2] = shear[a, m, 2]
                    break


@njit(cache=True, no_cfunc_wrapper=True)
def _build_list(sr, cr, pb):
    """Neighbour list of the active grains' components at their current centres cc.cp
    (with a packed bed ``pb``, bed.packed.PackedBed, its spheres too; None: none),
    history carried over. The new list's arrays replace the old in ``cr`` (the old become
    the spares for the next build)."""
    st, cc = as_tuple(sr, ClusterState), as_tuple(cr, ClusterContacts)
    na = cc.n_act[0]
    m = 0
    for q in range(na):
        p = cc.act[q]
        m += st.cstart[p + 1] - st.cstart[p]
    comps = np.empty(m, np.int64)
    creach = np.zeros(cc.grain_of.shape[0])
    m = 0
    rmax = 0.0
    for q in range(na):
        p = cc.act[q]
        for a in range(st.cstart[p], st.cstart[p + 1]):
            comps[m] = a
            m += 1
            creach[a] = cc.reach[p] + cc.rnorm[a] * cc.phi[p]
            rmax = max(rmax, creach[a])
    box = cc.par[5:8]
    skin = cc.par[4]
    dmax = st.d_comp.max()
    cut = dmax + 2.0 * rmax + skin
    if cut > 0.5 * min(box[0], box[2]):
        cut = 0.5 * min(box[0], box[2])
        cc.counters[OVERRUNS] += 1
    gn, size = grid_shape(box, cut)
    start, count, order = sort_points(cc.cp, comps, box, gn, size, PERIODIC)
    nbr2, cnt2, shear2 = cc.nbr2, cc.nbr_count2, cc.shear2
    most = _list_pass(cc.cp, comps, cc.grain_of, st.d_comp, creach, skin, box, gn, size, start, count, order,
                      nbr2, cnt2)
    if pb is not None:
        most = _bed_list_pass(cc.cp, comps, st.d_comp, creach, skin, pb, nbr2, cnt2)
    spare_nbr, spare_cnt, spare_shear = cc.nbr, cc.nbr_count, cc.shear
    if most > nbr2.shape[1]:
        k = most + most // 4 + 4
        kt = cc.grain_of.shape[0]
        nbr2 = np.zeros((kt, k), np.int64)
        cnt2 = np.zeros(kt, np.int64)
        shear2 = np.zeros((kt, k, 3))
        _list_pass(cc.cp, comps, cc.grain_of, st.d_comp, creach, skin, box, gn, size, start, count, order,
                   nbr2, cnt2)
        if pb is not None:
            _bed_list_pass(cc.cp, comps, st.d_comp, creach, skin, pb, nbr2, cnt2)
        spare_nbr = np.zeros((kt, k), np.int64)
        spare_cnt = np.zeros(kt, np.int64)
        spare_shear = np.zeros((kt, k, 3))
    _transfer(comps, cc.nbr, cc.nbr_count, cc.shear, nbr2, cnt2, shear2)
    # rows of components not in the new list (inactive grains): empty
    spare_cnt[:] = 0
    keep = np.zeros(cc.grain_of.shape[0], np.uint8)
    for q in range(m):
        keep[comps[q]] = 1
    for a in range(keep.shape[0]):
        if keep[a] == 0:
            cnt2[a] = 0
    cc.counters[LIST_BUILDS] += 1
    for q in range(na):
        cc.dev[cc.act[q]] = 0.0
    cr.nbr, cr.nbr_count, cr.shear = nbr2, cnt2, shear2
    cr.nbr2, cr.nbr_count2, cr.shear2 = spare_nbr, spare_cnt, spare_shear


# ----------------------------------------------------------------------------- poses and forces
@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _free_momentum(ib, f0, f1, f2, f3, o0, o1, o2):
    """R I_b Rᵀ Ω for the orientation (f0..f3) and world angular velocity (o0, o1, o2)."""
    r00 = 1.0 - 2.0 * (f2 * f2 + f3 * f3)
    r01 = 2.0 * (f1 * f2 - f0 * f3)
    r02 = 2.0 * (f1 * f3 + f0 * f2)
    r10 = 2.0 * (f1 * f2 + f0 * f3)
    r11 = 1.0 - 2.0 * (f1 * f1 + f3 * f3)
    r12 = 2.0 * (f2 * f3 - f0 * f1)
    r20 = 2.0 * (f1 * f3 - f0 * f2)
    r21 = 2.0 * (f2 * f3 + f0 * f1)
    r22 = 1.0 - 2.0 * (f1 * f1 + f2 * f2)
    b0 = r00 * o0 + r10 * o1 + r20 * o2
    b1 = r01 * o0 + r11 * o1 + r21 * o2
    b2 = r02 * o0 + r12 * o1 + r22 * o2
    c0 = ib[0, 0] * b0 + ib[0, 1] * b1 + ib[0, 2] * b2
    c1 = ib[1, 0] * b0 + ib[1, 1] * b1 + ib[1, 2] * b2
    c2 = ib[2, 0] * b0 + ib[2, 1] * b1 + ib[2, 2] * b2
    return (r00 * c0 + r01 * c1 + r02 * c2, r10 * c0 + r11 * c1 + r12 * c2, r20 * c0 + r21 * c1 + r22 * c2)


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _poses(sr, wr, cr, s, dt):
    """Pose of every active grain at σ = s on its free path plus deviation, its world
    inverse inertia and its components' world centres."""
    n = cr.n_act[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, wv, cv = _views(sr, wr, cr)
        _pose_grains(sv, wv, cv, *chunk_range(c, n), s, dt)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _pose_grains(st, w, cc, lo, hi, s, dt):
    """_pose_one of active grains lo..hi-1 (one compiled copy of it; module docstring, "Cost")."""
    for q in range(lo, hi):
        _pose_one(st, w, cc, cc.act[q], s, dt)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _pose_one(st, w, cc, p, s, dt):
    x0 = w.x0[p]
    x1 = cc.x1[p]
    h00, h10, h01, h11, d00, d10, d11 = hermite_weights(s)
    for i in range(3):
        cc.P[p, i] = h00 * x0[i] + h10 * dt * x0[3 + i] + h01 * x1[i] + h11 * dt * x1[3 + i] + cc.dx[p, i]
        cc.V[p, i] = (d00 * (x0[i] - x1[i])) / dt + d10 * x0[3 + i] + d11 * x1[3 + i] + cc.dv[p, i]
    # slerp q0 → q1 (shortest arc), then Q = q_f ⊗ δq
    a0, a1, a2, a3 = x0[6], x0[7], x0[8], x0[9]
    b0, b1, b2, b3 = x1[6], x1[7], x1[8], x1[9]
    dot = a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3
    if dot < 0.0:
        b0, b1, b2, b3, dot = -b0, -b1, -b2, -b3, -dot
    if s == 0.0:
        f0, f1, f2, f3 = a0, a1, a2, a3
    elif s == 1.0:
        f0, f1, f2, f3 = b0, b1, b2, b3
    elif dot > 0.9999999:
        f0 = a0 + s * (b0 - a0)
        f1 = a1 + s * (b1 - a1)
        f2 = a2 + s * (b2 - a2)
        f3 = a3 + s * (b3 - a3)
        nf = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2 + f3 * f3)
        f0, f1, f2, f3 = f0 / nf, f1 / nf, f2 / nf, f3 / nf
    else:
        th = 0.5 * cc.phi[p]  # = acos(dot): _reach_one (the same bits)
        sa = math.sin((1.0 - s) * th) / math.sin(th)
        sb = math.sin(s * th) / math.sin(th)
        f0 = sa * a0 + sb * b0
        f1 = sa * a1 + sb * b1
        f2 = sa * a2 + sb * b2
        f3 = sa * a3 + sb * b3
    dq = cc.dq[p]
    q0, q1, q2, q3 = _qmul(f0, f1, f2, f3, dq[0], dq[1], dq[2], dq[3])
    rot = cc.rot[p]
    _quat_to_matrix(q0, q1, q2, q3, rot)
    ib = st.inertia_inv[p]
    iw = cc.iw[p]
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for a in range(3):
                for b in range(3):
                    acc += rot[i, a] * ib[a, b] * rot[j, b]
            iw[i, j] = acc
    # Ω = I_w(Q)⁻¹ (L_f + δL): the free path's angular momentum is kept when the body is
    # turned by δq (so the kicks alone change the total angular momentum)
    o0 = (1.0 - s) * x0[10] + s * x1[10]
    o1 = (1.0 - s) * x0[11] + s * x1[11]
    o2 = (1.0 - s) * x0[12] + s * x1[12]
    l0, l1, l2 = _free_momentum(st.inertia[p], f0, f1, f2, f3, o0, o1, o2)
    l0 += cc.dL[p, 0]
    l1 += cc.dL[p, 1]
    l2 += cc.dL[p, 2]
    for i in range(3):
        cc.Om[p, i] = iw[i, 0] * l0 + iw[i, 1] * l1 + iw[i, 2] * l2
    cc.dOm[p, 0] = cc.Om[p, 0] - o0
    cc.dOm[p, 1] = cc.Om[p, 1] - o1
    cc.dOm[p, 2] = cc.Om[p, 2] - o2
    for k in range(st.cstart[p], st.cstart[p + 1]):
        r0, r1, r2 = st.r_body[k, 0], st.r_body[k, 1], st.r_body[k, 2]
        for i in range(3):
            cc.cp[k, i] = cc.P[p, i] + rot[i, 0] * r0 + rot[i, 1] * r1 + rot[i, 2] * r2


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def component_forces(sr, cr, h, sig):
    """Contact force and torque on every active grain from its component contacts
    (module docstring) at the current poses (cc.P, cc.V, cc.Om, cc.cp); ``h`` the
    sub-step ξ advances by, ``sig`` the poses' position σ in the step: σ = 0 is the set-up
    evaluation (ξ not advanced, only held at the Coulomb limit as every soft contact does;
    the statistics untouched). Race-free: iteration p writes only grain p's rows."""
    n = cr.n_act[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, cv = as_tuple(sr, ClusterState), as_tuple(cr, ClusterContacts)
        _force_kick_grains(sv, cv, *chunk_range(c, n), h, sig, False)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _grain_force(st, cc, p, h, sig):
    # σ a run-time float (not a literal flag): one compiled copy serves set-up and sub-steps
    update = sig > 0.0
    kn, kt, zeta, mu = cc.par[0], cc.par[1], cc.par[2], cc.par[3]
    lx, lz = cc.par[5], cc.par[7]
    fx = fy = fz = 0.0
    tx = ty = tz = 0.0
    npart = 0
    nbed = 0
    mp = st.mass[p]
    virtual = cc.vslot.shape[0] > 0
    for a in range(st.cstart[p], st.cstart[p + 1]):
        da = st.d_comp[a]
        nk = cc.nbr_count[a]
        for k in range(nk + 1 if virtual else nk):  # the listed partners, then the virtual bed
            if k == nk:  # the virtual bed sphere under component a (module docstring, "The virtual bed")
                if cc.vslot[a] == 0:
                    if not update or cc.cp[a, 1] >= 0.5 * da:
                        continue
                    _place_virtual(st, cc, p, a)
                g = -1
                cb = cc.vcentre[a]
                db = 1.0
                sh = cc.vshear[a]
            else:
                b = cc.nbr[a, k]
                if b >= 0:  # a component of grain g
                    g = cc.grain_of[b]
                    cb = cc.cp[b]
                    db = st.d_comp[b]
                else:  # bed sphere −1 − b: fixed, diameter 1
                    g = -1
                    cb = cc.bed_centres[-1 - b]
                    db = 1.0
                sh = cc.shear[a, k]
            dsum = 0.5 * (da + db)
            delx = min_image(cc.cp[a, 0] - cb[0], lx, 1)
            dely = cc.cp[a, 1] - cb[1]
            delz = min_image(cc.cp[a, 2] - cb[2], lz, 1)
            rsq = delx * delx + dely * dely + delz * delz
            if rsq >= dsum * dsum or rsq == 0.0:
                if update:
                    sh[0] = 0.0
                    sh[1] = 0.0
                    sh[2] = 0.0
                    if k == nk:
                        cc.vslot[a] = 0  # the contact ended: the sphere goes
                continue
            r = math.sqrt(rsq)
            n0, n1, n2 = delx / r, dely / r, delz / r
            dlt = dsum - r
            # contact point (middle of the overlap) relative to each centre of mass
            arm_a = 0.5 * da - 0.5 * dlt
            ci0 = cc.cp[a, 0] - cc.P[p, 0] - arm_a * n0
            ci1 = cc.cp[a, 1] - cc.P[p, 1] - arm_a * n1
            ci2 = cc.cp[a, 2] - cc.P[p, 2] - arm_a * n2
            oi = cc.Om[p]
            vr0 = cc.V[p, 0] + oi[1] * ci2 - oi[2] * ci1
            vr1 = cc.V[p, 1] + oi[2] * ci0 - oi[0] * ci2
            vr2 = cc.V[p, 2] + oi[0] * ci1 - oi[1] * ci0
            if g >= 0:
                arm_b = 0.5 * db - 0.5 * dlt
                cj0 = cb[0] - cc.P[g, 0] + arm_b * n0
                cj1 = cb[1] - cc.P[g, 1] + arm_b * n1
                cj2 = cb[2] - cc.P[g, 2] + arm_b * n2
                oj = cc.Om[g]
                vr0 -= cc.V[g, 0] + oj[1] * cj2 - oj[2] * cj1
                vr1 -= cc.V[g, 1] + oj[2] * cj0 - oj[0] * cj2
                vr2 -= cc.V[g, 2] + oj[0] * cj1 - oj[1] * cj0
                mg = st.mass[g]
                c_n = zeta * math.sqrt(mp * mg / (mp + mg) * kn)
                fric = mu
            else:  # the fixed partner: m_eff = m, the bed's restitution and friction
                c_n = cc.bed_par[0] * math.sqrt(mp * kn)
                fric = cc.bed_par[1]
            fn, ft0, ft1, ft2, sh[0], sh[1], sh[2] = spring_dashpot(
                n0, n1, n2, dlt, vr0, vr1, vr2, sh[0], sh[1], sh[2], h, update, kn, kt, c_n, 0.0, fric)
            f0 = fn * n0 + ft0
            f1 = fn * n1 + ft1
            f2 = fn * n2 + ft2
            fx += f0
            fy += f1
            fz += f2
            tx += ci1 * f2 - ci2 * f1
            ty += ci2 * f0 - ci0 * f2
            tz += ci0 * f1 - ci1 * f0
            if g < 0:
                nbed += 1
                continue
            if update:
                if dlt > cc.max_overlap[p]:
                    cc.max_overlap[p] = dlt
                cc.overlap_sum[p] += dlt
                cc.contact_substeps[p] += 1
                cc.touched[p] = 1
                seen = False
                for m in range(npart):
                    if cc.new_partners[p, m] == g:
                        seen = True
                        break
                if not seen and npart < cc.new_partners.shape[1]:
                    cc.new_partners[p, npart] = g
                    npart += 1
    cc.force[p, 0] = fx
    cc.force[p, 1] = fy
    cc.force[p, 2] = fz
    cc.torque[p, 0] = tx
    cc.torque[p, 1] = ty
    cc.torque[p, 2] = tz
    if update:
        # a grain–grain collision begins when a grain not touched at the last
        # evaluation is touched now
        for m in range(npart):
            g = cc.new_partners[p, m]
            old = False
            for j in range(cc.n_partners[p]):
                if cc.partners[p, j] == g:
                    old = True
                    break
            if not old:
                cc.collisions[p] += 1
        for m in range(npart):
            cc.partners[p, m] = cc.new_partners[p, m]
        cc.n_partners[p] = npart
        if nbed > 0:
            cc.touched[p] = 1
            cc.bed_touch[p] = 1
            if cc.in_bed[p] == 0:
                _bed_impact(st, cc, p, cc.step_t[0] + sig * cc.step_t[1])
        cc.in_bed[p] = 1 if nbed > 0 else 0


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _place_virtual(st, cc, p, a):
    """Component a of grain p has reached the bed top: a virtual bed sphere (diameter 1,
    fixed) is placed under it along a normal drawn as the hard virtual bed draws it
    (bed.virtual.virtual_bed_normal, from the component centre's velocity; vertical when it
    does not descend), touching it with the component's depth below the bed top as overlap
    (module docstring, "The virtual bed")."""
    u = cc.vshear[a]  # scratch for the velocity; the spring starts at zero below
    r0 = cc.cp[a, 0] - cc.P[p, 0]
    r1 = cc.cp[a, 1] - cc.P[p, 1]
    r2 = cc.cp[a, 2] - cc.P[p, 2]
    om = cc.Om[p]
    u[0] = cc.V[p, 0] + om[1] * r2 - om[2] * r1
    u[1] = cc.V[p, 1] + om[2] * r0 - om[0] * r2
    u[2] = cc.V[p, 2] + om[0] * r1 - om[1] * r0
    nrm = cc.vcentre[a]  # the normal first, then the centre
    # a draw of its own: counter-based on (seed, N + component, the grain's bed contacts)
    xi1, xi2 = uniform2(cc.bed_seed[0], st.pos.shape[0] + a, st.impacts[p])
    virtual_bed_normal(u, xi1, xi2, cc.bed_par[4], nrm)
    dist = 0.5 * (st.d_comp[a] + 1.0) - (0.5 * st.d_comp[a] - cc.cp[a, 1])
    n0, n1, n2 = nrm[0], nrm[1], nrm[2]
    cc.vcentre[a, 0] = cc.cp[a, 0] - dist * n0
    cc.vcentre[a, 1] = cc.cp[a, 1] - dist * n1
    cc.vcentre[a, 2] = cc.cp[a, 2] - dist * n2
    u[0] = 0.0
    u[1] = 0.0
    u[2] = 0.0
    cc.vslot[a] = 1


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _bed_impact(st, cc, p, t_hit):
    """A bed contact of grain p begins at t_hit: a bed impact; it ends a jump if the grain
    was airborne since an earlier step (SPEC §6, as bed/packed_composites.py), and the
    next jump starts here."""
    st.impacts[p] += 1
    if cc.last_contact[p] < cc.step_index[0] - 1:
        close_jump(st, p, st.jump_t0[p], cc.P[p, 0] - st.jump_x0[p], st.jump_ymax[p], t_hit,
                   cc.bed_par[2], cc.bed_par[3])
    st.jump_t0[p] = t_hit
    st.jump_x0[p] = cc.P[p, 0]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _kick_one(st, cc, p, k):
    """δv += k F/m, δL += k T, and δΩ += k I_w⁻¹ T (Ω = I_w⁻¹(L_f + δL) is linear in δL:
    the drift that follows must turn the grain with the kicked spin, as it moves it
    with the kicked velocity)."""
    inv = k / st.mass[p]
    iw = cc.iw[p]
    t0, t1, t2 = k * cc.torque[p, 0], k * cc.torque[p, 1], k * cc.torque[p, 2]
    for i in range(3):
        cc.dv[p, i] += inv * cc.force[p, i]
        cc.dOm[p, i] += iw[i, 0] * t0 + iw[i, 1] * t1 + iw[i, 2] * t2
    cc.dL[p, 0] += t0
    cc.dL[p, 1] += t1
    cc.dL[p, 2] += t2


# The sub-step passes (module docstring, "Cost"): a range of active grains per call of a
# kernel compiled without reference counting (_nrt=False), the per-grain kernels inlined
# into it. A per-grain kernel called once per grain and sub-step costs, per call, the
# passing of the three tuples (~60 arrays, some 500 words pushed on the stack) and, from a
# reference-counted caller, an atomic increment and decrement of every array.
@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _move_grains(st, w, cc, lo, hi, h, half_skin, sig, dt):
    """Half kick and drift of active grains lo..hi-1, then their poses at σ (a grain's pose
    reads only its own state); returns how many overran."""
    over = 0
    for q in range(lo, hi):
        p = cc.act[q]
        _kick_one(st, cc, p, 0.5 * h)
        over += _drift_one(st, cc, p, h, half_skin)
    _pose_grains(st, w, cc, lo, hi, sig, dt)
    return over


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _force_kick_grains(st, cc, lo, hi, h, sig, kick):
    """Contact forces at σ of active grains lo..hi-1 and, with ``kick``, their second half
    kick (a kick changes only the grain's own deviation, which no force reads)."""
    for q in range(lo, hi):
        p = cc.act[q]
        _grain_force(st, cc, p, h, sig)
        if kick:
            _kick_one(st, cc, p, 0.5 * h)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _substep_range(st, w, cc, s0, n_sub, h, half_skin, dt):
    """Sub-steps s0, s0 + 1, … of the contact phase on one thread, up to the last or to the
    first whose drift overran the list's skin (its forces not yet done: the caller
    rebuilds the list first); returns (that sub-step or n_sub, grains that overran)."""
    na = cc.n_act[0]
    for s in range(s0, n_sub):
        sig = (s + 1) / n_sub
        over = _move_grains(st, w, cc, 0, na, h, half_skin, sig, dt)
        if over > 0:
            return s, over
        _force_kick_grains(st, cc, 0, na, h, sig, True)
    return n_sub, 0


@njit(cache=True, no_cfunc_wrapper=True)
def _substeps_ser(sr, wr, cr, s0, n_sub, h, half_skin, dt):
    st, w, cc = _views(sr, wr, cr)
    return _substep_range(st, w, cc, s0, n_sub, h, half_skin, dt)


@njit(cache=True, no_cfunc_wrapper=True, inline="always")
def _piece(c, k, n):
    """Active grains lo..hi-1 of piece c of k (one piece per thread: a grain's result does
    not depend on how the grains are cut)."""
    return np.int64(c) * n // k, (np.int64(c) + 1) * n // k


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _move_par(sr, wr, cr, h, half_skin, sig, dt, k):
    n = cr.n_act[0]
    over = np.zeros(k, np.int64)
    for c in prange(k):
        sv, wv, cv = _views(sr, wr, cr)
        over[c] = _move_grains(sv, wv, cv, *_piece(c, k, n), h, half_skin, sig, dt)
    return over.sum()


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _force_kick_par(sr, cr, h, sig, k):
    n = cr.n_act[0]
    for c in prange(k):
        sv, cv = as_tuple(sr, ClusterState), as_tuple(cr, ClusterContacts)
        _force_kick_grains(sv, cv, *_piece(c, k, n), h, sig, True)


@njit(cache=True, no_cfunc_wrapper=True)
def _force_kick_ser(sr, cr, h, sig):
    st, cc = as_tuple(sr, ClusterState), as_tuple(cr, ClusterContacts)
    _force_kick_grains(st, cc, 0, cc.n_act[0], h, sig, True)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _drift_one(st, cc, p, h, half_skin):
    rot = cc.rot[p]
    w0, w1, w2 = cc.dOm[p, 0], cc.dOm[p, 1], cc.dOm[p, 2]
    # body frame of the free path: R_f = R(Q) R(δq)ᵀ; R_fᵀ δΩ = R(δq) R(Q)ᵀ δΩ
    b0 = rot[0, 0] * w0 + rot[1, 0] * w1 + rot[2, 0] * w2
    b1 = rot[0, 1] * w0 + rot[1, 1] * w1 + rot[2, 1] * w2
    b2 = rot[0, 2] * w0 + rot[1, 2] * w1 + rot[2, 2] * w2
    dq = cc.dq[p]
    # rotate (b0, b1, b2) by δq: v' = δq v δq*
    t0, t1, t2, t3 = _qmul(dq[0], dq[1], dq[2], dq[3], 0.0, b0, b1, b2)
    _, e0, e1, e2 = _qmul(t0, t1, t2, t3, dq[0], -dq[1], -dq[2], -dq[3])
    wm = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if wm > 0.0:
        ang = h * wm
        sn = math.sin(0.5 * ang) / wm
        r0, r1, r2, r3 = _qmul(math.cos(0.5 * ang), sn * e0, sn * e1, sn * e2, dq[0], dq[1], dq[2], dq[3])
        nq = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
        dq[0], dq[1], dq[2], dq[3] = r0 / nq, r1 / nq, r2 / nq, r3 / nq
    dv2 = 0.0
    for i in range(3):
        cc.dx[p, i] += h * cc.dv[p, i]
        dv2 += cc.dv[p, i] * cc.dv[p, i]
    cc.dev[p] += h * (math.sqrt(dv2) + cc.rho[p] * wm)
    return 1 if cc.dev[p] > half_skin else 0


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _finish(sr, wr, cr, coef):
    """End state of the grains that touched another one (module docstring, step 4)."""
    n = cr.n_act[0]
    for c in prange((n + CHUNK - 1) // CHUNK):
        sv, wv, cv = _views(sr, wr, cr)
        for q in range(*chunk_range(c, n)):
            _finish_one(sv, wv, cv, cv.act[q], coef)


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False, inline="always")
def _fluid_response(coef, st, w, cc, p):
    """The fluid's response to grain p's contacts over the rest of the step (module
    docstring, "Fluid response"): its velocity and angular velocity change by
    M⁻¹ (W(new) − W(free)) τ, W the fluid's force and torque on it (flight.composites._rhs,
    fluid sampled at the free path's end, history held) at its new and its free-flight end
    velocity and spin, M the generalized mass, τ = (δx · δv)/|δv|² the time since the contact."""
    dt = cc.step_t[1]
    uu = 0.0
    xu = 0.0
    for i in range(3):
        uu += cc.dv[p, i] * cc.dv[p, i]
        xu += cc.dx[p, i] * cc.dv[p, i]
    if uu == 0.0:
        return
    tau = min(max(xu / uu, 0.0), dt)
    x1 = cc.x1[p]
    xa = w.x[p]  # scratch: the free flight is done with it for a grain the phase moved
    for i in range(13):
        xa[i] = x1[i]
    for i in range(3):
        xa[3 + i] = st.vel[p, i]
        xa[10 + i] = st.omega[p, i]
    # the fluid's force and torque (world) at the new and at the free velocities; their
    # difference through the generalized mass (with added mass), without the rigid body's
    # gyroscopic terms, which the free rotation from the new spin is not
    held = w.aug[p, 0]  # scratch
    rot = w.rot[p]
    _quat_to_matrix(x1[6], x1[7], x1[8], x1[9], rot)  # the free path's end pose (w.rw: its sampling)
    _rhs(coef, st, w, p, xa, w.k[p, 0], False)
    ft = w.ft[p]
    for i in range(6):
        held[i] = ft[i]
    _rhs(coef, st, w, p, x1, w.k[p, 1], False)
    for i in range(6):
        ft[i] = held[i] - ft[i]
    body_loads(rot, ft)
    solve_generalized_mass(st, p, rot, ft)
    for i in range(3):
        st.vel[p, i] += tau * ft[18 + i]
        st.omega[p, i] += tau * ft[21 + i]


@njit(cache=True, no_cfunc_wrapper=True, _nrt=False)
def _finish_one(st, w, cc, p, coef):
    if cc.touched[p] != 0:
        x1 = cc.x1[p]
        dq = cc.dq[p]
        q0, q1, q2, q3 = _qmul(x1[6], x1[7], x1[8], x1[9], dq[0], dq[1], dq[2], dq[3])
        nq = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        st.quat[p, 0], st.quat[p, 1], st.quat[p, 2], st.quat[p, 3] = q0 / nq, q1 / nq, q2 / nq, q3 / nq
        rot = cc.rot[p]
        _quat_to_matrix(st.quat[p, 0], st.quat[p, 1], st.quat[p, 2], st.quat[p, 3], rot)
        ib = st.inertia_inv[p]
        iw = cc.iw[p]
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for a in range(3):
                    for b in range(3):
                        acc += rot[i, a] * ib[a, b] * rot[j, b]
                iw[i, j] = acc
        l0, l1, l2 = _free_momentum(st.inertia[p], x1[6], x1[7], x1[8], x1[9], x1[10], x1[11], x1[12])
        l0 += cc.dL[p, 0]
        l1 += cc.dL[p, 1]
        l2 += cc.dL[p, 2]
        for i in range(3):
            st.pos[p, i] = x1[i] + cc.dx[p, i]
            st.vel[p, i] = x1[3 + i] + cc.dv[p, i]
            st.omega[p, i] = iw[i, 0] * l0 + iw[i, 1] * l1 + iw[i, 2] * l2
        _fluid_response(coef, st, w, cc, p)
        # the fluid samples are stale and the contact is impulsive: re-sample, restart
        # the Basset memory (as a bed impact)
        st.fresh[p] = 0
        for k in range(st.cstart[p], st.cstart[p + 1]):
            history_mark_impact(st.hist_meta[k])  # the next step takes the slip step (physics/history.py)
        low = 1e300
        for k in range(st.cstart[p], st.cstart[p + 1]):
            y = st.pos[p, 1] + rot[1, 0] * st.r_body[k, 0] + rot[1, 1] * st.r_body[k, 1] \
                + rot[1, 2] * st.r_body[k, 2] - 0.5 * st.d_comp[k]
            low = min(low, y)
        if cc.bed_touch[p] != 0:
            # on the bed in this step (bed/packed_composites.py's bookkeeping): a lasting
            # contact moves the next jump's start along with the grain
            cc.last_contact[p] = cc.step_index[0]
            if cc.in_bed[p] != 0:
                st.jump_t0[p] = cc.step_t[0] + cc.step_t[1]
                st.jump_x0[p] = st.pos[p, 0]
            st.jump_ymax[p] = max(low, 0.0)
        elif low > st.jump_ymax[p]:
            st.jump_ymax[p] = low
    elif cc.bed_centres.shape[0] > 0:
        # untouched, on its free path; the hard bed pass skips it, so its highest point is
        # kept here, as that pass would (the free flight leaves it to the packed bed)
        q = st.quat[p]
        low, _ = _lowest(st, w, p, st.pos[p, 0], st.pos[p, 1], st.pos[p, 2], q[0], q[1], q[2], q[3])
        st.jump_ymax[p] = max(st.jump_ymax[p], low, highest_on_path(st, w, p, cc.step_t[1]))


@njit(cache=True, no_cfunc_wrapper=True, inline="always")  # inlined: one level less for the step to re-link (compile time)
def build_contact_list(sr, wr, cr, dt, pb):
    """Steps 2–3 set-up of the contact phase (module docstring): reach of every grain's
    free path from w.x0 (start) to the state st (end), active grains, their poses at
    σ = 0 and the component neighbour list (bed spheres of ``pb`` included; None: no
    packed bed), all written into ``cr``. Returns the number of active grains."""
    _reach(sr, wr, cr, dt)
    na = _engage(sr, wr, cr)
    if na > 0:
        _poses(sr, wr, cr, 0.0, dt)
        _build_list(sr, cr, pb)
    return na


@njit(cache=True, no_cfunc_wrapper=True, inline="always")  # inlined: one level less for the step to re-link (compile time)
def contact_phase(sr, wr, cr, dt, n_sub, pb, coef, threads=1):
    """Grain–grain contacts (and, with a packed bed ``pb``, soft bed contacts; None: none)
    of one hydrodynamic step of length dt, after the free flight of every grain (module
    docstring; cr.step_t and cr.step_index name the step). The state, work and contact
    tuples come as StructRefs (grains/refs.py), so that the step carries three pointers,
    not some ninety arrays (compile time); a list rebuild replaces arrays in ``cr``."""
    na = build_contact_list(sr, wr, cr, dt, pb)
    if na == 0:
        return
    cr.counters[ENGAGED] += na
    h = dt / n_sub
    half_skin = 0.5 * cr.par[4]
    component_forces(sr, cr, h, 0.0)
    par = na >= PARALLEL_FROM and threads > 1
    s = np.int64(0)  # not a literal: _substeps_ser compiles for one type of s
    while s < n_sub:
        # half kick, drift, pose at σ; contact forces and the second half kick. On one
        # thread the sub-steps run in one call until one overruns the list's skin
        if par:
            over = _move_par(sr, wr, cr, h, half_skin, (s + 1) / n_sub, dt, threads)
        else:
            s, over = _substeps_ser(sr, wr, cr, s, n_sub, h, half_skin, dt)
            if s == n_sub:
                break
        sig = (s + 1) / n_sub
        if over > 0:
            cr.counters[OVERRUNS] += over
            _build_list(sr, cr, pb)
        if par:
            _force_kick_par(sr, cr, h, sig, threads)
        else:
            _force_kick_ser(sr, cr, h, sig)
        s += 1
    cr.counters[SUBSTEPPED] += na * n_sub
    _finish(sr, wr, cr, coef)


def compile_jobs(st, w, cc, dt, n_sub, pb, coef):
    """``contact_phase``'s kernel tree in two lists of (kernel, arguments as contact_phase
    passes them), for a first run's compile on two cores (engine/cold_start.py): (set-up:
    reach and neighbour list; sub-steps: poses, engagement, forces, moves, kicks,
    ``_finish``). The engine compiles the set-up with the free flight in the run's process
    and the sub-steps in the helper: two halves of about the same compile time
    (``contact_phase`` itself is inlined into the step). The halves share no listed kernel;
    small leaves that both call (``cells.sort_points``, from ``_engage`` and
    ``_build_list``) may be compiled by both processes (~0.5 s each)."""
    h = dt / n_sub
    sr, wr, cr = as_refs(st, w, cc)
    step = (sr, wr, cr, h, 0.5 * cc.par[4], 1.0, dt, 2)
    setup = [(_reach, (sr, wr, cr, dt)), (_build_list, (sr, cr, pb))]
    substeps = [(_poses, (sr, wr, cr, 0.0, dt)), (_engage, (sr, wr, cr)), (component_forces, (sr, cr, h, 0.0)),
                (_move_par, step), (_substeps_ser, (sr, wr, cr, 0, n_sub, h, 0.5 * cc.par[4], dt)),
                (_force_kick_par, (sr, cr, h, 1.0, 2)),
                (_force_kick_ser, (sr, cr, h, 1.0)), (_finish, (sr, wr, cr, coef))]
    return setup, substeps


@njit(cache=True, no_cfunc_wrapper=True)
def contacts_of(cr):
    """The ClusterContacts over a ClusterContactsRef's arrays (for Python callers)."""
    return as_tuple(cr, ClusterContacts)


# ----------------------------------------------------------------------------- run loop
@njit(cache=True, no_cfunc_wrapper=True)
def advance_clusters_contacts(f, coef, bed, seed, st, w, hc, t0, dt, n_steps, top, cc, n_sub, timers, pb, threads=1):
    """flight.composites.advance_clusters with grain–grain contacts: free flight (RK4 + bed) of
    every grain, then ``contact_phase`` (pb: the packed bed or None), each step;
    timers += (free flight s, contacts s). Stops early when a grain is not finite or a
    jump buffer is full. Returns (steps done, the ClusterContacts to keep). ``threads``:
    Numba's thread count; on one the sub-steps run in one call until one overruns the
    list's skin, on more the passes of a sub-step are cut into one piece per thread (the
    same bits either way)."""
    n = st.pos.shape[0]
    cap = st.jump_buf.shape[1]
    k0 = round(t0 / dt)  # the global index of the first step (t0 is always k0 * dt)
    sr, wr, cr = as_refs(st, w, cc)
    after = bed[BED_MODEL] == BED_VIRTUAL_AFTER  # the virtual bed after the phase
    moved = np.zeros(n, np.uint8)
    for s in range(n_steps):
        t = (k0 + s) * dt  # from the global step index: never from where a chunk began
        c0 = wall_clock()
        free_flight_pass(f, coef, bed, seed, st, w, hc, t, dt, top)
        c1 = wall_clock()
        bad = False
        for p in range(n):
            if st.status[p] != OK:
                bad = True
                break
        c3 = c2 = c1
        if not bad:
            cr.step_t[0] = t
            cr.step_t[1] = dt
            cr.step_index[0] = k0 + s
            contact_phase(sr, wr, cr, dt, n_sub, pb, coef, threads)
            c2 = wall_clock()
            if after:
                # the grains the phase did not move keep their free paths and get the hard bed
                for p in range(n):
                    moved[p] = cr.active[p] & cr.touched[p]
                virtual_bed_pass(f, coef, bed, seed, st, w, hc, t, dt, k0 + s, moved, cr.last_contact)
            c3 = wall_clock()
        timers[0] += (c1 - c0) + (c3 - c2)
        timers[1] += c2 - c1
        stop = bad
        for p in range(n):
            if st.status[p] != OK or st.jump_buf_n[p] >= cap:
                stop = True
                break
        if stop:
            return s + 1, as_tuple(cr, ClusterContacts)
    return n_steps, as_tuple(cr, ClusterContacts)


# ----------------------------------------------------------------------------- diagnostics
def _component_centres(st) -> np.ndarray:
    out = np.zeros((st.r_body.shape[0], 3))
    for p in range(st.pos.shape[0]):
        rot = np.zeros((3, 3))
        q = st.quat[p]
        _quat_to_matrix(q[0], q[1], q[2], q[3], rot)
        a, b = st.cstart[p], st.cstart[p + 1]
        out[a:b] = st.pos[p] + st.r_body[a:b] @ rot.T
    return out


def brute_force_pairs(st, box, cut_extra: float = 0.0) -> set:
    """All pairs (a < b) of component spheres of different grains closer than
    (d_a + d_b)/2 + cut_extra (minimum image in x and z), by checking every pair."""
    cp = _component_centres(st)
    grain = np.repeat(np.arange(st.pos.shape[0]), np.diff(st.cstart))
    out = set()
    lx, lz = box[0], box[2]
    for a in range(len(cp)):
        d = cp[a + 1:] - cp[a]
        d[:, 0] -= lx * np.floor(d[:, 0] / lx + 0.5)
        d[:, 2] -= lz * np.floor(d[:, 2] / lz + 0.5)
        lim = 0.5 * (st.d_comp[a] + st.d_comp[a + 1:]) + cut_extra
        hit = np.nonzero(((d * d).sum(axis=1) < lim * lim) & (grain[a + 1:] != grain[a]))[0]
        out.update((a, a + 1 + int(b)) for b in hit)
    return out


def listed_pairs(cc) -> set:
    """Pairs (a < b) held by the component neighbour list."""
    out = set()
    for a in range(cc.nbr_count.shape[0]):
        for k in range(int(cc.nbr_count[a])):
            b = int(cc.nbr[a, k])
            out.add((min(a, b), max(a, b)))
    return out


def missed_contacts(st, cc) -> int:
    """Component pairs of different grains in contact now that the list does not hold
    (brute force; for tests and diagnostics)."""
    return len(brute_force_pairs(st, cc.par[5:8]) - listed_pairs(cc))


def grain_pose_centres(st) -> np.ndarray:
    """World component centres of the state (K, 3)."""
    return _component_centres(st)


__all__ += ["missed_contacts", "grain_pose_centres"]
