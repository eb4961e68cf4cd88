"""Whole-object assembly (`reassemble run`) on the bench set, beside Open3D's textbook pipeline.

    python benchmarks/assembly.py puzzles/bench                    # 2-20 pieces, seed 0, clean + noisy
    python benchmarks/assembly.py puzzles/bench --pieces 2,4,8 --seeds 0,1,2 --no-baseline --jobs 2

The bench set is built first if missing (python -m data_synth.make_sets bench --out DIR).
Per puzzle, `run_to_folder` (the code behind `reassemble run`, one process per puzzle)
writes transforms.json, which is scored as `reassemble eval` does, with the prediction
anchored on the largest placed fragment (our world frame is a fragment's file frame):
strict part accuracy (mean chamfer < 1 % of the diagonal), Breaking Bad part accuracy,
geodesic rotation RMSE, solved (every fragment strict-correct). The baseline is Open3D's
tutorial FPFH + RANSAC + ICP on every pair glued by a maximum spanning tree
(`reassemble.baseline.fpfh_assemble`, voxel 1/40 of the median fragment diagonal),
scored the same way. Times are wall-clock of the whole run (loading to written files).
Columns `gap` and `sm`: the separation of mating surfaces `run` used (fraction of the
size; 0: touching) and the Taubin iterations of the copies it matched on (0: none).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import add_selection, add_signature_radii, header, match_config, select  # noqa: E402

ALIGN = "anchor_largest"


def run_puzzle(gt_path: str, baseline: bool, seed: int, signature_radii: int | None = None) -> dict:
    from reassemble.metrics import ScoringFragment, evaluate
    from reassemble.pipeline import evaluate_files, read_puzzle, reference_size, run_to_folder

    gt_path = Path(gt_path)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        report = run_to_folder([gt_path.parent / "fragments"], Path(tmp) / "out", seed=seed,
                               config=match_config(signature_radii))
        elapsed = time.perf_counter() - t
        score = evaluate_files(Path(tmp) / "out" / "transforms.json", gt_path)
    out = {"name": gt_path.parent.name, "fragments": report["summary"]["fragments"],
           "placed": report["summary"]["placed"], "time": elapsed, "timings": report["summary"]["timings_s"],
           "gap": report["summary"]["gap"],
           "smoothing": max(f["smoothing_iterations"] for f in report["fragments"].values()),
           "ours": score["alignments"][ALIGN]["summary"],
           "rot_errors": [f["rotation_error_deg"] for f in score["alignments"][ALIGN]["fragments"].values()]}
    if baseline:
        from reassemble.baseline import fpfh_assemble

        puzzle = read_puzzle(gt_path, with_labels=False)
        names = sorted(puzzle.meshes)
        meshes = [(puzzle.meshes[n].vertices, puzzle.meshes[n].faces) for n in names]
        t = time.perf_counter()
        poses = fpfh_assemble(meshes, voxel=reference_size(meshes) / 40, seed=seed)
        out["base_time"] = time.perf_counter() - t
        truth = puzzle.ground_truth
        fragments = [ScoringFragment(n, *meshes[k], np.asarray(truth["fragments"][n]["transform"]))
                     for k, n in enumerate(names)]
        pred = {n: {"transform": poses[k], "placed": True} for k, n in enumerate(names)}
        base = evaluate(fragments, pred, bbox_min=np.array(truth["object"]["bbox_min"]),
                        bbox_max=np.array(truth["object"]["bbox_max"]))
        out["base"] = base["alignments"][ALIGN]["summary"]
        out["base_rot_errors"] = [f["rotation_error_deg"] for f in base["alignments"][ALIGN]["fragments"].values()]
    return out


def report_puzzle(r: dict) -> None:
    o, b = r["ours"], r.get("base")
    base = (f"{b['part_acc_strict']:>7.3f} {b['part_acc']:>6.3f} {b['rot_geodesic_rmse_deg']:>7.1f} "
            f"{r['base_time']:>7.1f}" if b else "")
    t = r["timings"]
    print(f"{r['name']:<36s} {r['fragments']:>5d} {r['placed']:>6d} {o['part_acc_strict']:>6.3f} {o['part_acc']:>6.3f} "
          f"{o['rot_geodesic_rmse_deg']:>7.2f} {str(o['solved']):>6s} {r['time']:>7.1f} "
          f"({t['prepare']:.0f}+{t['pairs']:.0f}+{t['assembly']:.0f}) {r['gap']:>6.4f} {r['smoothing']:>3d} {base}",
          flush=True)


def summarize(label: str, rs: list[dict]) -> None:
    def block(key, errs_key, rs=rs):
        strict = np.mean([r[key]["part_acc_strict"] for r in rs])
        bb = np.mean([r[key]["part_acc"] for r in rs])
        rot = np.mean([r[key]["rot_geodesic_rmse_deg"] for r in rs])
        errs = np.concatenate([r[errs_key] for r in rs])
        solved = np.mean([r[key]["solved"] for r in rs])
        return (f"strict part acc {strict:.3f}, BB part acc {bb:.3f}, geodesic rot RMSE {rot:.2f} deg "
                f"(mean over puzzles; over all fragments {np.sqrt(np.mean(errs ** 2)):.2f}, median "
                f"{np.median(errs):.3f}), solved {solved:.3f}")

    print(f"{label} ({len(rs)} puzzles) ours: {block('ours', 'rot_errors')}")
    with_base = [r for r in rs if "base" in r]
    if with_base:
        print(f"{label} ({len(with_base)} puzzles with the baseline) ours: {block('ours', 'rot_errors', with_base)}")
        print(f"{label} ({len(with_base)} puzzles with the baseline) fpfh: {block('base', 'base_rot_errors', with_base)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8,12,20")
    parser.add_argument("--no-baseline", action="store_true")
    add_signature_radii(parser)
    parser.add_argument("--baseline-max-pieces", type=int, default=12,
                        help="run the baseline on puzzles of at most this many pieces (default 12: it takes "
                        "about 300 s on a 20-piece puzzle)")
    args = parser.parse_args()
    header()
    specs = select(args)
    # the biggest first, so the pool is not left waiting on one 20-piece puzzle at the end
    specs.sort(key=lambda s: -s.pieces)
    paths = [str(args.root / s.name / "ground_truth.json") for s in specs]
    print(f"{len(specs)} puzzles; scored anchored on the largest placed fragment")
    print(f"{'puzzle':<36s} {'frags':>5s} {'placed':>6s} {'strict':>6s} {'BB':>6s} {'rot deg':>7s} {'solved':>6s} "
          f"{'time s':>7s} (prep+pairs+asm) {'gap':>6s} {'sm':>3s} " + ("" if args.no_baseline else
                                              f"{'fpfh st':>7s} {'BB':>6s} {'rot':>7s} {'time':>7s}"))
    t0 = time.perf_counter()
    results = []
    with ProcessPoolExecutor(args.jobs) as pool:
        baseline = [not args.no_baseline and s.pieces <= args.baseline_max_pieces for s in specs]
        for r in pool.map(run_puzzle, paths, baseline, [args.seed] * len(paths), [args.signature_radii] * len(paths)):
            results.append(r)
            report_puzzle(r)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}")
    groups: dict[str, list] = {"clean": [], "noisy": []}
    for spec, r in zip(specs, results):
        groups["noisy" if spec.noise else "clean"].append(r)
    for label, rs in groups.items():
        if rs:
            summarize(label, rs)
    for label, rs in groups.items():
        for cap in (8, 12):
            small = [r for r in rs if r["fragments"] <= cap]
            if small and len(small) < len(rs):
                summarize(f"{label} <= {cap} pieces", small)
    print("\ntime of `run` (one process) against fragment count, mean over puzzles:")
    by_n: dict[int, list] = {}
    for r in results:
        by_n.setdefault(r["fragments"], []).append(r)
    for n in sorted(by_n):
        rs = by_n[n]
        t = {k: np.mean([r["timings"][k] for r in rs]) for k in ("prepare", "pairs", "assembly")}
        print(f"  {n:>3d} fragments: {np.mean([r['time'] for r in rs]):6.1f} s (prepare {t['prepare']:.1f}, "
              f"pairs {t['pairs']:.1f}, assembly {t['assembly']:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
