"""The orchestrator: fragments in, the assembled object out.

:func:`reassemble` runs the stages in memory, in order: describe, segment and features
(:mod:`prepare`), match pairs (:mod:`pairs`), assemble (:mod:`assembly`).
:func:`run_to_folder` and :func:`match_to_folder` read the fragments (:mod:`inputs`), run
them and write the results (:mod:`outputs`). Puzzle files are in :mod:`puzzle`, the ``view``
and ``demo`` commands in :mod:`view` and :mod:`demo`.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np

from . import assembly
from .config import MatchConfig
from .descriptors import DescriptorParams, integral_invariants
from .errors import ReassembleError
from .files import check_output_folder, load_mesh, resolve_mesh_path, write_npz
from .inputs import load_fragments
from .outputs import pairs_json, run_report, write_match_folder, write_run_folder
from .pairs import match_pairs, match_set, registration_params
from .prepare import DescribedSet, PreparedFragment, describe_fragments, prepare_fragments, reference_size
from .puzzle import PuzzleFiles, break_to_folder, evaluate_files, read_puzzle
from .registration import RegistrationParams
from .segmentation import SegmentParams

log = logging.getLogger(__name__)

__all__ = [  # the stages' entry points, and the puzzle files, importable from here
    "DescribedSet", "MatchConfig", "PreparedFragment", "PuzzleFiles", "Result", "break_to_folder",
    "describe_fragments", "describe_to_file", "evaluate_files", "match_pairs", "match_set", "match_to_folder",
    "prepare_fragments", "read_puzzle", "reassemble", "reference_size", "registration_params", "run_to_folder",
]


@dataclasses.dataclass
class Result:
    """What :func:`reassemble` found; lists are in sorted fragment-name order.

    Attributes
    ----------
    fragments : PreparedFragment per fragment (descriptors, segmentation, fracture features)
    size : reference size (:func:`prepare.reference_size`), mesh units
    seed : the random seed of the run
    segment, registration, assembly_params : the stage options used, resolved from the data
        (registration: tolerance from the noise, ``gap`` measured)
    pairs : (source, target) index pair -> registration.PairResult
    assembly : assembly.Assembly, None when only the pairs were matched
    T_world : (n, 4, 4) T_world_fragment per fragment (:func:`assembly.world_poses`)
    touching : per contact of the assembly, the touching points of either fragment
    timings : seconds per step
    """

    fragments: list[PreparedFragment]
    size: float
    seed: int
    segment: SegmentParams
    registration: RegistrationParams
    assembly_params: assembly.AssemblyParams | None
    pairs: dict
    assembly: assembly.Assembly | None = None
    T_world: np.ndarray | None = None
    touching: list | None = None
    timings: dict = dataclasses.field(default_factory=dict)


def reassemble(
    meshes: dict[str, tuple[np.ndarray, np.ndarray]], config: MatchConfig = MatchConfig(), *, seed: int = 0,
    assembly_params: assembly.AssemblyParams | None = None, assemble: bool = True, jobs: int = 1,
    progress: bool = False,
) -> Result:
    """Reassemble fragments given as name -> (vertices (n, 3), faces (f, 3)), in memory.

    ``assemble`` False stops after matching the pairs (what ``reassemble match`` writes).
    ``jobs`` > 1 describes fragments and registers pairs in that many processes; the
    result does not depend on it.
    """
    t0 = time.perf_counter()
    seg_params = SegmentParams()
    frags, size = prepare_fragments(meshes, config=config, segment_params=seg_params, seed=seed, jobs=jobs,
                                    progress=progress)  # describe, segment, features
    reg_params = registration_params(frags, size=size, params=RegistrationParams())
    t1 = time.perf_counter()
    pairs, reg_params = match_set(frags, size=size, params=reg_params, gap=config.gap, seed=seed, jobs=jobs,
                                  progress=progress)
    t2 = time.perf_counter()
    result = Result(frags, size, seed, seg_params, reg_params, assembly_params or assembly.AssemblyParams(), pairs,
                    timings={"prepare": t1 - t0, "pairs": t2 - t1})
    if assemble:
        _assemble(result, progress=progress)
        result.timings["assembly"] = time.perf_counter() - t2
    return result


def _assemble(result: Result, *, progress: bool) -> None:
    """The assemble step: global assembly, world poses, touching points of every contact."""
    frags, size, reg = result.fragments, result.size, result.registration
    if progress:
        log.info("assembling %d fragments", len(frags))
    surfaces, meshes = [f.surface for f in frags], [f.mesh for f in frags]
    result.assembly = assembly.assemble(surfaces, meshes, result.pairs, size=size, params=result.assembly_params,
                                        reg_params=reg, seed=result.seed)
    result.T_world = assembly.world_poses(result.assembly, surfaces, gap=0.1 * size)
    result.touching = assembly.contact_points(result.assembly, surfaces, meshes, tol=reg.tolerance * size,
                                              normal_angle=reg.normal_angle, gap=reg.gap * size)


def _load(inputs, out, *, config: MatchConfig, force: bool):
    """The set-up of run and match: refuse an existing output first (before minutes of
    work, not after), then read the fragments. Returns (meshes, warnings, seconds)."""
    t0 = time.perf_counter()
    check_output_folder(out, force=force)
    meshes, warnings = load_fragments(inputs, fill_holes=config.fill_holes)
    return meshes, warnings, time.perf_counter() - t0


def match_to_folder(
    inputs: list[str | Path], out: str | Path, *, seed: int = 0, force: bool = False, debug: bool = False,
    config: MatchConfig = MatchConfig(), jobs: int = 1, progress: bool = False,
) -> dict:
    """Segment the fragments, register every pair, and write ``pairs.json`` (+ debug files).

    Writes into ``out`` (built aside, moved into place when complete): ``pairs.json`` with
    each pair's ranked candidates (``T_target_source``, score, contact and penetration
    areas) and verdict, ``fragments.json`` (fracture area, regions, warnings per fragment),
    ``config.json`` (the resolved configuration); with ``debug``, ``labels/NAME.ply``
    (fracture faces' vertices red) and ``matches/SOURCE__TARGET.npz`` (matched keypoints of
    the best candidate, each in its own fragment's frame).
    """
    meshes, warnings, _ = _load(inputs, out, config=config, force=force)
    result = reassemble(meshes, config, seed=seed, assemble=False, jobs=jobs, progress=progress)
    write_match_folder(out, result, config, warnings=warnings, force=force, debug=debug)
    pairs = pairs_json(result.fragments, result.pairs)
    return {"fragments": len(result.fragments), "pairs": len(pairs), "touching": sum(p["touching"] for p in pairs),
            "warnings": warnings, "pair_list": pairs}


def run_to_folder(
    inputs: list[str | Path], out: str | Path, *, seed: int = 0, force: bool = False, debug: bool = False,
    config: MatchConfig = MatchConfig(), assembly_params=None, jobs: int = 1, progress: bool = False,
) -> dict:
    """The main job: fragments in, the assembled object and its report out.

    Writes into ``out`` (built aside, moved into place only when complete, so no
    half-written ``transforms.json`` is ever left): ``transforms.json`` (per file stem
    ``T_world_fragment``, ``placed``, ``confidence``, ``group``), ``assembled.glb`` (one
    named node per fragment, its pose as the node transform), ``assembled.ply`` (the placed
    fragments in world coordinates, one colour each), ``report.json``, ``pairs.json``,
    ``config.json``, ``analysis.npz`` (what :func:`view.view_folder` draws: per-face fracture
    labels and mean curvature, the touching points of every contact); with ``debug`` the
    files of :func:`match_to_folder`'s ``debug``.

    Returns the report (a dict).
    """
    meshes, warnings, seconds = _load(inputs, out, config=config, force=force)
    result = reassemble(meshes, config, seed=seed, assembly_params=assembly_params, jobs=jobs, progress=progress)
    result.timings["prepare"] += seconds  # reading the files counts as preparing them
    report = run_report(result, warnings=warnings)
    write_run_folder(out, result, config, report=report, force=force, debug=debug)
    return report


def describe_to_file(
    mesh: str | Path, out: str | Path, *, radii, relative: bool = False, params=None, force: bool = False,
    fill_holes: float | None = None,
) -> dict:
    """Integral invariants of a closed mesh at its (welded) vertices, written to an ``.npz``;
    ``fill_holes`` as in :func:`files.load_mesh` (the patches' vertices are described too).

    Returns a small summary (vertex count, radii in mesh units, timings).
    """
    out = Path(out)
    if out.exists() and not force:
        raise ReassembleError(f"{out}: file exists (use --force to replace it)")
    path = resolve_mesh_path(mesh)
    data = load_mesh(path, require_closed=True, fill_holes=fill_holes)
    radii = np.asarray(radii, dtype=np.float64)
    diag = float(np.linalg.norm(np.ptp(data.vertices, axis=0)))
    if relative:
        radii = radii * diag
    try:
        d = integral_invariants(data.vertices, data.faces, radii, params=params or DescriptorParams())
    except ReassembleError as exc:
        raise ReassembleError(f"{path}: {exc}") from None
    arrays = dict(vertices=d.points, faces=data.faces, radii=d.radii, V=d.V, P=d.P, D2=d.D2,
                  H=d.H, H_rob=d.H_rob, K2=d.K2)
    if d.K2_cov is not None:
        arrays.update(K2_cov=d.K2_cov, k1=d.k1, k2=d.k2, dir1=d.dir1, normal=d.normal)
    write_npz(out, **arrays)
    return {"vertices": len(d.points), "radii": d.radii.tolist(), "diagonal": diag, "timings": d.timings}


