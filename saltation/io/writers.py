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

from ..engine.statistics import DISCARDED_JUMPS

TRACK_COLUMNS = ("particle", "t", "x", "y", "z", "u", "v", "w", "spin_x", "spin_y", "spin_z")
JUMP_COLUMNS = ("particle", "jump", "t_start", "length", "height", "duration", "velocity", "discarded")
ROW_GROUP_ROWS = 200_000  # rows per Parquet row group (appended batches are flushed at this size)

# (unit, meaning) of every column a run directory's Parquet files hold: stored in each
# file's schema (field metadata "unit", "description"), so a script reading the files
# with pyarrow or pandas needs none of this code. Particle units: d, u*, d/u*.
COLUMN_DOCS = {
    "particle": ("1", "grain index, 0 … N-1"),
    "t": ("d/u*", "time since the start of the run"),
    "x": ("d", "streamwise position of the grain's centre, unwrapped (continuous across the periodic boundary)"),
    "y": ("d", "height of the grain's centre above the bed top"),
    "z": ("d", "spanwise position of the grain's centre, unwrapped"),
    "u": ("u*", "streamwise velocity"), "v": ("u*", "wall-normal velocity"), "w": ("u*", "spanwise velocity"),
    "spin_x": ("u*/d", "angular velocity, x component (world frame)"),
    "spin_y": ("u*/d", "angular velocity, y component (world frame)"),
    "spin_z": ("u*/d", "angular velocity, z component (world frame; < 0 is topspin for a grain moving +x)"),
    "q0": ("1", "orientation quaternion body -> world, scalar part"),
    "q1": ("1", "orientation quaternion, x part"), "q2": ("1", "orientation quaternion, y part"),
    "q3": ("1", "orientation quaternion, z part"),
    "class_id": ("1", "Zingg class of the grain (summary.json shape.class_ids)"),
    "jump": ("1", "index of the grain's jump, from 0 (each grain's first jump starts at its release)"),
    "t_start": ("d/u*", "time of the bed contact the jump started from"),
    "length": ("d", "streamwise distance between the two bed contacts"),
    "height": ("d", "highest elevation of the grain's bottom above the bed top during the jump"),
    "duration": ("d/u*", "time between the two bed contacts (at least one step: saltation.bed.jumps)"),
    "velocity": ("u*", "mean streamwise grain velocity U = length / duration"),
    "discarded": ("bool", f"one of the grain's first {DISCARDED_JUMPS} jumps (initial-condition memory, "
                          "Moreno-Casas et al. 2022 §3.2): left out of summary.json's statistics"),
    "collisions": ("1", "grain-grain collisions of this grain"),
    "bed_impacts": ("1", "bed impacts of this grain (contacts, including those within one bed-contact episode)"),
    "jumps": ("1", "jumps this grain completed"),
    "max_overlap": ("d", "largest grain-grain contact overlap of this grain"),
    "zingg_class": ("1", "Zingg class: disk, blade, rod or equant (Zingg 1935 thresholds 2/3)"),
    "subtype": ("1", "equant sub-type of the seed construction (0 for other classes)"),
    "Dl": ("d", "long axis of the grain"), "Di": ("d", "intermediate axis"), "Ds": ("d", "short axis"),
    "n_spheres": ("1", "component spheres of the bonded-sphere grain"),
    "volume": ("d^3", "volume of the bonded-sphere grain"),
}


def schema_with_docs(columns, dtypes, meta: dict | None = None) -> pa.Schema:
    """Arrow schema whose fields carry their unit and meaning (COLUMN_DOCS) and whose file
    metadata holds ``meta`` as JSON under the key "saltation"."""
    fields = []
    for c, d in zip(columns, dtypes):
        unit, text = COLUMN_DOCS.get(c, ("", ""))
        kind = d if isinstance(d, pa.DataType) else pa.from_numpy_dtype(np.dtype(d))
        fields.append(pa.field(c, kind, metadata={"unit": unit, "description": text}))
    return pa.schema(fields, metadata={"saltation": json.dumps(meta or {}, default=_json_default)})


def run_metadata(case, kind: str) -> dict:
    """What a reader of a run's Parquet file needs to turn it into SI units."""
    from .. import __version__

    return {"file": kind, "saltation_version": __version__,
            "units": "particle units: lengths in d, velocities in u*, times in d/u*",
            "d_m": case.particle.diameter, "u_star_m_s": case.shear_velocity, "time_scale_s": case.time_scale,
            "tau_star": case.shields_number, "tau_ratio": case.tau_ratio, "dt_particle": case.dt_particle,
            "y_origin": "the bed top (the top of the bed grains)", "discarded_first_jumps": DISCARDED_JUMPS}


def write_table(path: Path, frame, meta: dict | None = None) -> None:
    """A pandas DataFrame → Parquet with the documented schema, written atomically."""
    path = Path(path)
    table = pa.Table.from_pandas(frame, preserve_index=False)
    schema = schema_with_docs(table.column_names, [f.type for f in table.schema], meta)
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table.cast(schema), tmp)
    tmp.replace(path)


class ParquetTableWriter:
    """Append column batches to one Parquet file (one row group per batch).

    ``parts``: a folder for checkpointable output. Batches then go to numbered part files
    ``parts/<stem>-00000.parquet`` …; ``checkpoint()`` closes the open part, so every part
    it counts is a complete file that survives a kill; ``close()`` merges the parts, in
    order, into ``path`` (written to a temporary name and renamed). ``first_part``: resume
    after that many parts (later ones, written after the checkpoint, are deleted).
    """

    def __init__(self, path: Path, columns, dtypes, parts: Path | None = None, first_part: int = 0,
                 meta: dict | None = None):
        """meta: the run's description (units, scales) stored in the file's metadata."""
        self.path = Path(path)
        self.schema = schema_with_docs(columns, dtypes, meta)
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
        if self._pending_rows >= ROW_GROUP_ROWS:
            self.flush()

    def flush(self):
        if not self._pending or self._closed:
            return
        arrays = []
        for field in self.schema:
            arrays.append(pa.array(np.concatenate([b[field.name] for b in self._pending]).astype(field.type.to_pandas_dtype()),
                                   type=field.type))
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

    sort_by: tuple[str, ...] = ()  # columns the finished file is ordered by (none: as appended)

    def close(self):
        if self._closed:
            return
        if self.parts is None:
            self.flush()
            self._writer.close()
            self._writer = None
            if self.sort_by:
                self._write_sorted([self.path])
        else:
            self.checkpoint()
            if self.sort_by:
                self._write_sorted(self._part_files())
            else:
                tmp = self.path.with_name(self.path.name + ".tmp")
                with pq.ParquetWriter(tmp, self.schema) as out:
                    for part in self._part_files():
                        f = pq.ParquetFile(part)
                        for g in range(f.num_row_groups):
                            out.write_table(f.read_row_group(g))
                tmp.replace(self.path)
        self._closed = True

    def _write_sorted(self, sources):
        """``path`` = the rows of ``sources`` ordered by ``sort_by`` (so that the file does not
        depend on when rows were appended: output switches and checkpoints move chunk ends)."""
        tables = [pq.read_table(f, schema=self.schema) for f in sources]
        table = pa.concat_tables(tables) if tables else self.schema.empty_table()  # no part: no row
        table = table.sort_by([(k, "ascending") for k in self.sort_by])
        tmp = self.path.with_name(self.path.name + ".tmp")
        with pq.ParquetWriter(tmp, self.schema) as out:
            out.write_table(table, row_group_size=ROW_GROUP_ROWS)
        tmp.replace(self.path)


class TrackWriter(ParquetTableWriter):
    """tracks.parquet: particle, t, unwrapped x, y above the bed top, z, velocity, spin."""

    def __init__(self, path, **kw):
        super().__init__(path, TRACK_COLUMNS, ["int32"] + ["float64"] * 10, **kw)

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
    """tracks.parquet of bonded-sphere grains (engine/composites.py): the sphere columns (spin =
    the grain's angular velocity, world frame, u*/d) plus the orientation quaternion
    q0..q3 (body → world, scalar first) and the grain's Zingg class id (summary.json
    ``shape.class_ids``)."""

    def __init__(self, path, **kw):
        super().__init__(path, CLUSTER_TRACK_COLUMNS, ["int32"] + ["float64"] * 14 + ["int8"], **kw)

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
    """jumps.parquet: one row per jump (dimensionless: d, d/u*, u*), ordered by (particle,
    jump); ``discarded`` marks each grain's first DISCARDED_JUMPS jumps."""

    sort_by = ("particle", "jump")

    def __init__(self, path, **kw):
        super().__init__(path, JUMP_COLUMNS, ["int32", "int32"] + ["float64"] * 5 + ["bool"], **kw)

    def collect(self, st, rows: list) -> None:
        """Move the finished jumps out of the kernels' per-grain buffers (st.jump_buf,
        jump_buf_n, jump_count of either grain family) into the file and into ``rows``
        (particle, jump, length, height, velocity, duration: the summary's statistics)."""
        drained = drain_jumps(st)
        if drained is None:
            return
        part, jidx, data = drained
        length, height, duration = data[:, 1], data[:, 2], data[:, 3]
        velocity = length / duration  # duration ≥ one step (saltation.bed.jumps)
        self.append(particle=part.astype(np.int32), jump=jidx.astype(np.int32), t_start=data[:, 0], length=length,
                    height=height, duration=duration, velocity=velocity, discarded=jidx < DISCARDED_JUMPS)
        rows.append(np.column_stack([part, jidx, length, height, velocity, duration]))


def drain_jumps(st):
    """Empty the kernels' per-grain jump buffers (st.jump_buf, jump_buf_n, jump_count of
    either grain family): (particle, jump index, records (M, 4): t_start, length, height,
    duration), or None when no jump finished since the last call."""
    nb = st.jump_buf_n
    idx = np.nonzero(nb)[0]
    if len(idx) == 0:
        return None
    counts = nb[idx]
    part = np.repeat(idx, counts)
    data = np.concatenate([st.jump_buf[p, : nb[p]] for p in idx])
    first = st.jump_count[idx] - counts  # index of the first buffered jump per grain
    jidx = np.concatenate([np.arange(a, a + k) for a, k in zip(first, counts)])
    nb[idx] = 0
    return part, jidx, data


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
