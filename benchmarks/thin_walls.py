"""Which fragments count as thin-walled sherds: the wall test over a puzzle set.

    python benchmarks/thin_walls.py puzzles/bench                  # every puzzle of the bench set
    python benchmarks/thin_walls.py puzzles/sherds --set sherds

Per puzzle: the smallest and the median over fragments of (median wall thickness / the
fragment's diagonal) and how many fragments pass :func:`reassemble.shells.is_thin_shell`
(walls over 60 % of the surface and under 8 % of the diagonal thick). The bench solids
should pass none: a set of them matched as sherds would lose its fracture surfaces.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import add_selection, header, select  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8,12,20")
    args = parser.parse_args()
    if args.seeds == "0":
        args.seeds = "0,1,2"
    header()
    from reassemble.pipeline import read_puzzle
    from reassemble.shells import is_thin_shell, wall_thickness, walls

    lowest, passed = [], 0
    for spec in select(args):
        puzzle = read_puzzle(args.root / spec.name / "ground_truth.json", with_labels=False)
        ratios, thin = [], 0
        for m in puzzle.meshes.values():
            t = wall_thickness(m.vertices, m.faces)
            ratios.append(walls(t)[1] / np.linalg.norm(np.ptp(m.vertices, axis=0)))
            thin += is_thin_shell(m.vertices, m.faces, t)
        lowest.append(min(ratios))
        passed += thin
        print(f"{spec.name:<36s} wall/diagonal min {min(ratios):.3f} median {np.median(ratios):.3f}; "
              f"thin-walled {thin} of {len(ratios)}", flush=True)
    print(f"{len(lowest)} puzzles: smallest wall/diagonal {min(lowest):.3f}; fragments passing the test: {passed}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
