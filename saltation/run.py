"""One saltation simulation: case → flow → grains → run directory (SPEC §9).

The loop is short on purpose: it advances the Numba kernel in chunks that end at output
times, collects finished jumps, and hands data to the writers. All arithmetic lives in
the kernels (integrator.py and the sub-model modules it calls).
"""
from __future__ import annotations

import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import pandas as pd

from . import history
from .bed import coefficient_set
from .config import Case, dump_toml, load_case, resolve_domain
from .forces import make_coefficients
from .initial import initial_conditions
from .integrator import NOT_FINITE, advance, make_state, make_workspace
from .writers import JumpWriter, ParaViewWriter, TrackWriter, write_json

DISCARDED_JUMPS = 10  # each grain's first jumps carry initial-condition memory (paper §3.2)


class SimulationError(RuntimeError):
    """A run stopped: the message names the particle, the step and its state."""


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
        return open_dataset(case.flow.dataset)
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


def run(case, out=None, progress=True, **overrides) -> RunResult:
    """Run one case (a path or a dict of tables); overrides use "table.key" names.

    Writes config.toml, summary.json, jumps.parquet, tracks.parquet, particles.pvd and
    returns a RunResult (.summary, .jumps, .tracks)."""
    case = load_case(case, overrides or None) if not isinstance(case, Case) else case
    ds = open_flow(case)
    case = resolve_domain(case, _les_box_m(ds, case) if case.flow.source == "les" else None)
    out = Path(out or case.output.directory or Path("runs") / (case.run.name or "run"))
    return Simulation(case, ds, out, progress=progress).run()


class Simulation:
    """Holds the state of one run; ``run()`` drives it to the end."""

    def __init__(self, case: Case, flow, out: Path, progress=True):
        self.case = case
        self.flow = flow
        self.out = Path(out)
        self.progress = progress
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
        )
        self.bed = np.array([case.bed_restitution, case.bed_friction, case.bed.max_tilt_radians])
        self.n_window = f.basset_window
        self.hist_coef = history.make_history_coefficients(self.dt, self.n_window)
        self.top_d = float(flow.y[-1]) / self.re_star

    # ------------------------------------------------------------------ helpers
    SERIAL_BELOW = 2000  # grains: below this a step is too short to share between threads

    def threads(self) -> int:
        """run.threads, or (0 = auto) all cores — one thread for small runs, where the
        per-step hand-over between threads costs more than the step."""
        most = numba.config.NUMBA_NUM_THREADS
        if self.case.run.threads:
            return min(self.case.run.threads, most)
        return 1 if self.n < self.SERIAL_BELOW else most

    def _initial_state(self):
        c = self.case
        pos, vel, spin = initial_conditions(self.n, self.domain_d, c.run.seed, c.run.release_height)
        return make_state(pos, vel, spin, 0.0, self.n_window)

    def _collect_jumps(self, st, writer: JumpWriter, rows: list):
        nb = st.jump_buf_n
        idx = np.nonzero(nb)[0]
        if len(idx) == 0:
            return
        counts = nb[idx]
        part = np.repeat(idx, counts)
        data = np.concatenate([st.jump_buf[p, : nb[p]] for p in idx])
        first = st.jump_count[idx] - counts  # index of the first buffered jump per grain
        jidx = np.concatenate([np.arange(a, a + k) for a, k in zip(first, counts)])
        length, height, duration = data[:, 1], data[:, 2], data[:, 3]
        velocity = np.divide(length, duration, out=np.zeros_like(length), where=duration > 0)
        writer.append(
            particle=part.astype(np.int32), jump=jidx.astype(np.int32), t_start=data[:, 0],
            length=length, height=height, duration=duration, velocity=velocity,
        )
        rows.append(np.column_stack([part, jidx, length, height, velocity]))
        nb[idx] = 0

    def _fail(self, st, step_base, steps_done):
        p = int(np.nonzero(st.status == NOT_FINITE)[0][0])
        raise SimulationError(
            f"particle {p} became non-finite during step {step_base + steps_done} "
            f"(t = {(step_base + steps_done) * self.dt:.6g} d/u*): position {st.pos[p].tolist()}, "
            f"velocity {st.vel[p].tolist()}, spin {st.spin[p].tolist()}; outputs up to here are kept in {self.out}"
        )

    # ------------------------------------------------------------------ main loop
    def run(self) -> RunResult:
        from tqdm import tqdm

        c = self.case
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "config.toml").write_text(dump_toml(c))
        numba.set_num_threads(self.threads())
        threads = numba.get_num_threads()
        st = self._initial_state()
        ws = make_workspace(self.n)
        f = self.flow.arrays
        d, ts = c.particle.diameter, c.time_scale
        jw = JumpWriter(self.out / "jumps.parquet")
        tw = TrackWriter(self.out / "tracks.parquet") if c.output.tracks else None
        vw = None
        if c.output.vtk:
            if (self.out / "vtk").exists():
                shutil.rmtree(self.out / "vtk")
            vw = ParaViewWriter(self.out, d)
        track_every = c.tracks_every
        vtk_every = c.vtk_every
        every = [e for e, w in ((track_every, tw), (vtk_every, vw)) if w is not None]
        rows: list = []
        wall0 = time.perf_counter()
        t_compile = time.perf_counter()
        advance(f, self.coef, self.bed, c.run.seed, st, ws, self.hist_coef, 0.0, self.dt, 0, self.top_d)
        compile_s = time.perf_counter() - t_compile
        kernel_s = 0.0
        status = "completed"
        step = 0
        bar = tqdm(total=self.n_steps, desc=c.run.name or "run", unit="step", disable=not self.progress, delay=2.0)
        particle_idx = np.arange(self.n)

        def output(step_now):
            t = step_now * self.dt
            if tw is not None and step_now % track_every == 0:
                tw.write(t, particle_idx, st.pos, st.vel, st.spin)
            if vw is not None and step_now % vtk_every == 0:
                vw.write(t * ts, st.pos * d, st.vel * (d / ts), st.spin / ts)

        try:
            output(0)
            while step < self.n_steps:
                nxt = min([self.n_steps] + [(step // e + 1) * e for e in every])
                t0 = time.perf_counter()
                want = nxt - step
                done = advance(f, self.coef, self.bed, c.run.seed, st, ws, self.hist_coef, step * self.dt, self.dt, want, self.top_d)
                kernel_s += time.perf_counter() - t0
                self._collect_jumps(st, jw, rows)
                if np.any(st.status == NOT_FINITE):
                    status = "failed"
                    self._fail(st, step, done)
                step += done
                bar.update(done)
                if step == nxt:
                    output(step)
        except KeyboardInterrupt:
            status = "interrupted"
            raise
        finally:
            bar.close()
            jw.close()
            if tw is not None:
                tw.close()
            if vw is not None:
                vw.close()
            wall = time.perf_counter() - wall0
            summary = self._summary(st, rows, step, wall, compile_s, kernel_s, threads, status)
            write_json(self.out / "summary.json", summary)
        return RunResult(self.out, summary)

    # ------------------------------------------------------------------ summary
    def _summary(self, st, rows, steps, wall, compile_s, kernel_s, threads, status):
        c = self.case
        jumps = np.concatenate(rows) if rows else np.zeros((0, 5))
        counted = jumps[jumps[:, 1] >= DISCARDED_JUMPS] if len(jumps) else jumps

        def stat(col):
            if len(counted) == 0:
                return None, None
            v = counted[:, col]
            return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0

        h, hs = stat(3)
        l, ls = stat(2)
        u, us = stat(4)
        bed_impacts = int(st.impacts.sum())
        particle_steps = self.n * steps
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
            "jumps": {
                "count": int(len(counted)),
                "recorded": int(len(jumps)),
                "discarded_first_per_particle": DISCARDED_JUMPS,
                "H_mean": h, "H_std": hs, "L_mean": l, "L_std": ls, "U_mean": u, "U_std": us,
                "units": "H, L in d; U in u*",
            },
            "collisions": {
                "particle_particle": 0,
                "bed": bed_impacts,
                "per_particle": bed_impacts / self.n,
                "bed_per_particle_per_unit_time": bed_impacts / self.n / duration_p if duration_p else None,
            },
            "steps_above_flow_top": int(st.above_top.sum()),
            "timing": {
                "wall_s": wall,
                "compile_s": compile_s,
                "kernel_s": kernel_s,
                "free_flight_s": kernel_s,
                "bed_s": None,
                "particle_collisions_s": 0.0,
                "threads": threads,
            },
            "particle_steps_per_s": particle_steps / kernel_s if kernel_s > 0 else None,
        }
