"""How well `geometry.vertex_noise` estimates scan noise, and the contact tolerance it sets.

    python benchmarks/noise_estimate.py puzzles/bench                   # all seeds 0, clean and noisy
    python benchmarks/noise_estimate.py puzzles/bench --seeds 0,1,2

Per puzzle: the set's estimate (median over fragments) as a fraction of the reference
size, the true sigma of the added noise (the generator's, per coordinate; 0 when clean)
and the registration tolerance that `registration.with_noise` resolves from the estimate.
Summary: estimate / truth on the noisy puzzles, the largest estimate on the clean ones,
and how many clean puzzles keep the default tolerance.
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
    header()
    from reassemble.geometry import vertex_noise
    from reassemble.pipeline import read_puzzle, reference_size
    from reassemble.registration import RegistrationParams, with_noise

    default = RegistrationParams()
    ratios, clean, kept = [], [], 0
    print(f"{'puzzle':<42s} {'estimate':>9s} {'true':>9s} {'ratio':>6s} {'tolerance':>9s}  (fractions of the size)")
    for spec in select(args):
        puzzle = read_puzzle(args.root / spec.name / "ground_truth.json", with_labels=False)
        meshes = [(m.vertices, m.faces) for m in puzzle.meshes.values()]
        size = reference_size(meshes)
        obj = puzzle.ground_truth["object"]
        diagonal = float(np.linalg.norm(np.subtract(obj["bbox_max"], obj["bbox_min"])))
        estimate = float(np.median([vertex_noise(v) for v, _ in meshes]))
        true = spec.noise * diagonal
        tol = with_noise(default, noise=estimate, size=size).tolerance
        ratio = estimate / true if true else float("nan")
        if true:
            ratios.append(ratio)
        else:
            clean.append(estimate / size)
            kept += tol == default.tolerance
        print(f"{spec.name:<42s} {estimate / size:>9.5f} {true / size:>9.5f} {ratio:>6.3f} {tol:>9.4f}", flush=True)
    if ratios:
        print(f"noisy ({len(ratios)}): estimate / true sigma median {np.median(ratios):.3f}, "
              f"range {min(ratios):.3f} - {max(ratios):.3f}")
    if clean:
        print(f"clean ({len(clean)}): largest estimate {max(clean):.5f} of the size; "
              f"{kept} of {len(clean)} keep the default tolerance {default.tolerance}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
