"""The describe and pairs stages on a Dask cluster (``--scheduler``): the same result as a local run."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from reassemble.parallel import pool_map, worker_state

from .conftest import TORUS3, assert_same_run, shared_run


@pytest.fixture(scope="module")
def cluster():
    """A local Dask cluster of two single-threaded worker processes."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as c:
        yield c


def _init(offset, table):
    worker_state.clear()
    worker_state.update(offset=offset, table=table, pid=os.getpid())


def _task(k):
    return worker_state["offset"] + worker_state["table"][k], worker_state["pid"]


def _plain(k):
    return k * k


def test_pool_map_on_a_cluster_keeps_order_and_each_stage_its_own_state(cluster):
    """Results come in task order, read the state their stage's initializer set (a second
    stage with other shared arguments is not served the first one's), and the tasks ran
    in more than one worker process."""
    table = list(range(100, 140))
    first = list(pool_map(_task, list(range(40)), jobs=1, initializer=_init, initargs=(0, table),
                          scheduler=cluster.scheduler_address))
    assert [v for v, _ in first] == table
    assert len({pid for _, pid in first} - {os.getpid()}) == 2
    second = list(pool_map(_task, list(range(40)), jobs=1, initializer=_init, initargs=(1000, table),
                           scheduler=cluster.scheduler_address))
    assert [v for v, _ in second] == [1000 + t for t in table]
    assert list(pool_map(_plain, list(range(7)), jobs=1, scheduler=cluster.scheduler_address)) == [k * k for k in
                                                                                                     range(7)]


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:9", "notanaddress"])
def test_an_unreachable_scheduler_is_a_one_line_error(tmp_path, puzzle_dir, address):
    """Nobody at the address, or no address at all: one line, no traceback (not even the
    one a half-made Dask client prints at exit), no output."""
    env = {**os.environ, "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"}
    proc = subprocess.run([sys.executable, "-m", "reassemble", "run", str(puzzle_dir / "fragments"), "--out",
                           str(tmp_path / "out"), "--quiet", "--scheduler", address],
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"Dask scheduler at {address}" in lines[0], proc.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@shared_run(TORUS3)
def test_run_on_a_cluster_writes_what_a_local_run_writes(puzzles, cluster, tmp_path):
    """``reassemble run --scheduler`` on two Dask workers: the files of the local run of the
    same puzzle and seed, byte for byte but for the timings."""
    local = puzzles.run(*TORUS3)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "reassemble", "run", str(puzzles.puzzle(*TORUS3) / "fragments"),
                           "--out", str(out), "--quiet", "--seed", "0", "--scheduler", cluster.scheduler_address],
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    assert_same_run(local, out)
