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
    """Append column batches to one Parquet file (one row group per batch).

    ``parts``: a folder for checkpointable output. Batches then go to numbered part files
    ``parts/<stem>-00000.parquet`` …; ``checkpoint()`` closes the open part, so every part
    it counts is a complete file that survives a kill; ``close()`` merges the parts, in
    order, into ``path`` (written to a temporary name and renamed). ``first_part``: resume
    after that many parts (later ones, written after the checkpoint, are deleted).
    """

    def __init__(self, path: Path, columns, dtypes, parts: Path | None = None, first_part: int = 0):
        self.path = Path(path)
        self.schema = pa.schema([(c, pa.from_numpy_dtype(np.dtype(d))) for c, d in zip(columns, dtypes)])
        self.parts = Path(parts) if parts is not None else None
        self.n_parts = int(first_part)
        if self.parts is None:
            self._writer = pq.ParquetWriter(self.path, self.schema)
        else:
            self.parts.mkdir(parents=True, exist_ok=True)
            for old in self._part_files():
                if int(old.stem.rsplit("-", 1)[1]) >= self.n_parts:
                    old.unlink()
            self._writer = None
        self._closed = False
        self._pending: list[dict] = []
        self._pending_rows = 0
        self.rows = 0

    def _part_files(self):
        return sorted(self.parts.glob(f"{self.path.stem}-[0-9][0-9][0-9][0-9][0-9].parquet"))

    def append(self, **cols):
        n = len(next(iter(cols.values())))
        if n == 0:
            return
        # copies: callers pass views of live state (st.pos[:, 0]) that the next step changes
        self._pending.append({k: np.array(v, copy=True) for k, v in cols.items()})
        self._pending_rows += n
        if self._pending_rows >= 200_000:
            self.flush()

    def flush(self):
        if not self._pending or self._closed:
            return
        arrays = []
        for field in self.schema:
            arrays.append(pa.array(np.concatenate([b[field.name] for b in self._pending]).astype(field.type.to_pandas_dtype())))
        if self._writer is None:  # parts mode: open the next part lazily
            self._writer = pq.ParquetWriter(self.parts / f"{self.path.stem}-{self.n_parts:05d}.parquet", self.schema)
        self._writer.write_table(pa.Table.from_arrays(arrays, schema=self.schema))
        self.rows += self._pending_rows
        self._pending, self._pending_rows = [], 0

    def checkpoint(self) -> int:
        """Flush and close the open part (parts mode); returns the number of complete parts."""
        if self.parts is None:
            raise RuntimeError(f"{self.path.name}: checkpoint() needs a writer opened with parts=")
        self.flush()
        if self._writer is not None:
            self._writer.close()
            self._writer = None
            self.n_parts += 1
        return self.n_parts

    def close(self):
        if self._closed:
            return
        if self.parts is None:
            self.flush()
            self._writer.close()
            self._writer = None
        else:
            self.checkpoint()
            tmp = self.path.with_name(self.path.name + ".tmp")
            with pq.ParquetWriter(tmp, self.schema) as out:
                for part in self._part_files():
                    f = pq.ParquetFile(part)
                    for g in range(f.num_row_groups):
                        out.write_table(f.read_row_group(g))
            tmp.replace(self.path)
        self._closed = True


class TrackWriter(ParquetTableWriter):
    """tracks.parquet: particle, t, unwrapped x, y above the bed top, z, velocity, spin."""

    def __init__(self, path, **parts):
        super().__init__(path, TRACK_COLUMNS, ["int32"] + ["float64"] * 10, **parts)

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


CLUSTER_TRACK_COLUMNS = TRACK_COLUMNS + ("q0", "q1", "q2", "q3", "class_id")


class ClusterTrackWriter(ParquetTableWriter):
    """tracks.parquet of bonded-sphere grains (run_clusters.py): the sphere columns (spin =
    the grain's angular velocity, world frame, u*/d) plus the orientation quaternion
    q0..q3 (body → world, scalar first) and the grain's Zingg class id (summary.json
    ``shape.class_ids``)."""

    def __init__(self, path, **parts):
        super().__init__(path, CLUSTER_TRACK_COLUMNS, ["int32"] + ["float64"] * 14 + ["int8"], **parts)

    def write(self, t, particles, pos_unwrapped, vel, omega, quat, class_id):
        n = len(particles)
        self.append(
            particle=particles.astype(np.int32), t=np.full(n, t),
            x=pos_unwrapped[:, 0], y=pos_unwrapped[:, 1], z=pos_unwrapped[:, 2],
            u=vel[:, 0], v=vel[:, 1], w=vel[:, 2],
            spin_x=omega[:, 0], spin_y=omega[:, 1], spin_z=omega[:, 2],
            q0=quat[:, 0], q1=quat[:, 1], q2=quat[:, 2], q3=quat[:, 3],
            class_id=np.asarray(class_id, dtype=np.int8),
        )


class JumpWriter(ParquetTableWriter):
    """jumps.parquet: one row per jump (dimensionless: d, d/u*, u*)."""

    def __init__(self, path, **parts):
        super().__init__(path, JUMP_COLUMNS, ["int32", "int32"] + ["float64"] * 5, **parts)


class ParaViewWriter:
    """particles.pvd + one VTU piece per frame (points with velocity, spin, diameter)."""

    def __init__(self, run_dir: Path, diameter_m: float, frames=None):
        """frames: [(t_seconds, file name), …] already written (resuming a run); VTU
        pieces beyond them, written after the checkpoint, are deleted."""
        self.run_dir = Path(run_dir)
        self.folder = self.run_dir / "vtk"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.frames: list[tuple[float, str]] = [(float(t), str(n)) for t, n in (frames or [])]
        self.diameter_m = diameter_m
        keep = {Path(n).name for _, n in self.frames}
        for piece in self.folder.glob("particles_*.vtu"):
            if piece.name not in keep:
                piece.unlink()

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
