"""`DaskExecutor`: trials on a `dask.distributed` scheduler (`trunkslam reproduce --dask ADDRESS`).

The only module that imports dask (the optional extra `trunkslam[dask]`). Chunks of trials are
submitted as tasks and their records gathered as they finish (`distributed.as_completed`); the
executor puts them back in trial order. Every worker must have trunkslam installed from the
same checkout (the scene files are read from it) and, for the Victoria Park experiments, the
data at its own `TRUNKSLAM_DATA`. Workers started by `dask worker` (through a nanny) run with
one BLAS/OpenMP thread already (distributed's `pre-spawn-environ`); on connecting, every worker
loads the numba kernels once (`warm_kernels`).
"""

from __future__ import annotations

import logging
import uuid

from experiments.errors import ConfigError
from experiments.exec.local import warm_kernels
from experiments.exec.trials import Executor, run_chunk

__all__ = ["DaskExecutor", "check_address"]

log = logging.getLogger(__name__)


def _client(address_or_client):
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(
            "--dask needs dask.distributed: pip install 'trunkslam[dask]' (or dask[distributed])"
        ) from None
    if isinstance(address_or_client, Client):
        return address_or_client, False
    check_address(address_or_client)
    try:
        return Client(address_or_client, timeout="20s"), True
    except OSError as exc:
        raise ConfigError(f"--dask: no Dask scheduler at {address_or_client!r}: {exc}") from None


def check_address(address) -> None:
    """`ConfigError` naming --dask when `address` is not a scheduler address dask can use (a
    string of a known scheme: tcp://host:8786, tls://..., or host:port), before connecting."""
    if not isinstance(address, str) or not address.strip():
        raise ConfigError(
            f"--dask: expected a scheduler address (tcp://host:8786), got {address!r}"
        )
    try:
        from distributed.comm.addressing import parse_address
        from distributed.comm.registry import get_backend
    except ImportError:
        return  # `_client` says what to install
    try:
        get_backend(parse_address(address)[0])
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"--dask {address!r}: not a Dask scheduler address ({exc})") from None


class DaskExecutor(Executor):
    """Trials on the workers of a Dask scheduler.

    target: the scheduler's address (`tcp://host:8786`), or a `distributed.Client` (then the
    caller keeps it open; a `LocalCluster`'s client in the tests)."""

    name = "dask"

    def __init__(self, target) -> None:
        self.client, self._own = _client(target)
        self.address = self.client.scheduler.address
        self.client.run(warm_kernels)
        log.info("Dask scheduler %s, %d worker threads", self.address, self.workers)

    @property
    def workers(self) -> int:
        n = sum(self.client.nthreads().values())
        return max(n, 1)

    def _submit(self, fn, chunks):
        token = uuid.uuid4().hex[:8]
        futures = {
            self.client.submit(run_chunk, fn, c, pure=False, key=f"trials-{token}-{k}"): c
            for k, c in enumerate(chunks)
        }

        def cancel() -> None:
            self.client.cancel(list(futures))

        return self._finished(futures, cancel), cancel

    @staticmethod
    def _finished(futures: dict, cancel):
        from distributed import as_completed

        try:
            for f in as_completed(futures):
                chunk = futures[f]
                try:
                    out = f.result()
                except Exception as exc:  # a worker lost, a record that does not pickle
                    out = [(i, False, (f"{type(exc).__name__}: {exc}", "")) for i, *_ in chunk]
                yield chunk, out
        finally:
            cancel()

    def describe(self) -> dict:
        return {"executor": self.name, "scheduler": self.address, "workers": self.workers}

    def close(self) -> None:
        if self._own:
            self.client.close()
