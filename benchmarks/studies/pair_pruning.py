"""Could a cheap test skip pairs before the full match? Recall of candidate pair priors.

    python -m benchmarks.studies.pair_pruning puzzles/bench                     # 20 pieces, seed 0, clean + noisy
    python -m benchmarks.studies.pair_pruning puzzles/bench --meshes torus,spot --full --jobs 2

Every pair of a puzzle's fragments gets a prior score, cheaply, from what exists after the
descriptors; a pruning would fully match only the pairs with the highest priors. Per prior
and puzzle: the time per pair, the ROC AUC of touching pairs (contact >= 5 % of the smaller
surface) against pairs that do not touch, and the share of touching pairs (>= 5 %, and any
contact) kept when only the best half or the best two thirds of the pairs are kept.

Priors:
- ``sig``: signature complementarity, the fracture area of either fragment whose mate
  signature (H flipped) lies within the set's 10th-percentile nearest-neighbour distance of
  the other's signatures (the smaller of the two ways);
- ``ppf``: how many pairs of signature correspondences agree as point-pair features (the
  distance, normal and chord-angle checks of the RANSAC, before any fit);
- ``full`` (with --full; slow, ~1.5 s a pair): the best score of the full registration, the
  reference a cheap prior would have to match.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.common import add_selection, select, start, table


def truth_share(gt: dict, frags) -> np.ndarray:
    """(n, n) true contact area over the smaller fragment's surface area."""
    contact = {tuple(sorted(c["fragments"])): float(c["area"]) for c in gt["contacts"]}
    n = len(frags)
    share = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if i != j:
                key = tuple(sorted((frags[i].name, frags[j].name)))
                share[i, j] = contact.get(key, 0.0) / min(frags[i].surface.area, frags[j].surface.area)
    return share


def sig_prior(frags) -> np.ndarray:
    from scipy.spatial import cKDTree

    from reassemble.features import mate_signature

    n = len(frags)
    dist = {}
    for i in range(n):
        for j in range(n):
            if i != j and len(frags[i].surface.keypoints) and len(frags[j].surface.keypoints):
                dist[i, j] = cKDTree(frags[j].surface.signature).query(mate_signature(frags[i].surface.signature))[0]
    S = np.zeros((n, n))
    if dist:
        delta = np.quantile(np.concatenate(list(dist.values())), 0.1)
        for (i, j), d in dist.items():
            S[i, j] = np.mean(d < delta) * frags[i].surface.fracture_area
    return np.minimum(S, S.T)


def ppf_prior(frags, *, size: float, params) -> np.ndarray:
    from reassemble.registration import correspondences, pair_candidates, point_pairs_agree

    n = len(frags)
    S = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            s, t = frags[i].surface, frags[j].surface
            if len(s.keypoints) < 3 or len(t.keypoints) < 3:
                continue
            pairs = correspondences(s, t, neighbours=params.neighbours)
            pick = pair_candidates(s, t, pairs, radius=params.pair_radius * size)
            if len(pick) == 0:
                continue
            ok, _ = point_pairs_agree(s.keypoints[pairs[pick, 0]], t.keypoints[pairs[pick, 1]],
                                      s.keypoint_normals[pairs[pick, 0]], -t.keypoint_normals[pairs[pick, 1]],
                                      tol=params.ransac_tolerance * size, normal_angle=params.normal_angle)
            S[i, j] = S[j, i] = ok.sum()
    return S


def full_prior(frags, *, size: float, params, jobs: int) -> np.ndarray:
    from reassemble.pipeline import match_pairs

    n = len(frags)
    S = np.full((n, n), -1.0)
    for (i, j), res in match_pairs(frags, size=size, params=params, jobs=jobs).items():
        S[i, j] = S[j, i] = res.best.score if res.best is not None else -1.0
    return S


def measure(S: np.ndarray, share: np.ndarray) -> dict:
    """ROC AUC of touching against apart pairs, and the shares kept by the best half / two thirds."""
    from sklearn.metrics import roc_auc_score

    iu = np.triu_indices(len(S), 1)
    x, sh = S[iu], share[iu]
    touch, apart = sh >= 0.05, sh == 0
    auc = roc_auc_score(touch[touch | apart], x[touch | apart]) if touch.any() and apart.any() else float("nan")
    out = {"auc": float(auc)}
    for label, keep in (("half", 0.5), ("two_thirds", 2 / 3)):
        kept = x >= np.quantile(x, 1 - keep)
        out[f"{label}_touching"] = float(kept[touch].mean())
        out[f"{label}_any_contact"] = float(kept[sh > 0].mean())
    return out


def say(m: dict) -> str:
    return (f"AUC {m['auc']:.3f} | best 0.50: {m['half_touching']:.2f} / {m['half_any_contact']:.2f}"
            f" | best 0.67: {m['two_thirds_touching']:.2f} / {m['two_thirds_any_contact']:.2f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_selection(parser, pieces="20")
    parser.add_argument("--full", action="store_true", help="also the full registration's best score (slow)")
    args = parser.parse_args()
    run = start()
    from reassemble.pipeline import prepare_fragments, read_puzzle, registration_params

    specs = select(args)
    print("kept shares: touching pairs (contact >= 5 %) / pairs with any contact")
    rows = []
    for spec in specs:
        puzzle = read_puzzle(args.root / spec.name / "ground_truth.json", with_labels=False)
        frags, size = prepare_fragments({n: (m.vertices, m.faces) for n, m in puzzle.meshes.items()}, seed=args.seed,
                                        jobs=args.jobs)
        share = truth_share(puzzle.ground_truth, frags)
        params = registration_params(frags, size=size)
        n_pairs = len(frags) * (len(frags) - 1) // 2
        priors = {"sig": lambda: sig_prior(frags), "ppf": lambda: ppf_prior(frags, size=size, params=params)}
        if args.full:
            priors["full"] = lambda: full_prior(frags, size=size, params=params, jobs=args.jobs)
        for name, fn in priors.items():
            t = time.perf_counter()
            S = fn()
            dt = (time.perf_counter() - t) / n_pairs
            m = measure(S, share)
            rows.append({"puzzle": spec.name, "prior": name, "seconds_per_pair": dt, **m})
            print(f"{spec.name:<34s} {name:>4s} {dt:6.3f} s/pair  {say(m)}", flush=True)
    run.write(args.json, figures={"puzzles": rows},
              tables=[table("Pair priors: ROC AUC of touching (contact >= 5 %) against apart pairs, and the share of "
                            "touching pairs kept by the best half / two thirds of the pairs",
                            ["puzzle", "prior", "s / pair", "AUC", "kept, best half", "kept, best two thirds"],
                            [[x["puzzle"], x["prior"], x["seconds_per_pair"], x["auc"], x["half_touching"],
                              x["two_thirds_touching"]] for x in rows], ["", "", ".3f", ".3f", ".2f", ".2f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
