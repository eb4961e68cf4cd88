"""The worker processes of the describe and match-pairs stages: a local pool or a Dask cluster.

A task function reads what every task shares (surfaces, meshes, options) from
:data:`worker_state`, filled once per process by an initializer, instead of receiving it
with every task. On a Dask cluster (``scheduler``) what the initializer needs is sent to
every worker once and the initializer runs once per worker and stage; the tasks are the
same, each with its own random stream, so the results are those of a local run.
"""

from __future__ import annotations

import threading

worker_state: dict = {}  # what a worker process holds between tasks (set by an initializer)
_state_lock = threading.Lock()  # a Dask worker may run several tasks at once, in threads
_clients: dict = {}  # scheduler address -> Dask client, one per process


def _start_worker(initializer, initargs) -> None:
    from .allocator import retain_freed_memory

    retain_freed_memory()  # as the command line does in the parent (a spawned process starts afresh)
    if initializer is not None:
        initializer(*initargs)


def pool_map(fn, tasks, *, jobs: int, initializer=None, initargs=(), scheduler: str | None = None):
    """``map(fn, tasks)`` in order: in this process, in ``jobs`` local processes when
    jobs > 1 (spawned, not forked: the parent holds Open3D and FFT thread pools), or on the
    Dask cluster of ``scheduler`` (``tcp://host:8786``) when given."""
    if scheduler:
        yield from _cluster_map(fn, tasks, scheduler=scheduler, initializer=initializer, initargs=initargs)
        return
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


def connect(scheduler: str):
    """A new Dask client of the cluster at ``scheduler``; ReassembleError, one line, when the
    address is malformed or nobody answers there."""
    from distributed import Client
    from distributed.comm.addressing import get_address_host_port

    from .errors import ReassembleError, first_line

    try:
        get_address_host_port(scheduler)  # first: a client made of a bad address complains again at exit
        return Client(scheduler, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ReassembleError(f"cannot reach the Dask scheduler at {scheduler}: {first_line(exc)}") from None


def client(scheduler: str):
    """The Dask client of this process for the cluster at ``scheduler`` (made once, kept)."""
    if scheduler not in _clients:
        _clients[scheduler] = connect(scheduler)
    return _clients[scheduler]


def _cluster_map(fn, tasks, *, scheduler: str, initializer, initargs):
    """:func:`pool_map` on a Dask cluster: the shared arguments scattered to every worker
    once, a task per item, the results in order."""
    import uuid

    c = client(scheduler)
    token = uuid.uuid4().hex  # this stage's shared state, told apart from an earlier stage's
    shared = c.scatter(list(initargs), broadcast=True, hash=False) if initializer is not None else []
    futures = [c.submit(_cluster_task, fn, task, initializer, shared, token, pure=False, key=f"{fn.__name__}-{token}-{k}")
               for k, task in enumerate(tasks)]
    try:
        for future in futures:
            yield future.result()
    finally:
        c.cancel(futures + shared)


def _cluster_task(fn, task, initializer, shared, token):
    with _state_lock:  # stages come one after another; within one the tasks only read the state
        if worker_state.get("_token") != token:
            if "_token" not in worker_state:
                from .allocator import retain_freed_memory

                retain_freed_memory()
            if initializer is not None:
                initializer(*shared)
            worker_state["_token"] = token
    return fn(task)
