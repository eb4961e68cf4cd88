"""Strict part accuracy of `reassemble run` against scan noise and against gaps between pieces.

    python -m benchmarks.accuracy.robustness --jobs 2                                   # the default curves
    python -m benchmarks.accuracy.robustness --meshes spot,torus --pieces 8 --noise 0,0.005 --gaps "" --decimate "" --jobs 2

Every mesh is broken (`reassemble break`, the bench set's meshes and seed 0) once per
setting: vertex noise sigma (fraction of the object diagonal) with no gap, gaps
(material lost at the break, mating surfaces that far apart: `break --gap`) with no noise,
and decimation (`break --decimate`: every fragment simplified to that tolerance).
Each puzzle is assembled with `run_to_folder` (one process per puzzle) and scored as
`reassemble eval` does, anchored on the largest placed fragment. Prints a line per
puzzle, then the curves: mean strict part accuracy and share solved per level.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, add_signature_radii, match_config, start, table

MESHES = "spot,fish_low_resolution,torus,wingnut,angle_block,featuretype"


def run_one(task) -> dict:
    from reassemble.pipeline import break_to_folder, evaluate_files, run_to_folder
    from reassemble.synth import BreakParams

    mesh, pieces, kind, level, seed, signature_radii = task
    params = BreakParams(pieces=pieces, **{kind: level})
    with tempfile.TemporaryDirectory() as tmp:
        puzzle = Path(tmp) / "puzzle"
        break_to_folder(mesh, puzzle, params=params, seed=seed)
        t = time.perf_counter()
        run_to_folder([puzzle / "fragments"], Path(tmp) / "out", seed=seed,
                      config=match_config(signature_radii))
        elapsed = time.perf_counter() - t
        s = evaluate_files(Path(tmp) / "out" / "transforms.json", puzzle / "ground_truth.json")
    s = s["alignments"]["anchor_largest"]["summary"]
    return {"mesh": mesh, "pieces": pieces, "kind": kind, "level": level, "strict": s["part_acc_strict"],
            "solved": s["solved"], "rot": s["rot_geodesic_rmse_deg"], "time": elapsed}


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
    tasks = [(m, int(p), kind, float(level), args.seed, args.signature_radii)
             for kind, levels in (("noise", args.noise), ("gap", args.gaps), ("decimate", args.decimate))
             for level in levels.split(",") if level
             for p in args.pieces.split(",") for m in args.meshes.split(",")]
    print(f"{'mesh':<22s} {'pieces':>6s} {'kind':>8s} {'level':>6s} {'strict':>6s} {'solved':>6s} {'rot deg':>8s} "
          f"{'time s':>7s}", flush=True)
    rows = []
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for r in pool.map(run_one, tasks):
            rows.append(r)
            print(f"{r['mesh']:<22s} {r['pieces']:>6d} {r['kind']:>8s} {r['level']:>6g} {r['strict']:>6.3f} "
                  f"{str(r['solved']):>6s} {r['rot']:>8.2f} {r['time']:>7.1f}", flush=True)
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
