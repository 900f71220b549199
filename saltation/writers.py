"""Writers of a run directory (SPEC §9): Parquet tables, ParaView PVD/VTU, JSON summary.

Writers are small classes driven by the run loop; they never touch the physics. Each
flushes what it has on ``close()``, which the run loop calls in a ``finally`` block, so an
interrupted or failed run keeps everything written so far.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

TRACK_COLUMNS = ("particle", "t", "x", "y", "z", "u", "v", "w", "spin_x", "spin_y", "spin_z")
JUMP_COLUMNS = ("particle", "jump", "t_start", "length", "height", "duration", "velocity")


class ParquetTableWriter:
    """Append column batches to one Parquet file (one row group per batch)."""

    def __init__(self, path: Path, columns, dtypes):
        self.path = Path(path)
        self.schema = pa.schema([(c, pa.from_numpy_dtype(np.dtype(d))) for c, d in zip(columns, dtypes)])
        self._writer = pq.ParquetWriter(self.path, self.schema)
        self._pending: list[dict] = []
        self._pending_rows = 0
        self.rows = 0

    def append(self, **cols):
        n = len(next(iter(cols.values())))
        if n == 0:
            return
        self._pending.append(cols)
        self._pending_rows += n
        if self._pending_rows >= 200_000:
            self.flush()

    def flush(self):
        if not self._pending or self._writer is None:
            return
        arrays = []
        for field in self.schema:
            arrays.append(pa.array(np.concatenate([b[field.name] for b in self._pending]).astype(field.type.to_pandas_dtype())))
        self._writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.rows += self._pending_rows
        self._pending, self._pending_rows = [], 0

    def close(self):
        if self._writer is not None:
            self.flush()
            self._writer.close()
            self._writer = None


class TrackWriter(ParquetTableWriter):
    """tracks.parquet: particle, t, unwrapped x, y above the bed top, z, velocity, spin."""

    def __init__(self, path):
        super().__init__(path, TRACK_COLUMNS, ["int32"] + ["float64"] * 10)

    def write(self, t, particles, pos_unwrapped, vel, spin):
        n = len(particles)
        self.append(
            particle=particles.astype(np.int32),
            t=np.full(n, t),
            x=pos_unwrapped[:, 0],
            y=pos_unwrapped[:, 1],
            z=pos_unwrapped[:, 2],
            u=vel[:, 0],
            v=vel[:, 1],
            w=vel[:, 2],
            spin_x=spin[:, 0],
            spin_y=spin[:, 1],
            spin_z=spin[:, 2],
        )


class JumpWriter(ParquetTableWriter):
    """jumps.parquet: one row per jump (dimensionless: d, d/u*, u*)."""

    def __init__(self, path):
        super().__init__(path, JUMP_COLUMNS, ["int32", "int32"] + ["float64"] * 5)


class ParaViewWriter:
    """particles.pvd + one VTU piece per frame (points with velocity, spin, diameter)."""

    def __init__(self, run_dir: Path, diameter_m: float):
        self.run_dir = Path(run_dir)
        self.folder = self.run_dir / "vtk"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.frames: list[tuple[float, str]] = []
        self.diameter_m = diameter_m

    def write(self, t_seconds, pos_m, vel_ms, spin_rads):
        import meshio

        name = f"vtk/particles_{len(self.frames):05d}.vtu"
        n = len(pos_m)
        mesh = meshio.Mesh(
            np.asarray(pos_m, dtype=np.float64),
            [("vertex", np.arange(n).reshape(-1, 1))],
            point_data={
                "velocity": np.asarray(vel_ms, dtype=np.float64),
                "spin": np.asarray(spin_rads, dtype=np.float64),
                "diameter": np.full(n, self.diameter_m),
            },
        )
        meshio.write(self.run_dir / name, mesh, binary=True)
        self.frames.append((float(t_seconds), name))
        self._write_pvd()

    def _write_pvd(self):
        lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1">', "  <Collection>"]
        for t, name in self.frames:
            lines.append(f'    <DataSet timestep="{t:.9g}" part="0" file="{name}"/>')
        lines += ["  </Collection>", "</VTKFile>", ""]
        (self.run_dir / "particles.pvd").write_text("\n".join(lines))

    def close(self):
        self._write_pvd()


def write_json(path: Path, obj) -> None:
    """Write JSON atomically (a reader never sees half a file)."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, default=_json_default))
    tmp.replace(path)


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serializable: {type(o).__name__}")
