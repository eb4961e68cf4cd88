"""Synthetic puzzles on disk: ``break_to_folder`` writes one, ``read_puzzle`` reads it back,
``evaluate_files`` scores a ``transforms.json`` against its ``ground_truth.json``."""

from __future__ import annotations

import dataclasses
import hashlib
import logging
from pathlib import Path

import numpy as np

from . import __version__
from .errors import ReassembleError
from .files import (
    TRANSFORMS_CONVENTION,
    file_in,
    load_mesh,
    load_solid,
    mesh_warning,
    read_json,
    read_transforms,
    resolve_mesh_path,
    staged_directory,
    write_json,
    write_npz,
    write_ply,
)
from .geometry import canonical_order, face_areas
from .metrics import ScoringFragment, evaluate
from .outputs import rounded
from .synth import break_mesh

log = logging.getLogger(__name__)

GROUND_TRUTH_FORMAT = "reassemble-ground-truth/1"


def break_to_folder(
    mesh: str | Path, out: str | Path, *, params, seed: int, force: bool = False, fill_holes: float | None = None
) -> Path:
    """Break ``mesh`` (a path or a bundled mesh name) and write the puzzle to ``out``;
    ``fill_holes`` as in :func:`files.load_mesh` (an open scan closed before breaking).

    Writes ``out/fragments/<name>.ply``, ``out/labels.npz`` (per-face int8, 1 = fracture,
    one array per fragment name) and ``out/ground_truth.json``. The folder appears only
    when complete.
    """
    path = resolve_mesh_path(mesh)
    params.check()
    data = load_solid(path, fill_holes=fill_holes)
    if mesh_warning(data):
        log.warning("%s", mesh_warning(data))
    try:
        puzzle = break_mesh(data.vertices, data.faces, params, rng=np.random.default_rng(seed))
    except ReassembleError as exc:
        raise ReassembleError(f"{path}: {exc}") from None

    with staged_directory(out, force=force) as tmp:
        fragments_json, labels = {}, {}
        for fr in puzzle.fragments:
            vertices, faces, order = canonical_order(fr.vertices, fr.faces)
            lab = fr.labels[order]
            write_ply(tmp / "fragments" / f"{fr.name}.ply", vertices, faces)
            labels[fr.name] = lab
            areas = face_areas(vertices, faces)
            fragments_json[fr.name] = {
                "transform": fr.T_world_fragment.tolist(),  # full precision: the truth is exact
                "placed": True,
                "confidence": 1.0,
                "file": f"fragments/{fr.name}.ply",
                "n_faces": int(len(faces)),
                "n_fracture_faces": int((lab == 1).sum()),
                "area": rounded(areas.sum()),
                "fracture_area": rounded(areas[lab == 1].sum()),
            }
        write_npz(tmp / "labels.npz", **labels)
        gt = {
            "format": GROUND_TRUTH_FORMAT,
            "convention": TRANSFORMS_CONVENTION,
            "generator": f"reassemble {__version__}",
            "source": {
                "mesh": path.name,
                "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            },
            "seed": seed,
            "parameters": params.to_dict(),
            "object": {
                "bbox_min": [rounded(x) for x in puzzle.bbox_min],
                "bbox_max": [rounded(x) for x in puzzle.bbox_max],
                "diagonal": rounded(float(np.linalg.norm(puzzle.bbox_max - puzzle.bbox_min))),
                "volume": rounded(puzzle.volume),
                "area": rounded(puzzle.area),
            },
            "labels": {"file": "labels.npz", "values": params.label_names()},
            "fragments": fragments_json,
            "contacts": [
                {"fragments": [c.a, c.b], "area": rounded(c.area)} for c in puzzle.contacts
            ],
        }
        write_json(tmp / "ground_truth.json", gt)
    log.info("wrote %d fragments to %s", len(puzzle.fragments), out)
    return Path(out)


@dataclasses.dataclass
class PuzzleFiles:
    """A puzzle read back from disk (see :func:`read_puzzle`)."""

    root: Path
    ground_truth: dict
    meshes: dict  # name -> MeshData
    labels: dict  # name -> (m,) int8


def read_puzzle(ground_truth: str | Path, *, with_labels: bool = True) -> PuzzleFiles:
    """Read a ``ground_truth.json`` (or the puzzle folder holding it) and the fragment meshes
    (and labels) beside it."""
    gt_path = file_in(ground_truth, "ground_truth.json")
    gt = read_json(gt_path, what="a ground_truth.json written by 'reassemble break'")
    if not isinstance(gt, dict) or not isinstance(gt.get("fragments"), dict) or "object" not in gt:
        raise ReassembleError(f"{gt_path}: not a ground_truth.json (no 'fragments' and 'object')")
    root = gt_path.parent
    meshes = {}
    for name, entry in gt["fragments"].items():
        mesh_file = root / entry.get("file", f"fragments/{name}.ply")
        meshes[name] = load_mesh(mesh_file, require_closed=False, weld=False)
    labels = {}
    if with_labels and "labels" in gt:
        labels_path = root / gt["labels"]["file"]
        if not labels_path.is_file():
            raise ReassembleError(f"{labels_path}: no such file (named in {gt_path})")
        with np.load(labels_path) as z:
            labels = {k: z[k] for k in z.files}
    return PuzzleFiles(root, gt, meshes, labels)


def evaluate_files(
    predicted: str | Path, ground_truth: str | Path, *, n_points: int = 1000, seed: int = 0
) -> dict:
    """Score ``predicted`` (a transforms.json, or the run's folder) against a puzzle's
    ``ground_truth.json`` (or the puzzle's folder)."""
    predicted, ground_truth = file_in(predicted, "transforms.json"), file_in(ground_truth, "ground_truth.json")
    pred = read_transforms(predicted)
    puzzle = read_puzzle(ground_truth, with_labels=False)  # first: its errors name a ground truth
    truth = read_transforms(ground_truth)
    fragments = [
        ScoringFragment(name, m.vertices, m.faces, truth[name]["transform"])
        for name, m in sorted(puzzle.meshes.items())
    ]
    obj = puzzle.ground_truth["object"]
    report = evaluate(
        fragments, pred, bbox_min=np.array(obj["bbox_min"]), bbox_max=np.array(obj["bbox_max"]),
        n_points=n_points, seed=seed,
    )
    report["predicted"] = str(predicted)
    report["ground_truth"] = str(ground_truth)
    return report

