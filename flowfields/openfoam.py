"""OpenFOAM case writer and runner for a periodic turbulent channel LES (SPEC §3).

Geometry: streamwise x in [0, lx], wall-normal y in [0, 2h] (walls at y = 0 and y = 2h),
spanwise z in [0, lz]; x and z periodic (cyclic patch pairs), no-slip walls `bottomWall`
and `topWall`. The mesh is two blockMesh blocks (lower and upper half channel), each
geometrically graded towards its wall so that the first cell centre sits at a requested
y⁺ for the target friction Reynolds number Re_τ = u_τ h / ν.

Solver: pimpleFoam (PISO mode: one outer corrector, two pressure correctors), LES with
the WALE sub-grid model and the `cubeRootVol` filter width. WALE's eddy viscosity already
vanishes like y³ at a wall (Nicoud & Ducros 1999), which is the reason to pick it over
Smagorinsky; adding van Driest damping on top would damp the near-wall ν_t twice, so the
plain cube root of the cell volume is used. The flow is driven by the `meanVelocityForce`
fvOption, which adjusts a uniform pressure gradient every step to hold the bulk velocity
at `Ubar`; `Ubar` is set from the target Re_τ through the bulk velocity of a smooth-wall
composite profile (Reichardt 1951, see `bulk_velocity_plus`).

All dictionaries are written from templates in this module; nothing is copied from the
OpenFOAM tutorials. The tutorial `channel395` is only used as the *source* of a developed
turbulent field when the initial condition is mapped (`map_tutorial_velocity`).

Units: SI-like OpenFOAM kinematic units (lengths in m, velocities in m/s, ν in m²/s,
pressure in m²/s²). Wall units use the nominal u_τ = Re_τ ν / h of the target; the LES's
own u_τ is measured later from the exported snapshots.
"""
from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

# Reichardt (1951) composite profile constants (von Kármán constant and the
# buffer-layer constant of his fit); gives u⁺ = y⁺ at the wall and
# u⁺ ≈ 2.44 ln y⁺ + 5.6 in the log layer.
REICHARDT_KAPPA = 0.41
REICHARDT_C = 7.8

TUTORIAL_CHANNEL395 = Path(
    "/usr/share/doc/openfoam-examples/examples/incompressible/pimpleFoam/LES/channel395"
)
# The tutorial's developed field: box 4 x 2 x 2 (h = 1), bulk velocity 0.1335 m/s.
TUTORIAL_BOX = (4.0, 2.0, 2.0)
TUTORIAL_UBAR = 0.1335
TUTORIAL_HALF_HEIGHT = 1.0

DEFAULT_WM_PROJECT_DIR = "/usr/share/openfoam"

WALL_PATCHES = ("bottomWall", "topWall")
# Cyclic pairs of the generated case: (patch, neighbour).
CYCLIC_PAIRS = (("xPeriodic0", "xPeriodic1"), ("zPeriodic0", "zPeriodic1"))
# The tutorial's patch names (one cyclic pair per block and direction), in its order.
# v1912 mapFields -consistent (meshToMesh0) needs the same patches in the same order,
# so the intermediate mesh used for mapping carries these names.
TUTORIAL_CYCLIC_PAIRS = (
    ("sides1_half0", "sides1_half1"),  # z faces, lower block
    ("sides2_half0", "sides2_half1"),  # z faces, upper block
    ("inout1_half0", "inout1_half1"),  # x faces, lower block
    ("inout2_half0", "inout2_half1"),  # x faces, upper block
)


class OpenFOAMError(RuntimeError):
    """An OpenFOAM tool failed; the message names the tool and its log file."""


# --------------------------------------------------------------------------------------
# Physics: mean profile, bulk velocity, wall-normal grading
# --------------------------------------------------------------------------------------


def reichardt_uplus(yplus):
    """Reichardt (1951) smooth-wall composite profile u⁺(y⁺), continuous from y⁺ = 0."""
    yp = np.asarray(yplus, dtype=float)
    k, c = REICHARDT_KAPPA, REICHARDT_C
    return np.log1p(k * yp) / k + c * (1.0 - np.exp(-yp / 11.0) - (yp / 11.0) * np.exp(-yp / 3.0))


def bulk_velocity_plus(re_tau: float, n_points: int = 20001) -> float:
    """Bulk velocity U_b⁺ = (1/Re_τ) ∫₀^Re_τ u⁺(y⁺) dy⁺ of the Reichardt profile.

    Integrated over the half channel (the channel is symmetric). Reichardt has no wake,
    but its log-layer intercept (≈ 5.6) compensates: U_b⁺ = 15.5, 17.6, 18.7 for
    Re_τ = 180, 395, 590 against 15.7, 17.5, 18.6 from the DNS of Moser, Kim & Mansour
    (1999) — within 1.5 %.
    """
    if re_tau <= 0:
        raise ValueError(f"re_tau must be positive, got {re_tau!r}")
    # Cluster points at the wall, where u⁺ changes fastest: y⁺ = Re_τ s², s uniform.
    s = np.linspace(0.0, 1.0, n_points)
    yp = re_tau * s**2
    u = reichardt_uplus(yp)
    return float(np.trapezoid(u * 2.0 * re_tau * s, s) / re_tau)


def friction_velocity(re_tau: float, nu: float, h: float) -> float:
    """Nominal u_τ = Re_τ ν / h (m/s)."""
    return re_tau * nu / h


def bulk_velocity(re_tau: float, nu: float, h: float) -> float:
    """Bulk velocity Ubar (m/s) that a smooth-wall channel at Re_τ carries."""
    return bulk_velocity_plus(re_tau) * friction_velocity(re_tau, nu, h)


def cell_growth_ratio(n_cells: int, length: float, first_cell: float) -> float:
    """Ratio r of successive cell sizes so that n geometric cells, the first of size
    `first_cell`, fill `length`: first_cell (rⁿ − 1)/(r − 1) = length."""
    if n_cells < 1:
        raise ValueError(f"n_cells must be >= 1, got {n_cells}")
    if not (0.0 < first_cell <= length):
        raise ValueError(f"first_cell must be in (0, length], got {first_cell} for length {length}")
    target = length / first_cell  # = sum_{j<n} r^j

    def cells_sum(r: float) -> float:
        if abs(r - 1.0) < 1e-12:
            return float(n_cells)
        return (r**n_cells - 1.0) / (r - 1.0)

    if abs(target - n_cells) < 1e-12 * n_cells:
        return 1.0
    # Bisection on log r (cells_sum is monotonic in r).
    lo, hi = (1.0, 2.0) if target > n_cells else (1e-6, 1.0)
    while target > n_cells and cells_sum(hi) < target:
        hi *= 2.0
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if cells_sum(mid) < target:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


def wall_grading(ny_half: int, re_tau: float, first_cell_yplus: float, h: float = 1.0) -> float:
    """blockMesh expansion ratio (last cell / first cell) of one half-channel block whose
    first cell centre sits at `first_cell_yplus` (nominal wall units).

    The first cell then has height 2 y₁⁺ ν/u_τ = 2 y₁⁺ h / Re_τ.
    """
    first_cell = 2.0 * first_cell_yplus * h / re_tau
    if first_cell * ny_half > h * (1.0 + 1e-12):
        raise ValueError(
            f"first_cell_yplus={first_cell_yplus} is too large for {ny_half} cells per half "
            f"channel at re_tau={re_tau}: a uniform mesh already has its first centre at "
            f"y+ = {0.5 * re_tau / ny_half:.3g}"
        )
    r = cell_growth_ratio(ny_half, h, first_cell)
    return r ** (ny_half - 1)


def wall_normal_faces(ny: int, h: float, expansion: float) -> np.ndarray:
    """Face coordinates y_0 = 0 … y_ny = 2h of the two symmetrically graded blocks,
    following blockMesh's geometric distribution (cell ratio r = expansion^(1/(n−1)))."""
    n = ny // 2
    r = expansion ** (1.0 / (n - 1)) if n > 1 else 1.0
    j = np.arange(n + 1, dtype=float)
    if abs(r - 1.0) < 1e-14:
        frac = j / n
    else:
        frac = (r**j - 1.0) / (r**n - 1.0)
    lower = h * frac
    upper = 2.0 * h - lower[::-1]
    return np.concatenate([lower, upper[1:]])


def cell_centres(lx: float, lz: float, h: float, nx: int, ny: int, nz: int,
                 expansion: float) -> np.ndarray:
    """Cell centres (N, 3) in blockMesh's cell order: block 0 (lower half) then block 1,
    within a block x fastest, then y, then z (hexahedra with straight edges, so the
    centroid is the midpoint)."""
    yf = wall_normal_faces(ny, h, expansion)
    xc = (np.arange(nx) + 0.5) * lx / nx
    zc = (np.arange(nz) + 0.5) * lz / nz
    yc = 0.5 * (yf[1:] + yf[:-1])
    n = ny // 2
    blocks = []
    for yb in (yc[:n], yc[n:]):
        Z, Y, X = np.meshgrid(zc, yb, xc, indexing="ij")
        blocks.append(np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]))
    return np.vstack(blocks)


def cell_volumes(lx: float, lz: float, h: float, nx: int, ny: int, nz: int,
                 expansion: float) -> np.ndarray:
    """Cell volumes in the same order as `cell_centres`."""
    dy = np.diff(wall_normal_faces(ny, h, expansion))
    n = ny // 2
    out = []
    for dyb in (dy[:n], dy[n:]):
        vol = np.broadcast_to((lx / nx) * (lz / nz) * dyb[None, :, None], (nz, n, nx))
        out.append(vol.ravel())
    return np.concatenate(out)


# --------------------------------------------------------------------------------------
# Dictionary writers
# --------------------------------------------------------------------------------------


def foam_header(cls: str, obj: str, location: str | None = None, fmt: str = "ascii") -> str:
    loc = f"    location    \"{location}\";\n" if location else ""
    return (
        "/* Written by saltation flowfields.openfoam for OpenFOAM v1912 (openfoam.com) */\n"
        "FoamFile\n{\n"
        "    version     2.0;\n"
        f"    format      {fmt};\n"
        f"    class       {cls};\n"
        f"{loc}"
        f"    object      {obj};\n"
        "}\n\n"
    )


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _fmt(x: float) -> str:
    return f"{x:.12g}"


def write_block_mesh_dict(case: Path, *, lx: float, lz: float, h: float, nx: int, ny: int,
                          nz: int, expansion: float, tutorial_patch_names: bool = False) -> Path:
    """Two hex blocks (lower/upper half channel) graded towards their walls.

    `tutorial_patch_names=True` names the cyclic patches as in the channel395 tutorial
    (one pair per block) so that mapFields can map that tutorial's field consistently.
    """
    if ny % 2:
        raise ValueError(f"ny must be even (two symmetric blocks), got {ny}")
    n = ny // 2
    # Vertices: index = 2*level + (x end), level 0..2 at y = 0, h, 2h; +6 for z = lz.
    verts = []
    for z in (0.0, lz):
        for y in (0.0, h, 2.0 * h):
            for x in (0.0, lx):
                verts.append((x, y, z))
    v = "\n".join(f"    ({_fmt(a)} {_fmt(b)} {_fmt(c)})" for a, b, c in verts)
    # hex (x0y0z0 x1y0z0 x1y1z0 x0y1z0 x0y0z1 x1y0z1 x1y1z1 x0y1z1)
    lower = "hex (0 1 3 2 6 7 9 8)"
    upper = "hex (2 3 5 4 8 9 11 10)"
    blocks = (
        f"    {lower} ({nx} {n} {nz}) simpleGrading (1 {_fmt(expansion)} 1)\n"
        f"    {upper} ({nx} {n} {nz}) simpleGrading (1 {_fmt(1.0 / expansion)} 1)"
    )
    # Faces of each block (outward normals don't matter to blockMesh for patches).
    x0 = {"lower": "(0 6 8 2)", "upper": "(2 8 10 4)"}
    x1 = {"lower": "(1 3 9 7)", "upper": "(3 5 11 9)"}
    z0 = {"lower": "(0 2 3 1)", "upper": "(2 4 5 3)"}
    z1 = {"lower": "(6 7 9 8)", "upper": "(8 9 11 10)"}

    def patch(name: str, ptype: str, faces: Iterable[str], neighbour: str | None = None) -> str:
        nb = f"        neighbourPatch  {neighbour};\n" if neighbour else ""
        return (f"    {name}\n    {{\n        type            {ptype};\n{nb}"
                f"        faces           ({' '.join(faces)});\n    }}\n")

    patches = [patch("bottomWall", "wall", ["(0 1 7 6)"]),
               patch("topWall", "wall", ["(4 10 11 5)"])]
    if tutorial_patch_names:
        for (a, b), fa, fb, blk in (
            (TUTORIAL_CYCLIC_PAIRS[0], z0, z1, "lower"),
            (TUTORIAL_CYCLIC_PAIRS[1], z0, z1, "upper"),
            (TUTORIAL_CYCLIC_PAIRS[2], x1, x0, "lower"),
            (TUTORIAL_CYCLIC_PAIRS[3], x1, x0, "upper"),
        ):
            patches.append(patch(a, "cyclic", [fa[blk]], b))
            patches.append(patch(b, "cyclic", [fb[blk]], a))
    else:
        (xa, xb), (za, zb) = CYCLIC_PAIRS
        patches.append(patch(xa, "cyclic", [x0["lower"], x0["upper"]], xb))
        patches.append(patch(xb, "cyclic", [x1["lower"], x1["upper"]], xa))
        patches.append(patch(za, "cyclic", [z0["lower"], z0["upper"]], zb))
        patches.append(patch(zb, "cyclic", [z1["lower"], z1["upper"]], za))
    text = (foam_header("dictionary", "blockMeshDict", "system")
            + "scale   1;\n\nvertices\n(\n" + v + "\n);\n\n"
            + "blocks\n(\n" + blocks + "\n);\n\nedges\n(\n);\n\n"
            + "boundary\n(\n" + "".join(patches) + ");\n\nmergePatchPairs\n(\n);\n")
    return _write(case / "system" / "blockMeshDict", text)


def patch_names(tutorial_patch_names: bool = False) -> list[str]:
    pairs = TUTORIAL_CYCLIC_PAIRS if tutorial_patch_names else CYCLIC_PAIRS
    return list(WALL_PATCHES) + [p for pair in pairs for p in pair]


def write_control_dict(case: Path, *, end_time: float, write_interval: float,
                       delta_t: float, max_courant: float, max_delta_t: float,
                       write_format: str = "binary", start_from: str = "latestTime") -> Path:
    """pimpleFoam controlDict. The time step adapts to `max_courant`; with
    `adjustableRunTime` OpenFOAM shortens the step to land exactly on every write time,
    so snapshots are equally spaced at `write_interval` after the run's start time."""
    text = foam_header("dictionary", "controlDict", "system") + f"""\
application     pimpleFoam;
startFrom       {start_from};
startTime       0;
stopAt          endTime;
endTime         {_fmt(end_time)};
deltaT          {_fmt(delta_t)};
writeControl    adjustableRunTime;
writeInterval   {_fmt(write_interval)};
purgeWrite      0;
writeFormat     {write_format};
writePrecision  8;
writeCompression off;
timeFormat      general;
timePrecision   12;
runTimeModifiable false;
adjustTimeStep  yes;
maxCo           {_fmt(max_courant)};
maxDeltaT       {_fmt(max_delta_t)};
"""
    return _write(case / "system" / "controlDict", text)


def write_fv_schemes(case: Path, convection: str = "linear") -> Path:
    """Second-order, low-dissipation LES schemes: backward (BDF2) in time, central
    (`linear`) or `LUST` (75 % linear / 25 % linear-upwind, more robust on stretched
    meshes) for momentum convection, linear everywhere else."""
    if convection == "linear":
        div_u = "Gauss linear"
    elif convection == "LUST":
        div_u = "Gauss LUST grad(U)"
    else:
        raise ValueError(f"convection must be 'linear' or 'LUST', got {convection!r}")
    text = foam_header("dictionary", "fvSchemes", "system") + f"""\
ddtSchemes
{{
    default         backward;
}}

gradSchemes
{{
    default         Gauss linear;
}}

divSchemes
{{
    default         none;
    div(phi,U)      {div_u};
    div((nuEff*dev2(T(grad(U))))) Gauss linear;
}}

laplacianSchemes
{{
    default         Gauss linear corrected;
}}

interpolationSchemes
{{
    default         linear;
}}

snGradSchemes
{{
    default         corrected;
}}
"""
    return _write(case / "system" / "fvSchemes", text)


def write_fv_solution(case: Path) -> Path:
    """PISO (one outer corrector, two pressure correctors); GAMG for pressure.
    The pressure level is fixed at one cell: every boundary is cyclic or zero-gradient."""
    text = foam_header("dictionary", "fvSolution", "system") + """\
solvers
{
    p
    {
        solver          GAMG;
        smoother        GaussSeidel;
        tolerance       1e-6;
        relTol          0.05;
    }

    pFinal
    {
        $p;
        tolerance       1e-6;
        relTol          0;
    }

    "(U|UFinal)"
    {
        solver          smoothSolver;
        smoother        symGaussSeidel;
        tolerance       1e-7;
        relTol          0;
    }
}

PIMPLE
{
    momentumPredictor yes;
    nOuterCorrectors 1;
    nCorrectors     2;
    nNonOrthogonalCorrectors 0;
    pRefCell        0;
    pRefValue       0;
}
"""
    return _write(case / "system" / "fvSolution", text)


def write_decompose_par_dict(case: Path, nprocs: int, nx: int, nz: int) -> Path:
    """Simple decomposition in x and z only (whole wall-normal lines stay on one rank)."""
    best = (nprocs, 1)
    for a in range(1, nprocs + 1):
        if nprocs % a == 0:
            b = nprocs // a
            if abs(nx / a - nz / b) < abs(nx / best[0] - nz / best[1]):
                best = (a, b)
    text = foam_header("dictionary", "decomposeParDict", "system") + f"""\
numberOfSubdomains {nprocs};
method          simple;
coeffs
{{
    n           ({best[0]} 1 {best[1]});
}}
"""
    return _write(case / "system" / "decomposeParDict", text)


def write_transport_properties(case: Path, nu: float) -> Path:
    text = foam_header("dictionary", "transportProperties", "constant") + (
        f"transportModel  Newtonian;\n\nnu              {_fmt(nu)};\n")
    return _write(case / "constant" / "transportProperties", text)


def write_turbulence_properties(case: Path, delta: str = "cubeRootVol") -> Path:
    """LES with WALE (Nicoud & Ducros 1999, Cw = 0.325). See the module docstring for
    why the filter width is the plain cube root of the cell volume."""
    if delta != "cubeRootVol":
        raise ValueError(f"only delta='cubeRootVol' is supported, got {delta!r}")
    text = foam_header("dictionary", "turbulenceProperties", "constant") + """\
simulationType  LES;

LES
{
    LESModel        WALE;
    turbulence      on;
    printCoeffs     on;
    WALECoeffs
    {
        Cw              0.325;
        Ck              0.094;
        Ce              1.048;
    }
    delta           cubeRootVol;
    cubeRootVolCoeffs
    {
        deltaCoeff      1;
    }
}
"""
    return _write(case / "constant" / "turbulenceProperties", text)


def write_fv_options(case: Path, ubar: float, bed_layers: Sequence[dict] = ()) -> Path:
    """meanVelocityForce: a uniform streamwise pressure gradient, re-adjusted each step,
    that holds the bulk velocity at `ubar` (constant-flow-rate channel); its gradient G,
    printed each step, gives u*² = ⟨G⟩ × depth above the wall or bed top (the momentum
    balance there, exact on average since the flow rate is fixed). With `bed_layers`
    (a rough bed, flowfields.rough_bed): one Ergun DarcyForchheimer zone per bed cell layer."""
    text = foam_header("dictionary", "fvOptions", "constant") + f"""\
momentumSource
{{
    type            meanVelocityForce;
    selectionMode   all;
    fields          (U);
    Ubar            ({_fmt(ubar)} 0 0);
    relaxation      1;
}}
""" + "".join(_porosity_zone(k, lay) for k, lay in enumerate(bed_layers))
    return _write(case / "constant" / "fvOptions", text)


def _boundary_block(kind: str, tutorial_patch_names: bool = False) -> str:
    """boundaryField for U ('vector'), p or nut ('scalar')."""
    lines = []
    for name in patch_names(tutorial_patch_names):
        if name in WALL_PATCHES:
            if kind == "vector":
                body = "type            noSlip;"
            elif kind == "nut":
                body = "type            zeroGradient;"  # ν_t → 0 at the wall is WALE's own
            else:
                body = "type            zeroGradient;"
        else:
            body = "type            cyclic;"
        lines.append(f"    {name}\n    {{\n        {body}\n    }}\n")
    return "boundaryField\n{\n" + "".join(lines) + "}\n"


def write_velocity_field(case: Path, values: np.ndarray | Sequence[float], time_name: str = "0",
                         tutorial_patch_names: bool = False) -> Path:
    """Write `U` (m/s): a uniform vector (3,) or a nonuniform list (N, 3), ASCII."""
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        internal = f"internalField   uniform ({' '.join(_fmt(c) for c in values)});\n\n"
    else:
        body = "\n".join(f"({a:.9g} {b:.9g} {c:.9g})" for a, b, c in values)
        internal = f"internalField   nonuniform List<vector>\n{len(values)}\n(\n{body}\n)\n;\n\n"
    text = (foam_header("volVectorField", "U", time_name) + "dimensions      [0 1 -1 0 0 0 0];\n\n"
            + internal + _boundary_block("vector", tutorial_patch_names))
    return _write(case / time_name / "U", text)


def write_scalar_fields(case: Path, time_name: str = "0", tutorial_patch_names: bool = False) -> None:
    """Uniform-zero kinematic pressure p (m²/s²) and eddy viscosity nut (m²/s)."""
    for name, dims, kind in (("p", "[0 2 -2 0 0 0 0]", "scalar"), ("nut", "[0 2 -1 0 0 0 0]", "nut")):
        text = (foam_header("volScalarField", name, time_name) + f"dimensions      {dims};\n\n"
                + "internalField   uniform 0;\n\n" + _boundary_block(kind, tutorial_patch_names))
        _write(case / time_name / name, text)


def write_channel_case(case: Path, *, lx: float, lz: float, h: float, nx: int, ny: int, nz: int,
                       expansion: float, nu: float, ubar: float, end_time: float,
                       write_interval: float, delta_t: float, max_courant: float,
                       max_delta_t: float, convection: str = "linear", nprocs: int = 1) -> Path:
    """Write every dictionary of the channel case (mesh, solver, model, forcing).
    Initial fields are written separately (`write_velocity_field`, `write_scalar_fields`,
    `perturbed_channel_velocity`, `map_tutorial_velocity`)."""
    case = Path(case)
    case.mkdir(parents=True, exist_ok=True)
    write_block_mesh_dict(case, lx=lx, lz=lz, h=h, nx=nx, ny=ny, nz=nz, expansion=expansion)
    write_control_dict(case, end_time=end_time, write_interval=write_interval, delta_t=delta_t,
                       max_courant=max_courant, max_delta_t=max_delta_t)
    write_fv_schemes(case, convection)
    write_fv_solution(case)
    write_transport_properties(case, nu)
    write_turbulence_properties(case)
    write_fv_options(case, ubar)
    if nprocs > 1:
        write_decompose_par_dict(case, nprocs, nx, nz)
    return case


# --------------------------------------------------------------------------------------
# Initial conditions
# --------------------------------------------------------------------------------------


def perturbed_channel_velocity(centres: np.ndarray, volumes: np.ndarray, *, lx: float, lz: float,
                               h: float, nu: float, re_tau: float, ubar: float, seed: int = 0,
                               streak_amplitude: float = 3.0, noise_amplitude: float = 0.05
                               ) -> np.ndarray:
    """Turbulent mean profile + near-wall streaks + noise (a de Villiers 2006-style trip).

    - mean: Reichardt u⁺(y⁺) from the nearer wall, rescaled so the volume-weighted bulk
      velocity is exactly `ubar`;
    - streaks: u′ = A u_τ f(y⁺) cos(β z), spanwise spacing ≈ 100 ν/u_τ (Kline et al. 1967),
      f peaking at 1 at y⁺ = 15, decaying away from the wall; a spanwise w′ = A/2 u_τ f(y⁺)
      sin(α x) with one wave per ~ 500 ν/u_τ makes the streaks meander, which is what
      breaks them down into turbulence;
    - noise: uniform random in all components, `noise_amplitude`·Ubar, vanishing at the walls.
    The field is not divergence-free; the first pressure correction projects it.
    """
    u_tau = friction_velocity(re_tau, nu, h)
    x, y, z = centres[:, 0], centres[:, 1], centres[:, 2]
    eta = np.minimum(y, 2.0 * h - y)
    yplus = eta * u_tau / nu
    u_mean = reichardt_uplus(yplus) * u_tau
    u_mean *= ubar / (np.sum(u_mean * volumes) / np.sum(volumes))
    y0 = 15.0
    shape = (yplus / y0) * np.exp(0.5 * (1.0 - (yplus / y0) ** 2))
    n_streaks = max(1, round(lz / (100.0 * nu / u_tau)))
    n_waves = max(1, round(lx / (500.0 * nu / u_tau)))
    beta = 2.0 * math.pi * n_streaks / lz
    alpha = 2.0 * math.pi * n_waves / lx
    rng = np.random.default_rng(seed)
    wall_damping = (eta / h) * (2.0 - eta / h)  # 0 at the walls, 1 at the centre line
    noise = noise_amplitude * ubar * rng.uniform(-1.0, 1.0, size=(len(x), 3)) * wall_damping[:, None]
    U = np.zeros((len(x), 3))
    U[:, 0] = u_mean + streak_amplitude * u_tau * shape * np.cos(beta * z)
    U[:, 2] = 0.5 * streak_amplitude * u_tau * shape * np.sin(alpha * x)
    return U + noise


_VECTOR_RE = re.compile(rb"\(\s*([-+0-9.eE]+)\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s*\)")


def read_ascii_internal_vector_field(path: Path) -> np.ndarray:
    """internalField of an ASCII (optionally .gz) OpenFOAM volVectorField as (N, 3)."""
    path = Path(path)
    if path.suffix == ".gz":
        import gzip
        raw = gzip.open(path, "rb").read()
    else:
        raw = path.read_bytes()
    if b"format      binary" in raw[:2000] or re.search(rb"format\s+binary", raw[:2000]):
        raise ValueError(f"{path} is binary; write it with writeFormat ascii")
    m = re.search(rb"internalField\s+nonuniform\s+List<vector>\s*(\d+)\s*\(", raw)
    if not m:
        m_uni = re.search(rb"internalField\s+uniform\s*\(([^)]*)\)", raw)
        if m_uni:
            raise ValueError(f"{path} has a uniform internalField; nothing was mapped")
        raise ValueError(f"no internalField List<vector> found in {path}")
    n = int(m.group(1))
    end = raw.index(b"boundaryField", m.end())
    vals = np.array(_VECTOR_RE.findall(raw[m.end():end]), dtype=float)
    if vals.shape != (n, 3):
        raise ValueError(f"{path}: expected {n} vectors, parsed {vals.shape}")
    return vals


# --------------------------------------------------------------------------------------
# Running OpenFOAM tools
# --------------------------------------------------------------------------------------


def openfoam_env(cwd: Path | None = None) -> dict:
    """Process environment for the tools (the Debian package needs WM_PROJECT_DIR)."""
    env = dict(os.environ)
    if cwd is not None:  # OpenFOAM warns when PWD disagrees with the working directory
        env["PWD"] = str(Path(cwd).resolve())
    if "WM_PROJECT_DIR" not in env and Path(DEFAULT_WM_PROJECT_DIR).is_dir():
        env["WM_PROJECT_DIR"] = DEFAULT_WM_PROJECT_DIR
    if hasattr(os, "geteuid") and os.geteuid() == 0:  # Open MPI refuses root otherwise
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        env.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    return env


def have_openfoam() -> bool:
    return all(shutil.which(t) for t in ("blockMesh", "pimpleFoam", "foamToVTK"))


def run_tool(args: Sequence[str], case: Path, log_name: str, *, commands: list | None = None,
             progress: Callable[[Path], None] | None = None, poll_s: float = 10.0) -> Path:
    """Run one OpenFOAM tool in `case`, its stdout+stderr captured to `case/log.<log_name>`.

    Raises OpenFOAMError naming the tool and the log when it cannot start, exits non-zero
    or prints a FOAM FATAL error. `progress(log_path)` is called every `poll_s` seconds.
    Returns the log path. The command is appended to `commands` (provenance).
    """
    case = Path(case)
    log = case / f"log.{log_name}"
    tool = args[0] if args[0] != "mpirun" else next((a for a in args if a.endswith("Foam")), "mpirun")
    if commands is not None:
        commands.append({"cwd": str(case), "args": list(args), "log": log.name})
    t0 = time.time()
    with open(log, "w") as fh:
        try:
            proc = subprocess.Popen(list(args), cwd=case, stdout=fh, stderr=subprocess.STDOUT,
                                    env=openfoam_env(case))
        except FileNotFoundError as exc:
            raise OpenFOAMError(f"{args[0]} not found on PATH (is OpenFOAM installed and "
                                f"its environment loaded?): {exc}") from exc
        while True:
            try:
                rc = proc.wait(timeout=poll_s)
                break
            except subprocess.TimeoutExpired:
                if progress is not None:
                    progress(log)
                bad = diverged_line(log)
                if bad is not None:
                    proc.terminate()
                    try:
                        proc.wait(timeout=30)
                    except subprocess.TimeoutExpired:
                        proc.kill()
                    if commands is not None:
                        commands[-1]["wall_s"] = round(time.time() - t0, 2)
                        commands[-1]["returncode"] = "stopped: diverged"
                    raise OpenFOAMError(f"{tool} diverged in {case}, stopped; log {log} line {bad[0]}: "
                                        f"{bad[1].strip()!r} (try a smaller --max-courant, or convection LUST)") from None
    if commands is not None:
        commands[-1]["wall_s"] = round(time.time() - t0, 2)
        commands[-1]["returncode"] = rc
    text_tail = _tail(log, 20000)
    if rc != 0 or "FOAM FATAL" in text_tail:
        raise OpenFOAMError(f"{tool} failed (exit code {rc}) in {case}; see log {log}\n"
                            + _fatal_excerpt(text_tail))
    return log


DIVERGED_COURANT = 20.0  # far above maxCo: the time-step control has lost the flow


def diverged_line(log: Path) -> tuple[int, str] | None:
    """(line number, line) of the first sign of a diverged solution in a solver log: a
    NaN or infinite residual/Courant number, or a Courant number above DIVERGED_COURANT."""
    try:
        with open(log, errors="replace") as fh:
            for n, line in enumerate(fh, 1):
                low = line.lower()
                if ("residual" in low or "courant" in low) and re.search(r"\b(nan|-?inf)\b", low):
                    return n, line
                if line.startswith("Courant Number"):
                    m = re.search(r"max: ([-+0-9.eE]+)", line)
                    if m and float(m.group(1)) > DIVERGED_COURANT:
                        return n, line
    except OSError:
        return None
    return None


def _tail(path: Path, n_bytes: int) -> str:
    with open(path, "rb") as fh:
        fh.seek(0, os.SEEK_END)
        size = fh.tell()
        fh.seek(max(0, size - n_bytes))
        return fh.read().decode(errors="replace")


def _fatal_excerpt(text: str) -> str:
    i = text.find("FOAM FATAL")
    return text[i:i + 1500] if i >= 0 else text[-1500:]


def openfoam_version(log: Path | None = None) -> str:
    """OpenFOAM version string, from $WM_PROJECT_VERSION, else a tool's banner
    ('Using: OpenFOAM-... (1912)' / 'Build: ...'), else 'unknown'."""
    env_version = os.environ.get("WM_PROJECT_VERSION")
    text = ""
    if log is not None and Path(log).exists():
        text = Path(log).read_text(errors="replace")[:4000]
    elif shutil.which("blockMesh"):
        try:
            text = subprocess.run(["blockMesh", "-help"], capture_output=True, text=True,
                                  env=openfoam_env(), timeout=60).stdout
        except (OSError, subprocess.SubprocessError):
            text = ""
    # v1912 banners: 'Build  : OPENFOAM=1912 patch=200626' (logs) or
    # 'Using: OpenFOAM- (1912)' + 'Build:  (patch=200626)' (-help).
    api = (re.search(r"OPENFOAM=(\d+)", text) or re.search(r"Using:\s*OpenFOAM-\S*\s*\((\d+)\)", text)
           or re.search(r"Version:\s*v?(\d+)", text))
    patch = re.search(r"patch=(\d+)", text)
    parts = []
    if env_version:
        parts.append(f"OpenFOAM {env_version}")
    elif api:
        parts.append(f"OpenFOAM v{api.group(1)} (openfoam.com)")
    if patch:
        parts.append(f"patch {patch.group(1)}")
    return ", ".join(parts) if parts else "unknown"


def run_block_mesh(case: Path, commands: list | None = None, log_name: str = "blockMesh") -> Path:
    return run_tool(["blockMesh"], case, log_name, commands=commands)


def prepare_tutorial_source(dest: Path, commands: list | None = None,
                            tutorial: Path = TUTORIAL_CHANNEL395) -> Path:
    """A runnable copy of the channel395 tutorial (mesh + its developed field in 0/) that
    mapFields can read. Kept outside the generated case; reused if already prepared."""
    dest = Path(dest)
    if (dest / "constant" / "polyMesh" / "points").exists() and (dest / "0").is_dir():
        return dest
    if not tutorial.is_dir():
        raise OpenFOAMError(f"tutorial channel395 not found at {tutorial} (package openfoam-examples)")
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(tutorial, dest)
    run_block_mesh(dest, commands)
    return dest


def map_tutorial_velocity(case: Path, source: Path, *, lx: float, lz: float, h: float, nx: int,
                          ny: int, nz: int, expansion: float, ubar: float,
                          commands: list | None = None) -> np.ndarray:
    """Developed turbulent velocity for the target mesh, mapped from the channel395 tutorial.

    mapFields (consistent, cell-volume weighted) maps onto an intermediate mesh that has the
    target's cell counts and grading but the tutorial's box (4 x 2 x 2, h = 1) and patch
    names, in `case/map_stage`. Cell order is identical to the target mesh, so the mapped
    values carry over cell by cell: a target box of another size or h gets the tutorial's
    turbulence stretched with it (the spin-up removes that memory). Velocities are scaled by
    ubar / 0.1335 (the tutorial's bulk velocity). Returns U (N, 3) in m/s.
    """
    stage = Path(case) / "map_stage"
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    lx_t, ly_t, lz_t = TUTORIAL_BOX
    write_block_mesh_dict(stage, lx=lx_t, lz=lz_t, h=TUTORIAL_HALF_HEIGHT, nx=nx, ny=ny, nz=nz,
                          expansion=expansion, tutorial_patch_names=True)
    write_control_dict(stage, end_time=1.0, write_interval=1.0, delta_t=0.1, max_courant=0.5,
                       max_delta_t=0.1, write_format="ascii", start_from="startTime")
    write_fv_schemes(stage)
    write_fv_solution(stage)
    write_transport_properties(stage, 2e-5)
    write_velocity_field(stage, np.zeros(3), tutorial_patch_names=True)
    run_block_mesh(stage, commands)
    # mapFields also creates the tutorial's other fields (p, nut, k, B, nuTilda) in the
    # intermediate case; only U is taken from it (p follows from the first pressure
    # solve, nut from WALE).
    src_fields_ok = (Path(source) / "0" / "U.gz").exists() or (Path(source) / "0" / "U").exists()
    if not src_fields_ok:
        raise OpenFOAMError(f"no 0/U in the mapping source {source}")
    run_tool(["mapFields", str(Path(source).resolve()), "-consistent", "-sourceTime", "0"],
             stage, "mapFields", commands=commands)
    U = read_ascii_internal_vector_field(stage / "0" / "U")
    expected = nx * ny * nz
    if len(U) != expected:
        raise OpenFOAMError(f"mapFields wrote {len(U)} cells, expected {expected}; see {stage}")
    return U * (ubar / TUTORIAL_UBAR)


def last_time_and_pressure_gradient(log: Path) -> tuple[float | None, float | None, float | None]:
    """(latest 'Time =', latest meanVelocityForce pressure gradient, latest max Courant)
    from a pimpleFoam log (reads only its tail)."""
    text = _tail(log, 30000)
    times = re.findall(r"^Time = ([-+0-9.eE]+)", text, flags=re.M)
    grads = re.findall(r"pressure gradient = ([-+0-9.eE]+)", text)
    cos = re.findall(r"Courant Number mean: [-+0-9.eE]+ max: ([-+0-9.eE]+)", text)
    f = lambda xs: float(xs[-1]) if xs else None  # noqa: E731
    return f(times), f(grads), f(cos)


def pressure_gradient_history(log: Path) -> np.ndarray:
    """(time, dp/dx) pairs from a pimpleFoam log: meanVelocityForce prints the driving
    gradient each step; averaged over time it equals τ_w/(ρ h) = u_τ²/h."""
    rows, t = [], None
    with open(log, errors="replace") as fh:
        for line in fh:
            if line.startswith("Time = "):
                try:
                    t = float(line.split("=")[1])
                except ValueError:
                    t = None
            elif "pressure gradient = " in line and t is not None:
                rows.append((t, float(line.rsplit("=", 1)[1])))
    return np.array(rows).reshape(-1, 2)


def run_pimple_foam(case: Path, *, nprocs: int = 1, log_name: str = "pimpleFoam",
                    commands: list | None = None,
                    progress: Callable[[Path], None] | None = None, poll_s: float = 15.0) -> Path:
    """pimpleFoam serially, or `mpirun -np N pimpleFoam -parallel` on a decomposed case."""
    if nprocs > 1:
        args = ["mpirun", "-np", str(nprocs), "pimpleFoam", "-parallel"]
    else:
        args = ["pimpleFoam"]
    return run_tool(args, case, log_name, commands=commands, progress=progress, poll_s=poll_s)


def run_decompose_par(case: Path, commands: list | None = None) -> Path:
    return run_tool(["decomposePar", "-force"], case, "decomposePar", commands=commands)


def run_reconstruct_par(case: Path, time_range: str, commands: list | None = None) -> Path:
    return run_tool(["reconstructPar", "-time", time_range], case, "reconstructPar",
                    commands=commands)


def time_range_arg(t_start: float, t_end: float) -> str:
    """An OpenFOAM `-time` range 'a:b' (inclusive bounds)."""
    return f"{t_start:.10g}:{t_end:.10g}"


def run_foam_to_vtk(case: Path, time_range: str | None = None, fields: Sequence[str] = ("U",),
                    commands: list | None = None) -> Path:
    """Export the internal mesh and cell data of `fields` to VTK/ (XML .vtu pieces inside a
    .vtm multiblock per time, plus a .vtm.series index). No boundary patches, no
    interpolated point data. Returns the .vtm.series path."""
    args = ["foamToVTK", "-fields", "(" + " ".join(fields) + ")", "-no-boundary",
            "-no-point-data", "-overwrite", "-noZero"]
    if time_range is not None:
        args += ["-time", time_range]
    run_tool(args, case, "foamToVTK", commands=commands)
    return find_vtk_series(case)


def find_vtk_series(case: Path) -> Path:
    vtk = Path(case) / "VTK"
    series = sorted(vtk.glob("*.vtm.series")) or sorted(vtk.glob("*.series"))
    if not series:
        raise OpenFOAMError(f"foamToVTK wrote no .series file in {vtk}; see {Path(case) / 'log.foamToVTK'}")
    return series[0]


def time_directories(case: Path) -> list[tuple[float, str]]:
    """Numeric time directories of a (reconstructed) case, sorted: (time, name)."""
    out = []
    for p in Path(case).iterdir():
        if p.is_dir():
            try:
                out.append((float(p.name), p.name))
            except ValueError:
                pass
    return sorted(out)


# --------------------------------------------------------------------------------------
# Rough bed: a porous layer of packed grains below each wall's bed top (flowfields.rough_bed)
# --------------------------------------------------------------------------------------


def rough_wall_normal_levels(h: float, b: float) -> tuple[float, float, float, float, float]:
    """y of the bottom wall, bottom bed top, centre line, top bed top, top wall."""
    return (0.0, b, b + h, b + 2.0 * h, 2.0 * b + 2.0 * h)


def write_rough_block_mesh_dict(case: Path, *, lx: float, lz: float, h: float, b: float, nx: int,
                                ny: int, ny_bed: int, nz: int, expansion: float) -> Path:
    """Four hex blocks: the two half channels above the bed tops (graded towards the bed
    tops exactly as the smooth channel's blocks are graded towards its walls), then the
    bottom and top bed layers (uniform, ny_bed cells each, thickness b). Block order puts
    the fluid blocks first, so their cells are numbered as the smooth channel's cells
    (``map_tutorial_velocity`` carries over cell by cell)."""
    if ny % 2:
        raise ValueError(f"ny must be even (two symmetric blocks), got {ny}")
    n = ny // 2
    levels = rough_wall_normal_levels(h, b)
    verts = [(x, y, z) for z in (0.0, lz) for y in levels for x in (0.0, lx)]
    v = "\n".join(f"    ({_fmt(a)} {_fmt(c)} {_fmt(e)})" for a, c, e in verts)
    off = 2 * len(levels)  # vertex offset of the z = lz plane

    def hexa(lev):
        a = 2 * lev
        return f"hex ({a} {a + 1} {a + 3} {a + 2} {a + off} {a + off + 1} {a + off + 3} {a + off + 2})"

    blocks = (f"    {hexa(1)} ({nx} {n} {nz}) simpleGrading (1 {_fmt(expansion)} 1)\n"
              f"    {hexa(2)} ({nx} {n} {nz}) simpleGrading (1 {_fmt(1.0 / expansion)} 1)\n"
              f"    {hexa(0)} ({nx} {ny_bed} {nz}) simpleGrading (1 1 1)\n"
              f"    {hexa(3)} ({nx} {ny_bed} {nz}) simpleGrading (1 1 1)")

    def face(kind, lev):
        a = 2 * lev
        return {"x0": f"({a} {a + off} {a + off + 2} {a + 2})", "x1": f"({a + 1} {a + 3} {a + off + 3} {a + off + 1})",
                "z0": f"({a} {a + 2} {a + 3} {a + 1})", "z1": f"({a + off} {a + off + 1} {a + off + 3} {a + off + 2})"}[kind]

    def patch(name, ptype, faces, neighbour=None):
        nb = f"        neighbourPatch  {neighbour};\n" if neighbour else ""
        return (f"    {name}\n    {{\n        type            {ptype};\n{nb}"
                f"        faces           ({' '.join(faces)});\n    }}\n")

    top = 2 * (len(levels) - 1)
    patches = [patch("bottomWall", "wall", [f"(0 1 {off + 1} {off})"]),
               patch("topWall", "wall", [f"({top} {top + off} {top + off + 1} {top + 1})"])]
    (xa, xb), (za, zb) = CYCLIC_PAIRS
    levs = range(len(levels) - 1)
    patches.append(patch(xa, "cyclic", [face("x0", k) for k in levs], xb))
    patches.append(patch(xb, "cyclic", [face("x1", k) for k in levs], xa))
    patches.append(patch(za, "cyclic", [face("z0", k) for k in levs], zb))
    patches.append(patch(zb, "cyclic", [face("z1", k) for k in levs], za))
    text = (foam_header("dictionary", "blockMeshDict", "system")
            + "scale   1;\n\nvertices\n(\n" + v + "\n);\n\n"
            + "blocks\n(\n" + blocks + "\n);\n\nedges\n(\n);\n\n"
            + "boundary\n(\n" + "".join(patches) + ");\n\nmergePatchPairs\n(\n);\n")
    return _write(case / "system" / "blockMeshDict", text)


def write_bed_topo_set(case: Path, layers: Sequence[dict], *, lx: float, lz: float, h: float, b: float,
                       d: float) -> Path:
    """One cellZone ``bed<k>`` per bed cell layer, holding the cells of that layer in both
    beds (the top bed mirrors the bottom one). Layer extents in d below the bed top."""
    y_bot_top, y_top_top = b, b + 2.0 * h
    pad = 1e-6 * (lx + lz)
    actions = []
    for k, lay in enumerate(layers):
        lo, hi = lay["y0_d"] * d, lay["y1_d"] * d  # ≤ 0, relative to the bed top
        boxes = (f"({_fmt(-pad)} {_fmt(y_bot_top + lo)} {_fmt(-pad)}) ({_fmt(lx + pad)} {_fmt(y_bot_top + hi)} {_fmt(lz + pad)}) "
                 f"({_fmt(-pad)} {_fmt(y_top_top - hi)} {_fmt(-pad)}) ({_fmt(lx + pad)} {_fmt(y_top_top - lo)} {_fmt(lz + pad)})")
        actions.append(f"    {{\n        name    bed{k}Set;\n        type    cellSet;\n        action  new;\n"
                       f"        source  boxToCell;\n        boxes   ({boxes});\n    }}\n"
                       f"    {{\n        name    bed{k};\n        type    cellZoneSet;\n        action  new;\n"
                       f"        source  setToCellZone;\n        set     bed{k}Set;\n    }}\n")
    text = foam_header("dictionary", "topoSetDict", "system") + "actions\n(\n" + "".join(actions) + ");\n"
    return _write(case / "system" / "topoSetDict", text)


def _porosity_zone(k: int, lay: dict) -> str:
    """One bed cell layer's Ergun drag (DarcyForchheimer on cellZone bed<k>); '' if none."""
    dc, fc = lay["darcy_d"], lay["forchheimer_f"]
    if dc <= 0 and fc <= 0:
        return ""
    return f"""
bedPorosity{k}
{{
    type            explicitPorositySource;
    explicitPorositySourceCoeffs
    {{
        selectionMode   cellZone;
        cellZone        bed{k};
        type            DarcyForchheimer;
        d   ({_fmt(dc)} {_fmt(dc)} {_fmt(dc)});
        f   ({_fmt(fc)} {_fmt(fc)} {_fmt(fc)});
        coordinateSystem
        {{
            origin  (0 0 0);
            rotation {{ type none; }}
        }}
    }}
}}
"""
