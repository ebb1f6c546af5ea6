"""Independent pieces of work run side by side: the recordings of a dataset (one process each).

A piece is a call ``fn(task)`` of a top-level function (so that it pickles) that never raises for
a failure of its own: it returns a row saying so, and the other pieces go on. Executors:

- ``"local"`` runs the pieces in ``jobs`` worker processes of this machine (started with
  ``spawn``, so each imports torch afresh); each worker's torch uses ``cores // jobs`` threads, so
  that ``jobs`` workers share the cores instead of fighting over them.
- ``"serial"`` runs them one after another in this process (what ``jobs=1`` does too).
- ``"dask"`` submits them to a Dask cluster (the ``cluster`` extra, ``distributed``): the running
  scheduler at ``address`` (``tcp://HOST:PORT``; its workers must see the same files, e.g. a shared
  file system), or, without an address, a local cluster of ``jobs`` worker processes started for
  the run. Each piece's torch uses as many threads as its Dask worker has. Dask rather than Ray:
  a pure-Python package that starts a local cluster in about a second, connects to an existing one
  with one address, and whose futures are those of :mod:`concurrent.futures`.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from fusiongs.errors import InputError, MissingDependencyError

EXECUTORS = ("local", "serial", "dask")


def default_jobs(n_pieces: int, cores: int | None = None) -> int:
    """Workers for ``n_pieces`` pieces: one per core, never more than there are pieces (>= 1)."""
    cores = cores or os.cpu_count() or 1
    return max(1, min(n_pieces, cores))


def worker_threads(jobs: int, cores: int | None = None) -> int:
    """torch threads of each of ``jobs`` workers on ``cores`` cores: ``max(1, cores // jobs)``."""
    cores = cores or os.cpu_count() or 1
    return max(1, cores // max(1, jobs))


def _start_worker(threads: int) -> None:
    """Worker initialiser: fix the thread count before anything imports torch."""
    os.environ["OMP_NUM_THREADS"] = str(threads)
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import torch

    torch.set_num_threads(threads)


def _on_dask_worker(fn: Callable[[Any], dict], task: Any) -> dict:
    """``fn(task)`` on a Dask worker, with torch using that worker's threads."""
    import torch
    from distributed import get_worker

    torch.set_num_threads(max(1, int(get_worker().state.nthreads)))
    return fn(task)


def _run_dask(fn: Callable[[Any], dict], tasks: Sequence[Any], jobs: int, address: str | None,
              done: Callable[[dict], None]) -> list[dict]:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise MissingDependencyError("distributed", "--executor dask", "cluster") from None
    cluster = None
    try:
        if address:
            try:
                client = Client(address, timeout="10s")
            except (OSError, TimeoutError) as e:
                raise InputError("command line", "--address", "the address of a running Dask scheduler "
                                 "(tcp://HOST:PORT)", f"{address}: {e}") from None
        else:
            workers = min(jobs, len(tasks))
            cluster = LocalCluster(n_workers=workers, threads_per_worker=worker_threads(workers),
                                   processes=True, dashboard_address=None)
            client = Client(cluster)
        with client:
            futures = {client.submit(_on_dask_worker, fn, task, pure=False): i
                       for i, task in enumerate(tasks)}
            rows: list[dict | None] = [None] * len(tasks)
            for future in as_completed(futures):
                rows[futures[future]] = future.result()
                done(rows[futures[future]])
        return rows
    finally:
        if cluster is not None:
            cluster.close()


def run_pieces(fn: Callable[[Any], dict], tasks: Sequence[Any], *, jobs: int, executor: str = "local",
               on_done: Callable[[dict], None] | None = None, address: str | None = None) -> list[dict]:
    """``[fn(task) for task in tasks]``, in the order of ``tasks``, run by ``executor``.

    Args:
        fn: a top-level function returning a dict (a summary row); it reports its own failures.
        tasks: picklable arguments, one per piece.
        jobs: workers at once (``>= 1``); 1 runs the pieces in this process.
        executor: one of :data:`EXECUTORS`.
        on_done: called with each row as its piece finishes (in finishing order), e.g. to print it.
        address: ``executor="dask"``: a running scheduler's address; None starts a local cluster.
    """
    if executor not in EXECUTORS:
        raise InputError("command line", "--executor", f"one of {', '.join(EXECUTORS)}", executor)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise InputError("command line", "--jobs", "a positive number of workers", jobs)
    done = on_done or (lambda row: None)
    if address and executor != "dask":
        raise InputError("command line", "--address", "--executor dask with a scheduler address", address)
    if executor == "dask":
        return _run_dask(fn, tasks, jobs, address, done) if tasks else []
    if executor == "serial" or jobs == 1 or len(tasks) <= 1:
        rows = []
        for task in tasks:
            rows.append(fn(task))
            done(rows[-1])
        return rows
    workers = min(jobs, len(tasks))
    rows: list[dict | None] = [None] * len(tasks)
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_start_worker, initargs=(worker_threads(workers),)) as pool:
        futures = {pool.submit(fn, task): i for i, task in enumerate(tasks)}
        for future in as_completed(futures):
            rows[futures[future]] = future.result()
            done(rows[futures[future]])
    return rows
