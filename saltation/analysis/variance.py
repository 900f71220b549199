"""Ensemble statistics of grain displacements, accumulated while a run goes (SPEC §6).

Nikora et al. (2002): ⟨X′²⟩(t) with X the displacement over an elapsed time t and the
average over the ensemble of grains. At paper scale (99 000 grains, thousands of d/u*)
the tracks do not fit in memory, so the run loop feeds positions to a
:class:`VarianceAccumulator`, which keeps only

* the x, z positions of every grain at each **time origin** t₀ₖ (K origins):
  K × N × 2 float64, and
* per **particle group** g, origin k and **lag** m (elapsed time τₘ): the count and the
  sums Σ X, Σ X², Σ Z, Σ Z² of the displacements X = x(t₀ₖ + τₘ) − x(t₀ₖ) (likewise Z):
  G × K × M × 5 float64.

Memory: 16·K·N + 40·G·K·M bytes. With the defaults (K = 8 origins, G = 128 groups,
M ≈ 70 lags) that is 12.7 MB + 2.9 MB at N = 99 000 grains, independent of run length.

Sampling plan (the same whether fed during a run or from tracks.parquet, so both give the
same numbers): samples j = 0 … n−1 on a uniform grid of spacing Δ (d/u*). The first
``skip_fraction`` (10 %) of the record is left out (initial-condition memory, cf. the
first 10 jumps dropped in paper §3.2); the longest lag is ``lag_fraction`` (half) of what
remains; the K origins are spread evenly over the rest, so **every origin covers every
lag** and the curve at each lag averages the same origins. Lags are integer multiples of
Δ spaced evenly in log t (20 per decade), which weights a log–log fit evenly.

Groups: grain p belongs to group p mod G. The groups are what the bootstrap resamples
(diffusion.py); with G = N each group is one grain. Pooling the group sums gives the exact
ensemble statistics, whatever G.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

N_ORIGINS = 8
SKIP_FRACTION = 0.1
LAG_FRACTION = 0.5
LAGS_PER_DECADE = 20
N_GROUPS = 128
SUM_FIELDS = ("n", "sum_x", "sum_xx", "sum_z", "sum_zz")
VARIANCE_FILE = "variance.parquet"


class AnalysisError(ValueError):
    """Data that cannot give the statistic asked for; the message says what is missing
    and what would be enough."""


@dataclass(frozen=True)
class SamplingPlan:
    """Origins and lags as sample indices on a uniform grid of spacing ``dt`` (d/u*)."""

    n_samples: int
    dt: float
    origins: np.ndarray  # (K,) sample index of each time origin
    lags: np.ndarray  # (M,) lag in samples, lags[0] == 0

    @property
    def lag_times(self) -> np.ndarray:
        return self.lags * self.dt

    @property
    def max_lag_time(self) -> float:
        return float(self.lags[-1] * self.dt)


def make_plan(n_samples: int, dt: float, n_origins: int = N_ORIGINS, skip_fraction: float = SKIP_FRACTION,
              lag_fraction: float = LAG_FRACTION, lags_per_decade: int = LAGS_PER_DECADE) -> SamplingPlan:
    """The sampling plan for ``n_samples`` samples spaced ``dt`` d/u* apart."""
    if n_origins < 1:
        raise AnalysisError(f"n_origins = {n_origins}: at least 1 time origin is needed")
    last = n_samples - 1
    skip = int(round(skip_fraction * last))
    max_lag = int(math.floor(lag_fraction * (last - skip)))
    if max_lag < 1:
        raise AnalysisError(
            f"the record holds {n_samples} samples spaced {dt:.4g} d/u* ({last * dt:.4g} d/u* in all): too short "
            f"for any displacement statistics; at least {int(math.ceil(2 / lag_fraction / (1 - skip_fraction))) + 2} samples are needed")
    origins = np.unique(np.round(np.linspace(skip, last - max_lag, n_origins)).astype(np.int64))
    n_log = max(2, int(math.ceil(math.log10(max_lag) * lags_per_decade)) + 1)
    lags = np.unique(np.concatenate([[0], np.round(np.geomspace(1, max_lag, n_log)).astype(np.int64)]))
    return SamplingPlan(n_samples=int(n_samples), dt=float(dt), origins=origins, lags=lags)


class VarianceAccumulator:
    """Group sums of x, z displacements per (time origin, lag), fed one sample at a time.

    ``sample(j, pos)`` takes sample index j (time j·Δ) and the (N, 3) unwrapped positions
    (x, y, z in d); samples that are neither an origin nor an origin + lag are ignored.
    ``next_sample(j)`` says which sample is needed next, so a run loop can stop its kernel
    only there.
    """

    def __init__(self, n_particles: int, plan: SamplingPlan, n_groups: int | None = None):
        self.n_particles = int(n_particles)
        self.plan = plan
        self.n_groups = int(min(n_particles, N_GROUPS if n_groups is None else n_groups))
        self.groups = np.arange(self.n_particles) % self.n_groups
        k, m = len(plan.origins), len(plan.lags)
        self.ref = np.full((k, self.n_particles, 2), np.nan)
        self.sums = np.zeros((self.n_groups, k, m, len(SUM_FIELDS)))
        targets = plan.origins[:, None] + plan.lags[None, :]  # (K, M) sample index of each cell
        self._due: dict[int, list[tuple[int, int]]] = {}
        for (kk, mm), j in np.ndenumerate(targets):
            self._due.setdefault(int(j), []).append((kk, mm))
        self._due_sorted = np.array(sorted(self._due), dtype=np.int64)
        self.last_sample = -1

    @property
    def memory_bytes(self) -> int:
        return int(self.ref.nbytes + self.sums.nbytes)

    def next_sample(self, j: int) -> int | None:
        """The first sample index > j that the accumulator needs (None: none left)."""
        i = np.searchsorted(self._due_sorted, j, side="right")
        return int(self._due_sorted[i]) if i < len(self._due_sorted) else None

    def sample(self, j: int, pos: np.ndarray) -> None:
        cells = self._due.get(int(j))
        if cells is None:
            return
        xz = np.asarray(pos)[:, (0, 2)]
        for k, m in cells:  # lag 0 comes first: it sets the origin's reference
            if m == 0:
                self.ref[k] = xz
            d = xz - self.ref[k]
            s = self.sums[:, k, m]
            g = self.groups
            s[:, 0] += np.bincount(g, minlength=self.n_groups)
            s[:, 1] += np.bincount(g, d[:, 0], minlength=self.n_groups)
            s[:, 2] += np.bincount(g, d[:, 0] * d[:, 0], minlength=self.n_groups)
            s[:, 3] += np.bincount(g, d[:, 1], minlength=self.n_groups)
            s[:, 4] += np.bincount(g, d[:, 1] * d[:, 1], minlength=self.n_groups)
        self.last_sample = int(j)

    # ------------------------------------------------------------------ files
    def metadata(self) -> dict:
        p = self.plan
        return {"n_particles": self.n_particles, "n_groups": self.n_groups, "dt": p.dt,
                "n_samples": p.n_samples, "origins": p.origins.tolist(), "lags": p.lags.tolist(),
                "last_sample": self.last_sample, "units": "t in d/u*, displacements in d",
                "memory_bytes": self.memory_bytes}

    def to_frame(self) -> pd.DataFrame:
        g, k, m = np.meshgrid(np.arange(self.n_groups), np.arange(len(self.plan.origins)),
                              np.arange(len(self.plan.lags)), indexing="ij")
        df = pd.DataFrame({"group": g.ravel().astype(np.int32), "origin": k.ravel().astype(np.int32),
                           "t_origin": self.plan.origins[k.ravel()] * self.plan.dt,
                           "lag": self.plan.lag_times[m.ravel()]})
        for i, name in enumerate(SUM_FIELDS):
            df[name] = self.sums[..., i].ravel()
        return df

    def write(self, path) -> Path:
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = Path(path)
        table = pa.Table.from_pandas(self.to_frame(), preserve_index=False)
        table = table.replace_schema_metadata({b"saltation.variance": json.dumps(self.metadata()).encode()})
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        tmp.replace(path)
        return path


def read_sums(path) -> tuple[np.ndarray, np.ndarray, dict]:
    """(sums (G, K, M, 5), lag times (M,), metadata) from a variance.parquet file."""
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    meta = json.loads(table.schema.metadata[b"saltation.variance"])
    df = table.to_pandas()
    g, k = meta["n_groups"], len(meta["origins"])
    m = len(meta["lags"])
    df = df.sort_values(["group", "origin", "lag"])
    sums = df[list(SUM_FIELDS)].to_numpy().reshape(g, k, m, len(SUM_FIELDS))
    lags = np.asarray(meta["lags"]) * meta["dt"]
    return sums, lags, meta


def variance_curves(sums: np.ndarray, weights: np.ndarray | None = None):
    """Ensemble variances ⟨X′²⟩, ⟨Z′²⟩ (d²) per lag, averaged over the origins.

    ``sums`` (G, K, M, 5); ``weights`` (B, G) group multiplicities for B bootstrap
    replicates (None: every group once). Returns var_x, var_z of shape (B, M) (or (M,))
    and the number of origins that hold each lag. The variance at one origin is the
    unbiased sample variance over the grains, X′ = X − X̄; cells a run never reached
    (count 0) are left out of the average over origins.
    """
    single = weights is None
    w = np.ones((1, sums.shape[0])) if single else np.asarray(weights, dtype=float)
    pooled = np.einsum("bg,gkmf->bkmf", w, sums)  # (B, K, M, 5)
    n = pooled[..., 0]
    have = n > 1
    safe = np.where(have, n, 2.0)
    out = []
    for s1, s2 in ((pooled[..., 1], pooled[..., 2]), (pooled[..., 3], pooled[..., 4])):
        v = np.where(have, (s2 - s1 * s1 / safe) / (safe - 1.0), 0.0)
        out.append(v.sum(axis=1) / np.maximum(have.sum(axis=1), 1))
    n_origins = have[0].sum(axis=0)
    if single:
        return out[0][0], out[1][0], n_origins
    return out[0], out[1], n_origins


class RunVariance:
    """The accumulator as the run loop sees it: time steps instead of sample indices.

    Sample j is taken at step j·``every``; ``next_step(step)`` is the next step the
    accumulator needs (the loop ends a kernel chunk there), ``sample_step(step, pos)``
    feeds the unwrapped positions. ``save``/``load`` carry the sums across a checkpoint.
    """


    def __init__(self, n_particles: int, n_steps: int, every: int, dt: float, n_origins: int = N_ORIGINS):
        self.every = int(every)
        n_samples = n_steps // self.every + 1
        self.acc = VarianceAccumulator(n_particles, make_plan(n_samples, dt * self.every, n_origins=n_origins))

    def next_step(self, step: int) -> int | None:
        j = self.acc.next_sample(step // self.every)
        return None if j is None else j * self.every

    def sample_step(self, step: int, pos: np.ndarray) -> None:
        if step % self.every == 0:
            self.acc.sample(step // self.every, pos)

    def write(self, path) -> Path:
        return self.acc.write(path)

    def summary(self) -> dict:
        p = self.acc.plan
        return {"file": VARIANCE_FILE, "sample_interval_particle": p.dt, "origins": len(p.origins),
                "lags": len(p.lags), "max_lag_particle": p.max_lag_time, "groups": self.acc.n_groups,
                "memory_bytes": self.acc.memory_bytes}

    def state_arrays(self) -> dict:
        """The sums so far, for the run's checkpoint (engine/simulation.py)."""
        return {"ref": self.acc.ref, "sums": self.acc.sums, "last_sample": np.int64(self.acc.last_sample)}

    def restore(self, arrays: dict, step: int) -> None:
        """The sums of a checkpoint taken at ``step`` (state_arrays)."""
        if arrays["sums"].shape != self.acc.sums.shape:
            raise AnalysisError(f"the checkpoint's variance sums have shape {arrays['sums'].shape}, "
                                f"this run's plan {self.acc.sums.shape}")
        self.acc.ref[...] = arrays["ref"]
        self.acc.sums[...] = arrays["sums"]
        self.acc.last_sample = int(arrays["last_sample"])
