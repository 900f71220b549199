"""How long idle OpenMP threads spin before they sleep (Numba's "omp" threading layer,
GNU libgomp).

At the end of every parallel loop libgomp's threads spin, by default 300 000 times
(milliseconds), waiting for the next loop. When another process holds one of the cores
that the loop's threads need, the thread there runs only in that process's gaps, and every
loop waits for it while the others spin on: a run on all cores of a machine with anything
else running is then several times slower than on one thread. A step of this code is a
dozen or more short parallel loops, so it meets that wait thousands of times a second.
Measured on a 2-core Intel Xeon VM (2026-12-07; ``cases/default.toml`` for 1 s, 300
grains, 2 threads; wall time of the run's steps, two or three runs each):

=====================  ==================  =========================================
GOMP_SPINCOUNT         machine quiet (s)   a busy loop on the other core (s)
=====================  ==================  =========================================
libgomp's default      1.05–1.11           3.78, 9.41 (one thread: 1.21–1.26)
1000                   1.08–1.10           1.80–1.88
300 (this default)     1.11–1.13           1.48–1.55
100                    1.21–1.24           1.37–1.43
OMP_WAIT_POLICY=passive 1.21–1.26          1.29–1.31
=====================  ==================  =========================================

and in the reduced sweep's dense cases after spin-up (``benchmarks/bench_dense.py
--threads 2``, µs per grain-step at 2.07 % and 3.94 %): quiet 2.53 and 4.04 with libgomp's
default, 2.77 and 4.16–4.29 with 300; busy 6.46 and 12.44 with libgomp's default, 3.43
and 5.05 with 300, 3.24 and 5.02 on one thread. So a short spin costs a few per cent on a
machine the run has to itself and saves a factor of two to eight on a shared one.

Set before libgomp is loaded (the first parallel kernel call), and only when the user has
set neither GOMP_SPINCOUNT nor OMP_WAIT_POLICY: a machine given to one run alone can take
libgomp's default back with ``GOMP_SPINCOUNT=300000`` or ``OMP_WAIT_POLICY=active``.
Results do not depend on it (the same bits).
"""
from __future__ import annotations

import os

SPIN_COUNT = 300  # libgomp spins before an idle thread sleeps (its default: 300 000)


def use_short_spin() -> None:
    """GOMP_SPINCOUNT = SPIN_COUNT unless GOMP_SPINCOUNT or OMP_WAIT_POLICY is set."""
    if "GOMP_SPINCOUNT" not in os.environ and "OMP_WAIT_POLICY" not in os.environ:
        os.environ["GOMP_SPINCOUNT"] = str(SPIN_COUNT)
