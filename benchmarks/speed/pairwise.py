"""Time of one pair registration on fragments of about 20k faces or more, after the descriptors.

    python -m benchmarks.speed.pairwise puzzles/bench

Takes the 2-piece bench puzzles (seed 0), subdivides both fragments (flat, trimesh's
``subdivide``: same geometry) until each has at least 20k faces, prepares them
(descriptors, segmentation, features: timed apart) and registers the pair three times
(median reported). Builds the bench set first if missing. Run it on an idle machine.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root", type=Path)
    parser.add_argument("--min-faces", type=int, default=20000)
    add_json_option(parser)
    args = parser.parse_args()
    run = start()
    import trimesh

    from data_synth.make_sets import build_set
    from data_synth.sets import BENCH_MESHES
    from reassemble.pipeline import match_pairs, prepare_fragments, read_puzzle

    if not (args.root / "index.json").is_file():
        build_set("bench", args.root, jobs=2)
    print(f"{'puzzle':<28s} {'faces':>13s} {'prepare s':>10s} {'pair s (median of 3)':>21s} {'touching':>8s}")
    times, rows = [], []
    for mesh in BENCH_MESHES:
        puzzle = read_puzzle(args.root / f"{mesh}_02p_s0" / "ground_truth.json")
        meshes = {}
        for name, m in puzzle.meshes.items():
            tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
            while len(tm.faces) < args.min_faces:
                tm = tm.subdivide()
            meshes[name] = (np.asarray(tm.vertices), np.asarray(tm.faces))
        t = time.perf_counter()
        frags, size = prepare_fragments(meshes, seed=0)
        t_prep = time.perf_counter() - t
        runs = []
        for _ in range(3):
            t = time.perf_counter()
            res = match_pairs(frags, size=size, seed=0)[(0, 1)]
            runs.append(time.perf_counter() - t)
        times.append(float(np.median(runs)))
        faces = "/".join(str(len(f.faces)) for f in frags)
        rows.append({"puzzle": mesh + "_02p_s0", "faces": faces, "prepare": t_prep, "pair": times[-1],
                     "runs": runs, "touching": bool(res.touching)})
        print(f"{mesh + '_02p_s0':<28s} {faces:>13s} {t_prep:>10.1f} {times[-1]:>21.2f} {str(res.touching):>8s}")
    print(f"median over puzzles: {np.median(times):.2f} s per pair")
    run.write(args.json, figures={"median_pair_seconds": float(np.median(times)), "puzzles": rows},
              tables=[table(f"One pair of fragments subdivided to >= {args.min_faces} faces each: preparation of the two "
                            "and registration (median of 3)", ["puzzle", "faces", "prepare s", "pair s", "touching"],
                            [[x["puzzle"], x["faces"], x["prepare"], x["pair"], "yes" if x["touching"] else "no"]
                             for x in rows], ["", "", ".1f", ".2f", ""])],
              headline=[("Time of one pair registration, >= 20k faces each (median)",
                         f"{np.median(times):.2f} s")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
