"""Whole-object assembly (`reassemble run`) on the bench set, beside Open3D's textbook pipeline.

    python -m benchmarks.accuracy.assembly puzzles/bench                    # 2-20 pieces, seed 0, clean + noisy
    python -m benchmarks.accuracy.assembly puzzles/bench --pieces 2,4,8 --seeds 0,1,2 --no-baseline --jobs 2

The bench set is built first if missing (python -m data_synth.make_sets bench --out DIR).
Our side runs through `reassemble bench` (reassemble.bench: each puzzle a task on a Dask
LocalCluster of --jobs workers, solved by `run`'s pipeline in one process and scored as
`reassemble eval` does), with the prediction anchored on the largest placed fragment (our
world frame is a fragment's file frame): strict part accuracy (mean chamfer < 1 % of the
diagonal), Breaking Bad part accuracy, geodesic rotation RMSE, solved (every fragment
strict-correct). The baseline is Open3D's tutorial FPFH + RANSAC + ICP on every pair glued
by a maximum spanning tree (`reassemble.baseline.fpfh_assemble`, voxel 1/40 of the median
fragment diagonal), scored the same way. Times are wall-clock of a set's task (reading,
solving and scoring; `run` also writes its files). Columns `gap` and `sm`: the separation
of mating surfaces `run` used (fraction of the size; 0: touching) and the Taubin iterations
of the copies it matched on (0: none). --out keeps bench's results.jsonl (a rerun resumes).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from reassemble.bench import bench, options_key, read_results

from benchmarks.common import (
    add_selection, add_setting_option, add_signature_radii, fpfh_baseline, match_config, select, start, table,
)

ALIGN = "anchor_largest"


def ours(rec: dict) -> dict:
    """A puzzle's line of `reassemble bench`'s results.jsonl as this benchmark's record."""
    if rec["error"]:
        print(f"{rec['set']}: {rec['error']}", flush=True)
        zero = {"part_acc_strict": 0.0, "part_acc": 0.0, "rot_geodesic_rmse_deg": float("nan"), "solved": False}
        return {"name": rec["set"], "fragments": rec["pieces"], "placed": 0, "time": rec["time_s"] or float("nan"),
                "timings": {"prepare": float("nan"), "pairs": float("nan"), "assembly": float("nan")},
                "gap": float("nan"), "smoothing": 0, "ours": zero, "rot_errors": [], "error": rec["error"]}
    info = rec["solver"]
    return {"name": rec["set"], "fragments": rec["pieces"], "placed": rec["placed"], "time": rec["time_s"],
            "timings": info["timings_s"], "gap": info["gap"], "smoothing": info["smoothing"],
            "ours": rec["metrics"][ALIGN], "rot_errors": rec["rotation_errors_deg"]}


def baseline_puzzle(gt_path: str, seed: int) -> dict:
    base, elapsed = fpfh_baseline(gt_path, seed=seed)
    return {"base": base["alignments"][ALIGN]["summary"], "base_time": elapsed,
            "base_rot_errors": [f["rotation_error_deg"] for f in base["alignments"][ALIGN]["fragments"].values()]}


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
    parser.add_argument("--out", type=Path, default=None,
                        help="keep reassemble bench's results here (a rerun with the same options resumes)")
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
    config = dataclasses.replace(match_config(args.signature_radii, tuple(args.setting)), seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        bench(args.root, out, config=config, pieces=(2, 10**6), timeout=None, jobs=args.jobs,
              only={s.name for s in specs}, progress=True)
        records = read_results(out / "results.jsonl", key=options_key(config, n_points=1000))
    results = [ours(records[s.name]) for s in specs]
    with ProcessPoolExecutor(args.jobs) as pool:
        todo = [k for k, s in enumerate(specs) if not args.no_baseline and s.pieces <= args.baseline_max_pieces]
        for k, b in zip(todo, pool.map(baseline_puzzle, [paths[k] for k in todo], [args.seed] * len(todo))):
            results[k].update(b)
    for r in results:
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
