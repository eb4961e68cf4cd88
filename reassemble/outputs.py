"""Output formats: what ``run`` and ``match`` write into their folder.

Every folder is built aside and moved into place only when complete
(:func:`files.staged_directory`); in a run folder ``transforms.json`` is written last, so
its presence means the run completed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import __version__
from .config import CONFIG_FORMAT, to_dict
from .files import TRANSFORMS_CONVENTION, staged_directory, write_glb, write_json, write_npz, write_ply
from .geometry import transform_points
from .prepare import PreparedFragment, set_noise, thin_walled
from .viz.colors import FRACTURE_RGB, ORIGINAL_RGB, fragment_colors

TRANSFORMS_FORMAT = "reassemble-transforms/1"
PAIRS_FORMAT = "reassemble-pairs/1"
REPORT_FORMAT = "reassemble-report/1"


def rounded(x: float) -> float:
    """``x`` to 12 significant digits: JSON figures that do not change with the last bits."""
    return float(f"{x:.12g}")


def fragment_entry(f: PreparedFragment) -> dict:
    """A fragment's line in ``fragments.json`` and ``report.json``: its fracture surface and notes."""
    return {
        "faces": len(f.faces), "area": f.surface.area, "fracture_area": f.surface.fracture_area,
        "fracture_share": f.surface.fracture_area / f.surface.area,
        "fracture_regions": int(f.segmentation.region.max()) + 1, "keypoints": len(f.surface.keypoints),
        "smoothing_iterations": f.smoothing, "notes": [f.note] if f.note else [],
    }


def pairs_json(frags: list[PreparedFragment], results: dict) -> list[dict]:
    """The ``pairs`` of ``pairs.json``: each pair's verdict and ranked candidates."""
    return [
        {
            "source": frags[i].name, "target": frags[j].name, "touching": res.touching,
            "candidates": [
                {"T_target_source": c.T_target_source.tolist(), "score": c.score, "contact_area": c.contact_area,
                 "penetration_area": c.penetration_area, "inliers": c.inliers}
                for c in res.candidates
            ],
        }
        for (i, j), res in sorted(results.items())
    ]


def _pairs_file(frags: list[PreparedFragment], results: dict) -> dict:
    return {"format": PAIRS_FORMAT, "convention": "T_target_source", "version": __version__,
            "pairs": pairs_json(frags, results)}


def write_debug(tmp: Path, frags: list[PreparedFragment], results: dict) -> None:
    """``labels/NAME.ply`` (fracture faces' vertices red) and ``matches/SOURCE__TARGET.npz``."""
    (tmp / "labels").mkdir()
    (tmp / "matches").mkdir()
    for f in frags:
        colors = np.tile(ORIGINAL_RGB, (len(f.vertices), 1))
        colors[np.unique(f.faces[f.segmentation.fracture])] = FRACTURE_RGB
        write_ply(tmp / "labels" / f"{f.name}.ply", f.vertices, f.faces, colors=colors)
    for (i, j), res in results.items():
        if res.best is None:
            continue
        write_npz(tmp / "matches" / f"{frags[i].name}__{frags[j].name}.npz",
                  source_points=frags[i].surface.keypoints[res.matches[:, 0]],
                  target_points=frags[j].surface.keypoints[res.matches[:, 1]],
                  T_target_source=res.best.T_target_source)


def config_json(result) -> dict:
    """``config.json``: the run's Config, resolved from the data (:func:`config.read_config`
    reads it back), and the reference size and vertex noise it was resolved from."""
    size = result.size
    return {"format": CONFIG_FORMAT, **to_dict(result.config), "reference_size": size,
            "vertex_noise": set_noise(result.fragments) / size,
            "note": "lengths are fractions of reference_size (the median fragment bounding-box diagonal), "
                    "as vertex_noise; registration.tolerance is at least registration.noise_tolerance x "
                    "sqrt(2) x vertex_noise"}


def write_match_folder(out, result, *, warnings: list[str], force: bool, debug: bool) -> None:
    """``pairs.json``, ``fragments.json``, ``config.json`` (+ debug files) of :func:`pipeline.match_to_folder`."""
    frags = result.fragments
    with staged_directory(out, force=force) as tmp:
        write_json(tmp / "pairs.json", _pairs_file(frags, result.pairs))
        write_json(tmp / "fragments.json", {"fragments": {f.name: fragment_entry(f) for f in frags},
                                            "warnings": warnings})
        write_json(tmp / "config.json", config_json(result))
        if debug:
            write_debug(tmp, frags, result.pairs)


def analysis_arrays(frags: list[PreparedFragment], contacts, touching, *, size: float, radii,
                    fracture: list[np.ndarray] | None = None) -> dict:
    """Arrays of ``analysis.npz``: ``names`` (n,), ``radii`` (r,) in mesh units and
    ``radii_relative``; per fragment k ``fracture_k`` (faces,) int8, its break surface
    (``fracture[k]``, after the assembly; the segmentation's labels without it) and
    ``segmented_k`` (faces,) int8, the segmentation's labels, and, when it has
    descriptors, ``H_k`` (faces, r) float32 mean curvature at the face centres; per contact i
    (``contact_pairs`` (c, 2) fragment indices) ``contact_i_a`` / ``contact_i_b`` (p, 3)
    touching points, each in its own fragment's coordinates."""
    arrays = {"names": np.array([f.name for f in frags]), "radii": size * np.asarray(radii, float),
              "radii_relative": np.asarray(radii, float),
              "contact_pairs": np.array([[c.a, c.b] for c in contacts], np.int64).reshape(-1, 2)}
    for k, f in enumerate(frags):
        arrays[f"segmented_{k}"] = f.segmentation.fracture.astype(np.int8)
        arrays[f"fracture_{k}"] = (f.segmentation.fracture if fracture is None else fracture[k]).astype(np.int8)
        if f.descriptors is not None:
            arrays[f"H_{k}"] = f.descriptors.H.astype(np.float32)
    for i, (points_a, points_b) in enumerate(touching):
        arrays[f"contact_{i}_a"], arrays[f"contact_{i}_b"] = points_a, points_b
    return arrays


def _largest(A, frags) -> int:
    main = np.flatnonzero(A.group == 0)
    return int(main[np.argmax([frags[k].surface.area for k in main])])


def transforms_json(result) -> dict:
    """``transforms.json``: per fragment ``T_world_fragment``, placed, confidence, group."""
    A, names = result.assembly, [f.name for f in result.fragments]
    return {
        "format": TRANSFORMS_FORMAT, "convention": TRANSFORMS_CONVENTION, "version": __version__,
        "seed": result.config.seed,
        "world": f"the coordinates of fragment {names[_largest(A, result.fragments)]!r}'s file "
                 "(the largest fragment of the main assembly)",
        "fragments": {
            n: {"transform": result.T_world[k].tolist(), "placed": bool(A.placed[k]),
                "confidence": rounded(A.confidence[k]), "group": int(A.group[k])}
            for k, n in enumerate(names)
        },
    }


def _fragment_report(result, groups) -> dict:
    A, frags = result.assembly, result.fragments
    names = [f.name for f in frags]
    neighbours = {n: [] for n in names}
    for c in A.contacts:
        neighbours[names[c.a]].append(names[c.b])
        neighbours[names[c.b]].append(names[c.a])
    fragment_report = {}
    for k, f in enumerate(frags):
        entry = {"placed": bool(A.placed[k]), "group": int(A.group[k]), "confidence": rounded(A.confidence[k]),
                 "neighbours": sorted(neighbours[f.name])}
        entry.update(fragment_entry(f))
        if not A.placed[k]:
            entry["notes"].append("not placed: no verified contact with the main assembly"
                                  + (f" (in sub-assembly {A.group[k]} with {len(groups[A.group[k]]) - 1} other(s))"
                                     if len(groups[A.group[k]]) > 1 else ""))
        fragment_report[f.name] = entry
    return fragment_report


def run_report(result, *, warnings: list[str]) -> dict:
    """``report.json``: a summary, the sub-assemblies, each fragment, each contact, the warnings."""
    A, frags, size, reg = result.assembly, result.fragments, result.size, result.config.registration
    names = [f.name for f in frags]
    groups = [[names[k] for k in np.flatnonzero(A.group == g)] for g in range(int(A.group.max()) + 1)]
    return {
        "format": REPORT_FORMAT, "version": __version__,
        "summary": {
            "fragments": len(frags), "placed": int(A.placed.sum()),
            "sub_assemblies": sum(len(g) > 1 for g in groups), "alone": sum(len(g) == 1 for g in groups),
            "contacts": len(A.contacts),
            "vertex_noise": rounded(set_noise(frags) / size), "contact_tolerance": rounded(reg.tolerance),
            "gap": rounded(reg.gap), "thin_walled": thin_walled(frags),
            "timings_s": {k: round(v, 2) for k, v in result.timings.items()},
            **({"fallback": result.fallback} if result.fallback else {}),
        },
        "groups": groups,
        "fragments": _fragment_report(result, groups),
        "contacts": [{"fragments": [names[c.a], names[c.b]], "score": rounded(c.score),
                      "contact_area": rounded(c.contact_area), "penetration_area": rounded(c.penetration_area)}
                     for c in A.contacts],
        "warnings": warnings,
    }


def _write_assembled(tmp: Path, result) -> None:
    """``assembled.glb`` (every fragment, posed) and ``assembled.ply`` (the placed ones)."""
    frags, A, T_world = result.fragments, result.assembly, result.T_world
    names = [f.name for f in frags]
    colors = fragment_colors(len(frags))
    write_glb(tmp / "assembled.glb", {f.name: (f.vertices, f.faces) for f in frags},
              {n: T_world[k] for k, n in enumerate(names)}, colors=dict(zip(names, colors)))
    placed = np.flatnonzero(A.placed)
    if len(placed):
        offsets = np.cumsum([0] + [len(frags[k].vertices) for k in placed])
        write_ply(tmp / "assembled.ply",
                  np.vstack([transform_points(T_world[k], frags[k].vertices) for k in placed]),
                  np.vstack([frags[k].faces + o for k, o in zip(placed, offsets)]),
                  colors=np.vstack([np.tile(colors[k], (len(frags[k].vertices), 1)) for k in placed]))


def write_run_folder(out, result, *, report: dict, force: bool, debug: bool) -> None:
    """The files of :func:`pipeline.run_to_folder`, ``transforms.json`` last."""
    frags = result.fragments
    with staged_directory(out, force=force) as tmp:
        write_json(tmp / "pairs.json", _pairs_file(frags, result.pairs))
        write_json(tmp / "report.json", report)
        write_json(tmp / "config.json", config_json(result))
        write_npz(tmp / "analysis.npz", **analysis_arrays(frags, result.assembly.contacts, result.touching,
                                                          size=result.size, radii=result.config.radii,
                                                          fracture=result.fracture))
        _write_assembled(tmp, result)
        if debug:
            write_debug(tmp, frags, result.pairs)
        write_json(tmp / "transforms.json", transforms_json(result))  # last: its presence means the run completed
