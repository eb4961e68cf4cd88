"""Fragments that are no clean solids: scanned with a hole, or cell unions keeping their walls.

Every fragment of a bench puzzle scanned with a hole, or written as a union of cells
keeping the walls between them (as Breaking Bad ships them).

    python -m benchmarks.accuracy.open_fragments puzzles/bench --pieces 4,8 --meshes spot,torus
    python -m benchmarks.accuracy.open_fragments puzzles/bench --hole 0.1 --with-closed
    python -m benchmarks.accuracy.open_fragments puzzles/bench --damage walls --with-closed \
        --json benchmarks/results/accuracy.cell_walls.json

Each fragment of the selected bench puzzles loses one disc of its original (not fracture)
surface, ``--hole`` of the fragment's own bounding-box diagonal across (the unit of
``--fill-holes``), centred on a seeded random face of its original surface (its triangles
split first, the surface unchanged, so that a large flat face loses a disc, not itself). The open
fragments are reassembled as they are (``run_to_folder`` without ``fill_holes``: the
loader keeps the holes open and the descriptors bridge them with the winding number) and
scored against the puzzle's ground truth (only the selected clean puzzles of the set are
built, where missing) as `reassemble eval` does (anchored on the
largest placed fragment): strict part accuracy, Breaking Bad part accuracy, solved.
``--with-closed`` also runs the closed fragments, for the same figures side by side.
``--damage walls``: instead of a hole, the same puzzle broken again with
``--keep-cell-faces`` (the same cuts, each fragment a union of 4 cells whose walls are
kept, once per cell), scored against its own ground truth.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_selection, start, table

ALIGN = "anchor_largest"


def punch(puzzle_dir: Path, out: Path, *, hole: float, seed: int) -> list[float]:
    """Write the puzzle's fragments to ``out`` with one hole each; the holes' extents
    (fractions of each fragment's diagonal)."""
    import trimesh

    from reassemble.files import write_ply
    from reassemble.holes import boundary_loops
    from reassemble.pipeline import read_puzzle

    puzzle = read_puzzle(puzzle_dir / "ground_truth.json")
    rng = np.random.default_rng(seed)
    out.mkdir(parents=True)
    extents = []
    for name, m in sorted(puzzle.meshes.items()):
        diag = float(np.linalg.norm(np.ptp(m.vertices, axis=0)))
        # triangles split (the surface unchanged) until none is longer than a fifth of the
        # hole: on a CAD part's large faces, removing whole triangles would cut far more
        vertices, faces, index = trimesh.remesh.subdivide_to_size(m.vertices, m.faces, 0.2 * hole * diag,
                                                                  return_index=True)
        labels = puzzle.labels[name][index]
        centres = vertices[faces].mean(axis=1)
        at = centres[rng.choice(np.flatnonzero(labels == 0))]
        keep = np.linalg.norm(centres - at, axis=1) > 0.5 * hole * diag
        used, faces = np.unique(faces[keep], return_inverse=True)
        faces = faces.reshape(-1, 3)
        write_ply(out / f"{name}.ply", vertices[used], faces)
        loops = boundary_loops(faces)
        extents.append(max((float(np.linalg.norm(np.ptp(vertices[used][lp], axis=0))) / diag for lp in loops),
                           default=0.0))
    return extents


def score(folder: Path, gt: Path, out: Path) -> dict:
    from reassemble.pipeline import evaluate_files, run_to_folder

    t = time.perf_counter()
    run_to_folder([folder], out, seed=0)
    seconds = time.perf_counter() - t
    s = evaluate_files(out / "transforms.json", gt)["alignments"][ALIGN]["summary"]
    return {"strict": s["part_acc_strict"], "bb": s["part_acc"], "solved": s["solved"], "seconds": seconds}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="4,8")
    parser.add_argument("--hole", type=float, default=0.1, help="hole extent / fragment diagonal (default 0.1)")
    parser.add_argument("--with-closed", action="store_true", help="also run the closed fragments")
    parser.add_argument("--damage", choices=("hole", "walls"), default="hole",
                        help="hole: one hole per fragment (default); walls: cell unions keeping their walls")
    args = parser.parse_args()
    bench = start()
    from data_synth.make_sets import break_params, build_one
    from reassemble.puzzle import break_to_folder
    from data_synth.sets import SETS

    pieces = {int(p) for p in args.pieces.split(",")}
    seeds = {int(s) for s in args.seeds.split(",")}
    meshes = set(args.meshes.split(",")) if args.meshes else None
    specs = [s for s in SETS[args.set]() if s.pieces in pieces and s.seed in seeds and not s.noise
             and (meshes is None or s.mesh in meshes)]
    for spec in specs:  # only the puzzles selected, each built if missing
        build_one(spec, args.root)
    print(f"{'puzzle':<28s} {'case':<7s} {'hole':>5s} {'strict':>6s} {'BB':>6s} {'solved':>6s} {'time s':>7s}",
          flush=True)
    rows: dict[str, list[dict]] = {"open" if args.damage == "hole" else "walls": [], "closed": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for spec in specs:
            puzzle = args.root / spec.name
            gt = puzzle / "ground_truth.json"
            if args.damage == "hole":
                extents = punch(puzzle, tmp / spec.name / "open", hole=args.hole, seed=spec.seed)
                cases = [("open", tmp / spec.name / "open", gt)]
            else:
                extents = [0.0]
                walls = tmp / spec.name / "walls"
                break_to_folder(spec.mesh, walls, seed=spec.seed,
                                params=dataclasses.replace(break_params(spec), keep_cell_faces=True))
                cases = [("walls", walls / "fragments", walls / "ground_truth.json")]
            if args.with_closed:
                cases.append(("closed", puzzle / "fragments", gt))
            for case, folder, truth in cases:
                r = score(folder, truth, tmp / spec.name / f"{case}-run")
                rows[case].append({"puzzle": spec.name, "hole": max(extents) if case == "open" else None, **r})
                hole = f"{max(extents):.3f}" if case == "open" else "-"
                print(f"{spec.name:<28s} {case:<7s} {hole:>5s} {r['strict']:6.3f} {r['bb']:6.3f} "
                      f"{str(r['solved']):>6s} {r['seconds']:7.0f}", flush=True)
    summary = []
    for case, rs in rows.items():
        if rs:
            strict, bb = np.mean([r["strict"] for r in rs]), np.mean([r["bb"] for r in rs])
            solved = sum(r["solved"] for r in rs)
            summary.append([case, len(rs), strict, bb, f"{solved}/{len(rs)}"])
            print(f"mean {case}: strict {strict:.3f}, BB {bb:.3f}, solved {solved}/{len(rs)} ({len(rs)} puzzles)")
    title = (f"Open fragments: one hole of {args.hole:g} of each fragment's diagonal, no --fill-holes"
             if args.damage == "hole" else "Cell unions keeping their walls (Breaking Bad's layout), as read")
    what = (f"open fragments (hole {args.hole:g} of the diagonal)" if args.damage == "hole"
            else "cell unions with their walls")
    bench.write(args.json, figures={"damage": args.damage, "hole": args.hole, "puzzles": rows},
                tables=[table(title,
                              ["fragments", "puzzles", "strict part accuracy", "BB part accuracy", "solved"],
                              summary, ["", "d", ".3f", ".3f", ""])],
                headline=[(f"{what}, strict part accuracy",
                           f"{summary[0][2]:.3f}")] if summary else [])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
