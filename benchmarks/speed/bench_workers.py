"""`reassemble bench` on a Dask LocalCluster: 2 workers against 1, and the cost per set beyond solving it.

    python -m benchmarks.speed.bench_workers                    # 40 two-piece sets, 1 then 2 workers
    python -m benchmarks.speed.bench_workers --sets 8 --jobs 1  # a quick look
    python -m benchmarks.speed.bench_workers --stand-in --jobs 1 --json /tmp/overhead.json  # no solving

The sets: bundled meshes broken into 2 pieces (`reassemble break`, seeds 0 and 1), written in
assembled pose as Breaking Bad stores them (`mesh/s<seed>/fractured_<k>/piece_*.ply`), each
puzzle four times (the poses are seeded by the set's folder, so the four are four draws).
They are solved with coarser descriptor grids than the default (`--setting`,
describe.resolution=5) so that 40 sets take minutes: the figures are about the machinery.
Per worker count, into a fresh output folder: the wall time of `bench()` (cluster start to
summary written), the time each task measured (reading, solving, scoring) and its solve
alone. Overhead per set = wall time x workers / sets - mean solve time: everything that is
not solving (cluster start, the fork of the solving process, reading, posing, scoring,
writing), shared out over the sets. Run it on an idle machine (the load average is recorded).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

MESHES = ("spot_low_resolution", "torus", "fish_low_resolution", "angle_block", "octagonal_pocket")


def stand_in(meshes, *, config):
    """No solving: every piece left where it is given (for the cost of the machinery alone)."""
    return {n: {"transform": np.eye(4), "placed": True} for n in meshes}, {}


def build(root: Path, *, sets: int) -> None:
    """``sets`` two-piece sets in assembled pose below ``root`` (made once, kept)."""
    from reassemble.files import write_ply
    from reassemble.geometry import transform_points
    from reassemble.puzzle import break_to_folder, read_puzzle
    from reassemble.synth import BreakParams

    made = 0
    for seed in range(10**3):
        for mesh in MESHES:
            if made >= sets:
                return
            first = root / mesh / f"s{seed}" / "fractured_0"
            if not first.is_dir():
                with tempfile.TemporaryDirectory() as tmp:
                    pz_dir = break_to_folder(mesh, Path(tmp) / "p", params=BreakParams(pieces=2), seed=seed)
                    pz = read_puzzle(pz_dir / "ground_truth.json", with_labels=False)
                    for copy in range(4):
                        for k, (name, m) in enumerate(sorted(pz.meshes.items())):
                            T = np.array(pz.ground_truth["fragments"][name]["transform"])
                            write_ply(root / mesh / f"s{seed}" / f"fractured_{copy}" / f"piece_{k}.ply",
                                      transform_points(T, m.vertices), m.faces)
            made += 4


def main() -> int:
    from reassemble.bench import bench, discover, options_key, read_results
    from reassemble.config import Config, with_setting

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sets", type=int, default=40)
    parser.add_argument("--jobs", default="1,2", help="worker counts to time, in order (default 1,2)")
    parser.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "reassemble-bench-workers",
                        help="where the sets are made (kept) and the runs written (replaced)")
    parser.add_argument("--setting", action="append", default=None, metavar="SECTION.NAME=VALUE",
                        help="configuration of the solves (default describe.resolution=5)")
    parser.add_argument("--stand-in", action="store_true",
                        help="do not solve (pieces left where given): the overhead alone")
    add_json_option(parser)
    args = parser.parse_args()
    run = start()
    data = args.work / "data"
    build(data, sets=args.sets)
    ids = {s.id for s in discover(data)}
    ids = set(sorted(ids)[: args.sets])
    config = Config()
    for setting in args.setting or ["describe.resolution=5"]:
        config = with_setting(config, setting)
    rows = []
    for jobs in (int(j) for j in args.jobs.split(",")):
        out = args.work / f"out_{jobs}"
        shutil.rmtree(out, ignore_errors=True)
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        # by its module's name, not __main__'s: the solving processes import it
        from benchmarks.speed.bench_workers import stand_in as by_name

        solver = by_name if args.stand_in else None
        bench(data, out, config=config, jobs=jobs, timeout=None, only=ids, solver=solver, progress=True)
        wall = time.perf_counter() - t0
        recs = list(read_results(out / "results.jsonl", key=options_key(config, n_points=1000, solver=solver)).values())
        ok = [r for r in recs if r["error"] is None]
        solve = float(np.mean([r["timings_s"]["solve"] for r in ok]))
        task = float(np.mean([r["time_s"] for r in ok]))
        row = {"workers": jobs, "sets": len(recs), "failed": len(recs) - len(ok), "wall_s": wall,
               "wall_per_set_s": wall / len(recs), "task_s": task, "solve_s": solve,
               "overhead_per_set_s": wall * jobs / len(recs) - solve,
               "in_task_overhead_s": task - solve,
               "peak_rss_mb_max": float(max(r["peak_rss_mb"] for r in ok)),
               "part_acc_strict": float(np.mean([r["metrics"]["anchor_largest"]["part_acc_strict"] for r in ok])),
               "load_start": load0, "load_end": os.getloadavg()[0]}
        rows.append(row)
        print(f"{jobs} worker(s): {len(recs)} sets in {wall:.1f} s ({row['wall_per_set_s']:.2f} s per set), task "
              f"{task:.2f} s of which solve {solve:.2f} s; overhead per set {row['overhead_per_set_s']:.2f} s "
              f"(in the task {row['in_task_overhead_s']:.2f} s); peak memory of a set {row['peak_rss_mb_max']:.0f} MB; "
              f"load {load0:.2f} -> {row['load_end']:.2f}", flush=True)
    speedup = rows[0]["wall_s"] / rows[-1]["wall_s"] if len(rows) > 1 else None
    if speedup is not None:
        print(f"{rows[-1]['workers']} workers vs {rows[0]['workers']}: {speedup:.2f}x faster")
    what = "not solved (--stand-in)" if args.stand_in else "describe.resolution=5"
    tables = [table(f"`reassemble bench` on {len(ids)} two-piece sets ({what}), LocalCluster; "
                    "overhead per set = wall x workers / sets - mean solve",
                    ["workers", "sets", "failed", "wall s", "wall per set s", "task s", "solve s",
                     "overhead per set s", "in task s", "peak MB", "load at start"],
                    [[r["workers"], r["sets"], r["failed"], r["wall_s"], r["wall_per_set_s"], r["task_s"],
                      r["solve_s"], r["overhead_per_set_s"], r["in_task_overhead_s"], r["peak_rss_mb_max"],
                      r["load_start"]] for r in rows],
                    ["d", "d", "d", ".1f", ".2f", ".2f", ".2f", ".2f", ".2f", ".0f", ".2f"])]
    headline = []
    if args.stand_in:
        headline.append((f"reassemble bench: cost per set beyond solving ({len(ids)} small sets, "
                         f"{rows[0]['workers']} worker, cluster start included)",
                         f"{rows[0]['overhead_per_set_s']:.2f} s (target <= 1 s)"))
    elif speedup is not None:
        headline.append((f"reassemble bench, {len(ids)} small sets: {rows[-1]['workers']} workers vs "
                         f"{rows[0]['workers']} on {os.cpu_count()} cores", f"{speedup:.2f}x"))
    run.write(args.json, figures={"rows": rows, "speedup": speedup, "stand_in": args.stand_in}, tables=tables,
              headline=headline)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
