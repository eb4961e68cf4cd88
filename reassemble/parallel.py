"""The process pool of the describe and match-pairs stages.

A task function reads what every task shares (surfaces, meshes, options) from
:data:`worker_state`, filled once per process by an initializer, instead of receiving it
with every task.
"""

from __future__ import annotations

worker_state: dict = {}  # what a worker process holds between tasks (set by an initializer)


def _start_worker(initializer, initargs) -> None:
    from .allocator import retain_freed_memory

    retain_freed_memory()  # as the command line does in the parent (a spawned process starts afresh)
    if initializer is not None:
        initializer(*initargs)


def pool_map(fn, tasks, *, jobs: int, initializer=None, initargs=()):
    """``map(fn, tasks)`` in order, in ``jobs`` processes when jobs > 1 (spawned, not forked:
    the parent holds Open3D and FFT thread pools)."""
    if jobs <= 1 or len(tasks) <= 1:
        if initializer is not None:
            initializer(*initargs)
        try:
            yield from map(fn, tasks)
        finally:
            worker_state.clear()
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=multiprocessing.get_context("spawn"),
                             initializer=_start_worker, initargs=(initializer, initargs)) as pool:
        yield from pool.map(fn, tasks, chunksize=max(1, len(tasks) // (8 * jobs)))
