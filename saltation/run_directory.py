"""The run directory: refuse to mix two runs' files, lock it while a run writes.

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
import time
from pathlib import Path

LOCK = ".lock"
# everything a run (spheres or composites) or `saltation analyze` of it writes
RUN_OUTPUTS = ("config.toml", "summary.json", "jumps.parquet", "tracks.parquet", "particles.parquet",
               "variance.parquet", "particles.pvd", "vtk", "checkpoint.npz", ".parts", "analysis")


class RunDirectoryError(RuntimeError):
    """The run directory cannot be used: the message says why and what to do."""


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
def claim_run_directory(path, *, resume: bool = False, overwrite: bool = False, checkpoint: str = "checkpoint.npz"):
    """Create and lock ``path`` for one run; refuse a directory with files in it unless
    resume (its checkpoint is then read by the run) or overwrite (the run's outputs are
    removed). Released when the block ends, however it ends."""
    path = Path(path)
    if resume and overwrite:
        raise RunDirectoryError("--resume and --overwrite contradict each other: give one")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise RunDirectoryError(f"run directory {path} is a file (or lies under one); choose another --out") from None
    except NotADirectoryError:
        raise RunDirectoryError(f"run directory {path} lies under a file; choose another --out") from None
    except PermissionError:
        raise RunDirectoryError(f"run directory {path} cannot be created (permission denied); "
                                f"choose another --out") from None
    if not path.is_dir():
        raise RunDirectoryError(f"run directory {path} is a file; choose another --out")
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
                    f"use --resume to continue its run{'' if (path / checkpoint).exists() else ' (it has no checkpoint)'}, "
                    f"--overwrite to replace it, or another --out")
            _remove_outputs(path)
        yield path
    finally:
        _unlock(path, fd)
