"""Import LES snapshots (foamToVTK output or any meshio-readable series) into a dataset.

Sources understood:

* a ParaView series file ``*.vtm.series`` / ``*.vtu.series`` / ``*.vtk.series`` (JSON list of
  files and times) — what OpenFOAM's ``foamToVTK`` writes; for ``.vtm`` multiblocks the
  ``internal`` piece (a VTU) is read;
* an XDMF time series (``*.xdmf`` / ``*.xmf``, meshio's TimeSeriesWriter format);
* a folder holding exactly one ``*.series`` file (e.g. OpenFOAM's ``VTK/``);
* a single mesh file (one snapshot at t = 0).

The cell-centred velocity ``U`` (or point data on a structured point set) is mapped onto a
tensor-product grid found from the centres: uniform in x and z, any increasing y. The
friction velocity is the LES's own, u_τ = √(ν ⟨u⟩(y₁)/y₁) from the first cell centre at
each wall, averaged over walls, planes and snapshots (SPEC §3).
"""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .dataset import DatasetError, write_dataset


class SnapshotError(DatasetError):
    """Raw snapshot data cannot be imported (message names the file)."""


# ---------------------------------------------------------------------- listing
def list_snapshots(src) -> list[tuple[float, Path]]:
    """(time, file) pairs of a series, sorted by time; checks every file exists."""
    src = Path(src)
    if not src.exists():
        raise SnapshotError(f"source not found: {src}")
    if src.is_dir():
        series = sorted(src.glob("*.series"))
        if len(series) != 1:
            raise SnapshotError(
                f"{src}: expected exactly one *.series file in the folder, found {len(series)} "
                "(pass the series file itself, an .xdmf file, or a single mesh file)"
            )
        src = series[0]
    if src.name.endswith(".series"):
        try:
            doc = json.loads(src.read_text())
            entries = [(float(e["time"]), src.parent / e["name"]) for e in doc["files"]]
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise SnapshotError(f"{src}: not a valid ParaView .series file ({exc})") from None
        if not entries:
            raise SnapshotError(f"{src}: the series lists no files")
    elif src.suffix.lower() in (".xdmf", ".xmf"):
        return [(float("nan"), src)]  # times come from the XDMF reader
    else:
        entries = [(0.0, src)]
    missing = [str(p) for _, p in entries if not p.exists()]
    if missing:
        raise SnapshotError(f"{src}: {len(missing)} snapshot file(s) missing, first: {missing[0]}")
    entries.sort(key=lambda e: e[0])
    return entries


def _vtm_internal_piece(vtm: Path) -> Path:
    """The internal-mesh VTU referenced by a foamToVTK multiblock file."""
    try:
        root = ET.parse(vtm).getroot()
    except ET.ParseError as exc:
        raise SnapshotError(f"{vtm}: corrupt multiblock file ({exc})") from None
    sets = [d for d in root.iter("DataSet") if d.get("file")]
    internal = [d for d in sets if d.get("name") == "internal"] or [d for d in sets if d.get("file").endswith(".vtu")]
    if not internal:
        raise SnapshotError(f"{vtm}: no internal-mesh (.vtu) piece referenced")
    piece = vtm.parent / internal[0].get("file")
    if not piece.exists():
        raise SnapshotError(f"{vtm}: referenced piece missing: {piece}")
    return piece


# ---------------------------------------------------------------------- reading
def _velocity_from_mesh(mesh, where: str):
    """(positions (N,3), U (N,3), (y_wall_bottom, y_wall_top)) from a meshio mesh."""
    import meshio  # noqa: F401  (imported for its types; reading is done by the caller)

    names = list(mesh.cell_data.keys())
    if "U" in mesh.cell_data:
        centres, values = [], []
        for block, arr in zip(mesh.cells, mesh.cell_data["U"]):
            centres.append(mesh.points[block.data].mean(axis=1))
            values.append(np.asarray(arr, dtype=np.float64).reshape(len(block.data), -1))
        pos = np.concatenate(centres)
        u = np.concatenate(values)
        walls = (float(mesh.points[:, 1].min()), float(mesh.points[:, 1].max()))
    elif "U" in mesh.point_data:
        pos = np.asarray(mesh.points, dtype=np.float64)
        u = np.asarray(mesh.point_data["U"], dtype=np.float64)
        walls = (float(pos[:, 1].min()), float(pos[:, 1].max()))
    else:
        raise SnapshotError(
            f"{where}: no velocity field 'U' (cell fields: {names}, point fields: {list(mesh.point_data)})"
        )
    if u.ndim != 2 or u.shape[1] != 3:
        raise SnapshotError(f"{where}: 'U' is not a 3-component vector field (shape {u.shape})")
    bad = ~np.isfinite(u)
    if bad.any():
        raise SnapshotError(f"{where}: velocity has {int(bad.any(axis=1).sum())} cell(s) with NaN or infinite values")
    return pos, u, walls


def read_snapshot(path: Path):
    """Read one snapshot file (.vtm via its internal piece, or anything meshio reads)."""
    import meshio

    path = Path(path)
    target = _vtm_internal_piece(path) if path.suffix == ".vtm" else path
    try:
        mesh = meshio.read(target)
    except (Exception, SystemExit) as exc:  # meshio raises many types (even SystemExit) for corrupt files
        why = "meshio cannot parse it" if isinstance(exc, SystemExit) else f"{type(exc).__name__}: {exc}"
        raise SnapshotError(f"{target}: snapshot cannot be read ({why})") from None
    return _velocity_from_mesh(mesh, str(target))


def _iter_xdmf(path: Path):
    import meshio

    try:
        with meshio.xdmf.TimeSeriesReader(str(path)) as reader:
            points, cells = reader.read_points_cells()
            for k in range(reader.num_steps):
                t, point_data, cell_data = reader.read_data(k)
                mesh = meshio.Mesh(points, cells, point_data=point_data, cell_data=cell_data)
                yield float(t), _velocity_from_mesh(mesh, f"{path} step {k}")
    except SnapshotError:
        raise
    except Exception as exc:
        raise SnapshotError(f"{path}: XDMF series cannot be read ({type(exc).__name__}: {exc})") from None


# ---------------------------------------------------------------------- grid detection
def _cluster(values: np.ndarray, tol: float) -> np.ndarray:
    """Distinct coordinate values (means of clusters closer than tol)."""
    s = np.sort(values)
    breaks = np.nonzero(np.diff(s) > tol)[0] + 1
    return np.array([g.mean() for g in np.split(s, breaks)])


def detect_tensor_grid(pos: np.ndarray, where: str):
    """Axes (xs, ys, zs) and the flat index of each position into (nx, ny, nz).

    Refuses positions that do not form a full tensor product with uniform x and z."""
    extent = np.ptp(pos, axis=0).max()
    tol = 1e-5 * max(extent, 1e-300)
    axes = [_cluster(pos[:, a], tol) for a in range(3)]
    nx, ny, nz = (len(a) for a in axes)
    if nx * ny * nz != len(pos):
        raise SnapshotError(
            f"{where}: cell centres do not form a tensor-product grid ({len(pos)} cells but "
            f"{nx} distinct x × {ny} distinct y × {nz} distinct z = {nx * ny * nz}); "
            "a channel mesh from blockMesh with uniform x and z spacing is required"
        )
    for name, a in (("x", axes[0]), ("z", axes[2])):
        if len(a) > 2:
            d = np.diff(a)
            if np.ptp(d) > 1e-3 * d.mean():
                raise SnapshotError(
                    f"{where}: {name} spacing is not uniform ({d.min():.6g}–{d.max():.6g}); "
                    "the channel must be uniform and periodic in x and z"
                )
    idx = []
    raw_axes = list(axes)
    for a, ax in enumerate(axes):
        i = np.clip(np.searchsorted(ax, pos[:, a] - tol), 0, len(ax) - 1)
        if np.any(np.abs(ax[i] - pos[:, a]) > tol):
            raise SnapshotError(f"{where}: cell centres off the detected {'xyz'[a]} grid lines")
        idx.append(i)
    flat = (idx[0] * ny + idx[1]) * nz + idx[2]
    if np.bincount(flat, minlength=nx * ny * nz).max() != 1:
        raise SnapshotError(f"{where}: two cells share one grid position: not a tensor-product mesh")
    # foamToVTK writes Float32 points: x and z lines scatter by ~1e-6 of their spacing.
    # Snap them to exact uniform lines (least-squares fit) so the periodic sampler sees one dx, dz.
    for a in (0, 2):
        ax = raw_axes[a]
        if len(ax) > 1:
            k = np.arange(len(ax))
            slope, x0 = np.polyfit(k, ax, 1)
            axes[a] = x0 + slope * k
    return axes, flat


# ---------------------------------------------------------------------- import
def import_series(src, out, *, nu, provenance=None, y_max_plus=None, dtype="float32", u_tau=None, progress=True,
                  max_snapshots=None, y_origin=None, y_min=None, bed_d_plus=None):
    """Import an LES snapshot series into a dataset folder ``out`` (wall units).

    nu: kinematic viscosity (m²/s, or the LES's own unit). y_max_plus: keep the lower
    part of the channel up to this y⁺ (default: the lower half, y ≤ h). dtype: "float32"
    or "int16" (quantized, for shipping). u_tau: override the measured friction velocity.
    Rough bed (the LES carries a porous grain layer, flowfields.rough_bed): y_origin is
    the bed top (LES length units), which becomes y⁺ = 0; cells from y_min (default: the
    bottom wall) up are kept, those inside the bed with negative y⁺; u_tau must be given
    (from the momentum balance at the bed top: the wall shear under the bed is not u*);
    bed_d_plus is the bed grain's diameter in wall units. Re_τ is then u_τ times the depth
    from the bed top to the centre line over ν.
    Returns the dataset path."""
    if y_origin is not None and (u_tau is None or bed_d_plus is None):
        raise ValueError("a rough-bed import (y_origin given) needs u_tau (momentum balance at the bed top) "
                         "and bed_d_plus")
    from tqdm import tqdm

    if nu is None or not nu > 0:
        raise ValueError(f"nu (kinematic viscosity) must be positive, got {nu}")
    if max_snapshots is not None and not int(max_snapshots) >= 1:
        raise ValueError(f"max_snapshots must be at least 1, got {max_snapshots!r}")
    src = Path(src)
    entries = list_snapshots(src)
    if max_snapshots is not None and len(entries) > 1:
        entries = entries[: int(max_snapshots)]
    if len(entries) == 1 and src.suffix.lower() in (".xdmf", ".xmf"):
        stream = _iter_xdmf(src)
    else:
        stream = ((t, read_snapshot(p)) for t, p in entries)

    times, grid, walls, wall_shear = [], None, None, []
    bar = tqdm(stream, total=len(entries) if len(entries) > 1 else None, desc="import", unit="snap", disable=not progress)
    rows = []
    for n, (t, (pos, u, wl)) in enumerate(bar):
        if max_snapshots is not None and n >= int(max_snapshots):
            break
        where = f"{entries[min(n, len(entries) - 1)][1]}"
        if grid is None:
            axes, flat = detect_tensor_grid(pos, where)
            grid = (axes, flat, pos)
            walls = wl
            # point data may include the wall planes themselves (u = 0 there): skip them
            eps = 1e-9 * (walls[1] - walls[0])
            jb = 1 if axes[1][0] - walls[0] <= eps else 0
            jt = len(axes[1]) - 2 if walls[1] - axes[1][-1] <= eps else len(axes[1]) - 1
            if y_min is not None:
                jb = max(jb, int(np.searchsorted(axes[1], y_min)))
        else:
            axes, flat, pos0 = grid
            if pos.shape != pos0.shape or np.max(np.abs(pos - pos0)) > 1e-5 * np.ptp(pos0):
                # same mesh with cells in another order is fine; another mesh is not
                try:
                    axes_n, flat = detect_tensor_grid(pos, where)
                except SnapshotError:
                    axes_n = None
                same = axes_n is not None and all(
                    len(a) == len(b) and np.allclose(a, b, rtol=0, atol=1e-5 * np.ptp(pos0)) for a, b in zip(axes, axes_n)
                )
                if not same:
                    raise SnapshotError(f"{where}: grid differs from the first snapshot's; a series must share one mesh")
        nx, ny, nz = (len(a) for a in axes)
        field = np.empty((nx * ny * nz, 3))
        field[flat] = u
        field = field.reshape(nx, ny, nz, 3)
        rows.append(field.astype(np.float32))
        times.append(t)
        # wall shear from the first cell centre at each wall (SPEC §3)
        tau = [np.mean(field[:, jb, :, 0]) / (axes[1][jb] - walls[0])]
        if jt > jb + 1:
            tau.append(np.mean(field[:, jt, :, 0]) / (walls[1] - axes[1][jt]))
        wall_shear.append(np.mean(tau))
    if grid is None:
        raise SnapshotError(f"{src}: no snapshots")
    axes, _, _ = grid
    mean_shear = float(np.mean(wall_shear))
    if u_tau is None and not mean_shear > 0:
        raise SnapshotError(f"{src}: mean wall shear is not positive: the mean flow must be along +x")
    ut = float(u_tau) if u_tau is not None else float(np.sqrt(nu * mean_shear))
    origin = walls[0] if y_origin is None else float(y_origin)
    h = 0.5 * (walls[1] + walls[0]) - origin  # depth from the wall (bed top) to the centre line
    re_tau = ut * h / nu
    yplus = (axes[1] - origin) * ut / nu
    top = re_tau if y_max_plus is None else float(y_max_plus)
    jmax = int(np.searchsorted(yplus, top)) + 1  # keep one centre at or above the top
    jmax = min(jmax, jt + 1)
    t = np.asarray(times, dtype=float)
    if np.isnan(t).any():
        raise SnapshotError(f"{src}: snapshot times missing")
    u_plus = np.stack([r[:, jb:jmax, :, :] for r in rows]) / ut
    prov = dict(provenance or {})
    prov.setdefault("source", str(src))
    prov.update(
        {
            "nu": nu,
            "u_tau": ut,
            "half_height": h,
            "wall_positions": list(walls),
            "times_source": t.tolist(),
            "u_tau_measured": u_tau is None,
        }
    )
    extra = None
    if y_origin is not None:
        extra = {"bed": {"kind": "porous", "d_plus": float(bed_d_plus),
                         "floor_plus": float((walls[0] - origin) * ut / nu),
                         "y_origin": "bed top (the grains' y = 0)"}}
    return write_dataset(
        out,
        extra_meta=extra,
        x=(axes[0] - axes[0][0] + 0.5 * (axes[0][1] - axes[0][0] if len(axes[0]) > 1 else 0)) * ut / nu,
        y=yplus[jb:jmax],
        z=(axes[2] - axes[2][0] + 0.5 * (axes[2][1] - axes[2][0] if len(axes[2]) > 1 else 0)) * ut / nu,
        u_plus=u_plus,
        re_tau=re_tau,
        times_plus=(t - t[0]) * ut * ut / nu,
        provenance=prov,
        dtype=dtype,
    )
