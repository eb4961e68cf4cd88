"""Why a run left a puzzle unsolved: each fragment's fracture labels, each true contact's rank.

    python -m benchmarks.studies.run_diagnosis PUZZLE RUN [--fragments NAME,...]

PUZZLE is a folder with ground_truth.json, labels.npz and fragments/; RUN is the output
folder ``reassemble run`` wrote for it (``analysis.npz``, ``pairs.json``, ``report.json``).
Per fragment: its sub-assembly in the report and the area-weighted precision, recall and F1
of the run's segmentation (``segmented_k`` of ``analysis.npz``, the labels its matching
used; ``fracture_k`` of runs that wrote no ``segmented_k``) against the generator's (``segmentation_f1`` of the field
benchmark). Per pair of fragments that touch in the ground truth (largest contact first):
the recall of each side's labels on the faces of their contact, whether the pair was
registered, where the true placement ranks among its candidates
(within 5 degrees, and 2 % of the diagonal at the source's centre) with its score, and the
best score. A true pair with no true candidate and a low recall on either side had no
keypoints to meet.
``--fragments`` keeps the fragments named and the contacts that involve them.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

ANGLE_DEG = 5.0  # a candidate within this of the true rotation ...
OFFSET = 0.02  # ... and this fraction of the diagonal of its translation is the true placement
SIDE = 0.01  # a true break face within this fraction of the diagonal of the other's is on their contact


def true_rank(candidates: list[dict], T_target_source: np.ndarray, centre: np.ndarray,
              diagonal: float) -> tuple[int | None, float | None]:
    """Rank and score of the first candidate at the true placement (errors measured at the
    source's ``centre``, as the pairwise benchmark does), (None, None) when none is."""
    from benchmarks.accuracy.pairwise import errors

    for i, c in enumerate(candidates):
        rotation, offset = errors(np.asarray(c["T_target_source"]), T_target_source, centre, diagonal)
        if rotation < ANGLE_DEG and offset < OFFSET:
            return i, float(c["score"])
    return None, None


def _true_breaks(files, T_world: dict) -> dict:
    """Per fragment: its faces' centres at the true pose, its generator labels and face areas."""
    from reassemble.geometry import face_areas, transform_points

    out = {}
    for n, m in files.meshes.items():
        out[n] = (transform_points(T_world[n], m.vertices[m.faces].mean(axis=1)), files.labels[n].astype(bool),
                  face_areas(m.vertices, m.faces))
    return out


def side_recall(breaks: dict, labels: dict, diagonal: float, a: str, b: str) -> float | None:
    """Area-weighted recall of ``a``'s run labels (``labels[a]``, per face) on the part of
    its true break that meets ``b``'s (face centres within ``SIDE`` of the diagonal of b's
    true break faces, at the true poses; ``breaks`` from :func:`_true_breaks`); None when
    they do not meet."""
    from scipy.spatial import cKDTree

    (ca, truth, area), (cb, truth_b, _) = breaks[a], breaks[b]
    if not truth_b.any():
        return None
    near = truth & (cKDTree(cb[truth_b]).query(ca)[0] < SIDE * diagonal)
    if not near.any():
        return None
    return float(area[near & np.asarray(labels[a], bool)].sum() / area[near].sum())


def study(puzzle: Path, run: Path, *, fragments: list[str] | None = None) -> dict:
    from benchmarks.accuracy.field import segmentation_f1
    from reassemble.inputs import load_fragments
    from reassemble.puzzle import read_puzzle

    files = read_puzzle(puzzle / "ground_truth.json")
    gt = files.ground_truth
    T_world = {n: np.asarray(f["transform"]) for n, f in gt["fragments"].items()}
    diagonal = float(gt["object"]["diagonal"])
    analysis = np.load(run / "analysis.npz", allow_pickle=True)
    names = [str(n) for n in analysis["names"]]
    keep = fragments or names
    report = json.loads((run / "report.json").read_text())
    group = {n: g for g, members in enumerate(report["groups"]) for n in members}
    meshes, _ = load_fragments([puzzle / "fragments" / f"{n}.ply" for n in keep])
    rows = []
    # the labels the matching used (a newer run's fracture_k are those after the assembly)
    key = "segmented" if "segmented_0" in analysis.files else "fracture"
    labels = {n: analysis[f"{key}_{k}"] for k, n in enumerate(names)}
    breaks = _true_breaks(files, T_world)
    for n in keep:
        s = segmentation_f1({n: meshes[n]}, {n: labels[n]}, files)
        rows.append({"fragment": n, "group": group.get(n), **s})
    pairs = {tuple(sorted((p["source"], p["target"]))): p
             for p in json.loads((run / "pairs.json").read_text())["pairs"]}
    contacts = []
    for c in sorted(gt["contacts"], key=lambda c: -c["area"]):
        a, b = sorted(c["fragments"])
        if not set(keep) & {a, b}:
            continue
        p = pairs.get((a, b))
        row = {"pair": f"{a} {b}", "area": c["area"], "registered": p is not None, "rank": None, "score": None,
               "best": None, "recall": [side_recall(breaks, labels, diagonal, x, y) for x, y in ((a, b), (b, a))]}
        if p is not None and p["candidates"]:
            T = np.linalg.inv(T_world[p["target"]]) @ T_world[p["source"]]
            centre = files.meshes[p["source"]].vertices.mean(axis=0)
            row["rank"], row["score"] = true_rank(p["candidates"], T, centre, diagonal)
            row["best"] = float(p["candidates"][0]["score"])
        contacts.append(row)
    return {"puzzle": puzzle.name, "fragments": rows, "contacts": contacts}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("puzzle", type=Path)
    parser.add_argument("run", type=Path)
    parser.add_argument("--fragments", default=None, help="comma-separated fragment names")
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    r = study(args.puzzle, args.run, fragments=args.fragments.split(",") if args.fragments else None)
    frag_rows = [[f["fragment"], f["group"], f["precision"], f["recall"], f["f1"]] for f in r["fragments"]]
    pair_rows = [[c["pair"], c["area"], " / ".join("-" if x is None else f"{x:.2f}" for x in c["recall"]),
                  "yes" if c["registered"] else "no", "-" if c["rank"] is None else c["rank"],
                  "-" if c["score"] is None else f"{c['score']:.3f}", "-" if c["best"] is None else f"{c['best']:.3f}"]
                 for c in r["contacts"]]
    for row in frag_rows:
        print(f"{row[0]}: sub-assembly {row[1]}, fracture labels P {row[2]:.2f} R {row[3]:.2f} F1 {row[4]:.2f}")
    for row in pair_rows:
        print(f"{row[0]}: contact {row[1]:.4f}, recall on each side {row[2]}, registered {row[3]}, "
              f"true placement ranks {row[4]} (score {row[5]}), best {row[6]}")
    bench.write(args.json, figures=r, tables=[
        table(f"{r['puzzle']}: the run's fracture labels per fragment", ["fragment", "sub-assembly", "precision",
                                                                          "recall", "F1"], frag_rows,
              ["", "d", ".2f", ".2f", ".2f"]),
        table(f"{r['puzzle']}: true contacts, largest first; where the true placement ranks among the pair's "
              "candidates; recall of each side's labels on the contact", ["pair", "contact area", "recall a / b",
                                                                          "registered", "true rank", "its score",
                                                                          "best score"], pair_rows,
              ["", ".4f", "", "", "", "", ""])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
