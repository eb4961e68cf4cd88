"""Train the segmentation classifier shipped as ``reassemble/data/segmenter.npz``.

    python -m data_synth.train_segmenter --sets puzzles --shared ../shared

Training puzzles are the field-tuning half only (``data_synth.sets``: every break style,
clean and with 0.1 % scan noise, 2-4 pieces; the validation half's meshes are never
seen), built into ``SETS/field-tuning`` if missing. Their descriptors are computed as a
run computes them (``benchmarks.common.described``, cached beside the set), their patches
and features by :func:`reassemble.segmentation.patch_evidence`, the pipeline's own code;
a patch's label is the generator's label of most of its area, its weight its share of the
puzzle's area (every puzzle weighs the same, as in the benchmark's mean F1). The model,
a scikit-learn ``HistGradientBoostingClassifier`` with a fixed ``random_state``, is written as
plain tree arrays (:mod:`reassemble.segmenter`) with the command, the commit, the puzzles
and the feature names. Thin-walled sherds are left out: the pipeline segments them along
their break strips (``reassemble.shells``), not with this classifier.
"""

from __future__ import annotations

import argparse
import dataclasses
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
PARAMS = dict(max_iter=200, max_leaf_nodes=15, learning_rate=0.1, min_samples_leaf=40, l2_regularization=1.0,
              early_stopping=False, random_state=0)


def training_specs(half: str = "tuning", *, max_pieces: int = 4, extra: bool = False) -> list:
    """The puzzles of one field half the classifier learns from (or is scored on): up to
    ``max_pieces`` pieces, no sherds. ``extra``: also every style on every mesh of the half
    with another seed and 5-8 pieces, clean (more breaks per mesh, and a larger share of
    the surface: fragments of larger sets have more break faces, meeting at edges and corners)."""
    from .sets import FIELD_MESHES, FIELD_STYLES, PuzzleSpec, field_set

    specs = [s for s in field_set(half) if s.pieces <= max_pieces and FIELD_MESHES[s.mesh].kind != "sherds"]
    if extra:
        meshes = [n for n, m in FIELD_MESHES.items() if m.half == half and m.kind != "sherds"]
        specs += [PuzzleSpec(mesh, 5 + (i + j) % 4, 3, style=style)
                  for i, mesh in enumerate(meshes) for j, style in enumerate(FIELD_STYLES)]
    return specs


def puzzle_rows(gt_path: Path, *, seed: int = 0, smoothing: int = 0) -> dict:
    """Patches, features and labels of one puzzle, segmented as a run segments it.

    Returns a dict: ``rows`` (patches, k) features, ``label`` (patches,) bool, ``weight``
    (patches,) area share, ``mixture`` (patches,) the mixture's probability, and for
    scoring the graph cut: ``frags`` (segmentation._Fragment list), ``truth`` (faces,) bool.
    """
    from benchmarks.common import described
    from reassemble.config import Config
    from reassemble.pipeline import read_puzzle
    from reassemble.segmentation import patch_evidence

    config = Config()
    ds = described(gt_path, config)
    labels = read_puzzle(gt_path).labels
    good = [k for k, d in enumerate(ds.descriptors) if d is not None]
    frags, mixture, rows = patch_evidence([(ds.matched[k], ds.meshes[k][1]) for k in good],
                                          [ds.descriptors[k] for k in good], size=ds.size, params=config.segment,
                                          seed=seed, smoothing=smoothing, learned=True)
    total = sum(float(f.face_area.sum()) for f in frags)
    label, weight, truth = [], [], []
    for k, f in zip(good, frags):
        t = labels[ds.names[k]] == 1
        n = len(f.patch_area)
        share = np.bincount(f.patch, f.face_area * t, n) / np.maximum(f.patch_area, 1e-300)
        label.append(share > 0.5)
        weight.append(f.patch_area / total)
        truth.append(t)
    return {"rows": np.concatenate(rows), "label": np.concatenate(label), "weight": np.concatenate(weight),
            "mixture": np.concatenate(mixture), "frags": frags, "truth": truth, "per_fragment_rows": rows,
            "per_fragment_mixture": mixture}


def _commit() -> str:
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO,
                               capture_output=True, text=True).stdout.strip()
        return sha + ("+changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def fit(rows: np.ndarray, label: np.ndarray, weight: np.ndarray, *, params: dict = PARAMS):
    from sklearn.ensemble import HistGradientBoostingClassifier

    model = HistGradientBoostingClassifier(**params)
    model.fit(rows, label.astype(int), sample_weight=weight / weight.mean())
    return model


def puzzle_f1(decision: np.ndarray, label: np.ndarray, weight: np.ndarray, puzzle: np.ndarray) -> float:
    """Mean over puzzles of the area-weighted F1 of the patch labels ``decision > 0``."""
    f1 = []
    for p in np.unique(puzzle):
        sel = puzzle == p
        pred, t, w = decision[sel] > 0, label[sel], weight[sel]
        tp = float(w[pred & t].sum())
        f1.append(2 * tp / max(float(w[pred].sum() + w[t].sum()), 1e-300))
    return float(np.mean(f1))


def choose_bias(rows: np.ndarray, label: np.ndarray, weight: np.ndarray, puzzle: np.ndarray, group: np.ndarray,
                *, folds: int, params: dict = PARAMS) -> tuple[float, dict]:
    """The offset added to the classifier's log-odds that maximizes the mean puzzle F1 of
    out-of-fold predictions (meshes split into ``folds`` groups), and the F1 before and after.

    Notes
    -----
    Weighted by area, fracture is about a quarter of a puzzle; trained on that, the
    classifier sides with "original surface" where unsure, and its labels come out precise
    but short of the break (precision near 1, recall 0.8-0.9 on the smoke set). The F1 the
    benchmarks score weighs both errors alike; the offset that balances them is chosen on
    predictions for meshes the fold's model never saw, so it is not fitted to the
    training puzzles' own labels (which a boosted model reproduces almost exactly).
    """
    from reassemble import segmenter

    meshes = np.unique(group)
    fold_of = {m: k % folds for k, m in enumerate(meshes)}
    fold = np.array([fold_of[g] for g in group])
    oof = np.zeros(len(label))
    for k in range(folds):
        test = fold == k
        model = fit(rows[~test], label[~test], weight[~test], params=params)
        oof[test] = segmenter.from_sklearn(model, {}).decision(rows[test])
    grid = np.round(np.arange(-3.0, 3.0001, 0.1), 1)
    scores = [puzzle_f1(oof + b, label, weight, puzzle) for b in grid]
    best = float(grid[int(np.argmax(scores))])
    return best, {"folds": folds, "f1_no_bias": puzzle_f1(oof, label, weight, puzzle), "f1": float(max(scores)),
                  "bias": best}


def main(argv: list[str] | None = None) -> int:
    from reassemble import segmenter

    from .make_sets import add_field_options, build_specs

    parser = argparse.ArgumentParser(prog="python -m data_synth.train_segmenter", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_field_options(parser, sets="SETS/field-tuning")
    parser.add_argument("--max-pieces", type=int, default=4)
    parser.add_argument("--out", type=Path, default=segmenter.MODEL_PATH)
    parser.add_argument("--extra", action="store_true", help="also 5-8 piece puzzles of every style and "
                        "mesh of the tuning half (training_specs): a second model is fitted on all the "
                        "puzzles and the two models' log-odds averaged (the shipped model)")
    parser.add_argument("--folds", type=int, default=0, help="mesh folds of a cross-validation that chooses "
                        "a log-odds offset (choose_bias; default 0: none, as the shipped model)")
    parser.add_argument("--drop", default="", help="comma-separated feature names left out of the model "
                        "(a study of which evidence generalizes; default: none)")
    parser.add_argument("--no-build", action="store_true", help="skip the puzzles not built yet (the generator "
                        "cannot make some: trying again takes minutes)")
    args = parser.parse_args(argv)
    command = "python -m data_synth.train_segmenter " + " ".join(sys.argv[1:] if argv is None else argv)
    root = args.sets / "field-tuning"
    specs = training_specs("tuning", max_pieces=args.max_pieces, extra=args.extra)
    missing = [s for s in specs if not (root / s.name / "ground_truth.json").is_file()]
    if missing and not args.no_build:
        print(f"building {len(missing)} puzzles in {root} ...", flush=True)
        build_specs(missing, root, set_name="field-tuning", shared=args.shared, keep_going=True)
    data, names, kept = [], [], []
    t0 = time.perf_counter()
    for s in specs:
        gt = root / s.name / "ground_truth.json"
        if not gt.is_file():
            print(f"  not generated: {s.name}", flush=True)
            continue
        data.append(puzzle_rows(gt))
        names.append(s.name)
        kept.append(s)
        print(f"  {s.name}: {len(data[-1]['label'])} patches ({time.perf_counter() - t0:.0f} s)", flush=True)
    rows = np.concatenate([d["rows"] for d in data])
    label = np.concatenate([d["label"] for d in data])
    weight = np.concatenate([d["weight"] for d in data])
    dropped = set(filter(None, args.drop.split(",")))
    keep = np.array([n not in dropped for n in segmenter.FEATURE_NAMES])
    full_rows, rows = rows, rows[:, keep]
    puzzle = np.concatenate([np.full(len(d["label"]), k) for k, d in enumerate(data)])
    base = {s.name for s in training_specs("tuning", max_pieces=args.max_pieces)}
    in_base = np.concatenate([np.full(len(d["label"]), s.name in base) for s, d in zip(kept, data)])
    group = np.concatenate([np.full(len(d["label"]), s.mesh) for s, d in zip(kept, data)])
    bias, cv = (0.0, {}) if args.folds < 2 else choose_bias(rows, label, weight, puzzle, group, folds=args.folds)
    if cv:
        print(f"log-odds offset {bias:+.1f}: out-of-fold mean puzzle F1 {cv['f1_no_bias']:.3f} -> {cv['f1']:.3f} "
              f"({args.folds} mesh folds)", flush=True)
    # with --extra, two models (the base puzzles; all of them) whose log-odds are averaged
    parts = [in_base, np.ones(len(label), bool)] if args.extra else [np.ones(len(label), bool)]
    models = [fit(rows[p], label[p], weight[p]) for p in parts]
    meta = {"format": segmenter.MODEL_FORMAT, "features": list(segmenter.FEATURE_NAMES), "command": command,
            "commit": _commit(), "trained_on": names, "params": PARAMS,
            "sklearn": __import__("sklearn").__version__, "patches": int(len(label)), "bias": bias,
            "dropped": [n for n, k in zip(segmenter.FEATURE_NAMES, keep) if not k],
            "averaged": [int(p.sum()) for p in parts], "cross_validation": cv}
    # the trees index the kept columns; the shipped model takes every feature
    exported = [segmenter.from_sklearn(m, meta) for m in models]
    exported = [dataclasses.replace(e, feature=np.flatnonzero(keep)[e.feature].astype(np.int32)) for e in exported]
    ensemble = exported[0] if len(exported) == 1 else segmenter.average(exported, meta)
    want = np.mean([m.decision_function(rows) for m in models], axis=0)
    check = np.abs(ensemble.decision(full_rows) - want).max()
    if check > 1e-9:
        raise SystemExit(f"train_segmenter: the exported trees differ from scikit-learn's by {check:.3g}")
    ensemble = dataclasses.replace(ensemble, init=ensemble.init + bias)
    segmenter.save(ensemble, args.out)
    print(f"{args.out}: {len(names)} puzzles, {len(label)} patches, {len(ensemble.roots)} trees "
          f"({args.out.stat().st_size / 1024:.0f} KiB) in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
