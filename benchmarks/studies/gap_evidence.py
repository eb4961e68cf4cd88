"""Whether a measured gap between mating surfaces is evidence: the fit touching against the fit apart.

    python -m benchmarks.studies.gap_evidence                  # torus 4 pieces: no gap, 1.5 % gap, each with 0.1 % noise
    python -m benchmarks.studies.gap_evidence --puzzles P1 P2   # puzzle folders made by `reassemble break`

For every touching pair of each puzzle (its pairs registered as ``run`` registers them,
seed 0): the rotation error of the best candidate against the truth; the gap
:func:`registration.estimate_gap` finds from it (fraction of the size); and the RMS of
the contact residual (:func:`registration.contact_rms`, within twice the tolerance,
fraction of the size) touching at the candidate and apart at the estimated gap. The
last column is what :func:`registration.set_gap` makes of it: ``gap`` when the fit
apart is the closer one, ``none`` when it is not, ``flat`` when the contact has no
relief to tell a gap from a motion. Ends with each puzzle's set gap.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

# (name, options of BreakParams), torus 4 pieces seed 0
DEFAULT = (
    ("torus 4 smooth noise 0.1 %", dict(style="smooth", noise=0.001)),
    ("torus 4 gap 1.5 %", dict(gap=0.015)),
    ("torus 4 gap 1.5 % noise 0.1 %", dict(gap=0.015, noise=0.001)),
)


def study(puzzle: Path) -> tuple[list[list], float]:
    from reassemble.geometry import invert_transform, rotation_angle_deg
    from reassemble.pairs import match_pairs, registration_params
    from reassemble.pipeline import prepare_fragments, read_puzzle
    from reassemble.registration import contact_relief, contact_rms, estimate_gap, set_gap

    pz = read_puzzle(puzzle / "ground_truth.json", with_labels=False)
    names = sorted(pz.meshes)
    frags, size = prepare_fragments({n: (pz.meshes[n].vertices, pz.meshes[n].faces) for n in names}, seed=0)
    params = registration_params(frags, size=size)
    results = match_pairs(frags, size=size, params=params, seed=0)
    truth = {n: np.asarray(pz.ground_truth["fragments"][n]["transform"], float) for n in names}
    surfaces = [f.surface for f in frags]
    tol = params.tolerance * size
    rows = []
    for (i, j), res in sorted(results.items()):
        if not res.touching:
            continue
        true = invert_transform(truth[names[j]]) @ truth[names[i]]
        T0 = res.best.T_target_source
        T, g = estimate_gap(surfaces[i], surfaces[j], T0, tol=tol, max_gap=0.08 * size,
                            normal_angle=params.normal_angle)
        touching = contact_rms(surfaces[i], surfaces[j], T0, tol=2 * tol, normal_angle=params.normal_angle)
        apart = contact_rms(surfaces[i], surfaces[j], T, tol=2 * tol, gap=g, normal_angle=params.normal_angle)
        flat = contact_relief(surfaces[i], surfaces[j], T, tol=tol, gap=g, normal_angle=params.normal_angle) <= tol
        verdict = "flat" if flat else ("gap" if g > 0 and apart < touching else "none")
        rows.append([puzzle.name, f"{names[i]}-{names[j]}", rotation_angle_deg(T0[:3, :3], true[:3, :3]), g / size,
                     touching / size, apart / size, verdict])
    return rows, set_gap(surfaces, results, size=size, params=params)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--puzzles", nargs="+", type=Path, help="puzzle folders (default: the three torus puzzles)")
    add_json_option(parser)
    args = parser.parse_args(argv)
    run = start()
    from reassemble.puzzle import break_to_folder
    from reassemble.synth import BreakParams

    rows, gaps = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        puzzles = args.puzzles
        if not puzzles:
            puzzles = []
            for name, options in DEFAULT:
                out = Path(tmp) / name.replace(" ", "_").replace("%", "pc")
                break_to_folder("torus", out, params=BreakParams(pieces=4, **options), seed=0)
                puzzles.append(out)
        for p in puzzles:
            r, g = study(p)
            rows += r
            gaps[p.name] = g
            for row in r:
                print("{:34s} {:24s} rot {:6.2f}  gap {:.4f}  rms touching {:.5f} apart {:.5f}  {}".format(*row))
            print(f"{p.name}: set gap {g:.4f}", flush=True)
    cols = ["puzzle", "pair", "rotation error deg", "gap / size", "RMS touching / size", "RMS apart / size", "counts as"]
    run.write(args.json, figures={"pairs": rows, "set_gap": gaps},
              tables=[table("Touching pairs: the fit touching and apart", cols, rows,
                            ["", "", ".2f", ".4f", ".5f", ".5f", ""]),
                      table("Set gap (fraction of the size)", ["puzzle", "gap"], [[k, v] for k, v in gaps.items()],
                            ["", ".4f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
