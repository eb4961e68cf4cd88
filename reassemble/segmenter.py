"""The learned fracture evidence: per-patch features and the tree ensemble that scores them.

The mixture of :mod:`segmentation` takes "rougher than the rest of the set" as fracture,
which inverts on smooth and planar breaks (cell fracture, clean breaks in glass or stone)
and on originals with fine detail (statues). The classifier here is trained offline on
generated puzzles of every break style (``python -m data_synth.train_segmenter``, the
field-tuning half only) on features that say more than roughness alone: the integral
invariants at every radius, the patch's fit residuals, its rim (how much of its boundary
is a sharp crease), whether it lies on the fragment's convex hull, the size of the smooth
sheet it belongs to, each also relative to the fragment and the set. Every feature is
free of units. Why, and what it was measured against: ``docs/method/segmentation.md``.

The model ships as ``reassemble/data/segmenter.npz``: the arrays of its trees, evaluated
here with numpy (no pickle, no dependence on the scikit-learn version that trained it).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MODEL_PATH = Path(__file__).resolve().parent / "data" / "segmenter.npz"
MODEL_FORMAT = "reassemble-segmenter/1"

# per radius, area-weighted over the patch (h = H r, k = |k1 - k2| r, nd = angle between the
# face normal and the normal of ball ∩ solid, v = V / ball volume)
_RADIUS_FEATURES = ("h_mean", "h_std", "k_mean", "k_std", "lognd_mean", "v_std")
_PATCH_FEATURES = ("log_quadric", "log_plane", "too_small", "log_area_share", "log_boundary", "crease_share",
                   "rim_dihedral", "hull_share", "log_sheet_share", "mixture_probability", "mixture_score")
N_RADII = 3


def _names() -> tuple[str, ...]:
    base = tuple(f"{f}_r{i}" for i in range(N_RADII) for f in _RADIUS_FEATURES) + _PATCH_FEATURES[:-2]
    return (base + tuple(f"z_{n}" for n in base) + tuple(f"rel_{n}" for n in base)
            + tuple(f"nb_{n}" for n in base) + _PATCH_FEATURES[-2:])


FEATURE_NAMES = _names()


def _patch_mean_std(patch: np.ndarray, w: np.ndarray, x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted mean and standard deviation of the face values ``x`` over each patch."""
    total = np.maximum(np.bincount(patch, w, n), 1e-300)
    mean = np.bincount(patch, w * x, n) / total
    var = np.bincount(patch, w * x * x, n) / total - mean * mean
    return mean, np.sqrt(np.maximum(var, 0.0))


def hull_distance(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n,) distance of each point inside the convex hull of ``vertices`` to the hull."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError):
        return np.zeros(len(points))
    eq = hull.equations  # outward normal, offset: n·x + d <= 0 inside
    out = np.full(len(points), -np.inf)
    for start in range(0, len(eq), 256):
        e = eq[start:start + 256]
        out = np.maximum(out, (points @ e[:, :3].T + e[:, 3]).max(axis=1))
    return np.maximum(-out, 0.0)


def fragment_features(
    vertices: np.ndarray, faces: np.ndarray, descriptors, *, patch: np.ndarray, pairs: np.ndarray,
    dihedral: np.ndarray, edge_length: np.ndarray, face_area: np.ndarray, patch_area: np.ndarray,
    log_quadric: np.ndarray, log_plane: np.ndarray, crease_angle: float,
) -> np.ndarray:
    """(patches, k) the per-patch features of one fragment that need no other fragment:
    the first block of :data:`FEATURE_NAMES` (``h_mean_r0`` .. ``log_sheet_share``)."""
    from .geometry import connected_components, face_normals

    n = len(patch_area)
    d = descriptors
    normals = face_normals(vertices, faces)
    cols = []
    for i in range(N_RADII):
        j = min(i, len(d.radii) - 1)
        r = float(d.radii[j])
        h = d.H_rob[:, j] * r
        k = np.sqrt(np.maximum(d.K2_cov[:, j], 0.0)) * r
        cos = np.abs(np.einsum("ij,ij->i", d.normal[:, j], normals))
        lognd = np.log(np.degrees(np.arccos(np.clip(cos, 0.0, 1.0))) + 1e-2)
        v = d.V[:, j] / (4.0 / 3.0 * np.pi * r**3)
        hm, hs = _patch_mean_std(patch, face_area, h, n)
        km, ks = _patch_mean_std(patch, face_area, k, n)
        ndm, _ = _patch_mean_std(patch, face_area, lognd, n)
        _, vs = _patch_mean_std(patch, face_area, v, n)
        cols += [hm, hs, km, ks, ndm, vs]
    total = float(face_area.sum())
    small = np.isnan(log_quadric)
    # exact quadrics (-inf) and patches too small to fit (NaN) as finite values the trees can split on
    quadric = np.where(np.isneginf(log_quadric), -14.0, np.where(small, 0.0, log_quadric))
    plane = np.where(np.isneginf(log_plane), -14.0, np.where(np.isnan(log_plane), 0.0, log_plane))
    pu, pv = patch[pairs[:, 0]], patch[pairs[:, 1]]
    cross = pu != pv
    length = np.bincount(np.r_[pu[cross], pv[cross]], np.r_[edge_length[cross], edge_length[cross]], n)
    crease = edge_length[cross] * (dihedral[cross] >= crease_angle)
    crease_len = np.bincount(np.r_[pu[cross], pv[cross]], np.r_[crease, crease], n)
    turn = edge_length[cross] * dihedral[cross]
    rim = np.bincount(np.r_[pu[cross], pv[cross]], np.r_[turn, turn], n)
    scale = np.sqrt(total)
    centres = vertices[faces].mean(axis=1)
    on_hull = (hull_distance(vertices, centres) < 0.01 * scale).astype(float)
    hull_share = np.bincount(patch, face_area * on_hull, n) / np.maximum(patch_area, 1e-300)
    # the smooth sheet: faces connected without crossing a crease, not capped in size
    _, sheet = connected_components(len(faces), pairs[dihedral < crease_angle])
    sheet_area = np.bincount(sheet, face_area)
    sheet_of_patch = np.zeros(n, np.int64)
    sheet_of_patch[patch] = sheet
    cols += [quadric, plane, small.astype(float), np.log(patch_area / total + 1e-9),
             np.log(length / np.sqrt(np.maximum(patch_area, 1e-300)) + 1e-3),
             crease_len / np.maximum(length, 1e-300), rim / np.maximum(length, 1e-300) / 90.0, hull_share,
             np.log(sheet_area[sheet_of_patch] / total + 1e-9)]
    return np.column_stack(cols)


def set_features(per_fragment: list[np.ndarray], patch_areas: list[np.ndarray], neighbours: list,
                 mixture_probability: list[np.ndarray], mixture_score: list[np.ndarray]) -> list[np.ndarray]:
    """The full feature rows (:data:`FEATURE_NAMES`) of every fragment of a set: each base
    feature as is, standardized over the set (area-weighted), relative to its fragment's
    area-weighted mean, and averaged over the patch's neighbours (by shared boundary
    length), then the mixture's probability and score.

    ``neighbours``: per fragment, (a, b, length) arrays of patch boundaries (both directions).
    """
    allx = np.concatenate(per_fragment)
    w = np.concatenate(patch_areas)
    w = w / max(w.sum(), 1e-300)
    mean = w @ allx
    std = np.sqrt(np.maximum(w @ (allx - mean) ** 2, 1e-24))
    out = []
    for x, a, (u, v, length), p, s in zip(per_fragment, patch_areas, neighbours, mixture_probability, mixture_score):
        fm = (a / max(a.sum(), 1e-300)) @ x
        n = len(x)
        wsum = np.bincount(u, length, n)
        nb = np.stack([np.bincount(u, length * x[v, j], n) for j in range(x.shape[1])], axis=1)
        nb = np.where(wsum[:, None] > 0, nb / np.maximum(wsum, 1e-300)[:, None], x)
        score = np.where(np.isfinite(s), s, -10.0)
        out.append(np.column_stack([x, (x - mean) / std, x - fm, nb, p, np.clip(score, -10.0, 10.0)]))
    return out


@dataclass(frozen=True)
class TreeEnsemble:
    """A boosted tree ensemble as plain arrays: ``sigmoid(init + sum of leaf values)``.

    Nodes of all trees are concatenated; ``left`` < 0 marks a leaf, and a row goes left
    where its feature is at most the node's threshold (as scikit-learn's histogram
    gradient boosting compares raw float64 inputs, so the scores match its own).
    """

    feature: np.ndarray  # (nodes,) int
    threshold: np.ndarray  # (nodes,) float64
    left: np.ndarray  # (nodes,) int, absolute node index, -1 at leaves
    right: np.ndarray
    value: np.ndarray  # (nodes,) float64, the leaf's value
    roots: np.ndarray  # (trees,) node index of each tree's root
    init: float
    meta: dict

    def decision(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        total = np.zeros(len(X))
        rows = np.arange(len(X))
        for root in self.roots:
            node = np.full(len(X), root, np.int64)
            while True:
                inner = self.left[node] >= 0
                if not inner.any():
                    break
                go_left = X[rows, self.feature[node]] <= self.threshold[node]
                node = np.where(inner, np.where(go_left, self.left[node], self.right[node]), node)
            total += self.value[node]
        return self.init + total

    def probability(self, X: np.ndarray) -> np.ndarray:
        """(n,) probability of fracture of each row of features."""
        return 1.0 / (1.0 + np.exp(-self.decision(X)))


def from_sklearn(model, meta: dict) -> TreeEnsemble:
    """The arrays of a fitted binary ``HistGradientBoostingClassifier`` (numeric features,
    no missing values)."""
    feature, threshold, left, right, value, roots = [], [], [], [], [], []
    offset = 0
    for (predictor,) in model._predictors:
        nodes = predictor.nodes
        roots.append(offset)
        leaf = nodes["is_leaf"].astype(bool)
        feature.append(np.where(leaf, 0, nodes["feature_idx"]))
        threshold.append(np.where(leaf, 0.0, nodes["num_threshold"]))
        left.append(np.where(leaf, -1, nodes["left"].astype(np.int64) + offset))
        right.append(np.where(leaf, -1, nodes["right"].astype(np.int64) + offset))
        value.append(np.where(leaf, nodes["value"], 0.0))
        offset += len(nodes)
    return TreeEnsemble(np.concatenate(feature).astype(np.int32), np.concatenate(threshold).astype(np.float64),
                        np.concatenate(left).astype(np.int32), np.concatenate(right).astype(np.int32),
                        np.concatenate(value).astype(np.float64), np.asarray(roots, np.int32),
                        float(np.ravel(model._baseline_prediction)[0]), meta)


def average(models: list[TreeEnsemble], meta: dict) -> TreeEnsemble:
    """One ensemble whose decision is the mean of the ``models``' decisions (log-odds).

    Notes
    -----
    Averaging models fitted on different training sets (bagging) keeps what each learned
    where the other has little data: trained on more pieces per object, a model labels the
    larger breaks of many-piece sets better and detailed originals worse
    (``docs/method/segmentation.md``).
    """
    k = len(models)
    offsets = np.cumsum([0] + [len(m.feature) for m in models[:-1]])
    return TreeEnsemble(
        np.concatenate([m.feature for m in models]), np.concatenate([m.threshold for m in models]),
        np.concatenate([np.where(m.left >= 0, m.left + o, -1) for m, o in zip(models, offsets)]).astype(np.int32),
        np.concatenate([np.where(m.right >= 0, m.right + o, -1) for m, o in zip(models, offsets)]).astype(np.int32),
        np.concatenate([m.value / k for m in models]), np.concatenate([m.roots + o for m, o in zip(models, offsets)]).astype(np.int32),
        float(sum(m.init for m in models) / k), meta)


def save(model: TreeEnsemble, path: Path = MODEL_PATH) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, feature=model.feature, threshold=model.threshold, left=model.left, right=model.right,
                            value=model.value, roots=model.roots, init=np.float64(model.init), meta=np.array(json.dumps(model.meta, sort_keys=True)))


def load(path: Path = MODEL_PATH) -> TreeEnsemble:
    """The ensemble in ``path``; raises ValueError when it is not one or its features differ."""
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        model = TreeEnsemble(z["feature"], z["threshold"], z["left"], z["right"], z["value"], z["roots"],
                             float(z["init"]), meta)
    if meta.get("format") != MODEL_FORMAT or tuple(meta.get("features", ())) != FEATURE_NAMES:
        raise ValueError(f"{path}: not a {MODEL_FORMAT} model over this version's features")
    return model


@functools.lru_cache(maxsize=1)
def shipped() -> TreeEnsemble:
    """The model shipped with the package."""
    return load(MODEL_PATH)
