"""The orchestrator: runs the stages in order and is the only module that touches files.

``break_to_folder`` writes a synthetic puzzle; ``evaluate_files`` scores a
``transforms.json`` against a puzzle's ``ground_truth.json``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
from pathlib import Path

import numpy as np

from . import __version__
from .errors import ReassembleError
from .geometry import canonical_order, face_areas, transform_points
from .files import (
    DEBRIS_SHARE,
    TRANSFORMS_CONVENTION,
    check_output_folder,
    load_mesh,
    load_solid,
    mesh_warning,
    read_json,
    read_transforms,
    resolve_mesh_path,
    split_bodies,
    staged_directory,
    write_glb,
    write_json,
    write_npz,
    write_ply,
)
from .viz.colors import FRACTURE_RGB, ORIGINAL_RGB, fragment_colors

log = logging.getLogger(__name__)

GROUND_TRUTH_FORMAT = "reassemble-ground-truth/1"


def describe_to_file(
    mesh: str | Path, out: str | Path, *, radii, relative: bool = False, params=None, force: bool = False,
    fill_holes: float | None = None,
) -> dict:
    """Integral invariants of a closed mesh at its (welded) vertices, written to an ``.npz``;
    ``fill_holes`` as in :func:`files.load_mesh` (the patches' vertices are described too).

    Returns a small summary (vertex count, radii in mesh units, timings).
    """
    from .descriptors import DescriptorParams, integral_invariants

    out = Path(out)
    if out.exists() and not force:
        raise ReassembleError(f"{out}: file exists (use --force to replace it)")
    path = resolve_mesh_path(mesh)
    data = load_mesh(path, require_closed=True, fill_holes=fill_holes)
    if mesh_warning(data):
        log.warning("%s", mesh_warning(data))
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


def _round(x: float) -> float:
    return float(f"{x:.12g}")


def break_to_folder(
    mesh: str | Path, out: str | Path, *, params, seed: int, force: bool = False, fill_holes: float | None = None
) -> Path:
    """Break ``mesh`` (a path or a bundled mesh name) and write the puzzle to ``out``;
    ``fill_holes`` as in :func:`files.load_mesh` (an open scan closed before breaking).

    Writes ``out/fragments/<name>.ply``, ``out/labels.npz`` (per-face int8, 1 = fracture,
    one array per fragment name) and ``out/ground_truth.json``. The folder appears only
    when complete.
    """
    from .synth import break_mesh

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
                "n_fracture_faces": int(lab.sum()),
                "area": _round(areas.sum()),
                "fracture_area": _round(areas[lab == 1].sum()),
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
            "parameters": dataclasses.asdict(params),
            "object": {
                "bbox_min": [_round(x) for x in puzzle.bbox_min],
                "bbox_max": [_round(x) for x in puzzle.bbox_max],
                "diagonal": _round(float(np.linalg.norm(puzzle.bbox_max - puzzle.bbox_min))),
                "volume": _round(puzzle.volume),
                "area": _round(puzzle.area),
            },
            "labels": {"file": "labels.npz", "values": {"0": "original surface", "1": "fracture"}},
            "fragments": fragments_json,
            "contacts": [
                {"fragments": [c.a, c.b], "area": _round(c.area)} for c in puzzle.contacts
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
    """Read a ``ground_truth.json`` and the fragment meshes (and labels) beside it."""
    gt_path = Path(ground_truth)
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
    """Score ``predicted`` (a transforms.json) against a puzzle's ``ground_truth.json``."""
    from .metrics import ScoringFragment, evaluate

    pred = read_transforms(predicted)
    truth = read_transforms(ground_truth)
    puzzle = read_puzzle(ground_truth, with_labels=False)
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


@dataclasses.dataclass(frozen=True)
class MatchConfig:
    """Options of the matching stages; lengths are fractions of the reference size (the
    median fragment bounding-box diagonal), resolved from the data.

    Parameters
    ----------
    radii : descriptor radii
    keypoint_spacing : spacing of fracture keypoints
    samples : fracture and surface samples per fragment (ICP, contact, penetration)
    max_memory : bytes of working memory one fragment's descriptor grid may take; a
        fragment that needs more is left out with a note naming ``--max-memory``
    gap : how far apart mating fracture surfaces are (material lost at the break); None:
        measured from the pairs (:func:`match_set`)
    denoise : when the set's vertex noise exceeds this fraction of the finest radius, every
        fragment is matched on a Taubin-smoothed copy (all smoothed alike, until the noisiest
        is down to half that); their own vertices stay in every output
    thin_walls : match as thin-walled sherds along their break strips (:mod:`shells`): None
        when most fragments are (:func:`shells.is_thin_shell`), or always / never
    fill_holes : close the holes of open scans up to this extent, a fraction of each mesh's
        diagonal (:func:`holes.fill_holes`); None reads an open mesh as it is (the winding
        number bridges its holes)
    signature_radii : the fracture signatures use this many of the finest ``radii`` (None:
        all of them); two by default: the coarsest ball reaches past a small contact into
        the air and other fragments, and with it the signatures of small mating faces
        disagree (``benchmarks/pairwise.py --signature-radii``)
    split_bodies : a file holding several separate bodies gives one fragment per body
        (else a file is one rigid piece, :func:`load_fragments`)
    """

    radii: tuple[float, ...] = (0.02, 0.04, 0.08)
    keypoint_spacing: float = 0.015
    samples: int = 4000
    max_memory: float = 4e9
    gap: float | None = None
    denoise: float = 0.2
    thin_walls: bool | None = None
    fill_holes: float | None = None
    signature_radii: int | None = 2
    split_bodies: bool = False


@dataclasses.dataclass
class PreparedFragment:
    """One fragment after descriptors, segmentation and features."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    descriptors: object
    segmentation: object
    surface: object
    note: str = ""
    noise: float = 0.0  # vertex noise sigma of ``vertices``, mesh units (geometry.vertex_noise)
    smoothing: int = 0  # Taubin iterations of the copy matched (0: ``vertices`` themselves)
    matched: np.ndarray | None = None  # (n, 3) the smoothed copy's vertices, when smoothing
    shell: bool = False  # matched as a thin-walled sherd, along its break strip (shells.py)

    @property
    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices, faces) the matching uses: the smoothed copy, if any (same faces)."""
        return (self.vertices if self.matched is None else self.matched), self.faces


def reference_size(meshes: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """The median bounding-box diagonal of the fragments: the unit of every default length."""
    return float(np.median([np.linalg.norm(np.ptp(v, axis=0)) for v, _ in meshes]))


_WORKER: dict = {}  # what a worker process holds between tasks (set by an initializer)


def _describe(task):
    """(Descriptors or None, note) of one fragment; a failure is a note, not fatal."""
    from .descriptors import integral_invariants

    v, f, radii, params, largest = task
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    if diag <= radii.max():
        return None, (f"not matched: too small (bounding-box diagonal {diag:.4g}, below the largest "
                      f"descriptor radius {radii.max():.4g} = {largest:g} x the median fragment)")
    try:
        return integral_invariants(v, f, radii, points=v[f].mean(axis=1), params=params), ""
    except ReassembleError as exc:  # e.g. a grid over the memory budget: the others go on
        return None, f"not matched: {exc}"


def _smoothed_copies(meshes, noise, *, threshold: float) -> tuple[list[np.ndarray], int]:
    """The vertices to match on: the given ones, or, when the set's median vertex noise is
    over ``threshold``, Taubin-smoothed copies, every fragment with the same number of
    iterations (mates smoothed differently fit worse), enough to bring the noisiest
    fragment down to half the threshold (at most 40)."""
    from .geometry import denoise, taubin_smooth

    if float(np.median(noise)) <= threshold:
        return [v for v, _ in meshes], 0
    first = [denoise(v, f, target=0.5 * threshold) for v, f in meshes]
    iterations = max(it for _, it in first)
    return [taubin_smooth(v, f, iterations - it) if it < iterations else v
            for (v, it), (_, f) in zip(first, meshes)], iterations


def _map(fn, tasks, *, jobs: int, initializer=None, initargs=()):
    """``map(fn, tasks)`` in order, in ``jobs`` processes when jobs > 1 (spawned, not forked:
    the parent holds Open3D and FFT thread pools)."""
    if jobs <= 1 or len(tasks) <= 1:
        if initializer is not None:
            initializer(*initargs)
        try:
            yield from map(fn, tasks)
        finally:
            _WORKER.clear()
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=multiprocessing.get_context("spawn"),
                             initializer=initializer, initargs=initargs) as pool:
        yield from pool.map(fn, tasks, chunksize=max(1, len(tasks) // (8 * jobs)))


@dataclasses.dataclass
class DescribedSet:
    """A fragment set after its descriptors: what segmentation and features start from
    (:func:`describe_fragments`). Lists are in ``names`` order.

    Attributes
    ----------
    names : sorted fragment names
    meshes : (vertices (n, 3), faces (f, 3)) as given
    matched : (n, 3) vertices the matching uses: the given ones, or Taubin-smoothed copies
    noise : vertex noise sigma per fragment, mesh units (:func:`geometry.vertex_noise`)
    smoothing : Taubin iterations of the copies (0: the given vertices)
    size : reference size (:func:`reference_size`)
    descriptors : Descriptors at the face centres, None where a fragment could not be described
    notes : name -> why it was not described
    """

    names: list[str]
    meshes: list[tuple[np.ndarray, np.ndarray]]
    matched: list[np.ndarray]
    noise: list[float]
    smoothing: int
    size: float
    descriptors: list
    notes: dict[str, str]


def describe_fragments(
    meshes: dict[str, tuple[np.ndarray, np.ndarray]],
    *,
    config: MatchConfig = MatchConfig(),
    jobs: int = 1,
    progress: bool = False,
) -> DescribedSet:
    """Vertex noise, the copies to match on and the descriptors at their face centres.

    ``jobs`` > 1 computes the descriptors of that many fragments at once, in processes.
    Raises ReassembleError when no fragment can be described.
    """
    from tqdm import tqdm

    from .descriptors import DescriptorParams
    from .geometry import vertex_noise

    names = sorted(meshes)
    pairs = [meshes[n] for n in names]
    size = reference_size(pairs)
    radii = size * np.asarray(config.radii)
    params = DescriptorParams(with_d2=False, principal=True, max_memory=config.max_memory)
    noise = [vertex_noise(v) for v, _ in pairs]
    # noise above a fifth of the finest radius swamps the finest scale: the crease angles,
    # face normals and finest invariants are noise (0.5 % of the diagonal, 4 pieces:
    # segmentation F1 0.38-0.83, 2 of 6 sets solved; matched on smoothed copies, with the
    # tolerance still from the noise of the given surfaces: 5 of 6; benchmarks/robustness.py).
    # A tenth helped 0.2 % noise (strict 0.72 -> 0.96) but smoothed the low-resolution fish
    # in 20 pieces with 0.1 % noise below its own facets (solved -> 2 of 20 right)
    matched, smoothing = _smoothed_copies(pairs, noise, threshold=config.denoise * radii[0])
    if smoothing:
        log.info("vertex noise %.3g x size, over %g x the finest radius: matching on copies smoothed %d times",
                 float(np.median(noise)) / size, config.denoise, smoothing)
    tasks = [(v, f, radii, params, config.radii[-1]) for v, (_, f) in zip(matched, pairs)]
    descriptors, notes = [], {}
    for name, (d, note) in zip(names, tqdm(_map(_describe, tasks, jobs=jobs), total=len(tasks),
                                           desc="descriptors", disable=not progress)):
        descriptors.append(d)
        if note:
            notes[name] = note
    if all(d is None for d in descriptors):  # nothing to match: say why rather than report every fragment unplaced
        raise ReassembleError(f"none of the {len(names)} fragments could be matched; "
                              f"{names[0]}: {notes[names[0]].removeprefix('not matched: ')}")
    return DescribedSet(names, pairs, matched, noise, smoothing, size, descriptors, notes)


def prepare_fragments(
    meshes: dict[str, tuple[np.ndarray, np.ndarray]],
    *,
    config: MatchConfig = MatchConfig(),
    segment_params=None,
    seed: int = 0,
    jobs: int = 1,
    progress: bool = False,
    described: DescribedSet | None = None,
) -> tuple[list[PreparedFragment], float]:
    """Descriptors at the face centres, segmentation over the whole set, fracture features.

    ``jobs`` > 1 computes the descriptors of that many fragments at once, in processes.
    ``described``: the set's :func:`describe_fragments` with this ``config``, when already
    computed (``meshes`` is then ignored).
    Returns the prepared fragments (in sorted name order) and the reference size.
    """
    from .features import empty_surface, fracture_surface
    from .segmentation import SegmentParams, Segmentation, segment
    from .shells import is_thin_shell, strip_frames, strip_segmentation, wall_thickness

    if config.signature_radii is not None and not 1 <= config.signature_radii <= len(config.radii):
        raise ReassembleError(f"signature_radii must be 1 to {len(config.radii)} (the descriptor radii), "
                              f"got {config.signature_radii}")
    n_signature = config.signature_radii or len(config.radii)  # one width for every fragment's signatures
    if described is None:
        described = describe_fragments(meshes, config=config, jobs=jobs, progress=progress)
    names, pairs, matched, size = described.names, described.meshes, described.matched, described.size
    descriptors, notes, smoothing = described.descriptors, dict(described.notes), described.smoothing
    good = [k for k, d in enumerate(descriptors) if d is not None]
    segs = [None] * len(names)
    thickness = {k: wall_thickness(matched[k], pairs[k][1]) for k in good}
    shell = config.thin_walls
    if shell is None:
        shell = 2 * sum(is_thin_shell(matched[k], pairs[k][1], thickness[k]) for k in good) > len(good)
    if shell:
        log.info("thin-walled fragments (sherds): matched along their break strips")
        for k in good:
            segs[k] = strip_segmentation(matched[k], pairs[k][1], thickness[k])
    else:
        for k, s in zip(good, segment([(matched[k], pairs[k][1]) for k in good], [descriptors[k] for k in good],
                                      size=size, params=segment_params or SegmentParams(), seed=seed)):
            segs[k] = s
    # on sherds one keypoint pair is a hypothesis: the cost grows as the product of the
    # keypoint counts (at the solids' spacing ~700 per vessel sherd)
    spacing = config.keypoint_spacing * size * (2.0 if shell else 1.0)
    rngs = np.random.default_rng(seed).spawn(len(names))
    out = []
    for k, (name, (given, f), v, d, s, rng, sigma) in enumerate(zip(names, pairs, matched, descriptors, segs, rngs,
                                                                  described.noise)):
        if s is None:
            s = Segmentation(np.zeros(len(f), bool), np.zeros(len(f)), np.zeros(len(f), int),
                             np.full(len(f), -1), 0.0, float(face_areas(v, f).sum()))
            surf = empty_surface(v, f, n_radii=n_signature, n_samples=config.samples, rng=rng)
            log.warning("%s: %s", name, notes[name])
        else:
            surf = fracture_surface(v, f, s, d, spacing=spacing, n_samples=config.samples,
                                    signature_radii=n_signature, rng=rng)
            if shell and len(surf.keypoints):
                n, t = strip_frames(v, f, thickness[k], surf.keypoints, surf.keypoint_normals)
                surf = dataclasses.replace(surf, keypoint_normals=n, keypoint_tangents=t)
            if surf.fracture_area == 0.0:
                notes[name] = "no fracture surface found; it can only be placed by others"
                log.warning("%s: %s", name, notes[name])
        out.append(PreparedFragment(name, given, f, d, s, surf, notes.get(name, ""), sigma, smoothing,
                                    v if smoothing else None, shell))
    return out, size


def set_noise(fragments: list[PreparedFragment]) -> float:
    """The vertex noise of a fragment set (mesh units): the median of its fragments'."""
    return float(np.median([f.noise for f in fragments])) if fragments else 0.0


def thin_walled(fragments: list[PreparedFragment]) -> bool:
    """Whether the set was prepared as thin-walled sherds (:func:`prepare_fragments` decides for all)."""
    return bool(fragments) and all(f.shell for f in fragments)


def registration_params(fragments: list[PreparedFragment], *, size: float, params=None):
    """The registration options for this set, resolved from the data: ``params`` (default
    ``RegistrationParams()``) with the contact tolerance raised to cover its vertex noise."""
    from .registration import RegistrationParams, with_noise

    params = with_noise(params or RegistrationParams(), noise=set_noise(fragments), size=size)
    if thin_walled(fragments):
        # one-point hypotheses on strips are many and their local consensus weak (a break
        # curve matches any curve over a short stretch): more of them go on to ICP
        params = dataclasses.replace(params, shortlist=100, consensus_pool=2000)
    return params


def _pair_worker_init(surfaces, meshes, size, params) -> None:
    _WORKER.clear()
    _WORKER.update(surfaces=surfaces, meshes=meshes, size=size, params=params, scenes={})


def _pair_worker(task):
    from .geometry import make_scene
    from .registration import register_pair

    i, j, rng = task
    scenes = _WORKER["scenes"]
    for k in (i, j):
        if k not in scenes:
            scenes[k] = make_scene(*_WORKER["meshes"][k])
    return (i, j), register_pair(_WORKER["surfaces"][i], _WORKER["surfaces"][j], source_scene=scenes[i],
                                 target_scene=scenes[j], size=_WORKER["size"], params=_WORKER["params"], rng=rng)


def match_pairs(
    fragments: list[PreparedFragment],
    *,
    size: float,
    pairs: list[tuple[int, int]] | None = None,
    params=None,
    seed: int = 0,
    jobs: int = 1,
    progress: bool = False,
) -> dict[tuple[int, int], object]:
    """Register fragment pairs (all, or the given (source, target) index pairs): PairResult per pair.

    ``jobs`` > 1 registers pairs in that many processes; every pair has its own random
    stream (spawned from ``seed`` in pair order), so results do not depend on ``jobs``.
    ``params``: default :func:`registration_params` of the fragments (noise-aware tolerance).
    """
    from tqdm import tqdm

    params = params or registration_params(fragments, size=size)
    if pairs is None:
        pairs = [(i, j) for i in range(len(fragments)) for j in range(i + 1, len(fragments))]
    rngs = np.random.default_rng(seed).spawn(len(pairs))
    tasks = [(i, j, rng) for (i, j), rng in zip(pairs, rngs)]
    init = ([f.surface for f in fragments], [f.mesh for f in fragments], size, params)
    results = {}
    for key, res in tqdm(_map(_pair_worker, tasks, jobs=jobs, initializer=_pair_worker_init, initargs=init),
                         total=len(tasks), desc="pairs", disable=not progress):
        results[key] = res
    return results


def match_set(
    fragments: list[PreparedFragment], *, size: float, params, gap: float | None = None, seed: int = 0,
    jobs: int = 1, progress: bool = False,
):
    """Register every pair, with the separation of mating surfaces measured or given.

    With ``gap`` None, the pairs are registered touching, the separation of the touching
    ones measured (:func:`registration.set_gap`), and when it exceeds the contact
    tolerance (plain contacts would close it, shifting every piece by it and counting
    rough surfaces as interpenetrating), every pair is registered again that far apart.

    Returns
    -------
    results : (source, target) -> PairResult
    params : the RegistrationParams used, ``gap`` resolved (fraction of ``size``)
    """
    import dataclasses

    from .registration import set_gap

    if gap is not None:
        params = dataclasses.replace(params, gap=float(gap))
    results = match_pairs(fragments, size=size, params=params, seed=seed, jobs=jobs, progress=progress)
    if gap is None:
        measured = set_gap([f.surface for f in fragments], results, size=size, params=params)
        if measured > params.tolerance:
            log.info("mating surfaces are %.3g x size apart (material lost at the break?): matching again with "
                     "that gap", measured)
            params = dataclasses.replace(params, gap=measured)
            results = match_pairs(fragments, size=size, params=params, seed=seed, jobs=jobs, progress=progress)
    return results, params


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
    from .files import MESH_SUFFIXES

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


def _fragment_entry(f: PreparedFragment) -> dict:
    return {
        "faces": len(f.faces), "area": f.surface.area, "fracture_area": f.surface.fracture_area,
        "fracture_share": f.surface.fracture_area / f.surface.area,
        "fracture_regions": int(f.segmentation.region.max()) + 1, "keypoints": len(f.surface.keypoints),
        "smoothing_iterations": f.smoothing, "notes": [f.note] if f.note else [],
    }


def _pairs_json(frags: list[PreparedFragment], results: dict) -> list[dict]:
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


def _write_debug(tmp: Path, frags: list[PreparedFragment], results: dict) -> None:
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


def _resolved_match(config: MatchConfig, frags: list[PreparedFragment]) -> MatchConfig:
    """``config`` with what was decided from the data filled in (thin walls or not)."""
    return dataclasses.replace(config, thin_walls=thin_walled(frags))


def _resolved(seed: int, size: float, noise: float, **stages) -> dict:
    out = {"seed": seed, "reference_size": size, "vertex_noise": noise / size}
    out.update({k: dataclasses.asdict(v) for k, v in stages.items()})
    out["note"] = ("lengths in the stage options and vertex_noise are fractions of reference_size "
                   "(the median fragment bounding-box diagonal); registration.tolerance is at least "
                   "noise_tolerance x sqrt(2) x vertex_noise")
    return out


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
    from .registration import RegistrationParams
    from .segmentation import SegmentParams

    check_output_folder(out, force=force)  # before minutes of work, not after
    meshes, warnings = load_fragments(inputs, fill_holes=config.fill_holes, split=config.split_bodies)
    seg_params = SegmentParams()
    frags, size = prepare_fragments(meshes, config=config, segment_params=seg_params, seed=seed, jobs=jobs,
                                     progress=progress)
    reg_params = registration_params(frags, size=size, params=RegistrationParams())
    results, reg_params = match_set(frags, size=size, params=reg_params, gap=config.gap, seed=seed, jobs=jobs,
                                    progress=progress)
    pairs = _pairs_json(frags, results)
    with staged_directory(out, force=force) as tmp:
        write_json(tmp / "pairs.json", {"format": "reassemble-pairs/1", "convention": "T_target_source",
                                        "version": __version__, "pairs": pairs})
        write_json(tmp / "fragments.json", {"fragments": {f.name: _fragment_entry(f) for f in frags},
                                            "warnings": warnings})
        write_json(tmp / "config.json", _resolved(seed, size, set_noise(frags), match=_resolved_match(config, frags),
                                                  segmentation=seg_params, registration=reg_params))
        if debug:
            _write_debug(tmp, frags, results)
    return {"fragments": len(frags), "pairs": len(pairs), "touching": sum(p["touching"] for p in pairs),
            "warnings": warnings, "pair_list": pairs}


TRANSFORMS_FORMAT = "reassemble-transforms/1"


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
    ``config.json``, ``analysis.npz`` (what :func:`view_folder` draws: per-face fracture
    labels and mean curvature, the touching points of every contact); with ``debug`` the
    files of :func:`match_to_folder`'s ``debug``.

    Returns the report (a dict).
    """
    import time

    from .assembly import AssemblyParams, assemble, contact_points, world_poses
    from .registration import RegistrationParams
    from .segmentation import SegmentParams

    check_output_folder(out, force=force)  # before minutes of work, not after
    timings = {}
    t0 = time.perf_counter()
    meshes, warnings = load_fragments(inputs, fill_holes=config.fill_holes, split=config.split_bodies)
    seg_params = SegmentParams()
    assembly_params = assembly_params or AssemblyParams()
    frags, size = prepare_fragments(meshes, config=config, segment_params=seg_params, seed=seed, jobs=jobs,
                                     progress=progress)
    reg_params = registration_params(frags, size=size, params=RegistrationParams())
    t1 = time.perf_counter()
    results, reg_params = match_set(frags, size=size, params=reg_params, gap=config.gap, seed=seed, jobs=jobs,
                                    progress=progress)
    t2 = time.perf_counter()
    if progress:
        log.info("assembling %d fragments", len(frags))
    surfaces = [f.surface for f in frags]
    A = assemble(surfaces, [f.mesh for f in frags], results, size=size, params=assembly_params,
                 reg_params=reg_params, seed=seed)
    T_world = world_poses(A, surfaces, gap=0.1 * size)
    touching = contact_points(A, surfaces, [f.mesh for f in frags], tol=reg_params.tolerance * size,
                              normal_angle=reg_params.normal_angle, gap=reg_params.gap * size)
    t3 = time.perf_counter()
    timings.update(prepare=t1 - t0, pairs=t2 - t1, assembly=t3 - t2)

    names = [f.name for f in frags]
    neighbours = {n: [] for n in names}
    for c in A.contacts:
        neighbours[names[c.a]].append(names[c.b])
        neighbours[names[c.b]].append(names[c.a])
    transforms = {
        "format": TRANSFORMS_FORMAT, "convention": TRANSFORMS_CONVENTION, "version": __version__, "seed": seed,
        "world": f"the coordinates of fragment {names[_largest(A, frags)]!r}'s file "
                 "(the largest fragment of the main assembly)",
        "fragments": {
            n: {"transform": T_world[k].tolist(), "placed": bool(A.placed[k]),
                "confidence": _round(A.confidence[k]), "group": int(A.group[k])}
            for k, n in enumerate(names)
        },
    }
    groups = [[names[k] for k in np.flatnonzero(A.group == g)] for g in range(int(A.group.max()) + 1)]
    fragment_report = {}
    for k, f in enumerate(frags):
        entry = {"placed": bool(A.placed[k]), "group": int(A.group[k]), "confidence": _round(A.confidence[k]),
                 "neighbours": sorted(neighbours[f.name])}
        entry.update(_fragment_entry(f))
        if not A.placed[k]:
            entry["notes"].append("not placed: no verified contact with the main assembly"
                                  + (f" (in sub-assembly {A.group[k]} with {len(groups[A.group[k]]) - 1} other(s))"
                                     if len(groups[A.group[k]]) > 1 else ""))
        fragment_report[f.name] = entry
    report = {
        "format": "reassemble-report/1", "version": __version__,
        "summary": {
            "fragments": len(frags), "placed": int(A.placed.sum()),
            "sub_assemblies": sum(len(g) > 1 for g in groups), "alone": sum(len(g) == 1 for g in groups),
            "contacts": len(A.contacts),
            "vertex_noise": _round(set_noise(frags) / size), "contact_tolerance": _round(reg_params.tolerance),
            "gap": _round(reg_params.gap), "thin_walled": thin_walled(frags),
            "timings_s": {k: round(v, 2) for k, v in timings.items()},
        },
        "groups": groups,
        "fragments": fragment_report,
        "contacts": [{"fragments": [names[c.a], names[c.b]], "score": _round(c.score),
                      "contact_area": _round(c.contact_area), "penetration_area": _round(c.penetration_area)}
                     for c in A.contacts],
        "warnings": warnings,
    }
    colors = fragment_colors(len(frags))
    with staged_directory(out, force=force) as tmp:
        write_json(tmp / "pairs.json", {"format": "reassemble-pairs/1", "convention": "T_target_source",
                                        "version": __version__, "pairs": _pairs_json(frags, results)})
        write_json(tmp / "report.json", report)
        write_json(tmp / "config.json", _resolved(seed, size, set_noise(frags), match=_resolved_match(config, frags),
                                                  segmentation=seg_params, registration=reg_params,
                                                  assembly=assembly_params))
        write_npz(tmp / "analysis.npz", **_analysis_arrays(frags, A.contacts, touching, size=size, config=config))
        write_glb(tmp / "assembled.glb", {f.name: (f.vertices, f.faces) for f in frags},
                  {n: T_world[k] for k, n in enumerate(names)}, colors=dict(zip(names, colors)))
        placed = np.flatnonzero(A.placed)
        if len(placed):
            offsets = np.cumsum([0] + [len(frags[k].vertices) for k in placed])
            write_ply(tmp / "assembled.ply",
                      np.vstack([transform_points(T_world[k], frags[k].vertices) for k in placed]),
                      np.vstack([frags[k].faces + o for k, o in zip(placed, offsets)]),
                      colors=np.vstack([np.tile(colors[k], (len(frags[k].vertices), 1)) for k in placed]))
        if debug:
            _write_debug(tmp, frags, results)
        write_json(tmp / "transforms.json", transforms)  # last: its presence means the run completed
    return report


def _analysis_arrays(frags: list[PreparedFragment], contacts, touching, *, size: float, config: MatchConfig) -> dict:
    """Arrays of ``analysis.npz``: ``names`` (n,), ``radii`` (r,) in mesh units and
    ``radii_relative``; per fragment k ``fracture_k`` (faces,) int8 and, when it has
    descriptors, ``H_k`` (faces, r) float32 mean curvature at the face centres; per contact i
    (``contact_pairs`` (c, 2) fragment indices) ``contact_i_a`` / ``contact_i_b`` (p, 3)
    touching points, each in its own fragment's coordinates."""
    arrays = {"names": np.array([f.name for f in frags]), "radii": size * np.asarray(config.radii, float),
              "radii_relative": np.asarray(config.radii, float),
              "contact_pairs": np.array([[c.a, c.b] for c in contacts], np.int64).reshape(-1, 2)}
    for k, f in enumerate(frags):
        arrays[f"fracture_{k}"] = f.segmentation.fracture.astype(np.int8)
        if f.descriptors is not None:
            arrays[f"H_{k}"] = f.descriptors.H.astype(np.float32)
    for i, (points_a, points_b) in enumerate(touching):
        arrays[f"contact_{i}_a"], arrays[f"contact_{i}_b"] = points_a, points_b
    return arrays


VIEW_HINT = "`reassemble run FRAGMENTS --out {folder}` makes one"
_PICTURE_FOLDERS = {"fragment": "fragments", "match": "matches"}
VIEWER_FACES = 200_000


def view_folder(
    folder: str | Path, *, truth: str | Path | None = None, radius: float | None = None, render: bool = True,
    viewer: bool = False, width: int = 640, height: int = 480, progress: bool = False,
) -> dict:
    """Pictures and ``report.html`` of a run folder (made by :func:`run_to_folder`).

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
    from .geometry import decimate
    from .files import glb_bytes, read_glb, write_bytes, write_text
    from .viz.report import report_html

    folder = Path(folder)
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
    relative = analysis["radii_relative"]
    r_index = len(relative) // 2
    if radius is not None:
        close = np.flatnonzero(np.isclose(relative, radius, rtol=1e-6))
        if len(close) == 0:
            raise ReassembleError(f"--radius {radius:g}: not one of this run's descriptor radii "
                                  f"({', '.join(f'{r:g}' for r in relative)}, fractions of the reference size)")
        r_index = int(close[0])
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


def _render_pictures(meshes, T_world, *, placed, colors, analysis, names, r_index, width, height, progress):
    """(PNG bytes per picture key, None) or ({}, why no picture can be made)."""
    from tqdm import tqdm

    from .files import png_bytes
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


def _largest(A, frags) -> int:
    main = np.flatnonzero(A.group == 0)
    return int(main[np.argmax([frags[k].surface.area for k in main])])


def demo_to_folder(
    out: str | Path, *, mesh: str = "spot", pieces: int = 8, seed: int = 1, force: bool = False, jobs: int = 1,
    progress: bool = False,
) -> tuple[dict, dict]:
    """Break ``mesh`` into ``out/puzzle``, reassemble it into ``out/result`` and score it.

    Returns the run's report and the score (also written to ``out/result/score.json``).
    """
    from .synth import BreakParams

    out = Path(out)
    check_output_folder(out, force=force)
    puzzle = break_to_folder(mesh, out / "puzzle", params=BreakParams(pieces=pieces), seed=seed, force=True)
    report = run_to_folder([puzzle / "fragments"], out / "result", seed=seed, force=True, jobs=jobs, progress=progress)
    score = evaluate_files(out / "result" / "transforms.json", puzzle / "ground_truth.json")
    write_json(out / "result" / "score.json", score)
    return report, score
