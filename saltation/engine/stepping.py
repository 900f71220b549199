"""The hydrodynamic step as an operator split, with its cost accounting (SPEC §5, §6).

Each step of Δt: (1) free flight of every grain (RK4 with the fluid forces, history
closure; flight.spheres.free_flight_particles), (2) grain–grain contacts (contacts/phase.py: soft
spheres sub-stepped along the free-flight paths, or binary hard-sphere impulses), (3) the
bed (virtual bed: flight.spheres._bed_check_body, per chunk of grains; packed bed: bed/packed.py). The order is
fixed; contacts/phase.py explains the split. Every phase is one parallel pass over the grains,
and the wall time of each is measured around it (``time.perf_counter`` through Numba's
object mode, ~0.6 µs per reading, four readings per step) and summed into
``timers = [free_flight_s, particle_collisions_s, bed_s]``. "Bed" is therefore the
whole bed pass (contact detection for every grain plus the rebounds), "particle
collisions" the whole contact phase (neighbour-list upkeep, engagement test,
sub-steps), "free flight" the RK4 pass.

:class:`Stepper` holds what the phases need besides the grain state (contact list,
contact-phase work arrays, packed bed, timers) and runs chunks of steps for engine/simulation.py.
:meth:`Stepper.state_arrays` / :meth:`Stepper.load_state_arrays` give the arrays a
checkpoint must keep to continue bit for bit (contact history, counters, bed contacts).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from ..bed.jumps import BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT
from ..bed.packed import make_packed_bed, packed_bed_check_particle
from ..contacts import phase
from ..contacts.fluid_response import fluid_response
from ..contacts.pairs import contact_model_from_case, make_contact_list, rebuild
from ..contacts.phase import (
    MERGED_PASSES,
    empty_substep_set,
    hard_contact_phase,
    make_bed_context,
    make_contact_phase,
    soft_contact_phase,
)
from ..flight.spheres import (  # the inline bed body
    CHUNK,
    OK,
    GrainState,
    GrainStateRef,
    Workspace,
    WorkspaceRef,
    _bed_check_body,
    free_flight_particles,
)
from ..grains.refs import as_tuple
from ..io.progress import wall_clock
from . import cold_start

CONTACTS_OFF, CONTACTS_SOFT, CONTACTS_HARD = 0, 1, 2
BED_VIRTUAL, BED_PACKED = 0, 1
SKIN_SPEED = 20.0  # u*: the default skin covers a grain at this speed over one step, ×1.2
SKIN_GROWTH = 2.0  # cells are made wide enough for this many times the skin
BED_CONTACT_STATE = ("slot_id", "slot_c", "slot_shear", "in_bed")  # checkpointed (state_arrays)
LIST_HEIGHT = (4.0, 60.0)  # d: bounds of the contact grid's height (grains above share its top layer)

__all__ = ["Stepper", "advance_split", "default_skin"]


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _free_flight(f, coef, st, w, hc, t, dt):
    n = st.pos.shape[0]
    # one pointer each into the loop, a tuple again per chunk for the hot loop (grains/refs.py)
    sr, wr = GrainStateRef(*st), WorkspaceRef(*w)
    for c in prange((n + CHUNK - 1) // CHUNK):
        free_flight_particles(f, coef, as_tuple(sr, GrainState), as_tuple(wr, Workspace), hc, c * CHUNK,
                              min(n, (c + 1) * CHUNK), t, dt)


# The contact model and the bed are chosen by which arguments are None: Numba prunes a
# branch ``if x is not None`` on an argument that is None before it types the code, so each
# combination is its own compiled step holding only its own contact phase and bed, and a
# run compiles what it uses and nothing else.
class SoftContacts(NamedTuple):
    """Soft contacts between grains: the sub-stepped contact phase (contacts/phase.py)."""
    n_sub: int  # sub-steps per hydrodynamic step
    threads: int = 1  # Numba threads: the contact blocks run in parallel on more than one
    skin: float = 0.0  # d: the case's skin, to which a skin widened for a fast grain narrows back


class HardContacts(NamedTuple):
    """Binary hard-sphere impulses (contacts/pairs.py)."""
    restitution: float
    friction: float


class VirtualBed(NamedTuple):
    """The virtual bed (bed/virtual.py): tilted bed grains drawn per impact."""
    seed: int


class PackedBedPass(NamedTuple):
    """The packed layer of bed spheres (bed/packed.py)."""
    unused: int = 0  # (a Numba tuple needs a field)


@njit(cache=True, no_cfunc_wrapper=True, error_model="numpy", _nrt=False)
def _bed_range(f, coef, hc, st, w, lo, hi, t, dt, step, bed, virtual, packed, pb, last_contact, top, skip, use_skip):
    """The bed for grains lo..hi-1 (one call per chunk: flight.spheres.CHUNK); one of
    ``virtual`` (VirtualBed) and ``packed`` (PackedBedPass) is given, the other None."""
    for p in range(lo, hi):
        if st.status[p] != OK:
            continue
        if not (use_skip and skip[p] != 0):
            if virtual is not None:
                _bed_check_body(f, coef, hc, st, w, p, t, dt, bed, virtual.seed)
            if packed is not None:
                packed_bed_check_particle(f, coef, hc, st, w, p, t, dt, step, bed, pb, last_contact)
        if st.pos[p, 1] > top:
            st.above_top[p] += 1


@njit(cache=True, no_cfunc_wrapper=True, parallel=True)
def _bed_pass(f, coef, hc, st, w, t, dt, step, bed, virtual, packed, pb, last_contact, top, skip):
    """The bed for every grain not in ``skip`` (grains whose bed contact the soft contact
    phase resolved; ``skip`` empty: none)."""
    n = st.pos.shape[0]
    use_skip = skip.shape[0] == n
    sr, wr = GrainStateRef(*st), WorkspaceRef(*w)  # as in _free_flight
    for c in prange((n + CHUNK - 1) // CHUNK):
        _bed_range(f, coef, hc, as_tuple(sr, GrainState), as_tuple(wr, Workspace), c * CHUNK, min(n, (c + 1) * CHUNK), t, dt,
                   step, bed, virtual, packed, pb, last_contact, top, skip, use_skip)


@njit(cache=True, no_cfunc_wrapper=True)
def advance_split(f, coef, bed, virtual, packed, st, w, hc, t0, dt, n_steps, top, step0, soft, hard, model, cl, ph,
                  bc, scratch, pb, last_contact, timers, cs):
    """Advance all grains n_steps from t0 (global step index step0): free flight →
    contacts → bed each step (module docstring). Stops early, like
    tests/peers/sphere_advance.advance, when a grain is not finite or a jump buffer is full.
    Returns (steps done, the ContactList to keep, the contact phase's SubstepSet to pass as
    ``cs`` next time). The set is scratch that keeps its size from call to call: a run
    advanced in short chunks (the variance samples end one every step or two) does not grow
    it afresh, page faults and all, at each chunk's first step. The contact model is
    ``soft`` (SoftContacts), ``hard`` (HardContacts) or neither (both None: grains pass
    through each other); the bed is ``virtual`` (VirtualBed) or ``packed``
    (PackedBedPass), the other None. Each combination is its own compiled step (the
    branches on None are pruned)."""
    n = st.pos.shape[0]
    cap = st.jump_buf.shape[1]
    skip = ph.active[:0]  # grains whose bed the contact phase resolved: none ...
    if soft is not None:
        skip = ph.active  # ... or the sub-stepped ones
    for s in range(n_steps):
        t = (step0 + s) * dt  # from the global step index: never from where a chunk began
        c0 = wall_clock()
        _free_flight(f, coef, st, w, hc, t, dt)
        c1 = wall_clock()
        bad = False
        for p in range(n):
            if st.status[p] != OK:
                bad = True
                break
        if not bad and soft is not None:
            cl, cs = soft_contact_phase(st, w.x0, model, cl, ph, bc, t, step0 + s, dt, soft.n_sub, cs,
                                        soft.threads, soft.skin)
            fluid_response(coef, hc.keep_impacts, st.vel, w.uf, ph.deviation, st.hist_meta, st.fresh, ph.act,
                           ph.n_act[0], dt)
        if not bad and hard is not None:
            hard_contact_phase(st, cl, hard.restitution, hard.friction, scratch)
        c2 = wall_clock()
        if not bad:
            _bed_pass(f, coef, hc, st, w, t, dt, step0 + s, bed, virtual, packed, pb, last_contact, top, skip)
        c3 = wall_clock()
        timers[0] += c1 - c0
        timers[1] += c2 - c1
        timers[2] += c3 - c2
        stop = bad
        for p in range(n):
            if st.status[p] != OK or st.jump_buf_n[p] >= cap:
                stop = True
                break
        if stop:
            return s + 1, cl, cs
    return n_steps, cl, cs


def default_skin(dt_particle: float) -> float:
    """Verlet skin (d): twice the distance a grain at SKIN_SPEED u* covers in a step, ×1.2,
    at least 0.1 d (contacts/phase.py: the list must hold for a whole step)."""
    return max(0.1, 2.0 * 1.2 * SKIN_SPEED * dt_particle)


class Stepper:
    """Contact and bed state of a run, and the chunked stepping (engine/simulation.py calls
    ``advance``). Particle units throughout (d, u*, d/u*)."""

    def __init__(self, case, n: int, domain_d, top_d: float, coef, bed, seed: int, hist_coef, dt: float):
        self.case = case
        self.n = n
        self.coef, self.bed, self.seed, self.hist_coef, self.dt = coef, bed, int(seed), hist_coef, float(dt)
        self.top_d = float(top_d)
        lx, lz = domain_d
        cc = case.collisions
        self.contacts_mode = {"off": CONTACTS_OFF, "soft": CONTACTS_SOFT, "hard": CONTACTS_HARD}[cc.model]
        self.bed_model = BED_PACKED if case.bed.model == "packed" else BED_VIRTUAL
        self.model = contact_model_from_case(case)
        self.n_sub = case.contact_substeps if self.contacts_mode == CONTACTS_SOFT else 1
        # the compiled step's choices (advance_split), fixed for the run
        self.soft = SoftContacts(int(self.n_sub)) if self.contacts_mode == CONTACTS_SOFT else None
        self.hard = (HardContacts(float(cc.restitution), float(cc.friction))
                     if self.contacts_mode == CONTACTS_HARD else None)
        self.virtual = VirtualBed(self.seed) if self.bed_model == BED_VIRTUAL else None
        self.packed = PackedBedPass() if self.bed_model == BED_PACKED else None
        skin = getattr(cc, "skin", None)
        self.skin = float(skin) if skin is not None else default_skin(dt)
        if self.soft is not None:
            self.soft = self.soft._replace(skin=self.skin)
        height = min(max(self.top_d, LIST_HEIGHT[0]), LIST_HEIGHT[1])
        self.box = (float(lx), height, float(lz))
        n_list = n if self.contacts_mode != CONTACTS_OFF else 0
        skin_used = self.skin if self.contacts_mode == CONTACTS_SOFT else 0.0
        cut = 1.0 + skin_used
        if self.contacts_mode != CONTACTS_OFF and min(lx, lz) < 2.0 * cut:
            raise ValueError(f"the particle domain {lx:.4g} × {lz:.4g} d is too small for contacts "
                             f"with a cutoff of {cut:.4g} d (needs ≥ {2 * cut:.4g} d in x and z)")
        # a placeholder until ``start`` has the positions (n coincident grains would all be
        # each other's neighbours: an n × n list)
        self.cl = make_contact_list(np.zeros((0, 3)), self.box, (True, False, True), 1.0, skin_used)
        self.ph = make_contact_phase(n_list)
        self.scratch = np.zeros(n_list, np.int64)
        self.pb = make_packed_bed(lx, lz) if self.bed_model == BED_PACKED else make_packed_bed(3.0, 3.0)
        self.last_contact = np.full(n, -2, np.int64)
        m = self.model
        self.bc = make_bed_context(n_list if self.contacts_mode == CONTACTS_SOFT else 0, self.bed_model == BED_PACKED,
                                   self.pb, float(bed[0]), float(bed[1]), float(bed[2]), m.kn, m.kt, self.seed,
                                   self.last_contact if self.contacts_mode == CONTACTS_SOFT else self.last_contact[:0],
                                   float(bed[BED_MIN_JUMP_DURATION]), float(bed[BED_MIN_JUMP_HEIGHT]))
        self.timers = np.zeros(3)
        self.cs = empty_substep_set()  # the contact phase's compact set, kept from chunk to chunk (advance_split)
        self.pp_collisions_hard = 0

    def start(self, pos):
        """Build the contact list on the initial positions (N, 3) (particle units). Soft
        contacts: cells wide enough for SKIN_GROWTH × the skin, so that the contact phase
        can widen the skin for a fast grain without new cells (contacts/phase.py)."""
        if self.contacts_mode == CONTACTS_HARD:
            self.cl = make_contact_list(pos, self.box, (True, False, True), 1.0, 0.0)
        elif self.contacts_mode == CONTACTS_SOFT:
            lx, _, lz = self.box
            widest = min(SKIN_GROWTH * self.skin, 0.5 * min(lx, lz) - 1.0)
            cl = make_contact_list(pos, self.box, (True, False, True), 1.0, max(widest, self.skin))
            self.cl = rebuild(np.ascontiguousarray(pos, dtype=np.float64),
                              cl._replace(cutoff=1.0 + self.skin, skin=self.skin))

    def _step_args(self, f, st, ws, t0: float, n_steps: int, step0: int) -> tuple:
        """advance_split's arguments."""
        soft = self.soft
        if soft is not None:
            soft = soft._replace(threads=int(numba.get_num_threads()))
        return (f, self.coef, self.bed, self.virtual, self.packed, st, ws, self.hist_coef, float(t0), self.dt,
                int(n_steps), self.top_d, int(step0), soft, self.hard, self.model, self.cl, self.ph, self.bc,
                self.scratch, self.pb, self.last_contact, self.timers, self.cs)

    def advance(self, f, st, ws, t0: float, n_steps: int, step0: int) -> int:
        """n_steps steps from t0 (global step index step0); returns the steps done."""
        done, self.cl, self.cs = advance_split(*self._step_args(f, st, ws, t0, n_steps, step0))
        return int(done)

    def precompile(self, f, st, ws) -> None:
        """A first run on two cores (engine/cold_start.py): with soft contacts, the contact
        phase is compiled in a helper process while this one compiles the free flight and
        the bed, each for the types advance_split calls it with; the first ``advance`` then
        compiles the step's own body and loads the rest. Nothing when the step is cached."""
        if self.soft is None:
            return
        args = self._step_args(f, st, ws, 0.0, 0, 0)
        soft, typed = args[13], cold_start.typed

        def jobs():
            elsewhere = [(soft_contact_phase, typed(st, ws.x0, self.model, self.cl, self.ph, self.bc, 0.0, 0, self.dt,
                                                    soft.n_sub, self.cs, soft.threads, soft.skin))]
            here = [(_free_flight, typed(f, self.coef, st, ws, self.hist_coef, 0.0, self.dt)),
                    (_bed_pass, typed(f, self.coef, self.hist_coef, st, ws, 0.0, self.dt, 0, self.bed, self.virtual, self.packed, self.pb,
                                      self.last_contact, self.top_d, self.ph.active))]
            return elsewhere, here

        cold_start.compile_split(advance_split, args, jobs)

    # ---------------------------------------------------------------- statistics
    def per_particle_collisions(self) -> np.ndarray:
        """Grain–grain collisions of each grain (N,) int64."""
        if self.contacts_mode == CONTACTS_OFF:
            return np.zeros(self.n, np.int64)
        return self.cl.collisions.copy()

    def collisions_summary(self, st, duration_p: float) -> dict:
        """The ``collisions`` block of summary.json (SPEC §9), particle units."""
        n = self.n
        per = self.per_particle_collisions()
        pairs = int(per.sum()) // 2
        bed_impacts = int(st.impacts.sum())
        out = {
            "model": self.case.collisions.model,
            "bed_model": self.case.bed.model,
            "particle_particle": pairs,
            "bed": bed_impacts,
            "per_particle": 2.0 * pairs / n,
            "per_particle_per_unit_time": 2.0 * pairs / n / duration_p if duration_p else None,
            "bed_per_particle": bed_impacts / n,
            "bed_per_particle_per_unit_time": bed_impacts / n / duration_p if duration_p else None,
            "units": "per_particle: grain–grain collisions per grain (each collision involves two "
                     "grains); unit time = d/u*",
        }
        if self.contacts_mode == CONTACTS_SOFT:
            ph, cl = self.ph, self.cl
            sub = int(ph.contact_substeps.sum())
            started = int(per.sum())
            h = self.dt / self.n_sub
            out["soft"] = {
                "stiffness_N_m": self.case.collision_stiffness,
                "kn_particle_units": self.model.kn,
                "contact_duration_particle": math.pi / math.sqrt(self.model.kn / (0.5 * self.model.mass)
                                                                 - 0.25 * self.model.gamma_n ** 2),
                "substeps_per_step": self.n_sub,
                "substep_particle": h,
                "skin_d": self.skin,
            }
            out["overlap"] = {
                "max_over_d": float(cl.max_overlap.max(initial=0.0)),
                "mean_over_d": float(ph.overlap_sum.sum() / sub) if sub else None,
                "mean_is": "time-mean overlap over the sub-steps in contact",
                "contact_duration_substeps_mean": sub / started if started else None,
                "contact_duration_particle_mean": h * sub / started if started else None,
                "bed_max_over_d": float(ph.bed_overlap_max.max(initial=0.0)),
                "bed_is": "largest overlap of a sub-stepped grain with a (soft) bed sphere",
            }
            out["contact_phase"] = {
                "list_rebuilds_in_steps": int(ph.counters[phase.LIST_REBUILDS]),
                "list_builds_total": int(cl.builds[0]),
                "overruns": int(ph.counters[phase.OVERRUNS]),
                "missed_contacts": int(ph.counters[phase.MISSED]),
                "overruns_are": "grain-steps whose path may have left the neighbour list's reach "
                                "(then checked: missed_contacts = pairs found in contact but not listed)",
                "wakes": int(ph.counters[phase.WAKES]),
                "substepped_grain_substeps": int(ph.counters[phase.SUBSTEPPED]),
                "blocks": int(ph.counters[phase.BLOCKS]),
                "phases_redone_merged": int(ph.counters[phase.REDONE_MERGED]),
                "phases_redone_unblocked": int(ph.counters[phase.REDONE_UNBLOCKED]),
                "blocks_are": "groups of grains sub-stepped together, out of touch with the other blocks "
                              "(contacts/phase.py, \"Blocks\"); when two blocks' grains came near each other the "
                              f"phase is redone with their groups joined (merged), after {MERGED_PASSES} such "
                              "passes as one block (unblocked)",
            }
        return out

    def timing(self) -> dict:
        ff, pc, bd = (float(x) for x in self.timers)
        out = {"free_flight_s": ff, "particle_collisions_s": pc, "bed_s": bd,
               "split_is": "wall time of each phase's pass over the grains, summed over steps "
                           "(engine/stepping.py)"}
        if self.contacts_mode == CONTACTS_SOFT:
            # how the contact phase shared its work between threads: execution, not results
            out["contact_blocks_in_parallel"] = int(self.ph.counters[phase.PARALLEL_BLOCKS])
            out["blocks_in_parallel_are"] = ("blocks whose sub-steps ran over their members on all threads "
                                             "(at least contacts/phase.LANE_THREADS threads and PARALLEL_MEMBERS "
                                             "candidates)")
            out["contact_phases_redone_unfiltered"] = int(self.ph.counters[phase.REDONE_FAR])
            out["redone_unfiltered_is"] = ("contact phases redone without the near-pair filter because a pair it "
                                           "had not looked at came near (contacts/phase.py, \"Near pairs\"); the "
                                           "result is the same either way")
            out["contact_rows_widened"] = int(self.ph.counters[phase.WIDENED])
            out["rows_widened_are"] = ("grains whose deviation from free flight reached the near-pair filter's "
                                       "slack in a step, after which they and their partners looked at every pair "
                                       "(contacts/phase.py, \"Near pairs\"); the result is the same either way")
            out["contact_substeps_retired"] = int(self.ph.counters[phase.RETIRED_SUBSTEPS])
            out["substeps_retired_are"] = ("grain-sub-steps (of substepped_grain_substeps) of grains that touched "
                                           "nothing and were sure to stay so unforced: moved on without looking for "
                                           "contacts (contacts/phase.py, \"Retired members\"); the result is the "
                                           "same either way")
        return out

    # ---------------------------------------------------------------- checkpoints
    def state_arrays(self) -> dict:
        """Arrays that a checkpoint must keep (with the GrainState) to resume bit for bit."""
        cl, ph = self.cl, self.ph
        out = {"last_contact": self.last_contact, "timers": self.timers}
        if self.contacts_mode != CONTACTS_OFF:
            out.update({"cl_" + k: getattr(cl, k) for k in
                        ("ref_pos", "nbr", "nbr_count", "shear", "touch", "n_touch", "collisions",
                         "max_overlap", "builds")})
            out.update({"ph_" + k: getattr(ph, k) for k in ("contact_substeps", "overlap_sum", "counters",
                                                            "bed_overlap_max", "unblocked")})
            # the bed as a soft contact of sub-stepped grains: its springs and contact slots
            # carry over from step to step (contacts.phase.BedContext)
            out.update({"bc_" + k: getattr(self.bc, k) for k in BED_CONTACT_STATE})
            out["cl_skin"] = np.array([cl.skin])  # widened for fast grains (contacts/phase.py)
        return out

    def load_state_arrays(self, arrays: dict, pos) -> None:
        """Restore ``state_arrays()`` (after ``start``); cells are rebuilt from ref_pos."""
        from ..contacts.cells import build_cells

        self.last_contact[:] = arrays["last_contact"]
        self.timers[:] = arrays["timers"]
        if self.contacts_mode == CONTACTS_OFF:
            return
        cl = self.cl
        k = arrays["cl_nbr"].shape[1]
        if cl.nbr.shape[1] != k:
            cl = cl._replace(nbr=np.zeros((self.n, k), np.int32), shear=np.zeros((self.n, k, 3)),
                             touch=np.zeros((self.n, k), np.uint8), nbr2=np.zeros((self.n, k), np.int32),
                             shear2=np.zeros((self.n, k, 3)), touch2=np.zeros((self.n, k), np.uint8))
        for name in ("ref_pos", "nbr", "nbr_count", "shear", "touch", "n_touch", "collisions", "max_overlap", "builds"):
            getattr(cl, name)[...] = arrays["cl_" + name]
        build_cells(cl.ref_pos, cl.grid, cl.cell_of, cl.cell_start, cl.cell_count, cl.order)
        if "cl_skin" in arrays:
            skin = float(arrays["cl_skin"][0])
            cl = cl._replace(cutoff=1.0 + skin, skin=skin)
        self.cl = cl
        for name in ("contact_substeps", "overlap_sum", "bed_overlap_max"):
            getattr(self.ph, name)[...] = arrays["ph_" + name]
        if "ph_unblocked" in arrays:  # older checkpoints: blocks tried at the next step
            self.ph.unblocked[...] = arrays["ph_unblocked"]
        saved = arrays["ph_counters"]  # older checkpoints have 5 or 7
        self.ph.counters[:saved.shape[0]] = saved
        for name in BED_CONTACT_STATE:
            getattr(self.bc, name)[...] = arrays["bc_" + name]
