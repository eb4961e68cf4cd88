"""Could each fragment retrieve its mates from one index over the set? Recall of retrieval cues.

    reassemble break spot --pieces 50 --style cells --seed 0 --out /tmp/spot50
    python -m benchmarks.studies.retrieval_cues /tmp/spot50

Issue 23 asks for candidate pairs in sub-quadratic time: every fragment summarized by what
a mate shares, one k-d tree over the whole set, each fragment registered only against the
partners it retrieves. The target: recall >= 0.98 of the touching pairs (true contact >= 5 %
of the smaller fragment's break, the break being the sum of its true contacts) while
registering <= 15 % of all pairs. Here each cue ranks every fragment's partners; keeping
each fragment's best ``k`` (a pair is kept when either side ranks the other), the share of
pairs kept and the recall of touching pairs are reported for k = 3 ... 12.

Cues:
- ``signatures``: :func:`reassemble.retrieval.partner_votes` (what ``run`` registers
  first on large sets): every fracture keypoint's mate signature (H flipped) queries its 8
  nearest keypoints of other fragments in one tree; a pair's votes over those expected by
  chance (the fragments' keypoint counts), both ways added;
- ``facets``: the fracture faces (the run's labels) cut into facets at creases (dihedral
  over 20 degrees, shards merged) and each facet described by log area and the log square
  roots of its three second moments (the same region on both mates has the same); a pair
  scores its best facet match among each facet's 10 nearest in the set;
- ``facets, true labels``: the same on the generator's exact fracture labels;
- ``true contact regions``: the oracle, each fragment's fracture faces split by the
  neighbour they touch at the true poses, with the same descriptor: the ceiling of any
  region-shape descriptor this coarse;
- ``planar outlines``: planar break faces (:func:`reassemble.planes.planar_patches` on the
  run's fracture samples) compared by outline, as the planar-mates labelling compares them
  (each face with its 16 nearest in area and spreads, laid together at the best in-plane
  turn and shift); a pair scores its best overlap.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.common import add_json_option, start, table

KS = (3, 4, 5, 6, 7, 8, 10, 12)


def truth_share(gt: dict, names: list[str]) -> np.ndarray:
    """(n, n) true contact area over the smaller fragment's break (the sum of its contacts)."""
    idx = {nm: k for k, nm in enumerate(names)}
    C = np.zeros((len(names), len(names)))
    for c in gt["contacts"]:
        a, b = (idx[x] for x in c["fragments"])
        C[a, b] = C[b, a] = c["area"]
    B = C.sum(axis=1)
    return C / np.maximum(np.minimum.outer(B, B), 1e-300)


def recall(S: np.ndarray, share: np.ndarray) -> list[tuple[int, float, float]]:
    """[(k, share of pairs kept, recall of touching pairs)] keeping each fragment's best k partners."""
    n = len(S)
    touching = share >= 0.05
    np.fill_diagonal(touching, False)
    S = S.astype(float).copy()
    np.fill_diagonal(S, -np.inf)
    order = np.argsort(-S, axis=1, kind="stable")
    out = []
    for k in (k for k in KS if k < n):
        keep = np.zeros((n, n), bool)
        keep[np.repeat(np.arange(n), k), order[:, :k].ravel()] = True
        keep |= keep.T
        np.fill_diagonal(keep, False)
        out.append((k, keep.sum() / (n * (n - 1)), (keep & touching).sum() / max(touching.sum(), 1)))
    return out


def region_descriptor(centres: np.ndarray, area: np.ndarray) -> np.ndarray:
    """(4,) log area and the log square roots of the area-weighted second moments, largest first."""
    A = area.sum()
    w = area / A
    X = centres - w @ centres
    ev = np.sort(np.linalg.eigvalsh((X * w[:, None]).T @ X))[::-1]
    return np.array([np.log(A), *(0.5 * np.log(np.maximum(ev, 1e-30)))])


def facets(vertices, faces, fracture, *, crease: float = 20.0, min_share: float = 0.02) -> list[np.ndarray]:
    """Descriptors of the fracture faces' crease-bounded facets (at least ``min_share`` of the fracture)."""
    from reassemble.geometry import connected_components, face_adjacency, face_areas, face_normals
    from reassemble.segmentation import merge_small_patches

    normals = face_normals(vertices, faces)
    pairs, _ = face_adjacency(faces)
    dihedral = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]), -1, 1)))
    both = fracture[pairs[:, 0]] & fracture[pairs[:, 1]]
    _, comp = connected_components(len(faces), pairs[both & (dihedral < crease)])
    area = face_areas(vertices, faces)
    comp = merge_small_patches(comp, pairs[both], dihedral[both], area, min_area=0.005 * area[fracture].sum(),
                               max_angle=60.0)
    centres = vertices[faces].mean(axis=1)
    out = []
    for k in np.unique(comp[fracture]):
        m = (comp == k) & fracture
        if area[m].sum() >= min_share * area[fracture].sum():
            out.append(region_descriptor(centres[m], area[m]))
    return out


def contact_regions(frags, gt: dict, *, size: float) -> list[list[np.ndarray]]:
    """Per fragment, the descriptors of its fracture faces grouped by the neighbour they touch at the true poses."""
    from scipy.spatial import cKDTree

    from reassemble.geometry import face_areas, transform_points

    world = [transform_points(np.array(gt["fragments"][f.name]["transform"]), f.vertices[f.faces].mean(axis=1))
             for f in frags]
    owner = np.concatenate([np.full(len(w), i) for i, w in enumerate(world)])
    tree = cKDTree(np.vstack(world))
    out = []
    for i, f in enumerate(frags):
        dist, idx = tree.query(world[i], k=8)
        other = np.where((owner[idx] != i) & (dist < 0.01 * size), owner[idx], -1)
        first = np.argmax(other >= 0, axis=1)
        nb = other[np.arange(len(other)), first]
        area, centres = face_areas(f.vertices, f.faces), f.vertices[f.faces].mean(axis=1)
        out.append([region_descriptor(centres[nb == j], area[nb == j]) for j in np.unique(nb[nb >= 0])
                    if area[nb == j].sum() > 0.006 * area.sum()])
    return out


def region_cue(regions: list[list[np.ndarray]], *, neighbours: int = 10) -> np.ndarray:
    from scipy.spatial import cKDTree

    owner = np.concatenate([np.full(len(r), i) for i, r in enumerate(regions)])
    D = np.vstack([d for r in regions for d in r])
    dist, idx = cKDTree(D).query(D, k=min(neighbours + 1, len(D)))
    S = np.zeros((len(regions), len(regions)))
    for a in range(len(D)):
        for d, b in zip(dist[a], idx[a]):
            if owner[a] != owner[b]:
                S[owner[a], owner[b]] = max(S[owner[a], owner[b]], np.exp(-d * d / 0.1))
    return np.maximum(S, S.T)


def planar_outlines(surfaces, *, tol: float, plane_area: float, candidates: int = 16, seed: int = 0) -> np.ndarray:
    """(n, n) per fragment pair, the best outline overlap of a planar break face of one with a
    plane of the other among its ``candidates`` nearest in log area and spreads: the test of
    :func:`reassemble.mates.relabel_planar_mates` (``mates._outline_overlap``) as a retrieval cue."""
    from reassemble.mates import _nearest_similar, _outline_overlap, _Plane
    from reassemble.planes import planar_patches

    rng = np.random.default_rng(seed)
    planes = [_Plane(k, True, p) for k, s in enumerate(surfaces) if s.fracture_area > 0
              for p in planar_patches(s.samples, s.sample_normals, s.sample_area, tol=tol,
                                      min_area=plane_area * s.fracture_area, rng=rng)]
    S = np.zeros((len(surfaces), len(surfaces)))
    for i, near in _nearest_similar(planes, count=candidates):
        a = planes[i]
        for j in near:
            b = planes[j]
            spacing = np.sqrt(max(surfaces[a.fragment].sample_area, surfaces[b.fragment].sample_area))
            S[a.fragment, b.fragment] = max(S[a.fragment, b.fragment], _outline_overlap(a.patch, b.patch,
                                                                                          spacing=spacing))
    return np.maximum(S, S.T)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("puzzle", type=Path, help="a puzzle folder (ground_truth.json, labels.npz, fragments/)")
    parser.add_argument("--jobs", type=int, default=2)
    add_json_option(parser)
    args = parser.parse_args()
    bench = start()
    from reassemble.config import Config
    from reassemble.pipeline import prepare_fragments, read_puzzle, registration_params
    from reassemble.retrieval import partner_votes

    puzzle = read_puzzle(args.puzzle / "ground_truth.json", with_labels=True)
    gt = json.loads((args.puzzle / "ground_truth.json").read_text())
    t0 = time.perf_counter()
    frags, size = prepare_fragments({n: (m.vertices, m.faces) for n, m in puzzle.meshes.items()}, config=Config(),
                                    jobs=args.jobs)
    print(f"{len(frags)} fragments prepared in {time.perf_counter() - t0:.0f} s")
    share = truth_share(gt, [f.name for f in frags])
    labels = [np.asarray(puzzle.labels[f.name], bool) if len(puzzle.labels[f.name]) == len(f.faces)
              else f.segmentation.fracture for f in frags]
    cues = {
        "signatures": lambda: partner_votes([f.surface for f in frags]),
        "facets": lambda: region_cue([facets(*f.mesh, f.segmentation.fracture) for f in frags]),
        "facets, true labels": lambda: region_cue([facets(*f.mesh, lab) for f, lab in zip(frags, labels)]),
        "true contact regions": lambda: region_cue(contact_regions(frags, gt, size=size)),
        "planar outlines": lambda: planar_outlines([f.surface for f in frags], tol=reg.tolerance * size,
                                                   plane_area=reg.plane_area),
    }
    reg = registration_params(frags, size=size, params=Config().registration)
    rows, figures = [], {"fragments": len(frags), "touching_pairs": int((share >= 0.05).sum() // 2), "cues": {}}
    print(f"touching pairs: {figures['touching_pairs']} of {len(frags) * (len(frags) - 1) // 2}")
    for name, fn in cues.items():
        t = time.perf_counter()
        curve = recall(fn(), share)
        figures["cues"][name] = {"seconds": time.perf_counter() - t, "curve": curve}
        print(f"{name:22s} " + "  ".join(f"k{k}: {kept:.2f}/{rec:.2f}" for k, kept, rec in curve), flush=True)
        rows += [[name, k, kept, rec] for k, kept, rec in curve]
    bench.write(args.json, figures=figures,
                tables=[table(f"{args.puzzle.name}: each fragment's best k partners kept; share of all pairs kept, "
                              "recall of touching pairs (contact >= 5 % of the smaller break)",
                              ["cue", "k", "pairs kept", "recall"], rows, ["", "d", ".3f", ".3f"])])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
