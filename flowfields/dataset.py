"""Flow datasets on disk: a folder of memory-mapped arrays in wall units + metadata.

Layout of a dataset folder ``NAME/``::

    meta.json   format version, Re_τ, grid, snapshot times (t⁺), storage, provenance
    x.npy       (nx,) cell-centre x⁺ (uniform, periodic with period nx·dx⁺)
    y.npy       (ny,) cell-centre y⁺ above the bottom wall (stretched, increasing, > 0)
    z.npy       (nz,) cell-centre z⁺ (uniform, periodic)
    u.npy       (nt, nx, ny, nz, 3) velocity u⁺, float32 — or int16 with a per-component
                linear quantization u⁺ = q·scale + offset (meta "storage")

``.npy`` files open with ``mmap_mode="r"``: loading is instant, and many processes
(sweep workers) share the same pages read-only.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .sampler import ABOVE_TOP, BELOW_WALL, FlowArrays, sample_many, sample_velocity_many

FORMAT_VERSION = 1
SHIPPED_DATASET = Path(__file__).resolve().parent / "data" / "channel395"
# Datasets by name: the shipped smooth-wall channel (the paper's set-up) and the sand bed
# inside the LES (SPEC §3 rough bed), which is not shipped (its porous layer gives no
# roughness function yet: README) but made in place by MAKE_SANDBED.
SHIPPED_DATASETS = {"channel395": SHIPPED_DATASET,
                    "sandbed395": SHIPPED_DATASET.parent / "sandbed395"}
MAKE_SANDBED = ("saltation flow generate --out {path} --work-dir les_work/sandbed395 --bed porous --bed-d-plus 19.5 "
                "--re-tau 395 --lx 4 --lz 1.5 --nx 48 --ny 64 --nz 48 --first-cell-yplus 0.8 --interval 6 "
                "--snapshots 33 --spinup 800 --np 2 --y-max-plus 200 --dtype int16")
_REQUIRED_META = ("format_version", "re_tau", "times_plus", "storage", "provenance")
_META_DOC = {
    "format_version": f"the integer {FORMAT_VERSION}",
    "re_tau": "a positive finite number: the friction Reynolds number u_tau h/nu of the LES",
    "times_plus": "a non-empty list of finite numbers: the snapshot times in t+",
    "storage": 'an object {"dtype": "float32" or "int16", "scale": [3 numbers], "offset": [3 numbers]}',
    "provenance": "an object: who made the data, and how",
}


class DatasetError(ValueError):
    """A flow dataset is missing, incomplete or inconsistent (the message names the file)."""


@dataclass
class FlowDataset:
    """A flow dataset in wall units, sampled by the Numba kernels of ``sampler``."""

    path: Path | None
    meta: dict
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    data: np.ndarray
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    # ------------------------------------------------------------------ properties
    @property
    def re_tau(self) -> float:
        """Friction Reynolds number u_τ h/ν of the source flow (its own u_τ)."""
        return float(self.meta["re_tau"])

    @property
    def times(self) -> np.ndarray:
        """Snapshot times t⁺ (starting at 0)."""
        return np.asarray(self.meta["times_plus"], dtype=float)

    @property
    def n_snapshots(self) -> int:
        return int(self.data.shape[0])

    @property
    def dx(self) -> float:
        return float(self.x[1] - self.x[0]) if len(self.x) > 1 else float(self.meta["box_plus"][0])

    @property
    def dz(self) -> float:
        return float(self.z[1] - self.z[0]) if len(self.z) > 1 else float(self.meta["box_plus"][2])

    @property
    def snapshot_interval(self) -> float:
        t = self.times
        return float(t[1] - t[0]) if len(t) > 1 else float("inf")

    @property
    def box(self) -> tuple[float, float, float]:
        """(Lx⁺, y_top⁺, Lz⁺): periodic lengths in x and z, top of the stored y range."""
        return (self.dx * len(self.x), float(self.y[-1]), self.dz * len(self.z))

    @property
    def bed(self) -> dict | None:
        """The rough bed's description (meta.json "bed"), or None for a smooth wall."""
        return self.meta.get("bed")

    @property
    def y_floor(self) -> float:
        """y⁺ below which the fluid is at rest: the wall (0), or the bottom of a rough
        bed's porous layer (negative: y⁺ = 0 is the bed top)."""
        return float(self.bed["floor_plus"]) if self.bed else 0.0

    @property
    def arrays(self) -> FlowArrays:
        """The tuple the Numba kernels take."""
        t = self.times
        dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
        return FlowArrays(
            self.data,
            np.asarray(self.scale, dtype=np.float64),
            np.asarray(self.offset, dtype=np.float64),
            float(self.x[0]),
            self.dx,
            int(len(self.x)),
            np.ascontiguousarray(self.y, dtype=np.float64),
            float(self.z[0]),
            self.dz,
            int(len(self.z)),
            float(t[0]),
            dt,
            int(self.data.shape[0]),
            self.y_floor,
            0.0 if self.bed else 1.0,
        )

    # ------------------------------------------------------------------ sampling
    def _points(self, points) -> np.ndarray:
        p = np.ascontiguousarray(np.atleast_2d(np.asarray(points, dtype=np.float64)))
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3) in wall units (x⁺, y⁺, z⁺); got {p.shape}")
        if not np.all(np.isfinite(p)):
            bad = int(np.argmax(~np.all(np.isfinite(p), axis=1)))
            raise ValueError(f"point {bad} is not finite: {p[bad].tolist()}")
        return p

    def _check_status(self, p, status):
        bad = np.nonzero((status == ABOVE_TOP) | (status == BELOW_WALL))[0]
        if len(bad):
            i = int(bad[0])
            raise ValueError(
                f"point {i} at y⁺ = {p[i, 1]:.6g} is outside the dataset's wall-normal range "
                f"[{self.y_floor:g}, {self.y[-1]:.6g}] ({len(bad)} point(s) outside)"
            )

    def velocity(self, points, t: float) -> np.ndarray:
        """u⁺ (N, 3) at points (N, 3) in wall units and time t⁺."""
        p = self._points(points)
        u = np.empty((len(p), 3))
        status = np.empty(len(p), dtype=np.int64)
        sample_velocity_many(self.arrays, p, float(t), u, status)
        self._check_status(p, status)
        return u

    def sample(self, points, t: float):
        """(u⁺ (N,3), ∇u⁺ (N,3,3) with [i, j] = ∂u_i/∂x_j, ∂u⁺/∂t⁺ (N,3))."""
        p = self._points(points)
        n = len(p)
        u = np.empty((n, 3))
        g = np.empty((n, 3, 3))
        dudt = np.empty((n, 3))
        status = np.empty(n, dtype=np.int64)
        sample_many(self.arrays, p, float(t), u, g, dudt, status)
        self._check_status(p, status)
        return u, g, dudt

    def gradient(self, points, t: float) -> np.ndarray:
        return self.sample(points, t)[1]

    def vorticity(self, points, t: float) -> np.ndarray:
        g = self.gradient(points, t)
        return np.stack(
            [g[:, 2, 1] - g[:, 1, 2], g[:, 0, 2] - g[:, 2, 0], g[:, 1, 0] - g[:, 0, 1]], axis=1
        )

    def dudt(self, points, t: float) -> np.ndarray:
        return self.sample(points, t)[2]

    def snapshot(self, i: int) -> np.ndarray:
        """Snapshot i as float64 u⁺ (nx, ny, nz, 3)."""
        return self.data[i].astype(np.float64) * self.scale + self.offset

    def describe(self) -> dict:
        """Grid, Re_τ, time span and provenance, as printed by ``saltation flow info``."""
        lx, ytop, lz = self.box
        t = self.times
        return {
            "path": str(self.path) if self.path else None,
            "kind": self.meta.get("kind", "les"),
            "re_tau": self.re_tau,
            "grid": {"nx": len(self.x), "ny": len(self.y), "nz": len(self.z)},
            "box_plus": {"Lx": lx, "y_top": ytop, "Lz": lz},
            "box_h": {"Lx": lx / self.re_tau, "y_top": ytop / self.re_tau, "Lz": lz / self.re_tau},
            "spacing_plus": {
                "dx": self.dx,
                "dz": self.dz,
                "y_first_centre": float(self.y[0]),
                "dy_max": float(np.max(np.diff(self.y))) if len(self.y) > 1 else 0.0,
            },
            "snapshots": len(t),
            "time_span_plus": float(t[-1] - t[0]) if len(t) else 0.0,
            "snapshot_interval_plus": self.snapshot_interval if len(t) > 1 else None,
            "storage": self.meta["storage"],
            "bed": self.bed,
            "provenance": self.meta["provenance"],
        }


# ---------------------------------------------------------------------- disk I/O
def quantize_int16(u: np.ndarray):
    """Per-component linear int16 quantization: returns (q, scale, offset)."""
    lo = np.array([float(u[..., c].min()) for c in range(3)])
    hi = np.array([float(u[..., c].max()) for c in range(3)])
    offset = 0.5 * (lo + hi)
    scale = np.maximum(hi - lo, 1e-12) / 65000.0
    q = np.empty(u.shape, dtype=np.int16)
    for c in range(3):
        q[..., c] = np.rint((u[..., c] - offset[c]) / scale[c]).astype(np.int16)
    return q, scale, offset


def write_dataset(path, x, y, z, u_plus, re_tau, times_plus, provenance, dtype="float32", extra_meta=None):
    """Write a dataset folder from arrays in wall units; returns its path.

    u_plus: (nt, nx, ny, nz, 3). dtype "float32" or "int16" (quantized)."""
    path = Path(path)
    x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
    times_plus = np.asarray(times_plus, dtype=np.float64)
    floor = float(extra_meta["bed"]["floor_plus"]) if extra_meta and "bed" in extra_meta else 0.0
    _validate_grid(x, y, z, times_plus, u_plus.shape, where=str(path), floor=floor)
    if not np.all(np.isfinite(u_plus)):
        raise DatasetError(f"{path}: velocity contains NaN or infinite values")
    path.mkdir(parents=True, exist_ok=True)
    np.save(path / "x.npy", x)
    np.save(path / "y.npy", y)
    np.save(path / "z.npy", z)
    if dtype == "float32":
        np.save(path / "u.npy", np.ascontiguousarray(u_plus, dtype=np.float32))
        storage = {"dtype": "float32", "scale": [1.0, 1.0, 1.0], "offset": [0.0, 0.0, 0.0]}
    elif dtype == "int16":
        q, scale, offset = quantize_int16(u_plus)
        np.save(path / "u.npy", q)
        storage = {
            "dtype": "int16",
            "scale": scale.tolist(),
            "offset": offset.tolist(),
            "max_quantization_error_plus": float(0.5 * scale.max()),
        }
    else:
        raise ValueError(f"dtype must be 'float32' or 'int16', got {dtype!r}")
    lx = float((x[1] - x[0]) * len(x)) if len(x) > 1 else float(provenance.get("box_plus", [1, 0, 1])[0])
    lz = float((z[1] - z[0]) * len(z)) if len(z) > 1 else float(provenance.get("box_plus", [1, 0, 1])[2])
    meta = {
        "format_version": FORMAT_VERSION,
        "re_tau": float(re_tau),
        "box_plus": [lx, float(y[-1]), lz],
        "grid": [len(x), len(y), len(z)],
        "times_plus": times_plus.tolist(),
        "storage": storage,
        "provenance": provenance,
    }
    if extra_meta:
        meta.update(extra_meta)
    (path / "meta.json").write_text(json.dumps(meta, indent=1))
    return path


def _validate_grid(x, y, z, times, shape, where, floor=0.0):
    for name, a in (("x", x), ("y", y), ("z", z)):
        if np.ndim(a) != 1:
            raise DatasetError(f"{where}: {name} cell centres must be a 1-D array, got shape {np.shape(a)}")
        if not np.issubdtype(np.asarray(a).dtype, np.number) or not np.all(np.isfinite(a)):
            raise DatasetError(f"{where}: {name} cell centres must be finite numbers")
    if len(shape) != 5:
        raise DatasetError(f"{where}: velocity array must have 5 dimensions (nt, nx, ny, nz, 3), got shape {tuple(shape)}")
    nt, nx, ny, nz, nc = shape
    if nc != 3 or (nx, ny, nz) != (len(x), len(y), len(z)) or nt != len(times):
        raise DatasetError(
            f"{where}: velocity array shape {shape} does not match grid "
            f"({len(times)}, {len(x)}, {len(y)}, {len(z)}, 3)"
        )
    for name, a in (("x", x), ("z", z)):
        if len(a) > 1:
            d = np.diff(a)
            if np.any(d <= 0) or np.ptp(d) > 1e-6 * abs(d.mean()) + 1e-9:
                raise DatasetError(f"{where}: {name} cell centres are not uniform and increasing")
    if len(y) == 0 or y[0] <= floor or np.any(np.diff(y) <= 0):
        if floor < 0:
            raise DatasetError(f"{where}: y⁺ cell centres must be increasing and above the bed floor y⁺ = {floor:g}")
        raise DatasetError(f"{where}: y⁺ cell centres must be positive and increasing (wall at y⁺ = 0)")
    if len(times) > 1:
        d = np.diff(times)
        if np.any(d <= 0) or np.ptp(d) > 1e-3 * d.mean():
            raise DatasetError(f"{where}: snapshot times are not uniformly spaced (intervals {d.min():.6g}–{d.max():.6g} t⁺)")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _validate_meta(meta, meta_file: Path) -> None:
    """Types and ranges of every meta.json key the code reads: DatasetError naming the
    file, the key, the bad value and what it must be."""
    fix = ("; fix the file, or write the dataset again with 'saltation flow import' / 'flow generate'")

    def bad(key, value, must):
        return DatasetError(f"{meta_file}: {key} = {json.dumps(value, default=str)} is not allowed: "
                            f"it must be {must}{fix}")

    if not isinstance(meta, dict):
        raise DatasetError(f"{meta_file}: must hold a JSON object (keys {', '.join(_REQUIRED_META)}), "
                           f"got {type(meta).__name__}{fix}")
    missing = [k for k in _REQUIRED_META if k not in meta]
    if missing:
        raise DatasetError(f"{meta_file}: missing metadata " + "; ".join(f"{k} ({_META_DOC[k]})" for k in missing) + fix)
    v = meta["format_version"]
    if not _is_number(v) or v != FORMAT_VERSION:
        newer = " (a newer saltation wrote it?)" if _is_number(v) and v > FORMAT_VERSION else ""
        raise bad("format_version", v, f"{FORMAT_VERSION}, the format this saltation reads{newer}")
    v = meta["re_tau"]
    if not _is_number(v) or not np.isfinite(v) or v <= 0:
        raise bad("re_tau", v, _META_DOC["re_tau"])
    t = meta["times_plus"]
    if (not isinstance(t, list) or not t or not all(_is_number(x) and np.isfinite(x) for x in t)):
        shown = t if not isinstance(t, list) or len(t) <= 4 else [*t[:4], "..."]
        raise bad("times_plus", shown, _META_DOC["times_plus"])
    st = meta["storage"]
    if not isinstance(st, dict):
        raise bad("storage", st, _META_DOC["storage"])
    if st.get("dtype") not in ("float32", "int16"):
        raise bad("storage.dtype", st.get("dtype"), '"float32" or "int16"')
    for key, positive in (("scale", True), ("offset", False)):
        a = st.get(key)
        if (not isinstance(a, list) or len(a) != 3 or not all(_is_number(x) and np.isfinite(x) for x in a)
                or (positive and not all(x > 0 for x in a))):
            raise bad(f"storage.{key}", a, f"a list of three {'positive ' if positive else ''}finite numbers "
                      f"(u+ = stored value * scale + offset, per component)")
    if not isinstance(meta["provenance"], dict):
        raise bad("provenance", meta["provenance"], _META_DOC["provenance"])
    if "box_plus" in meta:
        b = meta["box_plus"]
        if not isinstance(b, list) or len(b) != 3 or not all(_is_number(x) and np.isfinite(x) and x > 0 for x in b):
            raise bad("box_plus", b, "a list of three positive finite numbers [Lx+, y_top+, Lz+]")
    if "grid" in meta:
        g = meta["grid"]
        if not isinstance(g, list) or len(g) != 3 or not all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in g):
            raise bad("grid", g, "a list of three positive integers [nx, ny, nz]")
    if "bed" in meta:
        b = meta["bed"]
        if not isinstance(b, dict):
            raise bad("bed", b, "an object describing the rough bed (d_plus, floor_plus, ...)")
        v = b.get("d_plus")
        if not _is_number(v) or not np.isfinite(v) or v <= 0:
            raise bad("bed.d_plus", v, "the bed grain's diameter in wall units, a positive finite number")
        v = b.get("floor_plus")
        if not _is_number(v) or not np.isfinite(v) or v > 0:
            raise bad("bed.floor_plus", v, "the bottom of the stored bed layer in wall units below the bed top "
                      "(a number ≤ 0)")
    if "kind" in meta and not isinstance(meta["kind"], str):
        raise bad("kind", meta["kind"], 'a string (e.g. "les")')


def open_dataset(path=None) -> FlowDataset:
    """Open a flow dataset folder (None: the shipped default LES dataset).

    Arrays are memory-mapped read-only; nothing is copied."""
    if path is None:
        p = SHIPPED_DATASET
    elif isinstance(path, str) and path in SHIPPED_DATASETS and not Path(path).exists():
        p = SHIPPED_DATASETS[path]
    else:
        p = Path(path)
    if not p.exists():
        hint = " (the shipped dataset is missing from this installation)" if path is None else ""
        if path == "sandbed395":
            hint = (" (the sand bed inside the LES is made in place, ~30 min on 2 cores: "
                    + MAKE_SANDBED.format(path=p) + ")")
        raise DatasetError(f"flow dataset not found: {p}{hint}")
    if p.is_file():
        raise DatasetError(f"{p} is a file; a dataset is a folder made by 'saltation flow import' or 'flow generate'")
    meta_file = p / "meta.json"
    if not meta_file.exists():
        raise DatasetError(f"{p}: no meta.json — not a saltation flow dataset (import raw data with 'saltation flow import')")
    try:
        meta = json.loads(meta_file.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{meta_file}: not valid JSON ({exc}); fix the file, or write the dataset again "
                           f"with 'saltation flow import' / 'flow generate'") from None
    _validate_meta(meta, meta_file)
    arrays = {}
    for name in ("x", "y", "z", "u"):
        f = p / f"{name}.npy"
        if not f.exists():
            raise DatasetError(f"{p}: missing array file {f.name}")
        try:
            arrays[name] = np.load(f, mmap_mode="r" if name == "u" else None)
        except Exception as exc:  # corrupt/truncated .npy
            raise DatasetError(f"{f}: cannot be read ({exc})") from None
    st = meta["storage"]
    want = np.dtype(st["dtype"])
    if arrays["u"].dtype != want:
        raise DatasetError(f"{p / 'u.npy'}: dtype {arrays['u'].dtype} but meta.json says {want}")
    _validate_grid(arrays["x"], arrays["y"], arrays["z"], np.asarray(meta["times_plus"], dtype=float),
                   arrays["u"].shape, str(p), floor=float(meta["bed"]["floor_plus"]) if "bed" in meta else 0.0)
    if "grid" in meta and list(meta["grid"]) != [len(arrays["x"]), len(arrays["y"]), len(arrays["z"])]:
        raise DatasetError(f"{meta_file}: grid = {meta['grid']} but the arrays hold "
                           f"{[len(arrays['x']), len(arrays['y']), len(arrays['z'])]} cell centres (x, y, z)")
    if (len(arrays["x"]) < 2 or len(arrays["z"]) < 2) and "box_plus" not in meta:
        raise DatasetError(f"{meta_file}: box_plus is missing; a dataset one cell wide in x or z needs it "
                           f"([Lx+, y_top+, Lz+])")
    return FlowDataset(
        path=p,
        meta=meta,
        x=arrays["x"],
        y=arrays["y"],
        z=arrays["z"],
        data=arrays["u"],
        scale=np.asarray(st["scale"], dtype=np.float64),
        offset=np.asarray(st["offset"], dtype=np.float64),
    )


def in_memory_dataset(x, y, z, u_plus, re_tau, times_plus, meta_extra=None) -> FlowDataset:
    """A dataset held in memory (analytic profiles, tests)."""
    x, y, z = (np.asarray(a, dtype=np.float64) for a in (x, y, z))
    times_plus = np.asarray(times_plus, dtype=np.float64)
    u_plus = np.ascontiguousarray(u_plus, dtype=np.float32)
    floor = float(meta_extra["bed"]["floor_plus"]) if meta_extra and "bed" in meta_extra else 0.0
    _validate_grid(x, y, z, times_plus, u_plus.shape, "in-memory dataset", floor=floor)
    lx = float((x[1] - x[0]) * len(x))
    lz = float((z[1] - z[0]) * len(z))
    meta = {
        "format_version": FORMAT_VERSION,
        "re_tau": float(re_tau),
        "box_plus": [lx, float(y[-1]), lz],
        "grid": [len(x), len(y), len(z)],
        "times_plus": times_plus.tolist(),
        "storage": {"dtype": "float32", "scale": [1.0] * 3, "offset": [0.0] * 3},
        "provenance": {},
    }
    if meta_extra:
        meta.update(meta_extra)
    return FlowDataset(path=None, meta=meta, x=x, y=y, z=z, data=u_plus)


def dataset_size_bytes(path) -> int:
    return sum(os.path.getsize(f) for f in Path(path).iterdir() if f.is_file())
