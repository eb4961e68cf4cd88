"""The third-party vessel set: thin-walled sherds with gaps between them, scored against the truth.

    python benchmarks/vessel.py                  # ../shared/data/meshes/vessel-TU_96_2-5-fragments
    python benchmarks/vessel.py FOLDER --jobs 2

The fragments are stored in their assembled pose (the truth is the identity for each). They
are moved by seeded random rigid motions first (so nothing can profit from the given pose),
reassembled with ``reassemble run``, and scored as ``reassemble eval`` does: strict part
accuracy (mean surface distance < 1 % of the object's diagonal), Breaking Bad part accuracy,
rotation errors, anchored on the largest placed fragment. Prints per fragment the
rotation and the mean distance from its true place.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import header  # noqa: E402

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes" / "vessel-TU_96_2-5-fragments"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=Path, nargs="?", default=DEFAULT)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--gap", type=float, default=None, help="as run --gap (default: measured)")
    args = parser.parse_args()
    header()
    from reassemble.geometry import invert_transform, make_transform, random_rotation, transform_points
    from reassemble.io import load_mesh, read_json, write_ply
    from reassemble.metrics import ScoringFragment, evaluate
    from reassemble.pipeline import MatchConfig, run_to_folder

    rng = np.random.default_rng(args.seed)
    files = sorted(p for p in args.folder.iterdir() if p.suffix.lower() in {".obj", ".ply", ".stl", ".off"})
    meshes = {p.stem: load_mesh(p) for p in files}
    allv = np.vstack([m.vertices for m in meshes.values()])
    size = float(np.linalg.norm(np.ptp(allv, axis=0)))
    with tempfile.TemporaryDirectory() as tmp:
        moved_dir = Path(tmp) / "moved"
        moved_dir.mkdir()
        truth = {}
        for name, m in meshes.items():
            T_fragment_given = make_transform(random_rotation(rng), rng.normal(0, size, 3))
            write_ply(moved_dir / f"{name}.ply", transform_points(T_fragment_given, m.vertices), m.faces)
            truth[name] = invert_transform(T_fragment_given)  # T_world_fragment, world = the given pose
        t = time.perf_counter()
        run_to_folder([moved_dir], Path(tmp) / "out", seed=args.seed, jobs=args.jobs,
                      config=MatchConfig(gap=args.gap))
        elapsed = time.perf_counter() - t
        pred = read_json(Path(tmp) / "out" / "transforms.json", what="transforms")["fragments"]
        report = read_json(Path(tmp) / "out" / "report.json", what="report")
        fragments = [ScoringFragment(n, transform_points(invert_transform(truth[n]), meshes[n].vertices),
                                     meshes[n].faces, truth[n]) for n in sorted(meshes)]
        pred = {n: {"transform": np.asarray(v["transform"]), "placed": v["placed"]} for n, v in pred.items()}
        scores = evaluate(fragments, pred, bbox_min=allv.min(axis=0), bbox_max=allv.max(axis=0), seed=args.seed)
    res = scores["alignments"]["anchor_largest"]
    print(f"{'fragment':<20s} {'placed':>6s} {'rot deg':>8s} {'dist/diag':>9s} {'strict':>6s}")
    for name, f in res["fragments"].items():
        print(f"{name:<20s} {str(f['placed']):>6s} {f['rotation_error_deg']:>8.2f} {f['chamfer_mean_over_diag']:>9.4f} "
              f"{str(f['correct_strict']):>6s}")
    s = res["summary"]
    print(f"strict part acc {s['part_acc_strict']:.3f}, BB part acc {s['part_acc']:.3f}, geodesic rot RMSE "
          f"{s['rot_geodesic_rmse_deg']:.2f} deg, solved {s['solved']}; gap {report['summary'].get('gap')} x size; "
          f"run {elapsed:.1f} s (--jobs {args.jobs})")
    b = scores["alignments"]["best_anchor"]
    print(f"anchored on the best fragment instead ({b['anchor']}): strict part acc {b['summary']['part_acc_strict']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
