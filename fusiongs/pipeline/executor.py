"""Independent pieces of work run side by side: the recordings of a dataset (one process each).

A piece is a call ``fn(task)`` of a top-level function (so that it pickles) that never raises for
a failure of its own: it returns a row saying so, and the other pieces go on. ``executor="local"``
runs the pieces in ``jobs`` worker processes of this machine (started with ``spawn``, so each
imports torch afresh); each worker's torch uses ``cores // jobs`` threads, so that ``jobs``
workers share the cores instead of fighting over them. ``"serial"`` runs them one after another in
this process (what ``jobs=1`` does too).
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from fusiongs.errors import InputError

EXECUTORS = ("local", "serial")


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


def run_pieces(fn: Callable[[Any], dict], tasks: Sequence[Any], *, jobs: int, executor: str = "local",
               on_done: Callable[[dict], None] | None = None) -> list[dict]:
    """``[fn(task) for task in tasks]``, in the order of ``tasks``, run by ``executor``.

    Args:
        fn: a top-level function returning a dict (a summary row); it reports its own failures.
        tasks: picklable arguments, one per piece.
        jobs: workers at once (``>= 1``); 1 runs the pieces in this process.
        executor: one of :data:`EXECUTORS`.
        on_done: called with each row as its piece finishes (in finishing order), e.g. to print it.
    """
    if executor not in EXECUTORS:
        raise InputError("command line", "--executor", f"one of {', '.join(EXECUTORS)}", executor)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise InputError("command line", "--jobs", "a positive number of workers", jobs)
    done = on_done or (lambda row: None)
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
