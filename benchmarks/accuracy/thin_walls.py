"""Which fragments count as thin-walled sherds: the wall test over a puzzle set.

    python -m benchmarks.accuracy.thin_walls puzzles/bench                  # every puzzle of the bench set
    python -m benchmarks.accuracy.thin_walls puzzles/sherds --set sherds

Per puzzle: the smallest and the median over fragments of (median wall thickness / the
fragment's diagonal) and how many fragments pass :func:`reassemble.shells.is_thin_shell`
(walls over 60 % of the surface and under 8 % of the diagonal thick). The bench solids
should pass none: a set of them matched as sherds would lose its fracture surfaces.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.common import add_selection, select, start, table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8,12,20")
    args = parser.parse_args()
    if args.seeds == "0":
        args.seeds = "0,1,2"
    run = start()
    from reassemble.pipeline import read_puzzle
    from reassemble.shells import is_thin_shell, wall_thickness, walls

    lowest, passed, rows = [], 0, []
    for spec in select(args):
        puzzle = read_puzzle(args.root / spec.name / "ground_truth.json", with_labels=False)
        ratios, thin = [], 0
        for m in puzzle.meshes.values():
            t = wall_thickness(m.vertices, m.faces)
            ratios.append(walls(t)[1] / np.linalg.norm(np.ptp(m.vertices, axis=0)))
            thin += is_thin_shell(m.vertices, m.faces, t)
        lowest.append(min(ratios))
        rows.append({"puzzle": spec.name, "fragments": len(ratios), "wall_min": float(min(ratios)),
                     "wall_median": float(np.median(ratios)), "thin": int(thin)})
        passed += thin
        print(f"{spec.name:<36s} wall/diagonal min {min(ratios):.3f} median {np.median(ratios):.3f}; "
              f"thin-walled {thin} of {len(ratios)}", flush=True)
    print(f"{len(lowest)} puzzles: smallest wall/diagonal {min(lowest):.3f}; fragments passing the test: {passed}")
    fragments = sum(r["fragments"] for r in rows)
    medians = [r["wall_median"] for r in rows]
    run.write(args.json, figures={"set": args.set, "puzzles": rows, "fragments_thin": int(passed),
                                  "fragments": fragments, "smallest_wall_over_diagonal": float(min(lowest))},
              tables=[table(f"Wall test over the {args.set} set (median wall thickness / fragment diagonal)",
                            ["puzzles", "fragments", "thin-walled", "smallest", "median over a puzzle: lowest",
                             "highest"],
                            [[len(rows), fragments, int(passed), float(min(lowest)), min(medians), max(medians)]],
                            ["d", "d", "d", ".3f", ".3f", ".3f"])],
              headline=[(f"Thin-wall test on the {args.set} set", f"{passed} of {fragments} fragments thin-walled")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
