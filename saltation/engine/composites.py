"""One saltation run of bonded-sphere grains (issue 6 item 5; seed 000 §2.4, §4.4).

``saltation.run()`` hands a case here when ``particle.shape`` is not "sphere". The run
is engine/simulation.py's :class:`~saltation.engine.simulation.Simulation` with another grain
family: the same case keys, flow, time step,
force switches and coefficients, initial conditions (grains/initial.py), bed (virtual bed,
flight/composites.py), jump collection and writers, and a summary.json with the same keys, plus:

* ``shape``: the shape key, class fractions in use, grains and component spheres per
  class, mean grain volume (d³), the class ids of the track column ``class_id``;
* ``jumps_by_class``: the jump statistics of each Zingg class;
* ``transport``: q (volume per unit width) and q* = q/√(R g d³) of the run
  (analysis/transport.py), with the Ackers–White (1993) capacity for the LES channel and
  the ratio of the two — see that module for why the ratio is not a model error;
* ``spin``: mean spanwise angular velocity and mean |Ω| (u*/d) over the counted period.

Grains. ``particle.diameter`` is the nominal diameter Dn = (Dl Di Ds)^{1/3} of every
grain (the length scale d of the particle units). Axes are drawn by
``shapes.draw_axes(n, fractions, ratios, Dn=1)`` — classes with the case's fractions
(Smith 2003 by default; one class for shape = "disk" | "blade" | "rod" | "equant"),
axis ratios uniform in the class's range — from their own random stream (seed
[run.seed, 6]) and built with ``particle.construction`` ("seed" by default or "fitted":
``shapes.build(..., method=...)``), so the grains' start (positions, velocities, spins: grains/initial.py with
run.seed, identical to a sphere run's) does not depend on the shapes. Orientations are
uniformly random (Shoemake 1992, stream [run.seed, 7]); a grain whose lowest point would
start lower than the lowest sphere can (0.1 d above the bed top) is raised until it is
there.

Grain–grain contacts (collisions.model = "soft", the default): soft contacts between
the component spheres of different grains, with the case's [collisions] stiffness,
restitution, friction, k_t/k_n, steps_per_contact and skin (contacts/composites.py: units,
damping, sub-steps, the split with the free flight). The grains then start with their
bounding spheres apart (``_centres_apart``; contacts off: grains/initial.py's draw as before).
summary.json's ``collisions`` block has the sphere runs' keys (particle_particle,
per_particle, per_particle_per_unit_time, soft, overlap with max_over_d/mean_over_d in
Dn, contact_phase), ``timing.particle_collisions_s`` the wall time of the contact phase;
``timing.particle_collisions_share`` its share of the stepping time (compile excluded);
particles.parquet the collisions and largest overlap of each grain.

Bed: the virtual bed (flight/composites.py, inside the free-flight kernel, so the timing has no
separate bed share: ``timing.bed_s`` = 0, said in ``timing.note``; with soft contacts every
grain whose path can reach the bed top is sub-stepped and has its bed contacts there, as
soft contacts with a virtual bed sphere, and the free flight's bed check runs after the
phase for the others: contacts/composites.py, "The virtual bed") or, with
bed.model = "packed", the hexagonal layer of fixed spheres of diameter Dn acting on
every component sphere (bed/packed_composites.py, a pass after each step, timed as bed_s);
with soft contacts the grains sub-stepped in the contact phase — among them every grain
resting or rolling on the bed — have their bed contacts there, as soft contacts
(contacts/composites.py, "The packed bed"), and that pass skips them. run.start = "rest"
places each grain, turned by its orientation, on the bed above its own hollow
(grains/initial.composites_resting; it settles into a stable pose in its first steps).

The run loop — chunked stepping, recorders, checkpoints (every output.checkpoint_every s,
every 5 % of the steps, on SIGINT/SIGTERM), ``--resume`` bit for bit, progress, summary —
is engine/simulation.py's; this family supplies its state (flight/composites.ClusterState
and its work arrays; the contact state and packed-bed slots go into the checkpoint whole),
its step and its track columns. Not here (a clear error instead): binary hard-sphere
contacts for composites (collisions.model = "hard"). ParaView output holds the centres of
mass (diameter = Dn).
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numba
import numpy as np
import pandas as pd

from ..bed import packed_composites as cluster_bed
from ..bed.jumps import BED_MIN_JUMP_DURATION, BED_MIN_JUMP_HEIGHT
from ..bed.packed import hexagonal_layer, hexagonal_pockets, make_packed_bed
from ..bed.virtual import run_bed_parameters
from ..case.schema import Case, CaseError
from ..contacts import composites as cluster_contacts
from ..contacts.pairs import contact_model_from_case
from ..flight import composites as clusters
from ..grains import shapes
from ..grains.initial import Y_RANGE, composites_resting, initial_conditions
from ..io.writers import ClusterTrackWriter, run_metadata, write_table
from ..physics.forces import CM
from . import cold_start
from .simulation import Simulation, SimulationError
from .statistics import DISCARDED_JUMPS, empty_rows, jump_statistics
from .stepping import LIST_HEIGHT  # the cell height of sphere runs

CLASS_IDS = {c: i for i, c in enumerate(shapes.CLASSES)}  # track column class_id
MIN_START_BOTTOM = Y_RANGE[0] - 0.5  # d: lowest start of a sphere's bottom (grains/initial.py)
JUMP_CAPACITY = 16


def check_case(case: Case) -> None:
    """The parts of a case a bonded-sphere run cannot do: CaseError naming the key."""
    n = int(case.n_particles or 1)
    if case.collisions.model == "hard" and n > 1:
        raise CaseError(
            f'collisions.model = "hard" is not available with particle.shape = "{case.particle.shape}": '
            f'bonded-sphere grains have soft grain–grain contacts only (contacts/composites.py); set '
            f'collisions.model = "soft" or "off" (--set collisions.model=soft)', "collisions", "model")


def random_quaternions(n: int, rng) -> np.ndarray:
    """n uniformly distributed unit quaternions (scalar first), Shoemake (1992)."""
    u1, u2, u3 = rng.random(n), rng.random(n), rng.random(n)
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    return np.column_stack([b * np.cos(2 * np.pi * u3), a * np.sin(2 * np.pi * u2),
                            a * np.cos(2 * np.pi * u2), b * np.sin(2 * np.pi * u3)])


def draw_grains(case: Case, n: int):
    """(classes list, axes (n, 3) in d, composites in d) of a case's grains."""
    p = case.particle
    fractions = p.shape_fractions
    ratios = {k: (tuple(v[0]), tuple(v[1])) for k, v in (p.ratios or {}).items()}
    classes, axes = shapes.draw_axes(n, fractions=fractions, ratios=ratios or None, Dn=1.0,
                                     seed=[int(case.run.seed), 6])
    method = p.construction_method
    return classes, axes, [shapes.build(*a, method=method) for a in axes]


class ClusterSimulation(Simulation):
    """One run of bonded-sphere grains: the run loop, checkpoints and resume of
    :class:`~saltation.engine.simulation.Simulation`, with this family's state, step and
    output columns (module docstring)."""

    TRACK_WRITER = ClusterTrackWriter
    STATE = clusters.ClusterState

    def __init__(self, case: Case, flow, out: Path, progress=True, resume=False, stop_after_steps=None,
                 notice=None):
        check_case(case)
        self._setup_run(case, flow, out, progress, resume, stop_after_steps, notice)
        self._saved = None  # a checkpoint's contact and bed arrays, restored by _start
        self.packed = case.bed.model == "packed"
        # soft contacts: between grains, and on the bed for the grains sub-stepped
        self.contacts = case.collisions.model == "soft" and (self.n > 1 or self.packed)
        # the bed: packed (bed/packed_composites.py), or virtual — in the free flight, or with
        # contacts in the sub-steps and after them (contacts/composites.py, "The virtual bed")
        model = clusters.BED_PACKED if self.packed else clusters.BED_VIRTUAL_AFTER if self.contacts else 0.0
        self.bed = run_bed_parameters(case, self.coef, self.dt, model)
        self.pb = None  # packed bed (bed/packed_composites.py), built with the state
        self.last_contact = np.full(self.n, -2, np.int64)
        self.bed_s = 0.0
        self.classes, self.axes, self.composites = draw_grains(case, self.n)
        self.class_id = np.array([CLASS_IDS[c] for c in self.classes], dtype=np.int8)
        self.cc = None
        self.n_sub = 1
        self.timers = np.zeros(2)

    # ------------------------------------------------------------------ set-up
    def _initial_state(self):
        c = self.case
        pos, vel, spin = initial_conditions(self.n, self.domain_d, c.run.seed, c.run.release_height)
        quat = random_quaternions(self.n, np.random.default_rng([int(c.run.seed), 7]))
        resting = c.run.start == "rest"
        if resting:
            pos = self._centres_resting(quat)
            vel[:] = 0.0
            spin[:] = 0.0
        elif self.contacts:
            pos = self._centres_apart(pos)
        st = clusters.make_cluster_state(self.composites, pos, vel, quat, spin, 0.0, self.n_window,
                                         R=c.submerged_specific_gravity, Cm=self.coef[CM],
                                         re_star=self.re_star, jump_capacity=JUMP_CAPACITY,
                                         spin_drag=c.forces.spin,
                                         wake_shielding=c.forces.wake_shielding)
        low = clusters.lowest_points(st)
        lift = np.maximum(MIN_START_BOTTOM - low, 0.0)
        if np.any(lift > 0) and not resting:
            st.pos[:, 1] += lift
            st.jump_ymax[:] = clusters.lowest_points(st)
        return st

    def _contact_setup(self, st):
        """Grain–grain contact state (contacts/composites.py): the case's k_n, k_t, e, f in
        the composite units (k_n · (1+R)π/6, module docstring there), skin, cells."""
        c = self.case
        cc = c.collisions
        kn = contact_model_from_case(c).kn * (1.0 + c.submerged_specific_gravity) * math.pi / 6.0
        self.skin = float(cc.skin) if cc.skin is not None else cluster_contacts.default_skin(self.dt, cc.impact_speed)
        height = min(max(self.top_d, LIST_HEIGHT[0]), LIST_HEIGHT[1])
        lx, lz = self.domain_d
        self.kn = kn
        par = cluster_contacts.contact_parameters(kn, cc.restitution, cc.friction, cc.tangential_stiffness_ratio,
                                                  self.skin, (lx, height, lz))
        try:
            self.cc = cluster_contacts.make_cluster_contacts(st, par)
        except ValueError as err:
            raise CaseError(str(err), "run", "domain") from err
        self.n_sub = cluster_contacts.substeps(st, kn, self.dt, cc.steps_per_contact)
        b = self.bed  # bed/virtual.run_bed_parameters: e, f, max tilt, ..., the jump thresholds
        limits = (b[BED_MIN_JUMP_DURATION], b[BED_MIN_JUMP_HEIGHT])
        if self.packed:
            self.cc = cluster_contacts.with_packed_bed(self.cc, self.pb, b[0], b[1], limits, self.last_contact)
        else:
            self.cc = cluster_contacts.with_virtual_bed(self.cc, b[0], b[1], b[2], limits, self.last_contact,
                                                        int(c.run.seed))
        self.mu_min = float(cluster_contacts.point_effective_masses(st).min())

    def _advance_composites(self, f, st, w, seed, t0, n):
        if self.pb is None:
            return self._advance_flight(f, st, w, seed, t0, n)
        # packed bed: after each step's move (free flight, contacts), bed/packed_composites.py
        step0 = int(round(t0 / self.dt))
        cap = st.jump_buf.shape[1]
        # the grains sub-stepped in the contact phase had their bed contacts there (soft)
        skip = self.cc.active if self.cc is not None else np.zeros(self.n, np.uint8)
        if n == 0:  # compile call: nothing moves
            self._advance_flight(f, st, w, seed, t0, 0)
            cluster_bed.packed_bed_pass(f, self.coef, self.hist_coef, st, w, t0, self.dt, step0 - 1, self.bed, self.pb,
                                        self.last_contact, np.ones(self.n, np.uint8))
            return 0
        for s in range(n):
            t = (step0 + s) * self.dt  # from the global step index (as the kernels)
            done = self._advance_flight(f, st, w, seed, t, 1)
            c0 = time.perf_counter()
            cluster_bed.packed_bed_pass(f, self.coef, self.hist_coef, st, w, t, self.dt, step0 + s, self.bed, self.pb,
                                        self.last_contact, skip)
            self.bed_s += time.perf_counter() - c0
            if done < 1 or np.any(st.status != clusters.OK) or np.any(st.jump_buf_n >= cap):
                return s + 1
        return n

    def _advance_flight(self, f, st, w, seed, t0, n):
        if self.cc is None:
            return int(clusters.advance_clusters(f, self.coef, self.bed, seed, st, w, self.hist_coef, t0, self.dt,
                                                 n, self.top_d))
        done, self.cc = cluster_contacts.advance_clusters_contacts(*self._contact_step_args(f, st, w, seed, t0, n))
        return int(done)

    def _contact_step_args(self, f, st, w, seed, t0, n):
        """contacts.composites.advance_clusters_contacts's arguments."""
        return (f, self.coef, self.bed, seed, st, w, self.hist_coef, t0, self.dt, n, self.top_d, self.cc, self.n_sub,
                self.timers, self.pb, numba.get_num_threads())

    def _centres_resting(self, quat):
        """Start positions for run.start = "rest": each grain, turned by its orientation,
        lowered onto the packed bed above its own hollow (grains/initial.composites_resting);
        it then settles into a stable pose under its weight in the first steps."""
        lx, lz = self.domain_d
        offsets = [g.centres @ clusters.quat_to_matrix_py(q).T for g, q in zip(self.composites, quat)]
        radii = [0.5 * np.asarray(g.diameters) for g in self.composites]
        try:
            return composites_resting(offsets, radii, hexagonal_pockets(lx, lz), hexagonal_layer(lx, lz)[0],
                                      self.domain_d, int(self.case.run.seed))
        except ValueError as err:
            raise CaseError(f'run.start = "rest": {err}; lower run.n_particles or enlarge run.domain',
                            "run", "n_particles") from None

    def _centres_apart(self, pos):
        """Start positions for runs with grain–grain contacts: no two bounding spheres
        (radius ρ = max |r_k| + d_k/2 of the largest grain) overlap, so no components
        do (an overlapping start would be a violent first contact). Random sequential
        insertion (contacts.pairs.random_gas) in a layer from the usual lowest start (or
        run.release_height) + ρ up, tall enough for a solid fraction of bounding spheres
        of SOLID_FRACTION_AT_START (grains/initial.py); x, z as drawn there."""
        from ..contacts.pairs import random_gas
        from ..grains.initial import SOLID_FRACTION_AT_START

        c = self.case
        rho = max(float((np.linalg.norm(g.centres, axis=1) + g.radii).max()) for g in self.composites)
        lx, lz = self.domain_d
        gap = 0.02
        band = max(Y_RANGE[1] - Y_RANGE[0],
                   self.n * (math.pi / 6.0) * (2.0 * rho) ** 3 / (lx * lz * SOLID_FRACTION_AT_START),
                   2.0 * rho * (1.0 + gap))
        placed, _, _ = random_gas(self.n, (lx, band, lz), 2.0 * rho, int(c.run.seed), 0.0, gap)
        bottom = MIN_START_BOTTOM + rho if c.run.release_height is None else float(c.run.release_height)
        out = pos.copy()
        out[:, 0] = placed[:, 0]
        out[:, 2] = placed[:, 2]
        out[:, 1] = bottom + placed[:, 1]
        return out

    # ------------------------------------------------------------------ the family's part of the run loop
    def _new_state(self):
        st = self._initial_state()
        return st, clusters.make_cluster_work(st)

    def _start(self, st, resumed: bool):
        """Contacts and packed bed for the state; on resume their arrays from the checkpoint
        (the contact state whole: its lists may have grown)."""
        if self.packed:
            lx, lz = self.domain_d
            try:
                self.pb = make_packed_bed(lx, lz, cluster_bed.cut_for(st))
            except ValueError as err:
                raise CaseError(str(err), "run", "domain") from err
            if self.case.run.start == "rest":
                self.last_contact[:] = -1  # placed on the bed: in lasting contact from the first step
        if self.contacts:
            self._contact_setup(st)
        if resumed:
            saved = self._saved
            if self.cc is not None:
                self.cc = cluster_contacts.ClusterContacts(
                    *[np.ascontiguousarray(saved[f"contacts.{k}"]) for k in cluster_contacts.ClusterContacts._fields])
            self.last_contact[:] = saved["last_contact"]
            self.timers[:] = saved["timers"]
            self.bed_s = float(saved["bed_s"][0])
        if self.cc is not None:
            # the hard bed pass and the contact phase share one last_contact array
            self.cc = self.cc._replace(last_contact=self.last_contact)

    def _advance(self, f, st, ws, t0, n, step0) -> int:
        return self._advance_composites(f, st, ws, int(self.case.run.seed), t0, n)

    def _precompile(self, f, st, ws) -> None:
        """A first run on two cores (engine/cold_start.py): with contacts, a helper process
        compiles the contact phase's sub-step kernels while this one compiles the free
        flight and the contact phase's set-up (contacts/composites.compile_jobs: two halves
        of about the same size); the first step then compiles its own body (contact_phase
        inlined) and loads the rest."""
        if self.cc is None:
            return
        seed, t0, typed = int(self.case.run.seed), 0.0, cold_start.typed

        def jobs():
            setup, substeps = cluster_contacts.compile_jobs(st, ws, self.cc, self.dt, self.n_sub, self.pb, self.coef)
            flight = [(clusters.free_flight_pass, (f, self.coef, self.bed, seed, st, ws, self.hist_coef, t0, self.dt,
                                                   self.top_d))]
            if not self.packed:  # the virtual bed after the contact phase
                flight.append((clusters.virtual_bed_pass, (f, self.coef, self.bed, seed, st, ws, self.hist_coef, t0,
                                                           self.dt, 0, np.zeros(self.n, np.uint8), self.last_contact)))
            return [(k, typed(*a)) for k, a in substeps], [(k, typed(*a)) for k, a in setup + flight]

        cold_start.compile_split(cluster_contacts.advance_clusters_contacts,
                                 self._contact_step_args(f, st, ws, seed, t0, 0), jobs)

    def _write_tracks(self, tw, t, idx, st):
        tw.write(t, idx, st.pos, st.vel, st.omega, st.quat, self.class_id)

    @staticmethod
    def _angular_velocity(st):
        return st.omega

    def _family_arrays(self, st, ws) -> dict:
        out = {f"work.{k}": v for k, v in ws._asdict().items()}
        if self.cc is not None:
            out.update({f"contacts.{k}": v for k, v in self.cc._asdict().items()})
        out.update(last_contact=self.last_contact, timers=self.timers, bed_s=np.array([self.bed_s]))
        return out

    def _restore_family(self, st, data: dict):
        self._saved = data
        return clusters.ClusterWork(*[np.ascontiguousarray(data[f"work.{k}"]) for k in clusters.ClusterWork._fields])

    def _fail(self, st, step_base, steps_done):
        p = int(np.nonzero(st.status == clusters.NOT_FINITE)[0][0])
        raise SimulationError(
            f"grain {p} ({self.classes[p]}) became non-finite during step {step_base + steps_done}: position "
            f"{st.pos[p].tolist()}, velocity {st.vel[p].tolist()}, angular velocity "
            f"{st.omega[p].tolist()}; outputs up to here are kept in {self.out}")

    # ------------------------------------------------------------------ outputs
    def _write_particles(self, st):
        """particles.parquet: one row per grain — class, axes (d), component spheres, volume
        (d³), bed impacts, completed jumps, grain–grain collisions begun and the largest
        component overlap (d) (both 0 with contacts off)."""
        cc = self.cc
        table = pd.DataFrame({
            "particle": np.arange(self.n, dtype=np.int32),
            "zingg_class": self.classes,
            "class_id": self.class_id,
            "subtype": np.array([g.subtype for g in self.composites], dtype=np.int8),
            "Dl": self.axes[:, 0], "Di": self.axes[:, 1], "Ds": self.axes[:, 2],
            "n_spheres": np.array([g.n_spheres for g in self.composites], dtype=np.int32),
            "volume": np.array([g.volume for g in self.composites]),
            "collisions": cc.collisions.copy() if cc is not None else np.zeros(self.n, dtype=np.int64),
            "bed_impacts": st.impacts.copy(),
            "jumps": st.jump_count.copy(),
            "max_overlap": cc.max_overlap.copy() if cc is not None else np.zeros(self.n),
        })
        write_table(self.out / "particles.parquet", table, run_metadata(self.case, "particles"))

    def _transport(self, rows):
        """q, q* of the run from tracks.parquet (analysis/transport.py) and Ackers–White."""
        from ..analysis.transport import ackers_white, bulk_velocity_plus, einstein_number, transport_rate

        c = self.case
        if not c.output.tracks:
            return {"note": "output.tracks is off: no transport rate"}, None
        tracks = pd.read_parquet(self.out / "tracks.parquet")
        t_start = pd.read_parquet(self.out / "jumps.parquet", columns=["jump", "t_start"]) if rows else None
        volumes = np.array([g.volume for g in self.composites])
        lx, lz = self.domain_d
        try:
            tr = transport_rate(tracks, volumes, lx * lz, jumps=t_start, discarded=DISCARDED_JUMPS)
        except ValueError as err:
            return {"note": str(err)}, None
        out = dict(tr)
        out["q_star"] = einstein_number(tr["q_particle"], c.shields_number)
        out["q_m2_s"] = tr["q_particle"] * c.shear_velocity * c.particle.diameter
        out["definition"] = ("q = <sum_p V_p u_p>_t/(Lx Lz) (volume per unit width, samples at t >= t_from), "
                             "q* = q/sqrt(R g d^3), d the nominal diameter; proportional to the number of "
                             "grains per bed area")
        by_class = {}
        for name, cid in CLASS_IDS.items():
            sel = self.class_id == cid
            if sel.any():
                sub = tracks[np.isin(tracks["particle"].to_numpy(), np.nonzero(sel)[0])]
                t = transport_rate(sub, volumes, lx * lz, t_from=tr["t_from"])
                by_class[name] = {"q_star": einstein_number(t["q_particle"], c.shields_number),
                                  "u_volume_mean": t["u_volume_mean"]}
        out["by_class"] = by_class
        if c.flow.source == "les":
            ub = bulk_velocity_plus(self.flow)
            depth = self.flow.re_tau * c.viscous_length
            aw = ackers_white(c.particle.diameter, u_star=c.shear_velocity, velocity=ub * c.shear_velocity,
                              depth=depth, s=c.density_ratio, nu=c.fluid.viscosity)
            aw.update(depth_m=depth, velocity_m_s=ub * c.shear_velocity, bulk_velocity_plus=ub,
                      note="capacity (equilibrium) transport of an alluvial bed, Ackers & White 1973 with "
                           "the 1993 coefficients; the run's q* is set by its number of grains")
            out["ackers_white"] = aw
            out["ratio_to_ackers_white"] = out["q_star"] / aw["q_star"] if aw["q_star"] > 0 else None
        else:
            out["ackers_white"] = None
        return out, tracks

    def _summary(self, st, rows, steps, wall, compile_s, kernel_s, threads, status):
        c = self.case
        jumps = np.concatenate(rows) if rows else empty_rows()
        duration_p = steps * self.dt
        by_class = {}
        for name, cid in CLASS_IDS.items():
            grains = np.nonzero(self.class_id == cid)[0]
            if len(grains):
                by_class[name] = jump_statistics(jumps[np.isin(jumps[:, 0], grains)] if len(jumps) else jumps)
                by_class[name]["grains"] = int(len(grains))
        n_comp = np.array([g.n_spheres for g in self.composites])
        vol = np.array([g.volume for g in self.composites])
        summary = {
            **self._summary_head(status, steps),
            "shape": {
                "shape": c.particle.shape,
                "construction": c.particle.construction_method,
                "fractions": c.particle.shape_fractions,
                "nominal_diameter_m": c.particle.diameter,
                "grains_per_class": {k: int((self.class_id == i).sum()) for k, i in CLASS_IDS.items()},
                "component_spheres": int(n_comp.sum()),
                "component_spheres_mean": float(n_comp.mean()),
                "volume_mean_d3": float(vol.mean()),
                "volume_sphere_d3": math.pi / 6.0,
                "class_ids": CLASS_IDS,
                "note": "lengths in the nominal diameter d = (Dl Di Ds)^(1/3); concentration counts "
                        "(pi/6) d^3 per grain; grain-grain contacts "
                        + ("soft, between component spheres" if self.cc is not None else "off"),
            },
            "jumps": jump_statistics(jumps),
            "jumps_by_class": by_class,
            "collisions": self._collisions_summary(st, duration_p),
            "steps_above_flow_top": int(st.above_top.sum()),
            "timing": self._timing(wall, compile_s, kernel_s, threads),
            "particle_steps_per_s": self.n * steps / kernel_s if kernel_s > 0 else None,
            "component_sphere_steps_per_s": float(n_comp.sum()) * steps / kernel_s if kernel_s > 0 else None,
        }
        try:
            summary["transport"], tracks = self._transport(rows)
        except Exception as err:  # the run's outputs matter more than this derived block
            summary["transport"], tracks = {"note": f"not computed: {type(err).__name__}: {err}"}, None
        if tracks is not None and "t_from" in summary["transport"]:
            summary["spin"] = spin_statistics(tracks, summary["transport"]["t_from"], self.class_id)
        return summary


    def _collisions_summary(self, st, duration_p):
        """The ``collisions`` block (keys of stepping.Stepper.collisions_summary)."""
        c, cc, n = self.case, self.cc, self.n
        impacts = int(st.impacts.sum())
        per = cc.collisions if cc is not None else np.zeros(n, np.int64)
        pairs = int(per.sum()) // 2
        out = {
            "model": c.collisions.model if n > 1 else "off", "bed_model": c.bed.model,
            "particle_particle": pairs, "bed": impacts,
            "per_particle": 2.0 * pairs / n,
            "per_particle_per_unit_time": 2.0 * pairs / n / duration_p if duration_p else None,
            "bed_per_particle": impacts / n,
            "bed_per_particle_per_unit_time": impacts / n / duration_p if duration_p else None,
            "units": "per_particle: grain–grain collisions per grain (each collision involves two grains; a "
                     "collision begins when two grains go from no touching component pair to at least one); "
                     "unit time = d/u*",
        }
        if cc is None:
            return out
        sub = int(cc.contact_substeps.sum())
        h = self.dt / self.n_sub
        mu = 0.5 * self.mu_min
        out["soft"] = {
            "stiffness_N_m": c.collision_stiffness,
            "kn_particle_units": self.kn,
            "kn_units": "rho u*^2 d (rho: fluid density; contacts/composites.py)",
            "contact_duration_min_particle": math.pi * math.sqrt(mu / self.kn),
            "substeps_per_step": self.n_sub,
            "substep_particle": h,
            "skin_d": self.skin,
        }
        out["overlap"] = {
            "max_over_d": float(cc.max_overlap.max(initial=0.0)),
            "mean_over_d": float(cc.overlap_sum.sum() / sub) if sub else None,
            "mean_is": "time-mean overlap of the component-sphere contacts over the sub-steps in contact "
                       "(d = the nominal diameter Dn)",
            "component_contact_substeps": sub,
        }
        out["contact_phase"] = {
            "list_builds": int(cc.counters[cluster_contacts.LIST_BUILDS]),
            "overruns": int(cc.counters[cluster_contacts.OVERRUNS]),
            "overruns_are": "grain-sub-steps whose contact deviation exceeded half the skin (list rebuilt; "
                            "a grain that was not sub-stepped could then be reached unseen)",
            "substepped_grain_substeps": int(cc.counters[cluster_contacts.SUBSTEPPED]),
            "engaged_grain_steps": int(cc.counters[cluster_contacts.ENGAGED]),
        }
        return out

    def _timing(self, wall, compile_s, kernel_s, threads):
        bed_s = self.bed_s
        where = ("the packed bed: its own pass after each step (bed/packed_composites.py), bed_s" if self.packed else
                 "bed rebounds are computed inside the free-flight kernel (flight.composites.step_grain)"
                 if self.cc is None else
                 "the virtual bed: soft bed contacts in the contact phase for every grain whose path can reach "
                 "it (in particle_collisions_s), the free flight's bed check after it for the others (in "
                 "free_flight_s)")
        if self.cc is None:
            return {"wall_s": wall, "compile_s": compile_s, "kernel_s": kernel_s, "free_flight_s": kernel_s - bed_s,
                    "bed_s": bed_s, "particle_collisions_s": 0.0, "threads": threads, "note": where}
        ff, pc = (float(x) for x in self.timers)
        return {"wall_s": wall, "compile_s": compile_s, "kernel_s": kernel_s, "free_flight_s": ff, "bed_s": bed_s,
                "particle_collisions_s": pc, "particle_collisions_share": pc / kernel_s if kernel_s > 0 else None,
                "threads": threads,
                "note": where + "; particle_collisions_s: the whole contact phase (engagement, lists, sub-steps)"}


def spin_statistics(tracks: pd.DataFrame, t_from: float, class_id=None) -> dict:
    """Mean spanwise angular velocity ⟨Ω_z⟩ (negative: topspin) and mean |Ω| (u*/d) over
    the track samples at t ≥ t_from; per Zingg class when class ids are given."""
    tr = tracks[tracks["t"] >= t_from - 1e-12]

    def block(t):
        om = t[["spin_x", "spin_y", "spin_z"]].to_numpy()
        return {"omega_z_mean": float(om[:, 2].mean()) if len(om) else None,
                "omega_abs_mean": float(np.linalg.norm(om, axis=1).mean()) if len(om) else None}

    out = block(tr)
    out["units"] = "u*/d, world frame; samples at t >= t_from"
    if class_id is not None:
        cid = np.asarray(class_id)[tr["particle"].to_numpy()]
        out["by_class"] = {k: block(tr[cid == i]) for k, i in CLASS_IDS.items() if np.any(cid == i)}
    return out
