"""Whole-object assembly (`reassemble run`) on the bench set, beside Open3D's textbook pipeline.

    python -m benchmarks.accuracy.assembly puzzles/bench                    # 2-20 pieces, seed 0, clean + noisy
    python -m benchmarks.accuracy.assembly puzzles/bench --pieces 2,4,8 --seeds 0,1,2 --no-baseline --jobs 2

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
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import (
    add_selection, add_setting_option, add_signature_radii, fpfh_baseline, match_config, select, start, table,
)

ALIGN = "anchor_largest"


def run_puzzle(gt_path: str, baseline: bool, seed: int, signature_radii: int | None = None,
               settings: tuple[str, ...] = ()) -> dict:
    from reassemble.pipeline import evaluate_files, run_to_folder

    gt_path = Path(gt_path)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        report = run_to_folder([gt_path.parent / "fragments"], Path(tmp) / "out", seed=seed,
                               config=match_config(signature_radii, settings))
        elapsed = time.perf_counter() - t
        score = evaluate_files(Path(tmp) / "out" / "transforms.json", gt_path)
    out = {"name": gt_path.parent.name, "fragments": report["summary"]["fragments"],
           "placed": report["summary"]["placed"], "time": elapsed, "timings": report["summary"]["timings_s"],
           "gap": report["summary"]["gap"],
           "smoothing": max(f["smoothing_iterations"] for f in report["fragments"].values()),
           "ours": score["alignments"][ALIGN]["summary"],
           "rot_errors": [f["rotation_error_deg"] for f in score["alignments"][ALIGN]["fragments"].values()]}
    if baseline:
        base, out["base_time"] = fpfh_baseline(gt_path, seed=seed)
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


def summarize(label: str, rs: list[dict]) -> list[dict]:
    """Print and return the means over ``rs`` (ours, and the baseline where it ran)."""
    def block(method, key, errs_key, rs=rs):
        errs = np.concatenate([r[errs_key] for r in rs])
        return {"group": label, "method": method, "puzzles": len(rs),
                "strict": float(np.mean([r[key]["part_acc_strict"] for r in rs])),
                "part_acc": float(np.mean([r[key]["part_acc"] for r in rs])),
                "rot_rmse_deg": float(np.mean([r[key]["rot_geodesic_rmse_deg"] for r in rs])),
                "rot_rmse_all_deg": float(np.sqrt(np.mean(errs ** 2))), "rot_median_deg": float(np.median(errs)),
                "solved": float(np.mean([r[key]["solved"] for r in rs])),
                "solved_count": int(sum(bool(r[key]["solved"]) for r in rs))}

    def say(b, what):
        print(f"{label} ({b['puzzles']} puzzles{what}) {b['method']}: strict part acc {b['strict']:.3f}, BB part acc "
              f"{b['part_acc']:.3f}, geodesic rot RMSE {b['rot_rmse_deg']:.2f} deg (mean over puzzles; over all "
              f"fragments {b['rot_rmse_all_deg']:.2f}, median {b['rot_median_deg']:.3f}), solved {b['solved']:.3f}")

    out = [block("ours", "ours", "rot_errors")]
    say(out[-1], "")
    with_base = [r for r in rs if "base" in r]
    if with_base:
        for method, key, errs in (("ours (baseline's puzzles)", "ours", "rot_errors"),
                                  ("fpfh", "base", "base_rot_errors")):
            out.append(block(method, key, errs, with_base))
            say(out[-1], " with the baseline")
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8,12,20")
    parser.add_argument("--no-baseline", action="store_true")
    add_signature_radii(parser)
    add_setting_option(parser)
    parser.add_argument("--baseline-max-pieces", type=int, default=12,
                        help="run the baseline on puzzles of at most this many pieces (default 12: it takes "
                        "about 300 s on a 20-piece puzzle)")
    args = parser.parse_args()
    run = start()
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
        for r in pool.map(run_puzzle, paths, baseline, [args.seed] * len(paths), [args.signature_radii] * len(paths),
                           [tuple(args.setting)] * len(paths)):
            results.append(r)
            report_puzzle(r)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}")
    groups: dict[str, list] = {"clean": [], "noisy": []}
    for spec, r in zip(specs, results):
        groups["noisy" if spec.noise else "clean"].append(r)
    summary = []
    for label, rs in groups.items():
        if rs:
            summary += summarize(label, rs)
    for label, rs in groups.items():
        for cap in (8, 12):
            small = [r for r in rs if r["fragments"] <= cap]
            if small and len(small) < len(rs):
                summary += summarize(f"{label} <= {cap} pieces", small)
    print("\ntime of `run` (one process) against fragment count, mean over puzzles:")
    by_n: dict[int, list] = {}
    for r in results:
        by_n.setdefault(r["fragments"], []).append(r)
    times = []
    for n in sorted(by_n):
        rs = by_n[n]
        t = {k: float(np.mean([r["timings"][k] for r in rs])) for k in ("prepare", "pairs", "assembly")}
        times.append({"fragments": n, "puzzles": len(rs), "run": float(np.mean([r["time"] for r in rs])), **t})
        print(f"  {n:>3d} fragments: {times[-1]['run']:6.1f} s (prepare {t['prepare']:.1f}, "
              f"pairs {t['pairs']:.1f}, assembly {t['assembly']:.1f})")
    puzzles = [{"name": r["name"], "fragments": r["fragments"], "placed": r["placed"],
                "strict": r["ours"]["part_acc_strict"], "part_acc": r["ours"]["part_acc"],
                "rot_rmse_deg": r["ours"]["rot_geodesic_rmse_deg"], "solved": bool(r["ours"]["solved"]),
                "time": r["time"], "timings": r["timings"], "gap": r["gap"], "smoothing": r["smoothing"],
                **({"fpfh": r["base"]} if "base" in r else {})} for r in results]
    tables = [
        table("Means over puzzles, scored as `reassemble eval` does, anchored on the largest placed fragment "
              "(strict: mean chamfer < 1 % of the diagonal; targets: strict >= 0.95 clean, >= 0.90 noisy; "
              "solved >= 0.85)",
              ["puzzles", "method", "n", "strict part acc", "Breaking Bad part acc", "rotation RMSE deg", "solved",
               "solved (count)"],
              [[x["group"], x["method"], x["puzzles"], x["strict"], x["part_acc"], x["rot_rmse_deg"], x["solved"],
                x["solved_count"]] for x in summary], ["", "", "d", ".3f", ".3f", ".2f", ".3f", "d"]),
        table("Time of `run` in one process, mean over puzzles (s)",
              ["fragments", "puzzles", "run", "prepare", "pairs", "assembly"],
              [[x["fragments"], x["puzzles"], x["run"], x["prepare"], x["pairs"], x["assembly"]] for x in times],
              ["d", "d", ".1f", ".1f", ".1f", ".1f"]),
        table("Per puzzle", ["puzzle", "fragments", "placed", "strict", "rotation RMSE deg", "solved", "time s", "gap"],
              [[x["name"], x["fragments"], x["placed"], x["strict"], x["rot_rmse_deg"], "yes" if x["solved"] else "no",
                x["time"], x["gap"]] for x in puzzles], ["", "d", "d", ".3f", ".2f", "", ".1f", ".4f"]),
    ]
    headline = [(f"Assembly on the {args.set} set, {x['group']} ({x['puzzles']} puzzles): strict part accuracy, solved",
                 f"{x['strict']:.3f}, {x['solved_count']} of {x['puzzles']}")
                for x in summary if x["method"] == "ours" and x["group"] in ("clean", "noisy")]
    run.write(args.json, figures={"summary": summary, "times": times, "puzzles": puzzles}, tables=tables,
              headline=headline)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
