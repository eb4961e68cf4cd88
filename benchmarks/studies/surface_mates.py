"""How well do the two sides of a break cover each other, against other pairs of smooth regions?

    python -m benchmarks.studies.surface_mates PUZZLE [PUZZLE ...]

For each puzzle (a folder with ground_truth.json, labels.npz, fragments/): the fragments are
described and segmented as ``run`` does (first segmentation), the crease-bounded smooth
regions of each are taken as :func:`reassemble.surface_mates.relabel_surface_mates` takes
them, and every pair of regions it would compare is laid together and scored
(:func:`reassemble.surface_mates._overlap`). A pair is a true mate when both regions are
mostly (over half their faces) fracture by the generator's labels and their fragments
touch. Reported: the scores of true mates and the largest score of any other pair, and the
set's area-weighted segmentation F1 before and after the relabelling.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table


def f1(segs, described, labels) -> float:
    from reassemble.geometry import face_areas

    tp = fp = fn = 0.0
    for k, name in enumerate(described.names):
        if segs[k] is None:
            continue
        area = face_areas(described.matched[k], described.meshes[k][1])
        t, p = np.asarray(labels[name], bool), segs[k].fracture
        tp, fp, fn = tp + area[t & p].sum(), fp + area[~t & p].sum(), fn + area[t & ~p].sum()
    return 2 * tp / max(2 * tp + fp + fn, 1e-300)


def study(puzzle: Path) -> dict:
    from scipy.spatial import cKDTree

    from reassemble.config import Config
    from reassemble.pipeline import read_puzzle
    from reassemble.prepare import SURFACE_MATE_AREA, describe_fragments, segment_set
    from reassemble.registration import with_noise
    from reassemble.shells import wall_thickness
    from reassemble.surface_mates import _overlap, _region, _similar, relabel_surface_mates, smooth_regions

    config = Config()
    files = read_puzzle(puzzle / "ground_truth.json", with_labels=True)
    gt = json.loads((puzzle / "ground_truth.json").read_text())
    touching = {frozenset(c["fragments"]) for c in gt.get("contacts", [])}
    described = describe_fragments({n: (m.vertices, m.faces) for n, m in files.meshes.items()}, config=config)
    good = [k for k, d in enumerate(described.descriptors) if d is not None]
    thickness = {k: wall_thickness(described.matched[k], described.meshes[k][1]) for k in good}
    segs, _ = segment_set(described, thickness, config=config, seed=config.seed)
    reg = with_noise(config.registration, noise=float(np.median([described.noise[k] for k in good])),
                     size=described.size)
    tol = reg.tolerance * described.size
    min_area = SURFACE_MATE_AREA * float(np.median([segs[k].area for k in good]))
    rng = np.random.default_rng(config.seed)
    regions = [_region(k, described.matched[k], described.meshes[k][1], idx, samples=300, rng=rng)
               for k in good
               for idx in smooth_regions(described.matched[k], described.meshes[k][1],
                                         crease=config.segment.crease_angle, min_area=min_area)[:16]]
    trees = [cKDTree(r.points) for r in regions]

    def broken(r) -> bool:
        return np.asarray(files.labels[described.names[r.fragment]], bool)[r.faces].mean() > 0.5

    true, other = [], []
    for i, a in enumerate(regions):
        for j in range(i + 1, len(regions)):
            b = regions[j]
            if b.fragment == a.fragment or not _similar(a, b, 1.5):
                continue
            cover, _ = _overlap(a, b, trees[i], trees[j], tol=tol, spacing=np.sqrt(max(a.area, b.area) / 300))
            mates = broken(a) and broken(b) and frozenset(
                (described.names[a.fragment], described.names[b.fragment])) in touching
            (true if mates else other).append(cover)
    relabelled, _ = relabel_surface_mates([(described.matched[k], described.meshes[k][1]) for k in good],
                                          [segs[k] for k in good], tol=tol, min_area=min_area,
                                          min_overlap=config.segment.mate_overlap,
                                          crease=config.segment.crease_angle, rng=np.random.default_rng(config.seed))
    after = list(segs)
    for k, s in zip(good, relabelled):
        after[k] = s
    return {"puzzle": puzzle.name, "regions": len(regions), "true_mates": sorted(true, reverse=True),
            "other_pairs": len(other), "best_other": max(other, default=0.0),
            "f1_before": f1(segs, described, files.labels), "f1_after": f1(after, described, files.labels)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("puzzles", type=Path, nargs="+")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    rows = []
    for p in args.puzzles:
        r = study(p)
        print(f"{r['puzzle']}: {r['regions']} regions; true mates cover {', '.join(f'{x:.2f}' for x in r['true_mates'])}; "
              f"best of {r['other_pairs']} other pairs {r['best_other']:.2f}; F1 {r['f1_before']:.2f} -> {r['f1_after']:.2f}",
              flush=True)
        rows.append(r)
    bench.write(args.json, figures={"puzzles": rows},
                tables=[table("Smooth regions laid together: the cover of true mates (both sides of one break) "
                              "and the best of all other pairs; first segmentation's F1 before and after the "
                              "surface mates", ["puzzle", "regions", "true mates", "lowest true", "other pairs",
                                                "best other", "F1 before", "F1 after"],
                              [[r["puzzle"], r["regions"], len(r["true_mates"]), min(r["true_mates"], default=0.0),
                                r["other_pairs"], r["best_other"], r["f1_before"], r["f1_after"]] for r in rows],
                              ["", "d", "d", ".2f", "d", ".2f", ".2f", ".2f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
