"""The run's progress bar (tqdm on stderr).

On a terminal it redraws a few times a second; when stderr is a file or a pipe (a batch
job's log, a sweep worker) it writes a line at most every ``LOG_INTERVAL`` seconds, so
a long run does not fill its log with redraws.
"""
from __future__ import annotations

import sys

LOG_INTERVAL = 30.0  # s between progress lines when stderr is not a terminal


def progress_bar(total: int, *, desc: str, enabled: bool, initial: int = 0):
    from tqdm import tqdm

    tty = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    return tqdm(total=total, initial=initial, desc=desc, unit="step", disable=not enabled, delay=2.0,
                mininterval=0.1 if tty else LOG_INTERVAL, file=sys.stderr)
