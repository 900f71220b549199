"""One saltation simulation: case → flow → grains → run directory (SPEC §9).

The loop is short on purpose: it advances the Numba kernel in chunks that end at output
times, collects finished jumps, and hands data to the writers. All arithmetic lives in
the kernels (flight/spheres.py and the sub-model modules it calls).
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import pandas as pd

from ..bed.packed import hexagonal_pockets as resting_pockets
from ..bed.virtual import run_bed_parameters
from ..case.schema import Case, CaseError, dump_toml, load_case, resolve_domain
from ..contacts.phase import PARALLEL_MEMBERS
from ..flight.spheres import NOT_FINITE, GrainState, make_state, make_workspace
from ..grains.initial import initial_conditions, initial_conditions_apart, initial_conditions_resting
from ..io.progress import compile_notice
from ..io.run_directory import CHECKPOINT_NAME
from ..io.writers import JumpWriter, ParaViewWriter, TrackWriter, run_metadata, write_json, write_table
from ..physics import history
from ..physics.fluid import check_bed
from ..physics.forces import make_coefficients
from .statistics import empty_rows, jump_statistics
from .stepping import Stepper

VARIANCE_FILE = "variance.parquet"  # displacement variances for the diffusion exponents


class SimulationError(RuntimeError):
    """A run stopped: the message names the particle, the step and its state."""


class RunInterrupted(KeyboardInterrupt):
    """SIGINT/SIGTERM stopped a run at the end of a chunk: a checkpoint was written, the
    outputs flushed and summary.json says status "interrupted". ``result`` is the
    RunResult so far, ``signum`` the signal; ``run(..., resume=True)`` continues."""

    def __init__(self, result: RunResult, signum: int):
        super().__init__(f"run interrupted by signal {signum} at step {result.summary['steps']}; "
                         f"checkpoint in {result.directory / CHECKPOINT}")
        self.result = result
        self.signum = signum


# Checkpoints (SPEC §9 --resume). A checkpoint is taken only where the loop returns from
# the kernel anyway (chunk ends: output times, every CHUNK_STEPS steps, full jump
# buffers). Those points depend on the state alone, never on wall time or on when a
# signal came, so a resumed run calls the kernel with the same (t0, n_steps) chunks and
# collects jumps in the same order as an uninterrupted one: bit for bit the same run.
CHECKPOINT = CHECKPOINT_NAME  # "checkpoint.npz" (io/run_directory.py)
# 3: the Basset history keeps slip steps (history.N_JUMPS slots in hist_meta, hist_tail)
# 4: composites' contact state holds the packed bed's soft contacts (contacts/composites.py)
# 5: hist_meta holds the pending slip step's age, and the ages in ticks (physics/history.py)
# 6: composites' contact state holds the virtual bed's soft contacts (contacts/composites.py)
CHECKPOINT_FORMAT = 6
PARTS = ".parts"  # checkpointable Parquet parts, merged into jumps/tracks.parquet at the end
CHUNK_STEPS = 200  # longest stretch between two chunk ends (how soon a signal is honoured)
# besides every output.checkpoint_every s of wall time: a checkpoint each time the run has
# advanced by this fraction of its steps, so a kill -9 loses at most 5 % of a run
CHECKPOINT_FRACTION = 0.05
# the fluid seen at each grain is carried from one step to the next (flight.spheres.Workspace)
FLUID_FIELDS = ("uf", "grad", "dudt", "vort", "uf_top", "uf_bot")
_NOT_THE_RUN = {("output", "checkpoint_every"), ("output", "checkpoint_steps"), ("output", "directory"),
                ("output", "variance"), ("run", "threads")}


def _case_keys(case: Case) -> dict:
    """Flat {"table.key": value} of a case, less the keys a resumed run may change."""
    return {f"{t}.{k}": v for t, keys in case.to_dict().items() for k, v in keys.items()
            if (t, k) not in _NOT_THE_RUN}


@dataclass
class RunResult:
    directory: Path
    summary: dict

    @property
    def jumps(self) -> pd.DataFrame:
        return pd.read_parquet(self.directory / "jumps.parquet")

    @property
    def tracks(self) -> pd.DataFrame:
        return pd.read_parquet(self.directory / "tracks.parquet")


def open_flow(case: Case):
    """The flow dataset a case asks for (LES snapshots or an analytic profile)."""
    from flowfields import open_dataset, profile_dataset

    if case.flow.source == "les":
        ds = open_dataset(case.flow.dataset)
        check_bed(ds, case.shear_reynolds, case.flow.bed)  # before any long work
        return ds
    re_star = case.shear_reynolds
    if case.flow.source == "still":
        return profile_dataset("still", y_top_plus=1e4 * re_star)
    ks_plus = case.flow.roughness * re_star if case.flow.profile == "rough" else None
    # tall enough that no grain leaves it: 1000 d
    return profile_dataset(case.flow.profile, y_top_plus=1000.0 * re_star, ks_plus=ks_plus)


def _les_box_m(ds, case: Case):
    """(Lx, Lz, H) of the LES box in metres at this case's u*: H is the half height."""
    lx, _, lz = ds.box
    visc_len = case.fluid.viscosity / case.shear_velocity
    return (lx * visc_len, lz * visc_len, ds.re_tau * visc_len)


def run(case, out=None, progress=True, resume=False, overwrite=False, **overrides) -> RunResult:
    """Run one case (a path or a dict of tables); overrides use "table.key" names.

    Writes config.toml, summary.json, jumps.parquet, tracks.parquet, particles.pvd and
    returns a RunResult (.summary, .jumps, .tracks). A run directory that already holds
    files is refused unless ``resume=True`` (continue from its checkpoint: same case, the
    result is that of an uninterrupted run) or ``overwrite=True`` (replace the run's
    outputs); it is locked while the run writes (io/run_directory.py).
    SIGINT/SIGTERM write a checkpoint and raise :class:`RunInterrupted`."""
    from ..io.run_directory import claim_run_directory

    case = load_case(case, overrides or None) if not isinstance(case, Case) else case
    out = Path(out or case.output.directory or Path("runs") / (case.run.name or "run"))
    family = "spheres" if case.particle.shape == "sphere" else "composites"
    with claim_run_directory(out, resume=resume, overwrite=overwrite, checkpoint=CHECKPOINT), \
            compile_notice(progress, family) as notice:  # set-up and the first kernel call compile
        ds = open_flow(case)
        case = resolve_domain(case, _les_box_m(ds, case) if case.flow.source == "les" else None)
        if family == "composites":  # bonded-sphere grains: the same run loop, another family
            from .composites import ClusterSimulation

            return ClusterSimulation(case, ds, out, progress=progress, resume=resume, notice=notice).run()
        return Simulation(case, ds, out, progress=progress, resume=resume, notice=notice).run()


class Simulation:
    """Holds the state of one run; ``run()`` drives it to the end."""

    def __init__(self, case: Case, flow, out: Path, progress=True, resume=False, stop_after_steps=None,
                 notice=None):
        """resume: continue from out/checkpoint.npz. stop_after_steps: a test hook that
        acts as a SIGINT arriving once that many steps are done. notice: the run's
        progress.compile_notice, told when the kernels are compiled."""
        self._setup_run(case, flow, out, progress, resume, stop_after_steps, notice)
        self.bed = run_bed_parameters(case, self.coef, self.dt)
        # contacts and bed (engine/stepping.py: free flight → grain contacts → bed each step)
        self.stepper = Stepper(case, self.n, self.domain_d, self.top_d, self.coef, self.bed, case.run.seed,
                               self.hist_coef, self.dt)
        self._stepper_arrays = None

    def _setup_run(self, case: Case, flow, out, progress, resume, stop_after_steps, notice):
        """What every grain family's run holds: the case, flow and run directory, the
        interrupt state, the sizes and time step in particle units, the force and Basset
        history coefficients."""
        self.notice = notice
        self.case = case
        self.flow = flow
        self.out = Path(out)
        self.progress = progress
        self.resume = resume
        self.stop_after_steps = stop_after_steps
        self._signal = None
        self._writing = False  # a checkpoint or the final outputs are being written
        self._second_signal = False  # a signal came while writing: stop once it is done
        self.n = int(case.n_particles)
        d = case.particle.diameter
        lx, lz, _ = case.domain
        self.domain_d = (lx / d, lz / d)  # particle units
        self.dt = case.dt_particle
        self.n_steps = case.n_steps
        self.re_star = case.shear_reynolds
        f = case.forces
        self.coef = make_coefficients(
            tau_star=case.shields_number,
            R=case.submerged_specific_gravity,
            re_star=self.re_star,
            slope=case.flow.slope_radians,
            Cm=f.added_mass_coefficient,
            C_L=f.lift_coefficient,
            C_Omega=f.magnus_coefficient,
            weight=f.weight,
            drag=f.drag,
            lift=f.lift,
            magnus=f.magnus,
            added_mass=f.added_mass,
            fluid_acceleration=f.fluid_acceleration,
            basset=f.basset,
            spin=f.spin,
        )
        self.n_window = f.basset_window
        self.hist_coef = history.make_history_coefficients(self.dt, self.n_window, impacts=f.basset_impacts)
        self.top_d = float(flow.y[-1]) / self.re_star

    # ------------------------------------------------------------------ helpers
    SERIAL_BELOW = 2000  # grains: below this a step is too short to share between threads
    # ... unless soft contacts: from this many grains the passes of the contact phase over
    # all grains (list, engagement test) are worth sharing, and the sub-steps of a large
    # block too from contacts/phase.LANE_THREADS threads (benchmarks/bench_dense.py, 2
    # threads against 1, two runs: 364 grains at 0.52 % 1.20x and 1.35x, 1 450 at 2.07 %
    # 1.29x and 1.26x, 2 760 at 3.94 % 1.12x and 1.12x)
    SERIAL_BELOW_SOFT = PARALLEL_MEMBERS

    def threads(self) -> int:
        """run.threads, or (0 = auto) all cores — one thread for small runs, where the
        per-step hand-over between threads costs more than the step. (Results do not
        depend on it: the same bits on any thread count.)"""
        most = numba.config.NUMBA_NUM_THREADS
        if self.case.run.threads:
            return min(self.case.run.threads, most)
        soft_spheres = self.case.collisions.model == "soft" and self.case.particle.shape == "sphere"
        small = self.SERIAL_BELOW_SOFT if soft_spheres else self.SERIAL_BELOW
        return 1 if self.n < small else most

    def _initial_state(self):
        c = self.case
        if c.run.start == "rest":
            try:
                pos, vel, spin = initial_conditions_resting(self.n, resting_pockets(*self.domain_d), self.domain_d,
                                                            c.run.seed)
            except ValueError as err:
                raise CaseError(f'run.start = "rest": {err}; lower run.n_particles or enlarge run.domain',
                                "run", "n_particles") from None
        else:
            start = initial_conditions if c.collisions.model == "off" else initial_conditions_apart
            pos, vel, spin = start(self.n, self.domain_d, c.run.seed, c.run.release_height)
        return make_state(pos, vel, spin, 0.0, self.n_window)

    def _fail(self, st, step_base, steps_done):
        p = int(np.nonzero(st.status == NOT_FINITE)[0][0])
        raise SimulationError(
            f"particle {p} became non-finite during step {step_base + steps_done} "
            f"(t = {(step_base + steps_done) * self.dt:.6g} d/u*): position {st.pos[p].tolist()}, "
            f"velocity {st.vel[p].tolist()}, spin {st.spin[p].tolist()}; outputs up to here are kept in {self.out}"
        )

    # ------------------------------------------------------------------ the grain family
    # What a family of grains (spheres here, bonded-sphere composites in
    # engine/composites.py) supplies to the one run loop below: its state, its compiled
    # step, its output columns and the arrays a checkpoint must keep.
    TRACK_WRITER = TrackWriter
    STATE = GrainState  # the state's NamedTuple class

    def _new_state(self):
        """(state, workspace) at t = 0."""
        return self._initial_state(), make_workspace(self.n)

    def _start(self, st, resumed: bool):
        """Set up what the step needs besides the state (contact lists, bed), restoring
        what a checkpoint holds when ``resumed``."""
        self.stepper.start(st.pos)
        if resumed and self._stepper_arrays:
            self.stepper.load_state_arrays(self._stepper_arrays, st.pos)

    def _advance(self, f, st, ws, t0, n, step0) -> int:
        """n steps from t0 (global step index step0); returns the steps done."""
        return self.stepper.advance(f, st, ws, t0, n, step0)

    def _precompile(self, f, st, ws) -> None:
        """Before the first step: a cold compile on two cores (Stepper.precompile)."""
        self.stepper.precompile(f, st, ws)

    def _write_tracks(self, tw, t, idx, st):
        tw.write(t, idx, st.pos, st.vel, st.spin)

    @staticmethod
    def _angular_velocity(st):
        return st.spin

    def _family_arrays(self, st, ws) -> dict:
        """Arrays besides the state a checkpoint keeps (workspace, contacts, bed)."""
        out = {f"fluid.{k}": getattr(ws, k) for k in FLUID_FIELDS}
        out.update({f"stepper.{k}": v for k, v in self.stepper.state_arrays().items()})
        return out

    def _restore_family(self, st, data: dict):
        """The workspace from a checkpoint's arrays (the rest is restored by _start)."""
        ws = make_workspace(self.n)
        for k in FLUID_FIELDS:
            getattr(ws, k)[...] = data[f"fluid.{k}"]
        self._stepper_arrays = {k[len("stepper."):]: v for k, v in data.items() if k.startswith("stepper.")}
        return ws

    # ------------------------------------------------------------------ main loop
    def run(self) -> RunResult:
        from ..io.progress import progress_bar

        c = self.case
        self.out.mkdir(parents=True, exist_ok=True)
        ckpt = self._read_checkpoint() if self.resume else None
        # the initial state before any file is written: a case that cannot start (no room
        # for its grains at rest) leaves the directory as it was
        numba.set_num_threads(self.threads())  # before the state: its set-up kernels use the threads
        threads = numba.get_num_threads()
        new = self._new_state() if ckpt is None else None
        if ckpt is None:
            (self.out / "config.toml").write_text(dump_toml(c))
            for stale in (self.out / CHECKPOINT, self.out / PARTS):
                if stale.is_dir():
                    shutil.rmtree(stale)
                elif stale.exists():
                    stale.unlink()
        meta = ckpt[0] if ckpt else {}
        if ckpt:
            st, ws, rows = ckpt[1], ckpt[2], ckpt[3]
        else:
            (st, ws), rows = new, []
        self._start(st, resumed=ckpt is not None)
        f = self.flow.arrays
        d, ts = c.particle.diameter, c.time_scale
        parts = self.out / PARTS
        jw = JumpWriter(self.out / "jumps.parquet", parts=parts, first_part=meta.get("jump_parts", 0),
                        meta=run_metadata(c, "jumps"))
        tw = (self.TRACK_WRITER(self.out / "tracks.parquet", parts=parts, first_part=meta.get("track_parts", 0),
                                meta=run_metadata(c, "tracks")) if c.output.tracks else None)
        vw = None
        if c.output.vtk:
            vw = ParaViewWriter(self.out, d, frames=meta.get("vtk_frames"))
        track_every = c.tracks_every
        vtk_every = c.vtk_every
        every_progress = max(1, math.ceil(CHECKPOINT_FRACTION * self.n_steps))  # chunk ends at every 5 %
        every = [e for e, w in ((track_every, tw), (vtk_every, vw)) if w is not None] + [CHUNK_STEPS, every_progress]
        var = self._variance(resume_step=meta["step"] if ckpt else None)  # diffusion statistics (SPEC §6)
        wall0 = time.perf_counter() - meta.get("wall_s", 0.0)
        t_compile = time.perf_counter()
        self._precompile(f, st, ws)
        self._advance(f, st, ws, 0.0, 0, 0)  # compiles (zero steps)
        if self.notice is not None:
            self.notice.done()
        compile_s = time.perf_counter() - t_compile + meta.get("compile_s", 0.0)
        kernel_s = meta.get("kernel_s", 0.0)
        status = "completed"
        step = meta.get("step", 0)
        bar = progress_bar(self.n_steps, initial=step, desc=c.run.name or "run", enabled=self.progress)
        particle_idx = np.arange(self.n)

        def output(step_now):
            t = step_now * self.dt
            if tw is not None and step_now % track_every == 0:
                self._write_tracks(tw, t, particle_idx, st)
            if vw is not None and step_now % vtk_every == 0:
                vw.write(t * ts, st.pos * d, st.vel * (d / ts), self._angular_velocity(st) / ts)
            if var is not None:
                var.sample_step(step_now, st.pos)

        def checkpoint():
            times = {"wall_s": time.perf_counter() - wall0, "compile_s": compile_s, "kernel_s": kernel_s}
            with self._uninterruptible():
                self._write_checkpoint(st, ws, rows, step, jw, tw, vw, var, times)

        last_ckpt_wall, last_ckpt_step = time.perf_counter(), step
        every_s, every_steps = c.output.checkpoint_every, c.output.checkpoint_steps
        old_handlers = self._catch_signals()
        try:
            if ckpt is None:
                output(0)
            while step < self.n_steps:
                nxt = min([self.n_steps] + [(step // e + 1) * e for e in every]
                          + [s for s in [var.next_step(step) if var is not None else None] if s is not None])
                t0 = time.perf_counter()
                want = nxt - step
                done = self._advance(f, st, ws, step * self.dt, want, step)
                kernel_s += time.perf_counter() - t0
                jw.collect(st, rows)
                if np.any(st.status == NOT_FINITE):
                    status = "failed"
                    self._fail(st, step, done)
                step += done
                bar.update(done)
                if step == nxt:
                    output(step)
                # a chunk end: the only place a checkpoint is taken (see CHECKPOINT)
                if self.stop_after_steps is not None and step >= self.stop_after_steps and self._signal is None:
                    self._signal = signal.SIGINT
                if self._signal is not None and step < self.n_steps:
                    status = "interrupted"
                    checkpoint()
                    break
                if step < self.n_steps and (
                    (every_s > 0 and time.perf_counter() - last_ckpt_wall >= every_s)
                    or (every_steps > 0 and step // every_steps > last_ckpt_step // every_steps)
                    or step // every_progress > last_ckpt_step // every_progress
                ):
                    checkpoint()
                    last_ckpt_wall, last_ckpt_step = time.perf_counter(), step
        except KeyboardInterrupt:
            status = "interrupted"
            raise
        finally:
            self._writing = True  # the outputs below are written whole even on a second Ctrl-C
            try:
                bar.close()
                jw.close()
                if tw is not None:
                    tw.close()
                if vw is not None:
                    vw.close()
                wall = time.perf_counter() - wall0
                summary = self._summary(st, rows, step, wall, compile_s, kernel_s, threads, status)
                if var is not None:
                    var.write(self.out / VARIANCE_FILE)
                    summary["variance"] = var.summary()
                if ckpt is not None:
                    summary["resumed_from_step"] = meta["step"]
                if status == "completed":
                    (self.out / CHECKPOINT).unlink(missing_ok=True)
                    shutil.rmtree(self.out / PARTS, ignore_errors=True)
                elif status == "interrupted" and (self.out / CHECKPOINT).exists():
                    summary["checkpoint"] = {"file": CHECKPOINT, "step": self._checkpoint_step}
                write_json(self.out / "summary.json", summary)
                self._write_particles(st)
            finally:
                self._writing = False
                self._restore_signals(old_handlers)
        result = RunResult(self.out, summary)
        if status == "interrupted":
            raise RunInterrupted(result, int(self._signal))
        return result

    def _variance(self, resume_step=None):
        """The displacement-variance accumulator (analysis/variance.py), or None when
        output.variance is off or there are fewer than 2 grains. On resume its sums come
        from the checkpoint (one file with the state: they cannot be lost apart from it);
        a checkpoint written without them (output.variance was off) cannot switch it on."""
        from ..analysis.variance import AnalysisError, RunVariance

        c = self.case
        try:
            if not c.output.variance or self.n < 2:
                raise AnalysisError("off")
            var = RunVariance(self.n, self.n_steps, c.variance_every, self.dt, c.output.variance_origins)
        except AnalysisError:  # off, too few grains, or a run too short for any lag
            (self.out / VARIANCE_FILE).unlink(missing_ok=True)
            return None
        if resume_step is not None:
            saved = self._variance_arrays or {}
            if not saved:
                raise SimulationError(
                    f"cannot resume {self.out} with output.variance = true: its checkpoint was written without the "
                    "displacement variances (output.variance was false), so variance.parquet would miss the first "
                    f"{resume_step} steps; resume with --set output.variance=false, or rerun with --overwrite")
            var.restore(saved, resume_step)
        return var

    # ------------------------------------------------------------------ checkpoints
    _checkpoint_step = None
    _variance_arrays = None

    def _catch_signals(self):
        """SIGINT/SIGTERM → stop at the next chunk end with a checkpoint; a second signal
        stops at once (KeyboardInterrupt). Signals can be caught in the main thread only
        (a Dask worker's runs are stopped by the sweep, which skips finished cases)."""
        if threading.current_thread() is not threading.main_thread():
            return None

        def handler(signum, frame):
            if self._signal is None:
                self._signal = signum
            elif self._writing:  # a checkpoint or the final outputs: finish them first
                self._second_signal = True
            else:
                raise KeyboardInterrupt

        return {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

    @contextlib.contextmanager
    def _uninterruptible(self):
        """A second SIGINT/SIGTERM while the checkpoint is written waits for it to be
        complete (the first one already stops the run at this chunk end)."""
        self._writing = True
        try:
            yield
        finally:
            self._writing = False
        if self._second_signal:
            raise KeyboardInterrupt

    @staticmethod
    def _restore_signals(old):
        for s, h in (old or {}).items():
            signal.signal(s, h)

    def _write_checkpoint(self, st, ws, rows, step, jw, tw, vw, var, times):
        """Everything the loop needs to go on bit for bit, written atomically (tmp + rename)
        after the Parquet parts it counts are closed."""
        arrays = {f"state.{k}": v for k, v in st._asdict().items()}
        arrays.update(self._family_arrays(st, ws))
        arrays["jump_rows"] = np.concatenate(rows) if rows else empty_rows()
        if var is not None:
            arrays.update({f"variance.{k}": v for k, v in var.state_arrays().items()})
        meta = {
            "format": CHECKPOINT_FORMAT,
            "step": int(step),
            "n_particles": self.n,
            "case": _case_keys(self.case),
            "jump_parts": jw.checkpoint(),
            "track_parts": tw.checkpoint() if tw is not None else 0,
            "vtk_frames": list(vw.frames) if vw is not None else [],
            **times,
        }
        arrays["meta"] = np.frombuffer(json.dumps(meta, default=str).encode(), dtype=np.uint8)
        tmp = self.out / (CHECKPOINT + ".tmp")
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.out / CHECKPOINT)
        self._checkpoint_step = int(step)

    def _read_checkpoint(self):
        """(meta, GrainState, Workspace, jump rows) from out/checkpoint.npz; the case must be
        the one that wrote it (output.checkpoint_*, output.directory, run.threads may differ)."""
        path = self.out / CHECKPOINT
        if not path.exists():
            done = self.out / "summary.json"
            why = ""
            if done.exists():
                why = f' (summary.json says status "{json.loads(done.read_text()).get("status")}")'
            raise SimulationError(f"cannot resume: no checkpoint {path}{why}; run without --resume to start afresh")
        try:
            with np.load(path) as z:
                data = {k: z[k] for k in z.files}
            meta = json.loads(bytes(data.pop("meta")).decode())
            if meta.get("format") != CHECKPOINT_FORMAT:
                raise ValueError(f"format {meta.get('format')!r} from another saltation version, this version reads "
                                 f"format {CHECKPOINT_FORMAT}")
        except Exception as exc:  # truncated, corrupt or from another version
            raise SimulationError(
                f"cannot resume: the checkpoint {path} is damaged or unreadable ({type(exc).__name__}: {exc}); "
                f"rerun with --overwrite to start {self.out} afresh") from None
        now = _case_keys(self.case)
        changed = sorted(k for k in set(now) | set(meta["case"])
                         if json.dumps(now.get(k), default=str) != json.dumps(meta["case"].get(k), default=str))
        if changed:
            raise SimulationError(
                f"cannot resume from {path}: the case differs from the one that wrote it in "
                + ", ".join(f"{k} (checkpoint {meta['case'].get(k)!r}, now {now.get(k)!r})" for k in changed)
                + "; only output.checkpoint_every, output.checkpoint_steps, output.directory and run.threads may change")
        st = self.STATE(*[np.ascontiguousarray(data[f"state.{k}"]) for k in self.STATE._fields])
        ws = self._restore_family(st, data)
        rows = [data["jump_rows"]] if len(data["jump_rows"]) else []
        self._variance_arrays = {k[len("variance."):]: v for k, v in data.items() if k.startswith("variance.")}
        return meta, st, ws, rows

    def _write_particles(self, st):
        """particles.parquet: one row per grain — its state at the end (position, x and z
        unwrapped, velocity, spin), grain–grain collisions, bed impacts, completed jumps,
        largest contact overlap (d)."""
        table = pd.DataFrame({
            "particle": np.arange(self.n, dtype=np.int32),
            **{k: st.pos[:, i].copy() for i, k in enumerate("xyz")},
            **{k: st.vel[:, i].copy() for i, k in enumerate("uvw")},
            **{f"spin_{k}": st.spin[:, i].copy() for i, k in enumerate("xyz")},
            "collisions": self.stepper.per_particle_collisions(),
            "bed_impacts": st.impacts.copy(),
            "jumps": st.jump_count.copy(),
            "max_overlap": (self.stepper.cl.max_overlap.copy() if len(self.stepper.cl.max_overlap) == self.n
                            else np.zeros(self.n)),
        })
        write_table(self.out / "particles.parquet", table, run_metadata(self.case, "particles"))

    # ------------------------------------------------------------------ summary
    def _summary_head(self, status, steps) -> dict:
        """The first keys of summary.json, the same for every grain family: the case, the
        flow, the steps run."""
        c = self.case
        duration_p = steps * self.dt
        return {
            "status": status,
            "n_particles": self.n,
            "concentration": c.concentration,
            "domain_m": list(c.domain),
            "tau_star": c.shields_number,
            "tau_ratio": c.tau_ratio,
            "shear_velocity_m_s": c.shear_velocity,
            "re_star": self.re_star,
            "rp": c.particle_reynolds,
            "flow": {"source": c.flow.source, "dataset": str(self.flow.path) if self.flow.path else self.flow.meta.get("kind"),
                     "re_tau": self.flow.re_tau, "top_d": self.top_d},
            "dt_particle": self.dt,
            "steps": steps,
            "simulated_time_particle": duration_p,
            "simulated_time_s": duration_p * c.time_scale,
        }

    def _summary(self, st, rows, steps, wall, compile_s, kernel_s, threads, status):
        jumps = np.concatenate(rows) if rows else empty_rows()
        particle_steps = self.n * steps
        duration_p = steps * self.dt
        return {
            **self._summary_head(status, steps),
            "jumps": jump_statistics(jumps),
            "collisions": self.stepper.collisions_summary(st, duration_p),
            "steps_above_flow_top": int(st.above_top.sum()),
            "timing": {
                "wall_s": wall,
                "compile_s": compile_s,
                "kernel_s": kernel_s,
                **self.stepper.timing(),
                "threads": threads,
            },
            "particle_steps_per_s": particle_steps / kernel_s if kernel_s > 0 else None,
        }
