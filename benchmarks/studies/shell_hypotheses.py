"""Where a sherd pair's true placements rank among its one-point hypotheses, locally and over the whole fragment.

    python -m benchmarks.studies.shell_hypotheses puzzles/field-tuning/vase_04p_s10_mixed
    python -m benchmarks.studies.shell_hypotheses P1 P2 ...       # puzzle folders made by `reassemble break`

For every touching pair of each thin-walled puzzle (fragments segmented as ``run``
segments them, seed 0), the frame hypotheses of ``registration.frame_hypotheses`` without
the whole-fragment ones (``shell_whole`` = 0: the local ranking, as the shortlist sees it)
are compared with the pair's true relative pose: a hypothesis is *near* when its source
samples land within 5 % of the size of their true place. Reported: how many of the pool
are near, the best rank of a near one in the local order, and its best rank when the same
pool is ordered by consensus over keypoints spread across the whole fragment. A pair
whose best local rank is beyond the shortlist (``shell_shortlist``) reaches ICP only
through the whole-fragment ones (:func:`reassemble.registration._consensus`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table


def study(puzzle: Path) -> list[list]:
    """Rows [puzzle, pair, true area, near, best local rank, best whole rank, pool] per touching pair."""
    from scipy.spatial import cKDTree

    from reassemble.config import Config
    from reassemble.geometry import farthest_points, invert_transform, transform_points
    from reassemble.pipeline import read_puzzle, reassemble
    from reassemble.registration import _inliers, frame_hypotheses, offset_surface

    pz = read_puzzle(puzzle / "ground_truth.json", with_labels=False)
    gt = json.loads((puzzle / "ground_truth.json").read_text())
    names = sorted(pz.meshes)
    res = reassemble({n: (pz.meshes[n].vertices, pz.meshes[n].faces) for n in names}, Config(), assemble=False)
    frags = res.fragments
    if not all(f.shell for f in frags):
        return []
    reg = dataclasses.replace(res.config.registration, shell_whole=0)
    size = res.size
    T_world = [np.asarray(gt["fragments"][f.name]["transform"]) for f in frags]
    index = {f.name: k for k, f in enumerate(frags)}
    rows = []
    for c in gt["contacts"]:
        i, j = (index[x] for x in c["fragments"])
        source, target = frags[i].surface, offset_surface(frags[j].surface, reg.gap * size)
        T, _ = frame_hypotheses(source, target, tol=reg.ransac_tolerance * size, radius=reg.pair_radius * size,
                                params=reg, rng=np.random.default_rng(0))
        truth = invert_transform(T_world[j]) @ T_world[i]
        pts = source.surface[:200]
        err = np.array([np.linalg.norm(transform_points(h, pts) - transform_points(truth, pts), axis=1).max()
                        for h in T]) / size
        probes = np.broadcast_to(farthest_points(source.keypoints, reg.fine_probes),
                                 (len(T), min(reg.fine_probes, len(source.keypoints))))
        whole = _inliers(T, source, target, cKDTree(target.keypoints), probes, tol=reg.ransac_tolerance * size,
                         cos_tol=np.cos(np.radians(reg.normal_angle)))
        rank_whole = np.empty(len(T), int)
        rank_whole[np.argsort(-whole, kind="stable")] = np.arange(len(T))
        near = np.flatnonzero(err < 0.05)
        rows.append([puzzle.name, f"{frags[i].name}-{frags[j].name}", float(c["area"]), int(len(near)),
                     int(near.min()) if len(near) else None, int(rank_whole[near].min()) if len(near) else None,
                     int(len(T))])
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("puzzles", type=Path, nargs="+", help="puzzle folders (ground_truth.json, fragments/)")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    rows = []
    for puzzle in args.puzzles:
        for row in study(puzzle):
            print("  ".join(str(x) for x in row), flush=True)
            rows.append(row)
    columns = ["puzzle", "pair", "true area", "near hypotheses", "best local rank", "best whole-fragment rank",
               "pool"]
    bench.write(args.json, figures={"pairs": [dict(zip(columns, r)) for r in rows]},
                tables=[table("Sherd pairs: the true placements' rank among the frame hypotheses (local consensus "
                              "order; the same pool by whole-fragment consensus)", columns, rows,
                              ["", "", ".3f", "d", "", "", "d"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
