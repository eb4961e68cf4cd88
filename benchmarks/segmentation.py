"""Segmentation alone on the bench set: area-weighted F1, precision and recall per puzzle.

    python benchmarks/segmentation.py puzzles/bench                    # 2, 4, 8 pieces, seed 0, clean + noisy
    python benchmarks/segmentation.py puzzles/bench --noisy-only --jobs 2

The descriptors of every puzzle are computed once and cached beside the set
(``benchmarks.common.described``: keyed by the fragments, the options and the descriptor
code), so after the first run the whole selection is segmented again in seconds: the loop
for studying :mod:`reassemble.segmentation`. The F1 is the one ``benchmarks/pairwise.py``
reports (same segmentation, same seed).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import add_selection, described, header, select  # noqa: E402


def run_puzzle(gt_path: str, seed: int) -> dict:
    from reassemble.geometry import face_areas
    from reassemble.pipeline import Config, prepare_fragments, read_puzzle

    t = time.perf_counter()
    ds = described(gt_path, Config())
    t_describe = time.perf_counter() - t
    t = time.perf_counter()
    frags, _ = prepare_fragments({}, described=ds, seed=seed)
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
    args = parser.parse_args()
    header()
    specs = select(args)
    paths = [str(args.root / s.name / "ground_truth.json") for s in specs]
    print(f"{'puzzle':<36s} {'frags':>5s} {'F1':>6s} {'prec':>6s} {'recall':>6s} {'true':>6s} "
          f"{'worst fragment':>24s} {'describe s':>10s} {'segment s':>9s}")
    t0 = time.perf_counter()
    results = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for r in pool.map(run_puzzle, paths, [args.seed] * len(paths)):
            results.append(r)
            f1w, name = r["worst"]
            print(f"{r['name']:<36s} {r['fragments']:>5d} {r['f1']:>6.3f} {r['precision']:>6.3f} {r['recall']:>6.3f} "
                  f"{r['true_share']:>6.3f} {name:>17s} {f1w:>6.3f} {r['t_describe']:>10.1f} {r['t_segment']:>9.1f}",
                  flush=True)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}")
    for group, keep in (("all", lambda s: True), ("clean", lambda s: not s.noise), ("noisy", lambda s: bool(s.noise))):
        rs = [r for s, r in zip(specs, results) if keep(s)]
        if rs:
            print(f"{group:>5s}: {len(rs)} puzzles; F1 mean {np.mean([r['f1'] for r in rs]):.3f} "
                  f"(min {min(r['f1'] for r in rs):.3f}); precision {np.mean([r['precision'] for r in rs]):.3f}, "
                  f"recall {np.mean([r['recall'] for r in rs]):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
