"""Segmentation alone on the field sets, per break style and mesh kind, for each method.

    python -m benchmarks.accuracy.field_segmentation --sets puzzles --shared ../shared
    python -m benchmarks.accuracy.field_segmentation --sets puzzles --halves validation --methods learned

Per puzzle of the selected halves (``data_synth.sets``: field-validation first, then
field-tuning, up to ``--max-pieces`` pieces, clean and with 0.1 % scan noise), the
fragments are described as a run describes them (cached beside the set,
``benchmarks.common.described``) and segmented as a run segments them
(:func:`reassemble.prepare.segment_set`: sherds along their break strips, solids all
together) with each ``segment.method``; the area-weighted F1 of the fracture label is
scored against the generator's exact labels. Much cheaper than ``benchmarks.accuracy.field`` (no
matching): the loop for studying segmentation across styles.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

REPO = Path(__file__).resolve().parents[2]
HALVES = {"validation": "field-validation", "tuning": "field-tuning"}


def _scores(truth: np.ndarray, pred: np.ndarray, area: np.ndarray) -> tuple[float, float, float]:
    tp = float(area[truth & pred].sum())
    precision = tp / max(float(area[pred].sum()), 1e-300)
    recall = tp / max(float(area[truth].sum()), 1e-300)
    return precision, recall, 2 * precision * recall / max(precision + recall, 1e-300)


def run_puzzle(gt_path: Path, methods: list[str], seed: int) -> dict:
    """{method: {f1, precision, recall, seconds}} of one puzzle."""
    from benchmarks.common import described
    from reassemble.config import Config
    from reassemble.geometry import face_areas
    from reassemble.pipeline import read_puzzle
    from reassemble.prepare import segment_set
    from reassemble.shells import wall_thickness

    config = Config()
    ds = described(gt_path, config)
    labels = read_puzzle(gt_path).labels
    good = [k for k, d in enumerate(ds.descriptors) if d is not None]
    thickness = {k: wall_thickness(ds.matched[k], ds.meshes[k][1]) for k in good}
    truth = np.concatenate([labels[ds.names[k]] == 1 for k in good])
    area = np.concatenate([face_areas(*ds.meshes[k]) for k in good])
    out = {}
    for method in methods:
        c = dataclasses.replace(config, segment=dataclasses.replace(config.segment, method=method))
        t = time.perf_counter()
        segs, _ = segment_set(ds, thickness, config=c, seed=seed)
        pred = np.concatenate([segs[k].fracture for k in good])
        p, r, f = _scores(truth, pred, area)
        out[method] = {"f1": f, "precision": p, "recall": r, "seconds": time.perf_counter() - t}
    return out


def _mean(rows: list[dict], method: str) -> dict:
    if not rows:
        return {"puzzles": 0}
    f1 = [r[method]["f1"] for r in rows]
    worst = min(rows, key=lambda r: r[method]["f1"])
    return {"puzzles": len(rows), "f1": float(np.mean(f1)), "f1_min": float(np.min(f1)), "f1_min_puzzle": worst["name"],
            "precision": float(np.mean([r[method]["precision"] for r in rows])),
            "recall": float(np.mean([r[method]["recall"] for r in rows]))}


def figures(rows: list[dict], methods: list[str]) -> dict:
    out = {}
    for half in HALVES:
        for noise in ("clean", "noisy"):
            sel = [r for r in rows if r["half"] == half and (r["noise"] > 0) == (noise == "noisy")]
            if not sel:
                continue
            out[f"{half} {noise}"] = {
                m: {"all": _mean(sel, m),
                    "by_style": {s: _mean([r for r in sel if r["style"] == s], m) for s in sorted({r["style"] for r in sel})},
                    "by_kind": {k: _mean([r for r in sel if r["kind"] == k], m) for k in sorted({r["kind"] for r in sel})}}
                for m in methods}
    return out


def main(argv: list[str] | None = None) -> int:
    from data_synth.make_sets import add_field_options, build_specs
    from data_synth.sets import FIELD_MESHES, SETS

    parser = argparse.ArgumentParser(prog="python -m benchmarks.accuracy.field_segmentation", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_field_options(parser)
    parser.add_argument("--halves", default="validation,tuning")
    parser.add_argument("--methods", default="mixture,learned", help="segment.method values to compare")
    parser.add_argument("--max-pieces", type=int, default=4)
    parser.add_argument("--kinds", default=None, help="comma-separated mesh kinds")
    parser.add_argument("--clean-only", action="store_true")
    parser.add_argument("--noisy-only", action="store_true")
    parser.add_argument("--seed", type=int, default=0)
    add_json_option(parser)
    args = parser.parse_args(argv)
    run = start()
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    halves = [h.strip() for h in args.halves.split(",") if h.strip()]
    todo = []
    for half in halves:
        root = args.sets / HALVES[half]
        specs = [s for s in SETS[HALVES[half]]() if s.pieces <= args.max_pieces
                 and not (args.clean_only and s.noise) and not (args.noisy_only and not s.noise)
                 and (args.kinds is None or FIELD_MESHES[s.mesh].kind in args.kinds.split(","))]
        missing = [s for s in specs if not (root / s.name / "ground_truth.json").is_file()]
        if missing:
            print(f"building {len(missing)} puzzles in {root} ...", flush=True)
            build_specs(missing, root, set_name=HALVES[half], shared=args.shared, keep_going=True)
        todo += [(half, s, root / s.name / "ground_truth.json") for s in specs
                 if (root / s.name / "ground_truth.json").is_file()]
    print(f"{'half':<10s} {'puzzle':<44s} " + " ".join(f"{m:>8s}" for m in methods))
    rows = []
    for half, spec, gt in todo:
        r = run_puzzle(gt, methods, args.seed)
        style = spec.style if spec.roughness is None else f"{spec.style} r{spec.roughness:g}"
        rows.append({"half": half, "name": spec.name, "mesh": spec.mesh, "kind": FIELD_MESHES[spec.mesh].kind,
                     "style": style, "pieces": spec.pieces, "noise": spec.noise, **r})
        print(f"{half:<10s} {spec.name:<44s} " + " ".join(f"{r[m]['f1']:>8.3f}" for m in methods), flush=True)
    figs = figures(rows, methods)
    tables = []
    for group, per in figs.items():
        styles = sorted({s for m in methods for s in per[m]["by_style"]})
        kinds = sorted({k for m in methods for k in per[m]["by_kind"]})
        body = [["all", per[methods[0]]["all"]["puzzles"]] + [per[m]["all"]["f1"] for m in methods]]
        body += [[f"style {s}", per[methods[0]]["by_style"][s]["puzzles"]] + [per[m]["by_style"][s]["f1"] for m in methods]
                 for s in styles]
        body += [[f"kind {k}", per[methods[0]]["by_kind"][k]["puzzles"]] + [per[m]["by_kind"][k]["f1"] for m in methods]
                 for k in kinds]
        tables.append(table(f"Segmentation F1 (area-weighted), field {group}, up to {args.max_pieces} pieces",
                            ["group", "puzzles"] + [f"F1 {m}" for m in methods], body,
                            ["", "d"] + [".3f"] * len(methods)))
        print(f"\n{group}:  {'puzzles':>7s} " + " ".join(f"{m:>8s}" for m in methods))
        for line in body:
            print(f"  {line[0]:<28s} {line[1]:>5d} " + " ".join(f"{x:>8.3f}" for x in line[2:]))
    headline = headline_rows(figs, methods)
    run.write(args.json, figures={"groups": figs, "puzzles": rows, "methods": methods}, tables=tables,
              headline=headline)
    return 0


def headline_rows(figs: dict, methods: list[str]) -> list[tuple[str, str]]:
    """One README row per group: F1 of every method, the default (``SegmentParams().method``) named."""
    from reassemble.segmentation import SegmentParams

    default = SegmentParams().method
    names = " / ".join(m + (" (default)" if m == default else "") for m in methods)
    return [(f"Segmentation F1, field {g} ({per[methods[-1]]['all']['puzzles']} puzzles), {names}",
             " / ".join(f"{per[m]['all']['f1']:.3f}" for m in methods)) for g, per in figs.items()]


if __name__ == "__main__":
    raise SystemExit(main())
