"""Segmentation alone on the bench set: area-weighted F1, precision and recall per puzzle.

    python -m benchmarks.accuracy.segmentation puzzles/bench                    # 2, 4, 8 pieces, seed 0, clean + noisy
    python -m benchmarks.accuracy.segmentation puzzles/bench --noisy-only --jobs 2
    python -m benchmarks.accuracy.segmentation puzzles/bench --method mixture   # the unsupervised mixture

The descriptors of every puzzle are computed once and cached beside the set
(``benchmarks.common.described``: keyed by the fragments, the options and the descriptor
code), so after the first run the whole selection is segmented again in seconds: the loop
for studying :mod:`reassemble.segmentation`. The F1 is the one ``benchmarks.accuracy.pairwise``
reports (same segmentation, same seed).
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import add_selection, described, select, start, table


def run_puzzle(gt_path: str, seed: int, method: str | None = None) -> dict:
    import dataclasses

    from reassemble.geometry import face_areas
    from reassemble.pipeline import Config, prepare_fragments, read_puzzle

    config = Config()
    if method is not None:
        config = dataclasses.replace(config, segment=dataclasses.replace(config.segment, method=method))
    t = time.perf_counter()
    ds = described(gt_path, config)
    t_describe = time.perf_counter() - t
    t = time.perf_counter()
    frags, _ = prepare_fragments({}, described=ds, seed=seed, config=config)
    t_segment = time.perf_counter() - t
    labels = read_puzzle(gt_path).labels
    truth = [labels[f.name].astype(bool) for f in frags]
    pred = [f.segmentation.fracture for f in frags]
    area = [face_areas(f.vertices, f.faces) for f in frags]
    precision, recall, f1 = _scores(np.concatenate(truth), np.concatenate(pred), np.concatenate(area))
    worst = min((_scores(t, p, a)[2], f.name) for t, p, a, f in zip(truth, pred, area, frags))
    all_area = np.concatenate(area)
    return {"name": Path(gt_path).parent.name, "fragments": len(frags), "f1": f1, "precision": precision,
            "recall": recall, "true_share": float(all_area[np.concatenate(truth)].sum() / all_area.sum()),
            "smoothing": ds.smoothing, "worst": worst, "t_describe": t_describe, "t_segment": t_segment}


def _scores(truth: np.ndarray, pred: np.ndarray, area: np.ndarray) -> tuple[float, float, float]:
    """Area-weighted precision, recall and F1 of the fracture label."""
    tp = float(area[truth & pred].sum())
    precision = tp / max(float(area[pred].sum()), 1e-300)
    recall = tp / max(float(area[truth].sum()), 1e-300)
    return precision, recall, 2 * precision * recall / max(precision + recall, 1e-300)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8")
    parser.add_argument("--method", default=None, help="segment.method (default: Config's)")
    args = parser.parse_args()
    run = start()
    specs = select(args)
    paths = [str(args.root / s.name / "ground_truth.json") for s in specs]
    print(f"{'puzzle':<36s} {'frags':>5s} {'F1':>6s} {'prec':>6s} {'recall':>6s} {'true':>6s} "
          f"{'worst fragment':>24s} {'describe s':>10s} {'segment s':>9s}")
    t0 = time.perf_counter()
    results = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for r in pool.map(run_puzzle, paths, [args.seed] * len(paths), [args.method] * len(paths)):
            results.append(r)
            f1w, name = r["worst"]
            print(f"{r['name']:<36s} {r['fragments']:>5d} {r['f1']:>6.3f} {r['precision']:>6.3f} {r['recall']:>6.3f} "
                  f"{r['true_share']:>6.3f} {name:>17s} {f1w:>6.3f} {r['t_describe']:>10.1f} {r['t_segment']:>9.1f}",
                  flush=True)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}")
    summary = []
    for group, keep in (("all", lambda s: True), ("clean", lambda s: not s.noise), ("noisy", lambda s: bool(s.noise))):
        rs = [r for s, r in zip(specs, results) if keep(s)]
        if rs:
            worst = min(rs, key=lambda r: r["f1"])
            summary.append({"group": group, "puzzles": len(rs), "f1_mean": float(np.mean([r["f1"] for r in rs])),
                            "f1_min": worst["f1"], "f1_min_puzzle": worst["name"],
                            "precision_mean": float(np.mean([r["precision"] for r in rs])),
                            "recall_mean": float(np.mean([r["recall"] for r in rs]))})
            print(f"{group:>5s}: {len(rs)} puzzles; F1 mean {summary[-1]['f1_mean']:.3f} "
                  f"(min {worst['f1']:.3f}); precision {summary[-1]['precision_mean']:.3f}, "
                  f"recall {summary[-1]['recall_mean']:.3f}")
    for r in results:
        r["worst"] = {"f1": r["worst"][0], "fragment": r["worst"][1]}
    tables = [
        table("Area-weighted fracture-label scores, mean over puzzles (target: F1 >= 0.95)",
              ["puzzles", "n", "F1", "F1 min", "lowest", "precision", "recall"],
              [[x["group"], x["puzzles"], x["f1_mean"], x["f1_min"], x["f1_min_puzzle"], x["precision_mean"],
                x["recall_mean"]] for x in summary], ["", "d", ".3f", ".3f", "", ".3f", ".3f"]),
        table("Per puzzle", ["puzzle", "fragments", "F1", "precision", "recall", "fracture share", "worst fragment F1"],
              [[r["name"], r["fragments"], r["f1"], r["precision"], r["recall"], r["true_share"], r["worst"]["f1"]]
               for r in results], ["", "d", ".3f", ".3f", ".3f", ".3f", ".3f"]),
    ]
    method = f", segment.method={args.method}" if args.method else ""
    headline = [(f"Segmentation F1 ({x['group']}, {x['puzzles']} {args.set} puzzles of {args.pieces} pieces{method})",
                 f"{x['f1_mean']:.3f} (target >= 0.95)")
                for x in summary if x["group"] != "all"]
    run.write(args.json, figures={"summary": summary, "puzzles": results, "jobs": args.jobs},
              tables=tables, headline=headline)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
