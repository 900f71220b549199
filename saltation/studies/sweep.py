"""Sweeps: a grid of cases run on a Dask cluster, gathered into one table (SPEC §9).

A sweep file is a case file plus a ``[sweep]`` grid::

    base = "../default.toml"         # optional: a case file (relative to this file) …
    [flow]                            # … and/or inline tables (they override the base)
    source = "les"
    [sweep]
    concentration = [0.0004, 0.0012]  # short names where unique: run.concentration
    tau_ratio = [1.79, 2.43]          # flow.tau_ratio
    "run.seed" = [0, 1]               # or any case key by its "table.key" name

The grid is the Cartesian product of the lists, in the order written (the last key
varies fastest). Each point is a case named from its values, e.g. ``c0.04_t1.79_s0``
(concentration shown in **percent**, τ*/τ*c, seed; other keys by their name), and runs
through :func:`saltation.engine.simulation.run` into ``OUT/cases/NAME``.

Restart rules: a case whose ``summary.json`` says ``"completed"`` is finished and is not
run again (that file is written last, atomically, after every output is closed); a case
left with a checkpoint (killed or interrupted while running) resumes from it; anything
else starts afresh. A killed sweep therefore loses at most the work since the last
checkpoint of the cases in flight (``output.checkpoint_every``, 600 s of wall time by
default).

Cluster: a ``LocalCluster`` on loopback (127.0.0.1, no dashboard) with ``workers``
single-task processes, each running its case's Numba kernels on ``threads_per_worker``
threads (``run.threads``); by default workers × threads = the cores available, one case
per core while there are more cases than cores. ``scheduler="tcp://HOST:PORT"`` uses an
existing cluster instead (``dask scheduler`` and ``dask worker`` processes; tested with
two workers on loopback in tests/test_sweep_distributed.py). Start its workers with
``--nthreads 1``, so that each process runs one case at a time; ``threads_per_worker``
Numba threads per case, by default each host's cores shared among the task threads of
the workers on it (the smallest share over the hosts at the start). The sweep folder is
given to the workers as an absolute path: every worker must see it at that path (one
machine, or a shared file system). The workers must import the same saltation.

Workers that die: a case whose worker process dies (killed, out of memory, a crash) is
resubmitted by Dask to another worker and resumes from its last checkpoint — the result
is that of an uninterrupted run, bit for bit, and its summary.json says
``resumed_from_step``; the progress line says "resumed from step N". After
``distributed.scheduler.allowed-failures`` + 1 lost workers (4 by default) Dask gives the
case up (``KilledWorker``): it is reported as failed, with that reason and its checkpoint
step, and the other cases go on; running the sweep again resumes it. Each case is
counted once. Ctrl-C stops a LocalCluster's cases with its workers; on an existing
cluster the cases already running go on to the end of their run on their workers (Dask
cannot stop a running task), and a sweep started again meanwhile finds their run
directories locked ("in use by another run") until they finish.

Results: ``OUT/results.parquet``, one row per case (the grid values, then the numbers of
its summary.json: see :data:`RESULT_COLUMNS`), also returned as a DataFrame.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import time
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from flowfields.dataset import SHIPPED_DATASETS

from ..case.schema import TABLES, CaseError, load_case

# readable case names: short tags for the usual grid keys
_TAGS = {"run.concentration": "c", "flow.tau_ratio": "t", "run.seed": "s", "run.n_particles": "n",
         "flow.shear_velocity": "u", "collisions.model": "", "bed.model": "bed"}

RESULT_COLUMNS = {
    "case": "case name",
    "status": '"completed", "failed" or "interrupted"',
    "n_particles": "grains",
    "concentration": "volume fraction C (SPEC §1)",
    "tau_ratio": "τ*/τ*c",
    "tau_star": "Shields number τ*",
    "simulated_time_s": "simulated time (s)",
    "jumps": "jumps counted (each grain's first 10 dropped)",
    "H_mean": "jump height (d)", "H_std": "(d)", "L_mean": "jump length (d)", "L_std": "(d)",
    "U_mean": "mean grain velocity over a jump (u*)", "U_std": "(u*)",
    "collisions_pp": "particle–particle collisions (summary collisions.particle_particle)",
    "collisions_bed": "bed impacts",
    "collisions_pp_per_particle": "particle–particle collisions per grain, 2 × collisions_pp / N (each "
                                  "collision involves two grains; summary collisions.per_particle)",
    "collisions_pp_per_particle_per_unit_time": "the same per d/u* of simulated time",
    "collisions_pp_per_particle_per_s": "the same per simulated second",
    "bed_impacts_per_particle_per_s": "bed impacts per grain per simulated second",
    "wall_s": "wall time of the run (s), all segments", "free_flight_s": "(s)", "bed_s": "(s)",
    "particle_collisions_s": "(s)", "compile_s": "(s)", "threads": "Numba threads",
    "particle_steps_per_s": "grain-steps per second of kernel time",
}


class SweepError(CaseError):
    """A sweep file that cannot run: the message names the key and what is allowed."""


class MissingExtraError(ImportError):
    """Dask (the ``[sweep]`` extra) is not installed; the message says how to install it."""


def import_dask():
    """(Client, LocalCluster, as_completed) of dask.distributed, or MissingExtraError."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as err:
        raise MissingExtraError(f"the sweep needs the [sweep] extra: pip install 'saltation[sweep]' "
                                f"(importing dask.distributed failed: {err})", name=err.name) from None
    return Client, LocalCluster, as_completed


@dataclass
class SweepCase:
    name: str
    values: dict[str, Any]  # {"table.key": value} of the grid point
    tables: dict[str, dict[str, Any]] = field(repr=False)  # the base case tables


@dataclass
class Sweep:
    path: Path | None
    base: dict[str, dict[str, Any]]
    grid: dict[str, list]
    cases: list[SweepCase]


# --------------------------------------------------------------------------- the grid


def _all_keys() -> dict[str, list[str]]:
    """short name -> ["table.key", …] for every case key."""
    out: dict[str, list[str]] = {}
    for table, cls in TABLES.items():
        for key in cls.keys():
            out.setdefault(key, []).append(f"{table}.{key}")
    return out


def _flatten(grid: Mapping[str, Any], prefix="") -> dict[str, Any]:
    out = {}
    for k, v in grid.items():
        name = f"{prefix}{k}"
        if isinstance(v, Mapping):  # TOML dotted keys: run.seed = [...] is {"run": {"seed": [...]}}
            out.update(_flatten(v, name + "."))
        else:
            out[name] = v
    return out


def sweep_key(name: str) -> str:
    """A [sweep] key → its "table.key" name; SweepError naming the allowed keys."""
    shorts = _all_keys()
    full = {f for names in shorts.values() for f in names}
    if name in full:
        return name
    if name in shorts:
        if len(shorts[name]) == 1:
            return shorts[name][0]
        raise SweepError(f"sweep key {name!r} is ambiguous: write one of {', '.join(shorts[name])}", "sweep", name)
    import difflib

    guess = difflib.get_close_matches(name, sorted(full | set(shorts)), n=1, cutoff=0.6)
    hint = f" (did you mean {guess[0]!r}?)" if guess else ""
    unique = sorted(k for k, v in shorts.items() if len(v) == 1)
    raise SweepError(
        f"unknown sweep key {name!r}{hint}. Allowed: any case key as \"table.key\" "
        f"({', '.join(sorted(full))}), or one of the unique short names ({', '.join(unique)})",
        "sweep", name)


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value).replace("/", "-").replace(" ", "-")


def case_name(values: Mapping[str, Any]) -> str:
    """c0.04_t1.79_s0 style: concentration in percent, other keys by tag or key name."""
    parts = []
    for key, v in values.items():
        if key == "run.concentration":
            parts.append(f"c{_fmt(100.0 * v)}")
        elif key in _TAGS:
            parts.append(f"{_TAGS[key]}{_fmt(v)}")
        else:
            parts.append(f"{key.split('.', 1)[1]}{_fmt(v)}")
    return "_".join(parts) or "base"


def expand(grid: Mapping[str, list], base: Mapping[str, Mapping[str, Any]]) -> list[SweepCase]:
    """The Cartesian product of the grid lists (last key fastest), each case checked."""
    keys = list(grid)
    cases = []
    for combo in itertools.product(*(grid[k] for k in keys)):
        values = dict(zip(keys, combo))
        name = case_name(values)
        try:
            load_case(base, values)  # every case valid before anything runs
        except CaseError as err:
            raise SweepError(f"sweep case {name} ({', '.join(f'{k} = {v!r}' for k, v in values.items())}): {err}",
                             err.table, err.key) from None
        cases.append(SweepCase(name, values, {t: dict(v) for t, v in base.items()}))
    names = [c.name for c in cases]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise SweepError(f"sweep cases share names {sorted(dup)}: the grid repeats a value", "sweep")
    return cases


def load_sweep(source) -> Sweep:
    """A sweep from a TOML path or a dict (tables + "sweep" + optional "base")."""
    if isinstance(source, Mapping):
        raw, folder, path = dict(source), Path.cwd(), None
    else:
        path = Path(source)
        try:
            raw = tomllib.loads(path.read_text())
        except FileNotFoundError:
            raise SweepError(f"sweep file {str(path)!r} not found") from None
        except tomllib.TOMLDecodeError as err:
            raise SweepError(f"{path}: not valid TOML: {err}") from None
        folder = path.parent.absolute()
    grid_raw = raw.pop("sweep", None)
    if not isinstance(grid_raw, Mapping) or not grid_raw:
        raise SweepError("a sweep file needs a [sweep] table of lists, e.g. concentration = [0.0004, 0.0012]", "sweep")
    base: dict[str, dict[str, Any]] = {}
    base_file = raw.pop("base", None)
    if base_file is not None:
        if not isinstance(base_file, str):
            raise SweepError(f"base must be a path to a case file, got {base_file!r}", None, "base")
        bpath = Path(base_file) if Path(base_file).is_absolute() else folder / base_file
        base = load_case(bpath).to_dict()  # relative paths inside it resolved against its folder
        base["run"].pop("name", None)
    for table, keys in raw.items():
        if not isinstance(keys, Mapping):
            raise SweepError(f"top-level key {table!r} in a sweep file: allowed are base = \"case.toml\", "
                             f"the case tables ({', '.join(TABLES)}) and [sweep]", None, table)
        keys = dict(keys)
        if (table == "flow" and isinstance(keys.get("dataset"), str) and not Path(keys["dataset"]).is_absolute()
                and keys["dataset"] not in SHIPPED_DATASETS):  # a shipped dataset's name stays a name
            keys["dataset"] = os.path.normpath(folder / keys["dataset"])
        base.setdefault(table, {}).update(keys)
    grid: dict[str, list] = {}
    for key, values in _flatten(grid_raw).items():
        full = sweep_key(key)
        if not isinstance(values, list) or not values:
            raise SweepError(f"sweep key {key!r} must be a non-empty list of values, got {values!r}", "sweep", key)
        if full in grid:
            raise SweepError(f"sweep key {key!r} given twice (as {full})", "sweep", key)
        grid[full] = values
    return Sweep(path, base, grid, expand(grid, base))


# --------------------------------------------------------------------------- one case


def case_status(directory: Path) -> str | None:
    """The status in directory/summary.json, or None when there is none (yet)."""
    try:
        return json.loads((Path(directory) / "summary.json").read_text()).get("status")
    except (FileNotFoundError, json.JSONDecodeError):
        return None


CASE_FILE = "sweep_case.json"  # the base tables and grid values a case directory was run with


def _fingerprint(tables: Mapping, values: Mapping) -> str:
    return json.dumps({"tables": tables, "values": values}, sort_keys=True, default=str)


def is_finished(directory: Path, case: SweepCase) -> bool:
    """summary.json says "completed" and the directory was run with this very case."""
    try:
        ran = (Path(directory) / CASE_FILE).read_text()
    except FileNotFoundError:
        return False
    return case_status(directory) == "completed" and ran == _fingerprint(case.tables, case.values)


def run_case(tables: dict, values: dict, name: str, directory: str, threads: int) -> dict:
    """Run (or resume) one sweep case; returns its summary dict. Runs on a Dask worker."""
    from ..engine.simulation import CHECKPOINT, SimulationError, run

    directory = Path(directory)
    fingerprint = _fingerprint(tables, values)
    if is_finished(directory, SweepCase(name, values, tables)):
        return json.loads((directory / "summary.json").read_text())
    directory.mkdir(parents=True, exist_ok=True)
    (directory / CASE_FILE).write_text(fingerprint)
    overrides = dict(values)
    overrides["run.name"] = name
    overrides["run.threads"] = int(threads)
    resume = (directory / CHECKPOINT).exists()
    try:
        # not finished with this case: resume its checkpoint, or replace whatever is there
        res = run(tables, out=directory, progress=False, resume=resume, overwrite=not resume, **overrides)
    except SimulationError as err:
        if not (resume and str(err).startswith("cannot resume")):
            raise
        res = run(tables, out=directory, progress=False, overwrite=True, **overrides)  # the case changed: afresh
    return res.summary


# --------------------------------------------------------------------------- results


def result_row(name: str, values: Mapping[str, Any], summary: Mapping[str, Any] | None, status=None) -> dict:
    row: dict[str, Any] = {"case": name, **values}
    if summary is None:
        row["status"] = status or "missing"
        return row
    j, col, tm = summary.get("jumps", {}), summary.get("collisions", {}), summary.get("timing", {})
    n = summary.get("n_particles") or 0
    sim_s = summary.get("simulated_time_s") or 0.0
    pp = col.get("particle_particle")
    bed = col.get("bed")
    # per grain: the summary's own figure (2 × events / N: a collision involves two grains)
    per = col.get("per_particle", 2.0 * pp / n if pp is not None and n else None)
    sim_p = summary.get("simulated_time_particle") or 0.0
    row.update(
        status=summary.get("status"),
        n_particles=n,
        concentration=summary.get("concentration"),
        tau_ratio=summary.get("tau_ratio"),
        tau_star=summary.get("tau_star"),
        simulated_time_s=sim_s,
        jumps=j.get("count"),
        H_mean=j.get("H_mean"), H_std=j.get("H_std"),
        L_mean=j.get("L_mean"), L_std=j.get("L_std"),
        U_mean=j.get("U_mean"), U_std=j.get("U_std"),
        collisions_pp=pp,
        collisions_bed=bed,
        collisions_pp_per_particle=per,
        collisions_pp_per_particle_per_unit_time=per / sim_p if per is not None and sim_p else None,
        collisions_pp_per_particle_per_s=per / sim_s if per is not None and sim_s else None,
        bed_impacts_per_particle_per_s=bed / n / sim_s if bed is not None and n and sim_s else None,
        wall_s=tm.get("wall_s"),
        free_flight_s=tm.get("free_flight_s"),
        bed_s=tm.get("bed_s"),
        particle_collisions_s=tm.get("particle_collisions_s"),
        compile_s=tm.get("compile_s"),
        threads=tm.get("threads"),
        particle_steps_per_s=summary.get("particle_steps_per_s"),
    )
    return row


def gather(sweep: Sweep, out: Path) -> pd.DataFrame:
    """One row per case from the case directories' summary.json files."""
    rows = []
    for c in sweep.cases:
        d = Path(out) / "cases" / c.name
        try:
            summary = json.loads((d / "summary.json").read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            summary = None
        rows.append(result_row(c.name, c.values, summary))
    df = pd.DataFrame(rows)
    for col in df.columns:  # None → NaN in numeric columns, so Parquet gets float types
        if df[col].dtype == object and col not in ("case", "status") and df[col].map(
                lambda v: v is None or isinstance(v, (int, float)) and not isinstance(v, bool)).all():
            df[col] = pd.to_numeric(df[col])
    return df


def format_table(df: pd.DataFrame) -> str:
    cols = [c for c in df.columns if c not in ("tau_star", "simulated_time_s", "compile_s", "threads",
                                                "bed_impacts_per_particle_per_s",
                                                "collisions_pp_per_particle_per_unit_time")]
    fmt = {c: (lambda v: "" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.4g}")
           for c in cols if df[c].dtype.kind == "f"}
    return df[cols].to_string(index=False, formatters=fmt)


# --------------------------------------------------------------------------- the driver


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def plan_workers(n_cases: int, workers: int | None, threads: int | None, cores: int | None = None) -> tuple[int, int]:
    """(workers, Numba threads per case): given values kept, the rest filling the cores."""
    cores = cores or _cores()
    if workers is not None and workers < 1 or threads is not None and threads < 1:
        raise SweepError(f"workers and threads per worker must be >= 1 (got {workers}, {threads})")
    if workers is None:
        workers = max(1, min(max(n_cases, 1), cores // (threads or 1)))
    if threads is None:
        threads = max(1, cores // workers)
    return workers, threads


def _cost(case: SweepCase) -> int:
    """Grain-steps of a case (0 when its domain needs the LES box to resolve)."""
    from ..case.schema import resolve_domain

    try:
        c = resolve_domain(load_case(case.tables, case.values))
    except CaseError:
        return 0
    return int(c.n_particles) * int(c.n_steps)


def _worker_cores() -> int:
    """The cores this (worker) process may use; run on the workers by _remote_plan."""
    return _cores()


def _remote_plan(client, address: str, threads_per_worker: int | None) -> tuple[int, str]:
    """(Numba threads per case, the status line) on an existing scheduler's workers.

    threads_per_worker absent: each host's cores shared among the task threads of the
    workers on it (one case per task thread), the smallest share over the hosts, at least
    1; workers that join later get the same number."""
    workers = client.scheduler_info(n_workers=-1).get("workers", {})
    slots = sum(w.get("nthreads", 1) for w in workers.values())
    if threads_per_worker:
        threads = threads_per_worker
    elif workers:
        cores = client.run(_worker_cores)  # {worker address: cores}
        per_host: dict[str, int] = {}
        for w in workers.values():
            per_host[w["host"]] = per_host.get(w["host"], 0) + w.get("nthreads", 1)
        threads = max(1, min(cores[a] // per_host[w["host"]] for a, w in workers.items() if a in cores))
    else:
        threads = 1
    if not workers:
        return threads, (f"scheduler {address}: no workers yet: the cases wait for one; "
                         f"{threads} Numba thread(s) per case")
    line = (f"scheduler {address}: {len(workers)} worker(s), {slots} case(s) at a time; "
            f"{threads} Numba thread(s) per case")
    multi = sorted(w.get("name", a) for a, w in workers.items() if w.get("nthreads", 1) > 1)
    if multi:
        line += (f" (worker(s) {', '.join(map(str, multi))} run several cases in one process: "
                 f"start them with --nthreads 1)")
    return threads, line


def _failure(err: BaseException, directory: Path) -> str:
    """A failed case's message; a case whose workers kept dying says so, and where it stands."""
    from ..io.run_directory import CHECKPOINT_NAME

    if type(err).__name__ != "KilledWorker":
        return f"{type(err).__name__}: {err}"
    tries = getattr(err, "allowed_failures", 3) + 1
    last = getattr(getattr(err, "last_worker", None), "address", "?")
    step = None
    try:
        import numpy as np

        with np.load(directory / CHECKPOINT_NAME) as z:
            step = json.loads(bytes(z["meta"]).decode()).get("step")
    except (OSError, ValueError, KeyError):
        pass
    where = (f"its checkpoint at step {step} is kept: run the same command again to resume it" if step is not None
             else "it left no checkpoint: run the same command again to start it afresh")
    return (f"KilledWorker: the worker process running this case died, on {tries} worker(s) in turn (killed, out "
            f"of memory, or a crash; the last was {last}), and the scheduler gives a case up after "
            f"distributed.scheduler.allowed-failures + 1 = {tries} lost worker(s); {where}")


def run_sweep(source, out=None, scheduler: str | None = None, workers: int | None = None,
              threads_per_worker: int | None = None, processes: bool = True,
              echo: Callable[[str], None] | None = print) -> pd.DataFrame:
    """Run every unfinished case of a sweep; write and return the results table.

    out: the sweep folder (default sweeps/<file stem>); scheduler: address of an existing
    Dask scheduler (else a LocalCluster on loopback); processes=False keeps the local
    workers as threads of this process (tests; one worker at a time)."""
    sweep = source if isinstance(source, Sweep) else load_sweep(source)
    stem = sweep.path.stem if sweep.path else "sweep"
    out = Path(out or Path("sweeps") / stem)
    (out / "cases").mkdir(parents=True, exist_ok=True)
    say = echo or (lambda _m: None)
    (out / "sweep.json").write_text(json.dumps(
        {"source": str(sweep.path) if sweep.path else None, "grid": sweep.grid, "base": sweep.base,
         "cases": {c.name: c.values for c in sweep.cases}}, indent=1, default=str))
    todo = [c for c in sweep.cases if not is_finished(out / "cases" / c.name, c)]
    total, done = len(sweep.cases), len(sweep.cases) - len(todo)
    say(f"sweep {stem}: {total} cases, {done} already finished, {len(todo)} to run -> {out}")
    for c in todo:
        if case_status(out / "cases" / c.name) == "completed":
            say(f"{c.name}: completed, but with another case definition: running it again")
    t0 = time.perf_counter()
    failures = {}
    stopped = None
    if todo:
        Client, LocalCluster, as_completed = import_dask()

        n_workers, threads = plan_workers(len(todo), workers, threads_per_worker)
        if scheduler:
            cluster, client = None, Client(scheduler)
            threads, line = _remote_plan(client, scheduler, threads_per_worker)
            say(line)
            if workers is not None:
                say(f"workers = {workers} is for a LocalCluster; the scheduler's workers run the cases")
        else:
            if not processes:
                n_workers = 1  # Numba's thread pool serves one launching thread at a time
            # processes: TCP on loopback only; threads: in-process transport, no sockets at all
            net = {"host": "127.0.0.1"} if processes else {}
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=processes,
                                   dashboard_address=None, **net)
            client = Client(cluster)
            where = "127.0.0.1" if processes else "in-process threads"
            say(f"LocalCluster on {where}: {n_workers} worker(s) x {threads} Numba thread(s)")
        try:
            futures = {}
            # task keys name the sweep folder too: two sweeps of one file on one scheduler stay apart
            tag = hashlib.sha1(str(out.absolute()).encode()).hexdigest()[:8]
            # dearest first (grains × steps), so that no long case starts last and runs alone
            for c in sorted(todo, key=lambda c: -_cost(c)):
                fut = client.submit(run_case, c.tables, c.values, c.name, str((out / "cases" / c.name).absolute()),
                                    threads, key=f"saltation-{stem}-{c.name}-{tag}", pure=False)
                futures[fut] = c
            try:
                for fut in as_completed(futures):
                    c = futures.pop(fut, None)  # each case once, however often Dask ran it
                    if c is None:
                        continue
                    done += 1
                    try:
                        s = fut.result()
                        j = s["jumps"]
                        stats = (f"H {j['H_mean']:.2f} d, L {j['L_mean']:.1f} d, U {j['U_mean']:.2f} u*"
                                 if j.get("count") else "no jumps counted")
                        resumed = (f" (resumed from step {s['resumed_from_step']})"
                                   if s.get("resumed_from_step") is not None else "")
                        say(f"[{done}/{total}] {c.name}: {s['status']}{resumed}, N = {s['n_particles']}, {stats}, "
                            f"wall {s['timing']['wall_s']:.1f} s")
                    except Exception as err:  # noqa: BLE001 - one failed case must not stop the others
                        failures[c.name] = _failure(err, out / "cases" / c.name)
                        say(f"[{done}/{total}] {c.name}: FAILED {failures[c.name]}")
            except KeyboardInterrupt as err:
                # Ctrl-C: the cases in flight stop with the workers (their last periodic
                # checkpoint stays); what finished is gathered below; run again to go on
                stopped = err
                say(f"sweep interrupted with {done}/{total} cases finished; run the same command again to continue")
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    df = gather(sweep, out)
    for name, why in failures.items():
        df.loc[df["case"] == name, "status"] = "failed"
        df.loc[df["case"] == name, "error"] = why
    df.to_parquet(out / "results.parquet", index=False)
    say(f"sweep wall time {time.perf_counter() - t0:.1f} s; wrote {out / 'results.parquet'}")
    if stopped is not None:
        raise stopped
    df.attrs["wall_s"] = time.perf_counter() - t0
    df.attrs["out"] = str(out)
    return df
