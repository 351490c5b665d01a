"""How many BLAS/OpenMP threads this process uses: every command sets it (`trunkslam --threads
N`, default 1), so that a run is as fast on a busy machine as on a quiet one.

The filter's linear algebra works on matrices of a few hundred to a few thousand rows, where a
multi-threaded BLAS spends more on waking and synchronising its threads than it saves: the full
Victoria Park run took 44 s with the default threads of a 2-core machine against 9 s with one
(and 79 s against 15-18 s with another job on the second core), the same output to the bit.
The trials of `reproduce` run in worker processes of one thread each (`experiments.exec.local`).

Before numpy is loaded the limit goes into the environment (OMP_NUM_THREADS and friends, read
when the BLAS starts, and inherited by child processes); once it is loaded, `threadpoolctl`
sets it on the libraries in memory. An environment variable the user set is respected unless
`--threads` is given.
"""

from __future__ import annotations

import os
import sys

__all__ = ["THREAD_VARIABLES", "set_threads"]

THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)


def set_threads(n: int | None) -> int:
    """Limit this process's BLAS/OpenMP threads to `n` (None: the user's OMP_NUM_THREADS if
    set, else 1); returns the limit."""
    if n is None:
        given = os.environ.get("OMP_NUM_THREADS", "")
        n = int(given) if given.isdigit() and int(given) > 0 else 1
    if n < 1:
        raise ValueError(f"threads: must be at least 1, got {n}")
    if "numpy" not in sys.modules:
        for var in THREAD_VARIABLES:
            os.environ[var] = str(n)
    else:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=n)
    return n
