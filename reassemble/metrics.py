"""Scoring a reassembly against ground truth, in the Breaking Bad benchmark's terms and stricter ones.

The Breaking Bad figures follow the benchmark's reference code (multi_part_assembly,
``utils/eval_utils.py``): per fragment, 1000 points sampled on its surface are placed
by the predicted and by the true pose, on the object normalized to a unit bounding
box (longest side 1). A fragment counts as correct when the sum of the two mean
*squared* nearest-neighbour distances between the two placements is below 0.01.
Rotation errors compare Euler angles (intrinsic 'zyx' from the quaternion, wrapped
at 180 degrees) as the reference code does; translations are those of the
fragment's point centroid. See ``docs/method/metrics.md`` for every definition.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from .geometry import (
    face_areas,
    invert_transform,
    rotation_angle_deg,
    sample_surface,
    transform_points,
)

BB_THRESHOLD = 0.01  # Breaking Bad part accuracy: mean squared chamfer sum, unit-box object
STRICT_THRESHOLD = 0.01  # strict part accuracy: mean chamfer, fraction of the bbox diagonal
N_POINTS = 1000  # points per fragment, as the benchmark samples

ALIGNMENTS = ("as_given", "anchor_largest", "best_anchor")


@dataclass(frozen=True)
class ScoringFragment:
    """What scoring needs of one fragment: its surface in its own coordinates and true pose."""

    name: str
    vertices: np.ndarray  # (n, 3)
    faces: np.ndarray  # (m, 3)
    T_world_fragment: np.ndarray  # (4, 4) ground truth


def chamfer_sq(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared nearest-neighbour distances both ways: (len(a),) from a to b and (len(b),) from b to a."""
    d_ab, _ = cKDTree(b).query(a)
    d_ba, _ = cKDTree(a).query(b)
    return d_ab**2, d_ba**2


def euler_zyx_deg(R: np.ndarray) -> np.ndarray:
    """Euler angles (x, y, z) in degrees exactly as the reference code's ``qeuler(q, 'zyx')``.

    Parameters
    ----------
    R : (..., 3, 3) rotation matrices

    Returns
    -------
    (..., 3) angles in degrees
    """
    shape = R.shape[:-2]
    xyzw = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()
    q0, q1, q2, q3 = xyzw[:, 3], xyzw[:, 0], xyzw[:, 1], xyzw[:, 2]
    x = np.arctan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
    y = np.arcsin(np.clip(2 * (q0 * q2 - q1 * q3), -1.0, 1.0))
    z = np.arctan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
    return np.degrees(np.stack([x, y, z], axis=-1)).reshape(*shape, 3)


def _score(
    points: list[np.ndarray],
    T_gt: np.ndarray,
    T_pred: np.ndarray,
    placed: np.ndarray,
    *,
    scale: float,
    diag: float,
) -> tuple[dict, list[dict]]:
    """All metrics for one set of predicted poses. Points and poses in object units."""
    per_fragment = []
    world_gt, world_pred, dts = [], [], []
    for k, p in enumerate(points):
        gt = transform_points(T_gt[k], p)
        pred = transform_points(T_pred[k], p)
        world_gt.append(gt)
        world_pred.append(pred)
        d1, d2 = chamfer_sq(pred, gt)
        bb_loss = float((d1.mean() + d2.mean()) * scale**2)
        mean_dist = float(0.5 * (np.sqrt(d1).mean() + np.sqrt(d2).mean()))
        c = p.mean(axis=0)
        dt = (T_pred[k][:3, :3] @ c + T_pred[k][:3, 3] - T_gt[k][:3, :3] @ c - T_gt[k][:3, 3]) * scale
        dts.append(dt)
        per_fragment.append(
            {
                "placed": bool(placed[k]),
                "correct": bool(placed[k] and bb_loss < BB_THRESHOLD),
                "correct_strict": bool(placed[k] and mean_dist < STRICT_THRESHOLD * diag),
                "chamfer_sq_normalized": bb_loss,
                "chamfer_mean_over_diag": mean_dist / diag,
                "translation_error_normalized": float(np.linalg.norm(dt)),
            }
        )
    R_gt, R_pred = T_gt[:, :3, :3], T_pred[:, :3, :3]
    diff = np.abs(euler_zyx_deg(R_pred) - euler_zyx_deg(R_gt))
    diff = np.minimum(diff, 360.0 - diff)
    geo = rotation_angle_deg(R_gt, R_pred)
    dt = np.array(dts)
    for f, g in zip(per_fragment, geo):
        f["rotation_error_deg"] = float(g)
    d1, d2 = chamfer_sq(np.vstack(world_pred), np.vstack(world_gt))
    correct = np.array([f["correct"] for f in per_fragment])
    strict = np.array([f["correct_strict"] for f in per_fragment])
    summary = {
        "part_acc": float(correct.mean()),
        "part_acc_strict": float(strict.mean()),
        "solved": bool(strict.all()),
        "rot_rmse_euler_deg": float(np.sqrt((diff**2).mean(axis=1)).mean()),
        "rot_mae_euler_deg": float(diff.mean(axis=1).mean()),
        "rot_geodesic_mean_deg": float(geo.mean()),
        "rot_geodesic_rmse_deg": float(np.sqrt((geo**2).mean())),
        "trans_rmse": float(np.sqrt((dt**2).mean(axis=1)).mean()),
        "trans_mae": float(np.abs(dt).mean(axis=1).mean()),
        "shape_cd": float((d1.mean() + d2.mean()) * scale**2),
    }
    return summary, per_fragment


def evaluate(
    fragments: list[ScoringFragment],
    predicted: dict[str, dict],
    *,
    bbox_min: np.ndarray,
    bbox_max: np.ndarray,
    n_points: int = N_POINTS,
    seed: int = 0,
) -> dict:
    """Score predicted poses against the truth.

    Parameters
    ----------
    fragments : the puzzle's fragments with their true ``T_world_fragment``
    predicted : file stem -> ``{"transform": (4, 4), "placed": bool}``; a fragment missing
        here, or with ``placed`` false, counts as wrong (its errors use the transform it
        carries, the identity when it has none)
    bbox_min, bbox_max : (3,) the assembled object's bounding box, for normalization
    n_points : surface points per fragment
    seed : for the surface samples (the score is deterministic for a seed)

    Returns
    -------
    dict
        ``alignments``: for each of ``as_given``, ``anchor_largest`` (the prediction moved so
        the largest placed fragment sits exactly at its true pose) and ``best_anchor`` (the
        same with the anchor that scores best), a summary of all metrics and per-fragment
        figures.
    """
    rng = np.random.default_rng(seed)
    extent = np.asarray(bbox_max, float) - np.asarray(bbox_min, float)
    scale = 1.0 / float(extent.max())
    diag = float(np.linalg.norm(extent))
    names = [f.name for f in fragments]
    points = [sample_surface(f.vertices, f.faces, n_points, rng=rng)[0] for f in fragments]
    areas = np.array([face_areas(f.vertices, f.faces).sum() for f in fragments])
    T_gt = np.array([f.T_world_fragment for f in fragments])
    T_raw = np.array([np.asarray(predicted.get(n, {}).get("transform", np.eye(4)), float) for n in names])
    placed = np.array([bool(n in predicted and predicted[n].get("placed", True)) for n in names])

    def aligned(anchor: int) -> np.ndarray:
        T_align = T_gt[anchor] @ invert_transform(T_raw[anchor])
        return T_align[None] @ T_raw

    results = {}
    summary, per = _score(points, T_gt, T_raw, placed, scale=scale, diag=diag)
    results["as_given"] = {"summary": summary, "fragments": dict(zip(names, per))}
    candidates = np.flatnonzero(placed)
    if len(candidates) == 0:
        for mode in ("anchor_largest", "best_anchor"):
            results[mode] = dict(results["as_given"], anchor=None)
    else:
        largest = int(candidates[np.argmax(areas[candidates])])
        summary, per = _score(points, T_gt, aligned(largest), placed, scale=scale, diag=diag)
        results["anchor_largest"] = {"anchor": names[largest], "summary": summary,
                                     "fragments": dict(zip(names, per))}
        best = None
        for a in candidates:
            s, p = (summary, per) if a == largest else _score(
                points, T_gt, aligned(int(a)), placed, scale=scale, diag=diag
            )
            key = (s["part_acc_strict"], s["part_acc"], -s["shape_cd"])
            if best is None or key > best[0]:
                best = (key, int(a), s, p)
        _, a, s, p = best
        results["best_anchor"] = {"anchor": names[a], "summary": s, "fragments": dict(zip(names, p))}
    return {
        "n_fragments": len(fragments),
        "n_placed": int(placed.sum()),
        "missing": sorted(set(names) - set(predicted)),
        "unknown": sorted(set(predicted) - set(names)),
        "normalization": {"scale": scale, "bbox_diagonal": diag},
        "n_points": n_points,
        "alignments": results,
    }
