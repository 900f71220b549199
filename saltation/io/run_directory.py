"""Output folders and the run directory: checked before long work, never two runs' files
mixed, locked while a run writes.

Any ``--out`` (run, sweep, validate, flow …) is checked first (``check_output_directory``):
a path that is a file, lies under a file or cannot be written is a clear error at once,
not a traceback after the flow is loaded and the kernels compiled.

A run directory that already holds files is someone's results: a new run into it is
refused unless it resumes that run (``--resume``: its checkpoint) or replaces it
(``--overwrite``: the run's own outputs are deleted first; files the run did not write
are left alone). While a run writes, ``.lock`` in the directory holds an exclusive
``flock``: a second run into the same directory at the same time is refused with the
first one's pid and start time. The kernel drops the lock when its process dies, so a
run killed with kill -9 leaves no stale lock, only its checkpoint.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import socket
import tempfile
import time
from pathlib import Path

LOCK = ".lock"
CHECKPOINT_NAME = "checkpoint.npz"  # the run's checkpoint (simulation.CHECKPOINT), known here without Numba
# everything a run (spheres or composites) or `saltation analyze` of it writes
RUN_OUTPUTS = ("config.toml", "summary.json", "jumps.parquet", "tracks.parquet", "particles.parquet",
               "variance.parquet", "particles.pvd", "vtk", "checkpoint.npz", ".parts", "analysis")


class RunDirectoryError(RuntimeError):
    """The run directory cannot be used: the message says why and what to do."""


class OutputDirectoryError(RunDirectoryError, ValueError):
    """An output folder that cannot be used; the message names the path and the problem."""


def check_output_directory(path, what: str = "run directory") -> Path:
    """``path`` as a Path, once it is known that it is (or can be made as) a writable folder.

    Nothing is created: an existing folder is probed by really creating (and removing) a
    temporary file in it, a missing one by doing so in its nearest existing parent, since
    permission bits do not tell (root writes to a read-only folder; a read-only mount
    refuses even root). ``what`` starts the message (e.g. "--out", "run directory").
    Raises :class:`OutputDirectoryError`."""
    p = Path(path).expanduser()
    shown = f"{what} {str(path)!r}"
    if p.exists() and not p.is_dir():
        raise OutputDirectoryError(f"{shown} is an existing file, not a folder; give a folder path "
                                   f"(or remove the file)")
    probe = p
    while not probe.exists():
        if probe.is_symlink():  # a dangling link: mkdir would fail on it
            raise OutputDirectoryError(f"{shown}: {str(probe)!r} is a broken symbolic link")
        parent = probe.parent
        if parent == probe:
            break
        probe = parent
    if probe.exists() and not probe.is_dir():
        raise OutputDirectoryError(f"{shown} lies under {str(probe)!r}, which is a file, not a folder; "
                                   f"give a path whose parents are folders")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".saltation-write-test-", dir=probe)
    except OSError as err:
        where = "" if probe == p else f" (its nearest existing parent {str(probe)!r} cannot be written)"
        raise OutputDirectoryError(f"{shown} cannot be written{where}: {err.strerror or err}; "
                                   f"check its permissions or give another folder") from None
    os.close(fd)
    try:
        os.unlink(tmp)
    except OSError:
        pass
    return p


def _lock(path: Path):
    fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        try:
            holder = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
        except (ValueError, OSError):
            holder = {}
        os.close(fd)
        who = (f" (pid {holder.get('pid')} on {holder.get('host')}, since {holder.get('started')})" if holder else "")
        raise RunDirectoryError(f"run directory {path} is in use by another run{who}; wait for it to finish, "
                                f"or choose another --out") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                              "started": time.strftime("%Y-%m-%d %H:%M:%S")}).encode(), 0)
    return fd


def _unlock(path: Path, fd: int):
    with contextlib.suppress(OSError):
        os.unlink(path / LOCK)  # before the lock is dropped: a waiting run then makes a fresh one
    os.close(fd)


def _remove_outputs(path: Path):
    for name in RUN_OUTPUTS:
        for victim in (path / name, path / (name + ".tmp")):
            if victim.is_dir() and not victim.is_symlink():
                shutil.rmtree(victim)
            elif victim.exists() or victim.is_symlink():
                victim.unlink()


def _describe(path: Path, files: list[str]) -> str:
    try:
        status = json.loads((path / "summary.json").read_text()).get("status")
    except (OSError, ValueError):
        status = None
    shown = ", ".join(sorted(files)[:5]) + (f" and {len(files) - 5} more" if len(files) > 5 else "")
    return (f"summary.json says status \"{status}\"; " if status else "") + f"it holds {shown}"


@contextlib.contextmanager
def claim_run_directory(path, *, resume: bool = False, overwrite: bool = False, checkpoint: str = CHECKPOINT_NAME):
    """Create and lock ``path`` for one run; refuse a directory with files in it unless
    resume (its checkpoint is then read by the run) or overwrite (the run's outputs are
    removed). Released when the block ends, however it ends."""
    path = Path(path)
    if resume and overwrite:
        raise RunDirectoryError("--resume and --overwrite contradict each other: give one")
    check_output_directory(path)
    path.mkdir(parents=True, exist_ok=True)
    try:
        fd = _lock(path)
    except PermissionError:
        raise RunDirectoryError(f"run directory {path} is not writable (permission denied); choose another --out") from None
    except OSError as exc:  # read-only file system and the like
        raise RunDirectoryError(f"run directory {path} is not writable ({exc.strerror}); choose another --out") from None
    try:
        files = [p.name for p in path.iterdir() if p.name != LOCK]
        if files and not resume:
            if not overwrite:
                raise RunDirectoryError(
                    f"run directory {path} is not empty ({_describe(path, files)}); "
                    f"use --resume (Python: resume=True) to continue its run"
                    f"{'' if (path / checkpoint).exists() else ' (it has no checkpoint)'}, "
                    f"--overwrite (overwrite=True) to replace it, or another --out")
            _remove_outputs(path)
        yield path
    finally:
        _unlock(path, fd)
