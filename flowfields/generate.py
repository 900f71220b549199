"""Generate an LES-WALE channel-flow dataset with OpenFOAM (SPEC §3).

Chain: write the case → blockMesh → initial condition (mapped developed turbulence from
the channel395 tutorial, or a perturbed mean profile) → pimpleFoam spin-up (discarded) →
pimpleFoam sampling (N snapshots every Δt⁺) → foamToVTK (internal mesh, cell U) →
`flowfields.importer.import_series` (tensor-product dataset in wall units).

Times given in wall units (t⁺ = t u_τ²/ν) are converted with the *nominal* u_τ = Re_τ ν/h.
The importer measures the LES's own u_τ from the snapshots, so the stored interval in the
dataset's own t⁺ differs from `snapshot_interval_tplus` by the ratio (u_τ,LES/u_τ,nominal)².

Usage from Python::

    from flowfields.generate import ChannelParams, generate
    generate(ChannelParams(), "flowfields/data/channel395", "/tmp/les_case")

or `python -m flowfields.generate --help` (`--les-only` stops after the VTK export).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shlex
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flowfields import openfoam as of
from flowfields import rough_bed as rb

INITIAL_CONDITIONS = ("map", "perturb")
BED_KINDS = ("smooth", "porous")
BED_D_PLUS_RANGE = (5.0, 100.0)
# The dataset keeps the bed layer down to half a grain below the bed top (the top layer's
# centre plane): deeper the pore flow is below 1e-3 u* (Ergun drag at ε < 0.1 there).
STORED_BED_DEPTH_D = 0.5


@dataclass(frozen=True)
class ChannelParams:
    """Periodic channel LES parameters. Lengths in units of the half height h (lx_h, lz_h)
    or metres (h); ν in m²/s; times in nominal wall units."""

    re_tau: float = 395.0              # target friction Reynolds number u_τ h/ν
    lx_h: float = 4.0                  # streamwise box length / h
    lz_h: float = 2.0                  # spanwise box width / h
    nx: int = 48                       # cells streamwise (uniform)
    ny: int = 64                       # cells wall-normal, both halves (even)
    nz: int = 64                       # cells spanwise (uniform)
    first_cell_yplus: float = 0.8      # first cell centre, nominal y⁺
    snapshot_interval_tplus: float = 4.0
    n_snapshots: int = 80
    spinup_tplus: float = 650.0        # discarded development time
    nprocs: int = 1                    # >1: decomposePar + mpirun
    initial: str = "map"               # "map" (tutorial field) or "perturb"
    nu: float = 2e-5                   # kinematic viscosity, m²/s
    h: float = 1.0                     # half height, m
    max_courant: float = 0.5           # adaptive time step limit
    convection: str = "linear"         # "linear" or "LUST" for div(phi,U)
    seed: int = 0                      # random noise of the "perturb" initial condition
    # Rough bed (SPEC §3, flowfields.rough_bed): "smooth" walls, or "porous": a layer of
    # packed grains of d⁺ = bed_d_plus, bed_depth_d grains deep, below each bed top, with
    # Ergun drag per cell layer; driven by a fixed gradient u*²/h (h = depth above the bed
    # top), so that u* and the grain's d⁺ are what was asked for.
    bed: str = "smooth"
    bed_d_plus: float = 19.5           # bed grain diameter in wall units (Re* of the grains)
    bed_depth_d: float = 1.0           # porous layer thickness below the bed top, in d
    bed_porosity: float = 0.2595       # bulk porosity of the packing (close-packed spheres)
    ny_bed: int = 12                   # uniform cells across the porous layer

    def __post_init__(self):
        def positive(name):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")

        for name in ("re_tau", "lx_h", "lz_h", "first_cell_yplus", "snapshot_interval_tplus",
                     "spinup_tplus", "nu", "h", "max_courant"):
            positive(name)
        for name, minimum in (("nx", 2), ("ny", 4), ("nz", 2), ("n_snapshots", 1), ("nprocs", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
                raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
        if self.ny % 2:
            raise ValueError(f"ny must be even (two blocks graded towards the two walls), got {self.ny}")
        if self.bed not in BED_KINDS:
            raise ValueError(f"bed must be one of {BED_KINDS}, got {self.bed!r}")
        if self.bed == "porous":
            if not (isinstance(self.bed_d_plus, (int, float)) and math.isfinite(self.bed_d_plus)
                    and BED_D_PLUS_RANGE[0] <= self.bed_d_plus <= BED_D_PLUS_RANGE[1]):
                raise ValueError(f"bed_d_plus (the bed grain's d+, roughness) must lie in {BED_D_PLUS_RANGE} "
                                 f"(hydraulically smooth below, beyond the mesh's reach above), got {self.bed_d_plus!r}")
            if not (isinstance(self.bed_depth_d, (int, float)) and 0.5 <= self.bed_depth_d <= 5.0):
                raise ValueError(f"bed_depth_d must lie between 0.5 and 5 grain diameters, got {self.bed_depth_d!r}")
            rb.check_porosity(self.bed_porosity)
            if isinstance(self.ny_bed, bool) or not isinstance(self.ny_bed, int) or self.ny_bed < 4:
                raise ValueError(f"ny_bed must be an integer >= 4, got {self.ny_bed!r}")
            if self.bed_d_plus * self.bed_depth_d / self.ny_bed > 4.0:
                raise ValueError(f"bed cells of {self.bed_d_plus * self.bed_depth_d / self.ny_bed:.2f} wall units "
                                 "cannot resolve the grains' porosity profile: raise ny_bed (cells ≤ 4 wall units)")
        if self.initial not in INITIAL_CONDITIONS:
            raise ValueError(f"initial must be one of {INITIAL_CONDITIONS}, got {self.initial!r}")
        if self.convection not in ("linear", "LUST"):
            raise ValueError(f"convection must be 'linear' or 'LUST', got {self.convection!r}")
        if self.max_courant > 1.0:
            raise ValueError(f"max_courant must be <= 1 for this PISO LES, got {self.max_courant}")
        uniform_yplus = 0.5 * self.re_tau / (self.ny // 2)
        if self.first_cell_yplus > uniform_yplus:
            raise ValueError(
                f"first_cell_yplus={self.first_cell_yplus} exceeds the uniform-mesh value "
                f"{uniform_yplus:.3g} for ny={self.ny} at re_tau={self.re_tau}")

    # -- derived quantities (SI unless '_plus') --
    @property
    def u_tau(self) -> float:
        """Nominal friction velocity Re_τ ν/h (m/s)."""
        return of.friction_velocity(self.re_tau, self.nu, self.h)

    @property
    def ubar_plus(self) -> float:
        return of.bulk_velocity_plus(self.re_tau)

    @property
    def ubar(self) -> float:
        """Bulk velocity held by meanVelocityForce (m/s)."""
        return self.ubar_plus * self.u_tau

    # -- rough bed (bed = "porous") --
    @property
    def grain_diameter(self) -> float:
        """Bed grain diameter d (m) = d⁺ ν/u_τ."""
        return self.bed_d_plus * self.nu / self.u_tau

    @property
    def bed_thickness(self) -> float:
        """Porous layer thickness b (m) below each bed top."""
        return self.bed_depth_d * self.grain_diameter if self.bed == "porous" else 0.0

    @property
    def rough_ubar(self) -> float:
        """Bulk velocity of the whole rough box (bed layers at rest included), m/s."""
        return self.rough_ubar_estimate_plus * self.u_tau * self.h / (self.h + self.bed_thickness)

    def bed_layers(self) -> list[dict]:
        """Porous zones (one per bed cell layer, in d below the bed top)."""
        faces = np.linspace(-self.bed_depth_d, 0.0, self.ny_bed + 1)
        return rb.bed_layers(faces, self.grain_diameter, self.bed_porosity)

    @property
    def rough_ubar_estimate_plus(self) -> float:
        """Bulk u⁺ above the bed top expected before the run: the smooth value less
        Colebrook's ΔU⁺ at k_s = d (only scales the initial field)."""
        return self.ubar_plus - float(rb.colebrook_delta_u(self.bed_d_plus))

    @property
    def viscous_time(self) -> float:
        """ν/u_τ² (s): one nominal t⁺."""
        return self.nu / self.u_tau**2

    @property
    def lx(self) -> float:
        return self.lx_h * self.h

    @property
    def lz(self) -> float:
        return self.lz_h * self.h

    @property
    def expansion(self) -> float:
        """blockMesh expansion ratio of the lower block (last/first cell)."""
        return of.wall_grading(self.ny // 2, self.re_tau, self.first_cell_yplus, self.h)

    # Physical times are rounded to 8 significant digits (a relative change of ≤ 5e-8 in
    # t⁺) so that every write time has a short decimal name: OpenFOAM names time
    # directories with `timePrecision` digits, and a restart from a time whose name
    # needed more digits than that looks for a directory that does not exist.
    @property
    def spinup_time(self) -> float:
        return round_significant(self.spinup_tplus * self.viscous_time)

    @property
    def snapshot_interval(self) -> float:
        return round_significant(self.snapshot_interval_tplus * self.viscous_time)

    @property
    def end_time(self) -> float:
        return self.spinup_time + self.n_snapshots * self.snapshot_interval

    def resolution_plus(self) -> dict:
        """Nominal grid spacings in wall units."""
        yf = of.wall_normal_faces(self.ny, self.h, self.expansion)
        dy = np.diff(yf) * self.re_tau / self.h
        return {
            "dx_plus": self.lx_h * self.re_tau / self.nx,
            "dz_plus": self.lz_h * self.re_tau / self.nz,
            "dy_plus_wall": float(dy[0]),
            "dy_plus_centre": float(dy[self.ny // 2 - 1]),
            "first_cell_yplus": float(0.5 * dy[0]),
            "cell_growth_ratio": float(self.expansion ** (1.0 / max(1, self.ny // 2 - 1))),
            "n_cells": self.nx * (self.ny + (2 * self.ny_bed if self.bed == "porous" else 0)) * self.nz,
        }

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def round_significant(x: float, digits: int = 8) -> float:
    """x rounded to `digits` significant decimal digits."""
    if x == 0:
        return 0.0
    return round(x, digits - 1 - int(math.floor(math.log10(abs(x)))))


# --------------------------------------------------------------------------------------
# Stages
# --------------------------------------------------------------------------------------


def _say(msg: str) -> None:
    print(f"[flowfields.generate {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def _initial_delta_t(p: ChannelParams) -> float:
    """A first step safely under the Courant limit; pimpleFoam then adapts it."""
    dx = min(p.lx / p.nx, p.lz / p.nz)
    return 0.25 * p.max_courant * dx / p.ubar


def _max_delta_t(p: ChannelParams) -> float:
    # Courant binds first on the meshes we use; cap Δt⁺ at 1 regardless (the near-wall
    # cycle's shortest time scales are a few viscous times).
    return min(1.0 * p.viscous_time, p.snapshot_interval)


def write_case(p: ChannelParams, case: Path, commands: list) -> dict:
    """Dictionaries, mesh and initial fields. Returns a description of the IC."""
    of.write_channel_case(case, lx=p.lx, lz=p.lz, h=p.h, nx=p.nx, ny=p.ny, nz=p.nz,
                          expansion=p.expansion, nu=p.nu, ubar=p.ubar, end_time=p.spinup_time,
                          write_interval=p.spinup_time, delta_t=_initial_delta_t(p),
                          max_courant=p.max_courant, max_delta_t=_max_delta_t(p),
                          convection=p.convection, nprocs=p.nprocs)
    if p.bed == "porous":
        # the bed layers below both bed tops, their porous zones and the fixed gradient
        of.write_rough_block_mesh_dict(case, lx=p.lx, lz=p.lz, h=p.h, b=p.bed_thickness, nx=p.nx,
                                       ny=p.ny, ny_bed=p.ny_bed, nz=p.nz, expansion=p.expansion)
        of.write_bed_topo_set(case, p.bed_layers(), lx=p.lx, lz=p.lz, h=p.h, b=p.bed_thickness,
                              d=p.grain_diameter)
        of.write_fv_options(case, p.rough_ubar, p.bed_layers())
        of.write_control_dict(case, end_time=p.spinup_time, write_interval=p.spinup_time,
                              delta_t=_initial_delta_t(p), max_courant=p.max_courant,
                              max_delta_t=_max_delta_t(p))
    if p.initial == "map":
        source = of.prepare_tutorial_source(case / "channel395_source", commands)
        U = of.map_tutorial_velocity(case, source, lx=p.lx, lz=p.lz, h=p.h, nx=p.nx, ny=p.ny,
                                     nz=p.nz, expansion=p.expansion, ubar=p.ubar,
                                     commands=commands)
        shutil.rmtree(case / "map_stage")  # intermediate mesh, no longer needed
        ic = {"initial": "map", "source": str(of.TUTORIAL_CHANNEL395),
              "method": "mapFields -consistent onto the target cell counts/grading in the "
                        "tutorial's 4x2x2 box, values carried cell by cell to the target box, "
                        f"velocity scaled by Ubar/{of.TUTORIAL_UBAR}"}
    else:
        centres = of.cell_centres(p.lx, p.lz, p.h, p.nx, p.ny, p.nz, p.expansion)
        volumes = of.cell_volumes(p.lx, p.lz, p.h, p.nx, p.ny, p.nz, p.expansion)
        U = of.perturbed_channel_velocity(centres, volumes, lx=p.lx, lz=p.lz, h=p.h, nu=p.nu,
                                          re_tau=p.re_tau, ubar=p.ubar, seed=p.seed)
        ic = {"initial": "perturb", "seed": p.seed,
              "method": "Reichardt mean profile scaled to Ubar + streaks (spacing 100 nu/u_tau, "
                        "peak y+=15, amplitude 3 u_tau) + meandering w + 5% Ubar noise"}
    if p.bed == "porous":
        # the smooth field above the bed tops, slowed to the expected rough bulk velocity;
        # the bed blocks (numbered after the fluid blocks) start at rest
        U = np.vstack([U * (p.rough_ubar_estimate_plus / p.ubar_plus),
                       np.zeros((2 * p.nx * p.ny_bed * p.nz, 3))])
        ic["bed"] = (f"fluid velocity scaled by {p.rough_ubar_estimate_plus / p.ubar_plus:.4f} "
                     "(Colebrook's ΔU+ at k_s = d off the smooth bulk u+); bed at rest")
    of.write_velocity_field(case, U)
    of.write_scalar_fields(case)
    of.run_block_mesh(case, commands)
    if p.bed == "porous":
        of.run_tool(["topoSet"], case, "topoSet", commands=commands)
    return ic


def _progress_printer(stage: str, p: ChannelParams, t_begin: float, t_end: float):
    wall0 = time.time()

    def report(log: Path) -> None:
        t, _, co = of.last_time_and_pressure_gradient(log)
        if t is None:
            return
        grads = re_grads(log)
        tplus, tplus_end = (t - t_begin) / p.viscous_time, (t_end - t_begin) / p.viscous_time
        elapsed = time.time() - wall0
        frac = max(1e-9, (t - t_begin) / (t_end - t_begin))
        msg = (f"{stage}: t+ = {tplus:7.1f} / {tplus_end:.1f} ({100 * frac:4.1f} %), "
               f"Co max = {co if co is None else round(co, 3)}, elapsed {elapsed:6.0f} s, "
               f"ETA {elapsed / frac - elapsed:6.0f} s")
        if grads is not None:
            u_tau = math.sqrt(max(grads, 0.0) * p.h)  # dp/dx = u_τ²/h in equilibrium
            msg += f", Re_tau(dp/dx, last steps) = {u_tau * p.h / p.nu:5.1f}"
        _say(msg)

    def re_grads(log: Path):
        import re
        vals = re.findall(r"pressure gradient = ([-+0-9.eE]+)", of._tail(log, 60000))
        return float(np.mean([float(v) for v in vals])) if vals else None

    return report


def spinup_check(log: Path, p: ChannelParams) -> dict:
    """Has the wall shear settled? Compare the Re_τ implied by the driving pressure
    gradient (time-averaged dp/dx = u_τ²/h) over the second-last and last quarter of
    the spin-up."""
    hist = of.pressure_gradient_history(log)
    if len(hist) < 8:
        return {"n_steps": int(len(hist))}
    # one value per time step (the last pressure corrector's)
    _, last_idx = np.unique(hist[::-1, 0], return_index=True)
    per_step = hist[::-1][last_idx]
    t, g = per_step[:, 0], per_step[:, 1]
    quarter = (t[-1] - t[0]) / 4.0
    q3 = (t >= t[-1] - 2 * quarter) & (t < t[-1] - quarter)
    q4 = t >= t[-1] - quarter
    if not q3.any() or not q4.any():
        return {"n_steps": int(len(t))}
    re3 = math.sqrt(max(float(g[q3].mean()), 0.0) * p.h) * p.h / p.nu
    re4 = math.sqrt(max(float(g[q4].mean()), 0.0) * p.h) * p.h / p.nu
    out = {"n_steps": int(len(t)), "re_tau_dpdx_third_quarter": round(re3, 2),
           "re_tau_dpdx_last_quarter": round(re4, 2)}
    if re3 > 0:
        out["relative_change"] = round((re4 - re3) / re3, 4)
    return out


ROUGH_SPINUP_PHASES = 3


def _spin_up_to_target(p: ChannelParams, case: Path, commands: list) -> list[dict]:
    """Rough bed: the flow rate that gives the requested u* over the bed is not known
    before the run (it depends on the bed's ΔU⁺). The spin-up runs in ROUGH_SPINUP_PHASES
    equal phases; after each but the last, u* is measured from the mean driving gradient
    over the phase's second half (momentum balance at the bed top) and the flow rate is
    scaled by Re_τ,target/Re_τ,measured, so the grain's d⁺ comes out as asked. The last
    phase is run by the caller. Returns the corrections made."""
    corrections = []
    ubar = p.rough_ubar
    t_prev = 0.0
    for k in range(1, ROUGH_SPINUP_PHASES):
        t_end = round_significant(k * p.spinup_time / ROUGH_SPINUP_PHASES)
        of.write_control_dict(case, end_time=t_end, write_interval=t_end - t_prev, delta_t=_initial_delta_t(p),
                              max_courant=p.max_courant, max_delta_t=_max_delta_t(p))
        log = of.run_pimple_foam(case, nprocs=p.nprocs, log_name=f"pimpleFoam.spinup{k}", commands=commands,
                                 progress=_progress_printer(f"spin-up ({k}/{ROUGH_SPINUP_PHASES})", p, 0.0,
                                                            p.spinup_time))
        hist = of.pressure_gradient_history(log)
        late = hist[hist[:, 0] >= 0.5 * (t_prev + t_end), 1] if len(hist) else hist
        g_late = float(np.mean(late)) if len(late) else float("nan")
        if not math.isfinite(g_late):
            raise of.OpenFOAMError(f"no driving-gradient lines in {log}: the flow did not run")
        # a gradient ≤ 0 holds back a flow far too fast for its bed: halve the flow rate
        re_meas = math.sqrt(max(g_late, 0.0) * p.h) * p.h / p.nu
        # at most a factor 2 per phase (a flow far from its equilibrium is corrected over
        # several phases; what it reaches is measured and recorded in the end)
        factor = min(2.0, max(0.5, p.re_tau / re_meas)) if re_meas > 0 else 0.5
        ubar *= factor
        of.write_fv_options(case, ubar, p.bed_layers())
        corrections.append({"phase": k, "t_end_s": t_end, "re_tau_measured": round(re_meas, 2),
                            "factor": round(factor, 5), "ubar_m_s": ubar})
        _say(f"spin-up phase {k}: Re_tau = {re_meas:.1f} from the driving gradient; flow rate scaled by {factor:.4f}")
        t_prev = t_end
    # the caller's last phase: one write, at the spin-up end (write times count from the run's start)
    of.write_control_dict(case, end_time=p.spinup_time, write_interval=p.spinup_time - t_prev,
                          delta_t=_initial_delta_t(p), max_courant=p.max_courant,
                          max_delta_t=_max_delta_t(p))
    return corrections


def run_channel_les(p: ChannelParams, case: Path | str, command_line: str | None = None,
                    overwrite: bool = False) -> tuple[Path, dict]:
    """Run the whole OpenFOAM chain in the case directory `case`.

    Returns (path of the VTK .vtm.series, provenance dict). The provenance is also written
    to `case/provenance.json`.
    """
    case = Path(case).resolve()
    _prepare_case_dir(case, overwrite)
    commands: list = []
    walls: dict = {}
    if command_line is None:
        command_line = " ".join(shlex.quote(a) for a in sys.argv)
    res = p.resolution_plus()
    _say(f"case {case}: {p.nx}x{p.ny}x{p.nz} = {res['n_cells']} cells, "
         f"dx+ = {res['dx_plus']:.1f}, dz+ = {res['dz_plus']:.1f}, first cell y+ = "
         f"{res['first_cell_yplus']:.2f}, dy+ centre = {res['dy_plus_centre']:.1f}; "
         f"Ubar = {p.ubar:.6g} m/s (Ub+ = {p.ubar_plus:.3f}), nominal u_tau = {p.u_tau:.6g} m/s")

    t0 = time.time()
    _say(f"stage 1: writing case, blockMesh, initial condition '{p.initial}'")
    ic = write_case(p, case, commands)
    walls["case_mesh_initial_condition"] = round(time.time() - t0, 1)

    if p.nprocs > 1:
        t0 = time.time()
        of.run_decompose_par(case, commands)
        walls["decomposePar"] = round(time.time() - t0, 1)

    t0 = time.time()
    _say(f"stage 2: spin-up, {p.spinup_tplus} t+ (t = 0 .. {p.spinup_time:.6g} s)")
    ubar_correction = None
    if p.bed == "porous":
        ubar_correction = _spin_up_to_target(p, case, commands)
    spin_log = of.run_pimple_foam(case, nprocs=p.nprocs, log_name="pimpleFoam.spinup",
                                  commands=commands,
                                  progress=_progress_printer("spin-up", p, 0.0, p.spinup_time))
    walls["spinup"] = round(time.time() - t0, 1)
    if not any(abs(t - p.spinup_time) <= 1e-9 * p.spinup_time
               for t, _ in of.time_directories(case if p.nprocs == 1 else case / "processor0")):
        raise of.OpenFOAMError(f"pimpleFoam wrote no time directory at the spin-up end "
                               f"t = {p.spinup_time:.12g} in {case}; see {spin_log}")
    settle = spinup_check(spin_log, p)
    if p.bed == "porous":
        settle["ubar_correction"] = ubar_correction
    _say(f"spin-up done in {walls['spinup']:.0f} s; wall-shear check {settle}")

    t0 = time.time()
    _say(f"stage 3: sampling {p.n_snapshots} snapshots every {p.snapshot_interval_tplus} t+ "
         f"({p.snapshot_interval:.6g} s)")
    of.write_control_dict(case, end_time=p.end_time, write_interval=p.snapshot_interval,
                          delta_t=_initial_delta_t(p), max_courant=p.max_courant,
                          max_delta_t=_max_delta_t(p))
    of.run_pimple_foam(case, nprocs=p.nprocs, log_name="pimpleFoam.sampling", commands=commands,
                       progress=_progress_printer("sampling", p, p.spinup_time, p.end_time))
    walls["sampling"] = round(time.time() - t0, 1)

    # Snapshot times: strictly after the spin-up end, up to the end time.
    half = 0.5 * p.snapshot_interval
    time_range = of.time_range_arg(p.spinup_time + half, p.end_time + half)
    if p.nprocs > 1:
        t0 = time.time()
        of.run_reconstruct_par(case, time_range, commands)
        walls["reconstructPar"] = round(time.time() - t0, 1)
    times = [t for t, _ in of.time_directories(case) if t > p.spinup_time + half * 1e-3]
    if len(times) != p.n_snapshots:
        raise of.OpenFOAMError(f"expected {p.n_snapshots} snapshot time directories after "
                               f"t = {p.spinup_time:.6g} in {case}, found {len(times)}; "
                               f"see {case / 'log.pimpleFoam.sampling'}")

    t0 = time.time()
    _say("stage 4: foamToVTK (internal mesh, cell U)")
    series = of.run_foam_to_vtk(case, time_range=time_range, fields=("U",), commands=commands)
    walls["foamToVTK"] = round(time.time() - t0, 1)
    _say(f"wrote {series}; stage wall times (s): {walls}")

    provenance = {
        "generator": "flowfields.generate.run_channel_les",
        "openfoam_version": of.openfoam_version(case / "log.blockMesh"),
        "command_line": command_line,
        "params": p.as_dict(),
        "derived": {
            "u_tau_nominal_m_s": p.u_tau, "ubar_m_s": p.ubar, "ubar_plus": p.ubar_plus,
            "ubar_plus_source": "Reichardt (1951) profile integrated over the half channel",
            "viscous_time_s": p.viscous_time, "spinup_time_s": p.spinup_time,
            "snapshot_interval_s": p.snapshot_interval, "end_time_s": p.end_time,
            "block_expansion_ratio": p.expansion, **res,
        },
        "solver": {
            "application": "pimpleFoam (PISO: 1 outer, 2 pressure correctors)",
            "les_model": "WALE (Cw 0.325), delta cubeRootVol",
            "forcing": "meanVelocityForce holding Ubar",
            "ddt": "backward", "div(phi,U)": p.convection,
            "time_step": f"adaptive, maxCo {p.max_courant}, maxDeltaT {_max_delta_t(p):.6g} s",
        },
        "initial_condition": ic,
        "spinup_check": settle,
        "sampling_check": spinup_check(case / "log.pimpleFoam.sampling", p),
        "bed": bed_description(p, case / "log.pimpleFoam.sampling"),
        "snapshot_times_s": times,
        "case_dir": str(case),
        "vtk_series": str(series),
        "commands": commands,
        "stage_wall_s": walls,
    }
    (case / "provenance.json").write_text(json.dumps(provenance, indent=2))
    return series, provenance


def measured_u_tau(log: Path, p: ChannelParams) -> float:
    """u* from the momentum balance of the fluid above the bed top, u*² = ⟨G⟩ h, with ⟨G⟩
    the driving gradient averaged over the sampling run (m/s)."""
    hist = of.pressure_gradient_history(log)
    if not len(hist):
        raise of.OpenFOAMError(f"{log}: no driving-gradient lines ('pressure gradient = '); cannot measure u*")
    g = float(np.mean(hist[:, 1]))
    if not g > 0:
        raise of.OpenFOAMError(f"{log}: mean driving gradient {g} is not positive")
    return math.sqrt(g * p.h)


def bed_description(p: ChannelParams, sampling_log: Path | None = None) -> dict | None:
    """What the dataset records about its bed (SPEC §3 rough bed)."""
    if p.bed == "smooth":
        return None
    u_tau = measured_u_tau(sampling_log, p) if sampling_log is not None else p.u_tau
    return {
        "u_tau_m_s": u_tau, "d_plus_measured": p.grain_diameter * u_tau / p.nu,
        "re_tau_measured": u_tau * p.h / p.nu,
        "kind": "porous layer of hexagonally close-packed grains, Ergun (1952) Darcy-Forchheimer drag "
                "per cell layer at the layer's mean solid fraction",
        "d_plus": p.bed_d_plus, "depth_d": p.bed_depth_d, "porosity": p.bed_porosity,
        "grain_diameter_m": p.grain_diameter, "thickness_m": p.bed_thickness,
        "bed_top_y_m": [p.bed_thickness, p.bed_thickness + 2.0 * p.h],
        "depth_above_bed_top_m": p.h,
        "u_tau_source": "momentum balance at the bed top: u*^2 = <G> h (G the driving gradient that holds the "
                        "flow rate, averaged over the sampling run; h the depth from the bed top to the centre line)",
        "layers": p.bed_layers(),
    }


def _prepare_case_dir(case: Path, overwrite: bool) -> None:
    if case.exists() and (case / "system" / "controlDict").exists():
        if not overwrite:
            raise FileExistsError(f"{case} already holds an OpenFOAM case; pass overwrite=True "
                                  "or choose another work_dir")
        # Remove only what this module writes.
        for child in case.iterdir():
            is_time = _is_number(child.name)
            if (is_time or child.name in ("system", "constant", "VTK", "map_stage",
                                          "postProcessing", "provenance.json")
                    or child.name.startswith(("processor", "log."))):
                shutil.rmtree(child) if child.is_dir() else child.unlink()
    case.mkdir(parents=True, exist_ok=True)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def generate(params: ChannelParams, out_dataset, work_dir, command_line: str | None = None,
             y_max_plus: float | None = None, dtype: str = "float32",
             overwrite: bool = False) -> Path:
    """Run the OpenFOAM LES in `work_dir` (the case directory) and import its snapshots
    into the dataset `out_dataset`. Returns the dataset path."""
    if dtype not in ("float32", "int16"):
        raise ValueError(f"dtype must be 'float32' or 'int16', got {dtype!r}")
    if y_max_plus is not None and not y_max_plus > 0:
        raise ValueError(f"y_max_plus must be positive, got {y_max_plus!r}")
    series, provenance = run_channel_les(params, work_dir, command_line=command_line,
                                         overwrite=overwrite)
    from flowfields.importer import import_series  # lazy: importer is a separate module

    t0 = time.time()
    _say(f"stage 5: importing {series} into {out_dataset}")
    rough = {}
    if params.bed == "porous":
        # y = 0 at the bottom bed top; u* from the momentum balance there, not the wall
        bed = provenance["bed"]
        rough = {"y_origin": params.bed_thickness, "u_tau": bed["u_tau_m_s"],
                 "y_min": params.bed_thickness - STORED_BED_DEPTH_D * params.grain_diameter,
                 "bed_d_plus": bed["d_plus_measured"]}
    result = import_series(series, out_dataset, nu=params.nu, provenance=provenance,
                           y_max_plus=y_max_plus, dtype=dtype, **rough)
    _say(f"import done in {time.time() - t0:.0f} s")
    path = Path(result) if result is not None else Path(out_dataset)
    if params.bed == "porous":
        fit = record_roughness(path)
        if "error" in fit:
            _say(f"rough bed: no roughness fit ({fit['error']})")
        else:
            _say(f"rough bed: dU+ = {fit['delta_u_plus']:.2f}, virtual origin {fit['virtual_origin_d']:.3f} d, "
                 f"k_s = {fit['ks_d_colebrook']:.2f} d (Colebrook)")
    return path


def record_roughness(dataset_path) -> dict:
    """Measure the rough bed's ΔU⁺, virtual origin and k_s from the dataset's own mean
    profile (rough_bed.roughness_fit) and record them in its meta.json "bed"."""
    from flowfields.check import profile_statistics
    from flowfields.dataset import open_dataset

    ds = open_dataset(dataset_path)
    prof = profile_statistics(ds)
    meta_file = Path(dataset_path) / "meta.json"
    meta = json.loads(meta_file.read_text())
    try:
        fit = rb.roughness_fit(prof["y_plus"].to_numpy(), prof["u_plus"].to_numpy(), float(ds.bed["d_plus"]),
                               re_tau=ds.re_tau)
    except ValueError as exc:  # a channel too shallow for a log region
        meta["bed"]["roughness_fit_error"] = str(exc)
        meta_file.write_text(json.dumps(meta, indent=1))
        return {"error": str(exc)}
    meta["bed"].update({k: fit[k] for k in ("delta_u_plus", "virtual_origin_plus", "virtual_origin_d",
                                            "ks_plus_colebrook", "ks_d_colebrook", "ks_plus_nikuradse",
                                            "ks_d_nikuradse", "log_range_plus", "log_fit_max_rel_dev")})
    meta_file.write_text(json.dumps(meta, indent=1))
    return fit


# --------------------------------------------------------------------------------------
# Command line: python -m flowfields.generate
# --------------------------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m flowfields.generate", description=__doc__.split("\n")[0])
    defaults = ChannelParams()
    for f in dataclasses.fields(ChannelParams):
        ap.add_argument("--" + f.name.replace("_", "-"), type=type(getattr(defaults, f.name)),
                        default=getattr(defaults, f.name), help=f"(default {getattr(defaults, f.name)!r})")
    ap.add_argument("--work-dir", required=True, help="OpenFOAM case directory")
    ap.add_argument("--out", help="dataset path (required unless --les-only)")
    ap.add_argument("--les-only", action="store_true", help="stop after the VTK export")
    ap.add_argument("--y-max-plus", type=float, default=None)
    ap.add_argument("--dtype", default="float32", choices=("float32", "int16"))
    ap.add_argument("--overwrite", action="store_true")
    return ap


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = _parser().parse_args(argv)
    kwargs = {f.name: getattr(args, f.name) for f in dataclasses.fields(ChannelParams)}
    params = ChannelParams(**kwargs)
    command_line = "python -m flowfields.generate " + " ".join(shlex.quote(a) for a in argv)
    if args.les_only:
        series, _ = run_channel_les(params, args.work_dir, command_line=command_line,
                                    overwrite=args.overwrite)
        print(series)
        return 0
    if not args.out:
        raise SystemExit("--out is required unless --les-only")
    print(generate(params, args.out, args.work_dir, command_line=command_line,
                   y_max_plus=args.y_max_plus, dtype=args.dtype, overwrite=args.overwrite))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
