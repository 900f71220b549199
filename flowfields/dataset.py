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
_REQUIRED_META = ("format_version", "re_tau", "times_plus", "storage", "provenance")


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
                f"[0, {self.y[-1]:.6g}] ({len(bad)} point(s) outside)"
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
    _validate_grid(x, y, z, times_plus, u_plus.shape, where=str(path))
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


def _validate_grid(x, y, z, times, shape, where):
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
    if len(y) == 0 or y[0] <= 0 or np.any(np.diff(y) <= 0):
        raise DatasetError(f"{where}: y⁺ cell centres must be positive and increasing (wall at y⁺ = 0)")
    if len(times) > 1:
        d = np.diff(times)
        if np.any(d <= 0) or np.ptp(d) > 1e-3 * d.mean():
            raise DatasetError(f"{where}: snapshot times are not uniformly spaced (intervals {d.min():.6g}–{d.max():.6g} t⁺)")


def open_dataset(path=None) -> FlowDataset:
    """Open a flow dataset folder (None: the shipped default LES dataset).

    Arrays are memory-mapped read-only; nothing is copied."""
    p = SHIPPED_DATASET if path is None else Path(path)
    if not p.exists():
        hint = " (the shipped dataset is missing from this installation)" if path is None else ""
        raise DatasetError(f"flow dataset not found: {p}{hint}")
    if p.is_file():
        raise DatasetError(f"{p} is a file; a dataset is a folder made by 'saltation flow import' or 'flow generate'")
    meta_file = p / "meta.json"
    if not meta_file.exists():
        raise DatasetError(f"{p}: no meta.json — not a saltation flow dataset (import raw data with 'saltation flow import')")
    try:
        meta = json.loads(meta_file.read_text())
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{meta_file}: not valid JSON ({exc})") from None
    missing = [k for k in _REQUIRED_META if k not in meta]
    if missing:
        raise DatasetError(f"{meta_file}: missing metadata {missing}")
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
    _validate_grid(arrays["x"], arrays["y"], arrays["z"], np.asarray(meta["times_plus"]), arrays["u"].shape, str(p))
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
    _validate_grid(x, y, z, times_plus, u_plus.shape, "in-memory dataset")
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
