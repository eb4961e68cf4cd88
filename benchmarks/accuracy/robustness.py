"""Strict part accuracy of `reassemble run` against scan noise and against gaps between pieces.

    python -m benchmarks.accuracy.robustness --jobs 2                                   # the default curves
    python -m benchmarks.accuracy.robustness --meshes spot,torus --pieces 8 --noise 0,0.005 --gaps "" --decimate "" --jobs 2

Every mesh is broken (`reassemble break`, the bench set's meshes and seed 0) once per
setting: vertex noise sigma (fraction of the object diagonal) with no gap, gaps
(material lost at the break, mating surfaces that far apart: `break --gap`) with no noise,
and decimation (`break --decimate`: every fragment simplified to that tolerance).
The puzzles are broken first (``--jobs`` at once), into one tree, which then runs through
``reassemble bench`` (:func:`reassemble.bench.bench`: each puzzle a task on a Dask
LocalCluster of ``--jobs`` workers, solved in a child process by ``run``'s pipeline) and
is scored as `reassemble eval` does, anchored on the largest placed fragment; a puzzle
that fails counts as unsolved. Prints a line per puzzle (time: reading and solving), then
the curves: mean strict part accuracy and share solved per level.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, add_signature_radii, match_config, start, table

MESHES = "spot,fish_low_resolution,torus,wingnut,angle_block,featuretype"


def break_one(task) -> str:
    """Break one mesh at one setting into ``folder`` (a puzzle, ``ground_truth.json`` beside
    its fragments); its name in the tree."""
    from reassemble.pipeline import break_to_folder
    from reassemble.synth import BreakParams

    root, mesh, pieces, kind, level, seed = task
    name = f"{kind}_{level:g}/{mesh}_{pieces}p"
    break_to_folder(mesh, Path(root) / name, params=BreakParams(pieces=pieces, **{kind: level}), seed=seed)
    return name


def run_all(tasks: list[tuple], *, seed: int, signature_radii, jobs: int) -> list[dict]:
    """Break every (mesh, pieces, kind, level), solve and score them all through bench."""
    from reassemble.bench import bench, options_key, read_results

    config = dataclasses.replace(match_config(signature_radii), seed=seed)
    with tempfile.TemporaryDirectory() as tmp:
        tree, out = Path(tmp) / "puzzles", Path(tmp) / "bench"
        with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
            names = list(pool.map(break_one, [(tree, *t, seed) for t in tasks]))
        bench(tree, out, config=config, pieces=(2, 10**6), timeout=None, jobs=max(1, jobs), progress=True)
        records = read_results(out / "results.jsonl", key=options_key(config, n_points=1000))
    rows = []
    for (mesh, pieces, kind, level), name in zip(tasks, names):
        rec = records[name]
        r = {"mesh": mesh, "pieces": pieces, "kind": kind, "level": level}
        if rec["error"]:  # a failure is a figure too: unsolved
            rows.append({**r, "strict": 0.0, "solved": False, "rot": float("nan"), "time": rec["time_s"] or 0.0,
                         "error": rec["error"]})
            continue
        s = rec["metrics"]["anchor_largest"]
        rows.append({**r, "strict": s["part_acc_strict"], "solved": s["solved"], "rot": s["rot_geodesic_rmse_deg"],
                     "time": rec["timings_s"]["load"] + rec["timings_s"]["solve"]})
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--meshes", default=MESHES)
    parser.add_argument("--pieces", default="4,8")
    parser.add_argument("--noise", default="0,0.001,0.002,0.005", help="noise sigmas / diagonal")
    parser.add_argument("--gaps", default="0.005,0.01,0.02", help="gaps / diagonal")
    parser.add_argument("--decimate", default="0.002,0.005", help="decimation tolerances / diagonal")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=1, help="puzzles run at once")
    add_signature_radii(parser)
    add_json_option(parser)
    args = parser.parse_args()
    run = start()
    tasks = [(m, int(p), kind, float(level))
             for kind, levels in (("noise", args.noise), ("gap", args.gaps), ("decimate", args.decimate))
             for level in levels.split(",") if level
             for p in args.pieces.split(",") for m in args.meshes.split(",")]
    t0 = time.perf_counter()
    rows = run_all(tasks, seed=args.seed, signature_radii=args.signature_radii, jobs=args.jobs)
    print(f"{'mesh':<22s} {'pieces':>6s} {'kind':>8s} {'level':>6s} {'strict':>6s} {'solved':>6s} {'rot deg':>8s} "
          f"{'time s':>7s}", flush=True)
    for r in rows:
        err = f"  ERROR {r['error']}" if "error" in r else ""
        print(f"{r['mesh']:<22s} {r['pieces']:>6d} {r['kind']:>8s} {r['level']:>6g} {r['strict']:>6.3f} "
              f"{str(r['solved']):>6s} {r['rot']:>8.2f} {r['time']:>7.1f}{err}", flush=True)
    print(f"\ncurves (mean over {len(args.meshes.split(','))} meshes x pieces {args.pieces}):")
    curves = []
    for kind in ("noise", "gap", "decimate"):
        for level in sorted({r["level"] for r in rows if r["kind"] == kind}):
            sel = [r for r in rows if r["kind"] == kind and r["level"] == level]
            curves.append({"kind": kind, "level": level, "puzzles": len(sel),
                           "strict": float(np.mean([r["strict"] for r in sel])),
                           "solved": int(sum(bool(r["solved"]) for r in sel))})
            print(f"  {kind:>8s} {level:>6g} of the diagonal: strict {curves[-1]['strict']:.3f}, "
                  f"solved {np.mean([r['solved'] for r in sel]):.3f} ({len(sel)} puzzles)")
    print(f"total {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}")
    run.write(args.json, figures={"curves": curves, "puzzles": rows},
              tables=[table(f"Strict part accuracy and puzzles solved per level ({args.meshes}; pieces {args.pieces}; "
                            "levels are fractions of the diagonal)", ["kind", "level", "puzzles", "strict", "solved"],
                            [[x["kind"], x["level"], x["puzzles"], x["strict"], x["solved"]] for x in curves],
                            ["", "g", "d", ".3f", "d"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
