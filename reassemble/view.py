"""The ``view`` command: pictures and ``report.html`` of a run folder."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .errors import ReassembleError
from .files import glb_bytes, png_bytes, read_glb, read_json, read_transforms, staged_directory, write_bytes, write_text
from .geometry import decimate
from .puzzle import evaluate_files
from .viz.colors import fragment_colors

log = logging.getLogger(__name__)

VIEW_HINT = "`reassemble run FRAGMENTS --out {folder}` makes one"
_PICTURE_FOLDERS = {"fragment": "fragments", "match": "matches"}
VIEWER_FACES = 200_000


def view_folder(
    folder: str | Path, *, truth: str | Path | None = None, radius: float | None = None, render: bool = True,
    viewer: bool = False, width: int = 640, height: int = 480, progress: bool = False,
) -> dict:
    """Pictures and ``report.html`` of a run folder (made by :func:`pipeline.run_to_folder`).

    Writes ``folder/pictures/`` (``assembly.png``: six sides; ``exploded.png``;
    ``fragments/NAME.png``: fracture labels and mean curvature from both sides;
    ``matches/A__B.png``: each accepted contact pulled apart with lines between touching
    points, and in contact), replaced as a whole, and ``folder/report.html``: one
    self-contained page (interactive 3D view, its meshes decimated to 200k triangles in all;
    pictures; tables; with ``truth`` a
    ``ground_truth.json``, or a ``score.json`` in the folder, the metrics). Where no OpenGL
    context can be made the pictures are skipped with a warning and the page is still written.
    ``radius``: the descriptor radius of the curvature pictures, as a fraction of the
    reference size (one of the run's; default the middle one). ``viewer`` opens an
    interactive window afterwards (needs a display).

    Returns a summary: pictures written, the page's path, why pictures were skipped.
    """
    from .viz.report import report_html

    folder = Path(folder)
    poses, report, analysis, names, meshes = _read_run(folder)
    r_index = _radius_index(analysis["radii_relative"], radius)
    if truth is not None:
        metrics = evaluate_files(folder / "transforms.json", truth)
    elif (folder / "score.json").is_file():
        metrics = read_json(folder / "score.json", what="scores against a ground truth")
    else:
        metrics = None

    colors = fragment_colors(len(names))
    T_world = np.array([poses[n]["transform"] for n in names])
    placed = np.array([poses[n]["placed"] for n in names])
    pictures, notes, problem = {}, [], None
    if render:
        pictures, problem = _render_pictures(
            meshes, T_world, placed=placed, colors=colors, analysis=analysis, names=names, r_index=r_index,
            width=width, height=height, progress=progress)
        if problem:
            log.warning("%s: pictures skipped: %s", folder, problem)
            notes.append(f"Pictures skipped: {problem}.")
        else:
            with staged_directory(folder / "pictures", force=True) as tmp:
                for key, png in pictures.items():
                    kind, _, name = key.partition("/")
                    path = tmp / f"{kind}.png" if not name else tmp / _PICTURE_FOLDERS[kind] / f"{name}.png"
                    path.parent.mkdir(exist_ok=True)
                    write_bytes(path, png)
    # the page's 3D view: at most VIEWER_FACES triangles in all, so scans stay mailable
    per = max(2000, VIEWER_FACES // max(1, len(names)))
    light = {n: decimate(v, f, per) for n, (v, f) in zip(names, meshes)}
    page_glb = glb_bytes(light, dict(zip(names, T_world)), colors=dict(zip(names, colors)))
    page = report_html(report, title=folder.resolve().name, colors=dict(zip(names, colors)),
                       glb=page_glb, pictures=pictures, metrics=metrics, notes=notes)
    write_text(folder / "report.html", page)
    if viewer:
        from .viz.pictures import posed_shapes
        from .viz.render import show_interactive

        show_interactive(posed_shapes(meshes, T_world, colors=colors), title=f"reassemble: {folder.name}")
    return {"pictures": len(pictures), "report": str(folder / "report.html"), "skipped": problem}


def _read_run(folder: Path):
    """(poses, report, analysis arrays, names, meshes) of a run folder; a one-line error for a
    missing or inconsistent file."""
    if not folder.is_dir():
        raise ReassembleError(f"{folder}: no such run folder ({VIEW_HINT.format(folder=folder)})")
    if not (folder / "transforms.json").is_file():
        raise ReassembleError(f"{folder}: no transforms.json here ({VIEW_HINT.format(folder=folder)})")
    poses = read_transforms(folder / "transforms.json")
    report = read_json(folder / "report.json", what="the run's report.json")
    analysis_path = folder / "analysis.npz"
    if not analysis_path.is_file():
        raise ReassembleError(f"{analysis_path}: missing (made by `reassemble run` since 0.1; run it again)")
    try:
        with np.load(analysis_path, allow_pickle=False) as z:
            analysis = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise ReassembleError(f"{analysis_path}: cannot read ({exc})") from None
    glb_path = folder / "assembled.glb"
    scene = read_glb(glb_path)
    names = [str(n) for n in analysis["names"]]
    missing = [n for n in names if n not in scene or n not in poses]
    if missing:
        raise ReassembleError(f"{folder}: fragment {missing[0]!r} is in analysis.npz but not in assembled.glb "
                              "or transforms.json (files of different runs?)")
    meshes = [scene[n][:2] for n in names]
    for k, (n, (_, f)) in enumerate(zip(names, meshes)):
        if len(analysis[f"fracture_{k}"]) != len(f):
            raise ReassembleError(f"{glb_path}: {n!r} has {len(f)} faces, analysis.npz {len(analysis[f'fracture_{k}'])}"
                                  " (files of different runs?)")
    return poses, report, analysis, names, meshes


def _radius_index(relative: np.ndarray, radius: float | None) -> int:
    """Index of the descriptor radius ``radius`` (a fraction of the reference size) among the run's; None: the middle one."""
    r_index = len(relative) // 2
    if radius is not None:
        close = np.flatnonzero(np.isclose(relative, radius, rtol=1e-6))
        if len(close) == 0:
            raise ReassembleError(f"--radius {radius:g}: not one of this run's descriptor radii "
                                  f"({', '.join(f'{r:g}' for r in relative)}, fractions of the reference size)")
        r_index = int(close[0])
    return r_index


def _render_pictures(meshes, T_world, *, placed, colors, analysis, names, r_index, width, height, progress):
    """(PNG bytes per picture key, None) or ({}, why no picture can be made)."""
    from .viz.pictures import assembly_pictures, fragment_picture, match_picture
    from .viz.render import Renderer, RenderUnavailable, gl_problem

    problem = gl_problem()
    if problem:
        return {}, problem
    radius = float(analysis["radii"][r_index])
    H_title = f"H, 1/length\nr = {analysis['radii_relative'][r_index]:g} x size\n  = {radius:.3g}"
    pairs = analysis["contact_pairs"]
    out = {}
    try:
        with Renderer(width=width, height=height) as r:
            views, exploded = assembly_pictures(r, meshes, T_world, placed=placed, colors=colors)
            out["assembly"], out["exploded"] = png_bytes(views), png_bytes(exploded)
            for k in tqdm(range(len(names)), desc="fragment pictures", disable=not progress):
                H = analysis.get(f"H_{k}")
                image = fragment_picture(r, *meshes[k], fracture=analysis[f"fracture_{k}"],
                                         H=None if H is None else H[:, r_index], title=names[k], H_title=H_title)
                out[f"fragment/{names[k]}"] = png_bytes(image)
            for i in tqdm(range(len(pairs)), desc="match pictures", disable=not progress):
                a, b = (int(x) for x in pairs[i])
                image = match_picture(r, (meshes[a], meshes[b]), (T_world[a], T_world[b]),
                                      points=(analysis[f"contact_{i}_a"], analysis[f"contact_{i}_b"]),
                                      colors=(colors[a], colors[b]),
                                      fracture=(analysis[f"fracture_{a}"], analysis[f"fracture_{b}"]),
                                      title=f"{names[a]} + {names[b]}")
                out[f"match/{names[a]}__{names[b]}"] = png_bytes(image)
    except RenderUnavailable as exc:
        return {}, str(exc)
    return out, None

