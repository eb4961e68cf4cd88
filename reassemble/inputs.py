"""Input discovery: fragment meshes from files and folders."""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path

import numpy as np

from .errors import ReassembleError
from .files import DEBRIS_SHARE, MESH_SUFFIXES, load_mesh, mesh_warning, split_bodies

log = logging.getLogger(__name__)


def load_fragments(
    inputs: list[str | Path], *, fill_holes: float | None = None, split: bool = False
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], list[str]]:
    """Read fragment meshes from files and folders; a bad file is skipped with a warning.

    Returns the meshes by name and the warnings (one line each). The name is the file
    stem: a file is one rigid piece, whatever its separate bodies. With ``split``, a file
    holding several separate bodies gives one fragment per body (``stem.1``, ``stem.2``,
    ... largest first; specks under 1 % of the largest's volume are dropped).
    A fragment identical to one already read (same welded vertices and faces) is skipped.
    A mesh that is not a clean closed surface is repaired (see :func:`files.load_mesh`), with
    one warning saying what was found and done; with ``fill_holes``, the holes of open
    scans are closed with flat patches.
    """
    files: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
            if not found:
                raise ReassembleError(f"{path}: no mesh files ({' '.join(MESH_SUFFIXES)}) in this folder")
            files += found
        elif path.is_file():
            files.append(path)
        else:
            raise ReassembleError(f"{path}: no such file or folder")
    meshes, warnings, digests = {}, [], {}
    for path in files:
        try:
            whole = load_mesh(path, require_closed=True, fill_holes=fill_holes)
        except ReassembleError as exc:
            warnings.append(f"skipped: {exc}")
            continue
        if mesh_warning(whole):
            warnings.append(mesh_warning(whole))
        bodies, debris = split_bodies(whole) if split else ([whole], 0)
        if debris:
            warnings.append(f"{path}: dropped {debris} tiny separate piece(s) (each under "
                            f"{DEBRIS_SHARE:.0%} of the main body's volume: scan debris)")
        names = [path.stem] if len(bodies) == 1 else [f"{path.stem}.{k + 1}" for k in range(len(bodies))]
        if len(bodies) > 1:
            warnings.append(f"{path}: holds {len(bodies)} separate bodies, each taken as a fragment "
                            f"({names[0]} ... {names[-1]}, largest first)")
        for name, m in zip(names, bodies):
            if name in meshes:
                warnings.append(f"skipped: {path}: a fragment named {name!r} was already read")
                continue
            digest = hashlib.sha256(np.ascontiguousarray(m.vertices).tobytes() + m.faces.tobytes()).hexdigest()
            if digest in digests:  # the same piece twice: both would fit the same place, overlapping
                warnings.append(f"skipped: {path}: identical to fragment {digests[digest]!r}")
                continue
            digests[digest] = name
            meshes[name] = (m.vertices, m.faces)
    for w in warnings:
        log.warning("%s", w)
    if len(meshes) < 2:
        raise ReassembleError(f"need at least two readable fragments, got {len(meshes)} "
                              f"({len(files)} mesh file(s) given)")
    return meshes, warnings
