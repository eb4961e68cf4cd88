"""What a pair's score is a share of: the smaller break against the smaller whole surface.

    python -m benchmarks.studies.score_shares --sets puzzles --half tuning --max-pieces 4 --jobs 2
    python -m benchmarks.studies.score_shares --puzzles P1 P2          # puzzle folders made by `reassemble break`

Every pair of each clean puzzle is registered as ``run`` registers it (its own
segmentation, seed 0, no assembly). A candidate is *true* when it is within 5 degrees and
2 % of the size of the pair's true relative pose. For each candidate the score is read
two ways: as ``registration.contact_score`` gives it (net contact over the smaller of the
two breaks, each at least ``break_floor`` of its whole area) and over the smaller
fragment's whole area, as before. For each threshold the table counts the pairs whose
best true candidate falls under it (lost mates) and the wrong candidates at or above it
(what the assembly must reject), and gives the lowest true score of each reading.
Tune on the tuning half only.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

THRESHOLDS = {"break": (0.04, 0.06, 0.08, 0.1), "whole": (0.01, 0.015, 0.02, 0.03)}


def study(puzzle: Path) -> list[dict]:
    """Per pair: its areas and each candidate's two scores and truth."""
    from reassemble.config import Config
    from reassemble.geometry import invert_transform, rotation_angle_deg
    from reassemble.pipeline import read_puzzle, reassemble
    from reassemble.registration import RegistrationParams, _score_area

    pz = read_puzzle(puzzle / "ground_truth.json", with_labels=False)
    names = sorted(pz.meshes)
    meshes = {n: (pz.meshes[n].vertices, pz.meshes[n].faces) for n in names}
    res = reassemble(meshes, Config(), assemble=False)
    truth = {n: np.asarray(pz.ground_truth["fragments"][n]["transform"], float) for n in names}
    floor = RegistrationParams().break_floor
    rows = []
    for (i, j), pair in sorted(res.pairs.items()):
        a, b = res.fragments[i].surface, res.fragments[j].surface
        true = invert_transform(truth[names[j]]) @ truth[names[i]]
        whole = min(a.area, b.area) / _score_area(a, b, floor=floor)  # break score x this = whole score
        cands = []
        for c in pair.candidates:
            T = c.T_target_source
            ok = rotation_angle_deg(T[:3, :3], true[:3, :3]) < 5 and np.linalg.norm(T[:3, 3] - true[:3, 3]) < 0.02 * res.size
            cands.append({"break": c.score, "whole": c.score / whole, "true": bool(ok)})
        rows.append({"puzzle": puzzle.name, "pair": f"{names[i]}-{names[j]}", "candidates": cands})
    return rows


def summary(rows: list[dict]) -> tuple[list[list], dict]:
    """Lost true pairs and passing wrong candidates per reading and threshold."""
    out, figures = [], {}
    for reading, thresholds in THRESHOLDS.items():
        best_true = [max(c[reading] for c in r["candidates"] if c["true"]) for r in rows
                     if any(c["true"] for c in r["candidates"])]
        wrong = [c[reading] for r in rows for c in r["candidates"] if not c["true"]]
        lowest = min(best_true) if best_true else float("nan")
        figures[reading] = {"pairs_with_a_true_candidate": len(best_true), "lowest_true": lowest, "thresholds": {}}
        for t in thresholds:
            lost, passing = int(sum(s < t for s in best_true)), int(sum(s >= t for s in wrong))
            figures[reading]["thresholds"][str(t)] = {"lost": lost, "wrong_passing": passing}
            out.append([reading, t, len(best_true), lost, passing, lowest])
    return out, figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--puzzles", nargs="+", type=Path, help="puzzle folders")
    parser.add_argument("--sets", type=Path, help="folder holding the field sets (data_synth.sets)")
    parser.add_argument("--half", default="tuning", choices=("tuning", "validation"))
    parser.add_argument("--max-pieces", type=int, default=4)
    parser.add_argument("--jobs", type=int, default=1, help="puzzles studied at once")
    add_json_option(parser)
    args = parser.parse_args(argv)
    if not args.puzzles and not args.sets:
        parser.error("give --puzzles or --sets")
    run = start()
    puzzles = list(args.puzzles or [])
    if args.sets:
        import json

        folder = args.sets / f"field-{args.half}"
        for p in sorted(folder.iterdir()):
            gt = p / "ground_truth.json"
            if not gt.is_file():
                continue
            params = json.loads(gt.read_text())["parameters"]
            if params["pieces"] <= args.max_pieces and params.get("noise", 0) == 0:
                puzzles.append(p)
    rows = []
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        for p, r in zip(puzzles, pool.map(study, puzzles)):
            rows += r
            print(f"{p.name}: {len(r)} pairs", flush=True)
    out, figures = summary(rows)
    for row in out:
        print("{:6s} >= {:<6} pairs {:4d}  true lost {:3d}  wrong passing {:4d}  lowest true {:.3f}".format(*row))
    figures.update(puzzles=[p.name for p in puzzles], pairs=len(rows))
    cols = ["score over", "threshold", "pairs with a true candidate", "true lost", "wrong candidates passing",
            "lowest true"]
    run.write(args.json, figures=figures,
              tables=[table("Pair scores: share of the smaller break or of the smaller whole surface", cols, out,
                            ["", "", "d", "d", "d", ".3f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
