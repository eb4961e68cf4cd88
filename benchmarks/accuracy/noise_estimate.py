"""How well `geometry.vertex_noise` estimates scan noise, and the contact tolerance it sets.

    python -m benchmarks.accuracy.noise_estimate puzzles/bench                   # all seeds 0, clean and noisy
    python -m benchmarks.accuracy.noise_estimate puzzles/bench --seeds 0,1,2

Per puzzle: the set's estimate (median over fragments) as a fraction of the reference
size, the true sigma of the added noise (the generator's, per coordinate; 0 when clean)
and the registration tolerance that `registration.with_noise` resolves from the estimate.
Summary: estimate / truth on the noisy puzzles, the largest estimate on the clean ones,
and how many clean puzzles keep the default tolerance.
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.common import add_selection, select, start, table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="2,4,8,12,20")
    args = parser.parse_args()
    run = start()
    from reassemble.geometry import vertex_noise
    from reassemble.pipeline import read_puzzle, reference_size
    from reassemble.registration import RegistrationParams, with_noise

    default = RegistrationParams()
    ratios, clean, kept, rows = [], [], 0, []
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
        rows.append({"puzzle": spec.name, "estimate": estimate / size, "true": true / size,
                     "ratio": ratio if true else None, "tolerance": float(tol)})
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
    summary = []
    if ratios:
        summary.append(["noisy", len(ratios), "estimate / true sigma", f"median {np.median(ratios):.3f}, "
                        f"range {min(ratios):.3f} - {max(ratios):.3f}"])
    if clean:
        summary.append(["clean", len(clean), "largest estimate / size; default tolerance kept",
                        f"{max(clean):.5f}; {kept} of {len(clean)}"])
    run.write(args.json, figures={"puzzles": rows, "default_tolerance": default.tolerance,
                                  "noisy_ratio_median": float(np.median(ratios)) if ratios else None,
                                  "clean_largest_estimate": max(clean) if clean else None, "clean_kept_default": kept},
              tables=[table("Vertex-noise estimate (geometry.vertex_noise) against the added noise",
                            ["puzzles", "n", "figure", "value"], summary, ["", "d", "", ""])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
