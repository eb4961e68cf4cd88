"""Segmentation and pairwise registration on the bench set, beside Open3D's textbook pipeline.

    python -m benchmarks.accuracy.pairwise puzzles/bench                       # 2, 4, 8 pieces, seed 0, clean + noisy
    python -m benchmarks.accuracy.pairwise puzzles/bench --pieces 2,4,8,12,20 --seeds 0,1,2 --jobs 2

The bench set is built first if missing (python -m data_synth.make_sets bench --out DIR).
Per puzzle:
- segmentation: area-weighted F1 of the fracture label against the generator's labels;
- every fragment pair registered (ours: signatures + point-pair RANSAC + ICP, scored by
  contact minus penetration); a pair touching in the truth with a contact area of at least
  5 % of the smaller fragment's surface is "correct" when the top candidate is within 2° and
  1 % of the object's bounding-box diagonal (translation error at the source's centroid);
- the best score of touching pairs (>= 5 %) against pairs that do not touch: ROC AUC;
- the same pairs with Open3D's FPFH + RANSAC + ICP (tutorial settings, voxel 1/40 of the
  reference size; its ICP fitness as the score), unless --no-baseline;
- time: preparation (descriptors, segmentation, features) per fragment, and per pair.

With --cached the descriptors come from the cache beside the set (``benchmarks.common.described``,
computed on first use): the figures are the same, and a study of segmentation or matching
skips the slowest part.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import add_selection, add_signature_radii, described, match_config, select, start, table

MIN_CONTACT = 0.05


def errors(T: np.ndarray, T_true: np.ndarray, centre: np.ndarray, diag: float) -> tuple[float, float]:
    from reassemble.geometry import rotation_angle_deg

    rot = float(rotation_angle_deg(T[:3, :3], T_true[:3, :3]))
    t = float(np.linalg.norm(T[:3, :3] @ centre + T[:3, 3] - T_true[:3, :3] @ centre - T_true[:3, 3])) / diag
    return rot, t


def run_puzzle(gt_path: str, baseline: bool, seed: int, signature_radii: int | None = None,
               cache: bool = False) -> dict:
    from sklearn.metrics import f1_score

    from reassemble.geometry import face_areas, invert_transform
    from reassemble.pipeline import match_pairs, prepare_fragments, read_puzzle

    puzzle = read_puzzle(gt_path)
    gt = puzzle.ground_truth
    config = match_config(signature_radii)
    t = time.perf_counter()
    frags, size = prepare_fragments({}, described=described(gt_path, config, cache=cache), seed=seed, config=config)
    t_prepare = time.perf_counter() - t
    labels = np.concatenate([puzzle.labels[f.name] for f in frags])
    pred = np.concatenate([f.segmentation.fracture for f in frags])
    area = np.concatenate([face_areas(f.vertices, f.faces) for f in frags])
    f1 = float(f1_score(labels, pred, sample_weight=area))
    t = time.perf_counter()
    results = match_pairs(frags, size=size, seed=seed)
    t_pairs = time.perf_counter() - t
    diag = float(gt["object"]["diagonal"])
    T_world = {n: np.asarray(v["transform"]) for n, v in gt["fragments"].items()}
    contact = {tuple(sorted(c["fragments"])): float(c["area"]) for c in gt["contacts"]}
    rows = []
    t_base = 0.0
    for (i, j), res in results.items():
        a, b = frags[i], frags[j]
        share = contact.get(tuple(sorted((a.name, b.name))), 0.0) / min(a.surface.area, b.surface.area)
        T_true = invert_transform(T_world[b.name]) @ T_world[a.name]
        centre = a.vertices.mean(axis=0)
        row = {"share": share, "score": -np.inf, "ok": False, "base_score": 0.0, "base_ok": False}
        if res.best is not None:
            rot, tr = errors(res.best.T_target_source, T_true, centre, diag)
            row.update(score=res.best.score, ok=rot < 2.0 and tr < 0.01, rot=rot, t=tr)
        if baseline:
            from reassemble.baseline import fpfh_register

            tb = time.perf_counter()
            T_b, fitness = fpfh_register(a.vertices, a.faces, b.vertices, b.faces, voxel=size / 40, seed=seed)
            t_base += time.perf_counter() - tb
            rot, tr = errors(T_b, T_true, centre, diag)
            row.update(base_score=fitness, base_ok=rot < 2.0 and tr < 0.01)
        rows.append(row)
    return {"name": Path(gt_path).parent.name, "fragments": len(frags), "f1": f1, "rows": rows,
            "t_prepare": t_prepare, "t_pairs": t_pairs, "t_base": t_base,
            "faces": int(np.mean([len(f.faces) for f in frags]))}


def report_puzzle(r: dict) -> None:
    rows = r["rows"]
    touch = [x for x in rows if x["share"] >= MIN_CONTACT]
    apart = [x for x in rows if x["share"] == 0.0]
    n_pairs = max(1, len(rows))
    print(f"{r['name']:<36s} {r['fragments']:>5d} {r['f1']:>6.3f} {len(touch):>5d} "
          f"{sum(x['ok'] for x in touch):>5d} {sum(x['base_ok'] for x in touch):>5d} "
          f"{auc([x['score'] for x in touch], [x['score'] for x in apart]):>6.3f} "
          f"{auc([x['base_score'] for x in touch], [x['base_score'] for x in apart]):>7.3f} "
          f"{r['t_prepare'] / r['fragments']:>11.2f} {r['t_pairs'] / n_pairs:>7.2f} {r['t_base'] / n_pairs:>11.2f}",
          flush=True)


def auc(pos: list[float], neg: list[float]) -> float:
    from sklearn.metrics import roc_auc_score

    if not pos or not neg:
        return float("nan")
    y = np.r_[np.ones(len(pos)), np.zeros(len(neg))]
    s = np.nan_to_num(np.r_[pos, neg], neginf=-1e9)
    return float(roc_auc_score(y, s))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8")
    parser.add_argument("--no-baseline", action="store_true")
    parser.add_argument("--cached", action="store_true",
                        help="descriptors from the cache beside the set (benchmarks.accuracy.segmentation fills it): "
                        "same results, the preparation time then leaves the descriptors out")
    add_signature_radii(parser)
    args = parser.parse_args()
    run = start()
    specs = select(args)
    paths = [str(args.root / s.name / "ground_truth.json") for s in specs]
    print(f"{len(specs)} puzzles; pairs touching with contact >= {MIN_CONTACT:.0%} of the smaller fragment's "
          "surface must be within 2° and 1 % of the diagonal")
    print(f"{'puzzle':<36s} {'frags':>5s} {'F1':>6s} {'touch':>5s} {'ours':>5s} {'fpfh':>5s} "
          f"{'AUC':>6s} {'fpfhAUC':>7s} {'prep/frag s':>11s} {'s/pair':>7s} {'fpfh s/pair':>11s}")
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        results = []
        for spec, r in zip(specs, pool.map(run_puzzle, paths, [not args.no_baseline] * len(paths),
                                           [args.seed] * len(paths), [args.signature_radii] * len(paths),
                                           [args.cached] * len(paths))):
            results.append(r)
            report_puzzle(r)
    groups: dict[str, list] = {"all": [], "clean": [], "noisy": []}
    for spec, r in zip(specs, results):
        for g in ("all", "noisy" if spec.noise else "clean"):
            groups[g].append(r)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s with --jobs {args.jobs}")
    summary = []
    for g, rs in groups.items():
        if not rs:
            continue
        rows = [x for r in rs for x in r["rows"]]
        touch = [x for x in rows if x["share"] >= MIN_CONTACT]
        apart = [x for x in rows if x["share"] == 0.0]
        area_f1 = np.mean([r["f1"] for r in rs])
        summary.append({"group": g, "puzzles": len(rs), "f1_mean": float(area_f1), "f1_min": min(r["f1"] for r in rs),
                        "touching": len(touch), "ours_right": int(sum(x["ok"] for x in touch)),
                        "ours_share": float(np.mean([x["ok"] for x in touch])) if touch else None,
                        "ours_auc": auc([x["score"] for x in touch], [x["score"] for x in apart]),
                        "baseline": not args.no_baseline,
                        "fpfh_share": float(np.mean([x["base_ok"] for x in touch])) if touch else None,
                        "fpfh_auc": auc([x["base_score"] for x in touch], [x["base_score"] for x in apart])})
        print(f"{g:>5s}: {len(rs)} puzzles; segmentation F1 mean {area_f1:.3f} (min {min(r['f1'] for r in rs):.3f}); "
              f"touching pairs correct: ours {np.mean([x['ok'] for x in touch]):.3f}, "
              f"fpfh {np.mean([x['base_ok'] for x in touch]):.3f} of {len(touch)}; "
              f"AUC ours {auc([x['score'] for x in touch], [x['score'] for x in apart]):.3f}, "
              f"fpfh {auc([x['base_score'] for x in touch], [x['base_score'] for x in apart]):.3f}")
    by_n: dict[int, list] = {}
    for r in results:
        by_n.setdefault(r["fragments"], []).append(r)
    print("\nall-pairs time against fragment count (ours; mean over puzzles):")
    for n in sorted(by_n):
        rs = by_n[n]
        print(f"  {n:>3d} fragments ({n * (n - 1) // 2:>4d} pairs, ~{np.mean([r['faces'] for r in rs]):.0f} faces each): "
              f"prepare {np.mean([r['t_prepare'] for r in rs]):6.1f} s, pairs {np.mean([r['t_pairs'] for r in rs]):6.1f} s")
    per_puzzle = []
    for r in results:
        touch = [x for x in r["rows"] if x["share"] >= MIN_CONTACT]
        apart = [x for x in r["rows"] if x["share"] == 0.0]
        per_puzzle.append({"name": r["name"], "fragments": r["fragments"], "f1": r["f1"], "touching": len(touch),
                           "ours_right": int(sum(x["ok"] for x in touch)),
                           "fpfh_right": int(sum(x["base_ok"] for x in touch)),
                           "ours_auc": auc([x["score"] for x in touch], [x["score"] for x in apart]),
                           "t_prepare_per_fragment": r["t_prepare"] / r["fragments"],
                           "t_per_pair": r["t_pairs"] / max(1, len(r["rows"]))})
    cols = ["puzzles", "n", "segmentation F1", "F1 min", "touching pairs", "right (ours)", "AUC (ours)"]
    fmts = ["", "d", ".3f", ".3f", "d", ".3f", ".3f"]
    if not args.no_baseline:
        cols, fmts = cols + ["right (FPFH)", "AUC (FPFH)"], fmts + [".3f", ".3f"]
    tables = [
        table(f"Pairs touching over >= {MIN_CONTACT:.0%} of the smaller surface, right within 2 deg and 1 % of the "
              "diagonal; ROC AUC of the best score, touching against apart (targets: F1 >= 0.95, right >= 0.95, "
              "AUC >= 0.98)", cols,
              [[x["group"], x["puzzles"], x["f1_mean"], x["f1_min"], x["touching"], x["ours_share"], x["ours_auc"]]
               + ([x["fpfh_share"], x["fpfh_auc"]] if x["baseline"] else []) for x in summary], fmts),
        table("Per puzzle", ["puzzle", "fragments", "F1", "touching", "right (ours)", "AUC (ours)",
                             "prepare s / fragment", "s / pair"],
              [[x["name"], x["fragments"], x["f1"], x["touching"], x["ours_right"], x["ours_auc"],
                x["t_prepare_per_fragment"], x["t_per_pair"]] for x in per_puzzle],
              ["", "d", ".3f", "d", "d", ".3f", ".2f", ".2f"]),
    ]
    headline = [(f"Pairs right ({x['group']}, {x['touching']} touching pairs of {x['puzzles']} {args.set} puzzles of "
                  f"{args.pieces} pieces)",
                 f"{x['ours_share']:.3f} (target >= 0.95)"
                 + (f"; ROC AUC {x['ours_auc']:.3f} (target >= 0.98)" if np.isfinite(x["ours_auc"]) else ""))
                for x in summary if x["group"] != "all" and x["ours_share"] is not None]
    run.write(args.json, figures={"summary": summary, "puzzles": per_puzzle, "min_contact": MIN_CONTACT},
              tables=tables, headline=headline)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
