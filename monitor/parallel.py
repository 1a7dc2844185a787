"""Independent pieces of work (a design per envelope point) run in parallel on Dask.

Why Dask and not a process pool of our own: the same code then runs on this machine's cores (a ``LocalCluster`` of
worker processes, the default) and on a real cluster (``--scheduler tcp://host:8786``: a ``dask scheduler`` with
workers on other machines), with the scheduler's retries, its reporting of a worker that died, and its dashboard
for free. The work must be picklable functions of picklable arguments (module-level functions, plants, numpy).

* ``jobs <= 1`` and no scheduler, or a single task: in this process, one after the other (no cluster to start).
* no scheduler: a ``LocalCluster`` of ``min(jobs, tasks)`` worker processes of one thread each, on loopback
  (``127.0.0.1``), its dashboard on a free port (the fixed 8787 would collide between two runs), its INFO log
  quiet. The workers
  are started with the thread-count variables (``OMP_NUM_THREADS``, ...) set to 1 unless the user set them: a
  numerical library's own threads in every worker on a 2-core machine fight each other.
* a scheduler address: that cluster's workers, which must have this package installed. An address that does not
  answer within ``CONNECT_TIMEOUT_S`` is a one-line error.

``done(name, result, seconds)`` is called in this process as each task finishes (for the caller's progress line);
a task that raises ``UserError`` cancels the others and is re-raised naming the task.
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from monitor.errors import UserError

__all__ = ["run_tasks", "CONNECT_TIMEOUT_S"]

T = TypeVar("T")
CONNECT_TIMEOUT_S = 10.0
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS")


@contextlib.contextmanager
def one_thread_each() -> Iterator[None]:
    """Set the thread-count variables the workers inherit (those the user set are kept), then restore ours."""
    saved = {name: os.environ.get(name) for name in _THREAD_VARIABLES}
    try:
        for name in _THREAD_VARIABLES:
            os.environ.setdefault(name, "1")
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def run_tasks(
    fn: Callable[..., T],
    tasks: Sequence[tuple[str, tuple[Any, ...]]],
    jobs: int,
    done: Callable[[str, T, float], None],
    scheduler: str | None = None,
    what: str = "{}",
) -> dict[str, T]:
    """``fn(*args)`` for each ``(name, args)`` (see the module docstring); the results by name, in ``tasks``' order.
    ``what``: how an error names its task (``"point '{}'"``)."""
    out: dict[str, T] = {}
    t0 = time.perf_counter()
    if scheduler is None and (jobs <= 1 or len(tasks) <= 1):
        for name, args in tasks:
            try:
                out[name] = fn(*args)
            except UserError as exc:
                raise type(exc)(f"{what.format(name)}: {exc}") from None
            done(name, out[name], time.perf_counter() - t0)
        return out
    with _client(scheduler, min(jobs, len(tasks))) as client:
        from distributed import as_completed

        run = uuid.uuid4().hex[:8]
        futures = {client.submit(fn, *args, key=f"{name}-{run}", pure=False): name for name, args in tasks}
        for future in as_completed(futures):
            name = futures[future]
            try:
                out[name] = future.result()
            except UserError as exc:
                client.cancel(list(futures))
                raise type(exc)(f"{what.format(name)}: {exc}") from None
            done(name, out[name], time.perf_counter() - t0)
    return {name: out[name] for name, _ in tasks}


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int) -> Iterator[Any]:
    """A Dask client: of the cluster at ``scheduler``, or of a local cluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S:g}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise UserError(
                f"--scheduler {scheduler}: no Dask scheduler answered within {CONNECT_TIMEOUT_S:g} s ({exc})"
            ) from None
        with _quiet("distributed"), client:
            yield client
        return
    with (
        _quiet("distributed"),
        one_thread_each(),
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.ERROR,
        ) as cluster,
        Client(cluster) as client,
    ):
        yield client


@contextlib.contextmanager
def _quiet(name: str) -> Iterator[None]:
    """The ``name`` logger at WARNING while the cluster lives: its INFO lines (a scheduler's, each worker's) are
    the cluster's business, not the command's output (``--log-level DEBUG`` on the command keeps them)."""
    logger = logging.getLogger(name)
    saved = logger.level
    if logging.getLogger().getEffectiveLevel() > logging.DEBUG:
        logger.setLevel(logging.WARNING)
    try:
        yield
    finally:
        logger.setLevel(saved)
