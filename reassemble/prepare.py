"""The fragment set through the first stages: describe, segment, features.

:func:`describe_fragments` measures each fragment's vertex noise, picks the vertices to
match on and computes the integral invariants at the face centres; :func:`prepare_fragments`
then segments the whole set into fracture and original surface and extracts each fragment's
fracture features.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from tqdm import tqdm

from .config import Config
from .descriptors import integral_invariants
from .errors import ReassembleError
from .features import empty_surface, fracture_surface
from .geometry import denoise, face_areas, taubin_smooth, vertex_noise
from .mates import relabel_planar_mates
from .parallel import pool_map
from .registration import with_noise
from .retrieval import candidates_only
from .segmentation import Segmentation, all_fracture, segment
from .shells import is_thin_shell, strip_frames, strip_segmentation, wall_thickness
from .surface_mates import relabel_surface_mates

log = logging.getLogger(__name__)


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


def _describe(task):
    """(Descriptors or None, note) of one fragment; a failure is a note, not fatal."""
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
    if float(np.median(noise)) <= threshold:
        return [v for v, _ in meshes], 0
    first = [denoise(v, f, target=0.5 * threshold) for v, f in meshes]
    iterations = max(it for _, it in first)
    return [taubin_smooth(v, f, iterations - it) if it < iterations else v
            for (v, it), (_, f) in zip(first, meshes)], iterations



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
    config: Config = Config(),
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
) -> DescribedSet:
    """Vertex noise, the copies to match on and the descriptors at their face centres.

    ``jobs`` > 1 computes the descriptors of that many fragments at once, in processes;
    ``scheduler``, on the Dask cluster at that address. Raises ReassembleError when no fragment can be described.
    """
    names = sorted(meshes)
    pairs = [meshes[n] for n in names]
    size = reference_size(pairs)
    radii = size * np.asarray(config.radii)
    params = config.describe
    noise = [vertex_noise(v) for v, _ in pairs]
    # noise above a fifth of the finest radius swamps the finest scale (crease angles, face
    # normals, finest invariants): match on smoothed copies (docs/method/descriptors.md, CHANGELOG.md)
    matched, smoothing = _smoothed_copies(pairs, noise, threshold=config.denoise * radii[0])
    if smoothing:
        log.info("vertex noise %.3g x size, over %g x the finest radius: matching on copies smoothed %d times",
                 float(np.median(noise)) / size, config.denoise, smoothing)
    tasks = [(v, f, radii, params, config.radii[-1]) for v, (_, f) in zip(matched, pairs)]
    descriptors, notes = [], {}
    for name, (d, note) in zip(names, tqdm(pool_map(_describe, tasks, jobs=jobs, scheduler=scheduler), total=len(tasks),
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
    config: Config = Config(),
    seed: int = 0,
    jobs: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
    described: DescribedSet | None = None,
) -> tuple[list[PreparedFragment], float]:
    """Descriptors at the face centres, segmentation over the whole set, fracture features.

    ``jobs`` > 1 computes the descriptors of that many fragments at once, in processes (and
    compares planar mates' outlines so), or ``scheduler`` on a Dask cluster.
    ``described``: the set's :func:`describe_fragments` with this ``config``, when already
    computed (``meshes`` is then ignored).
    Returns the prepared fragments (in sorted name order) and the reference size.
    """
    config.check()
    if described is None:
        described = describe_fragments(meshes, config=config, jobs=jobs, scheduler=scheduler, progress=progress)
    good = [k for k, d in enumerate(described.descriptors) if d is not None]
    thickness = {k: wall_thickness(described.matched[k], described.meshes[k][1]) for k in good}
    segs, shell = segment_set(described, thickness, config=config, seed=seed, jobs=jobs, scheduler=scheduler)
    return fracture_features(described, segs, thickness, shell=shell, config=config, seed=seed), described.size


def segment_set(described: DescribedSet, thickness: dict[int, np.ndarray], *, config: Config, seed: int,
                jobs: int = 1, scheduler: str | None = None):
    """The segment step: (Segmentation or None per fragment, whether they are thin-walled sherds).

    Sherds (``config.thin_walls``, or None and most fragments are) are segmented along
    their break strips (:func:`shells.strip_segmentation`), solids all together
    (:func:`segmentation.segment`), those named in ``config.segment.whole`` then labelled
    fracture all over; ``thickness``: wall thickness of each described fragment;
    ``jobs``, ``scheduler``: where planar mates are compared (:func:`mates.relabel_planar_mates`).
    """
    matched, faces = described.matched, [f for _, f in described.meshes]
    good = sorted(thickness)
    segs = [None] * len(described.names)
    shell = config.thin_walls
    if shell is None:
        shell = 2 * sum(is_thin_shell(matched[k], faces[k], thickness[k]) for k in good) > len(good)
    if shell:
        log.info("thin-walled fragments (sherds): matched along their break strips")
        for k in good:
            segs[k] = strip_segmentation(matched[k], faces[k], thickness[k])
    else:
        for k, s in zip(good, segment([(matched[k], faces[k]) for k in good],
                                      [described.descriptors[k] for k in good],
                                      size=described.size, params=config.segment, seed=seed)):
            segs[k] = s
        if config.segment.mates and good:
            segs = _with_mates(described, segs, good, config=config, seed=seed, jobs=jobs, scheduler=scheduler)
        whole = set(config.segment.whole or ())
        for name in sorted(whole - set(described.names)):
            log.warning("segment.whole: no fragment named %s in the set", name)
        for k in good:
            if described.names[k] in whole:
                segs[k] = all_fracture(segs[k])
    return segs, bool(shell)


def _with_mates(described: DescribedSet, segs: list, good: list[int], *, config: Config, seed: int, jobs: int = 1,
                scheduler: str | None = None) -> list:
    """``segs`` with the planar mates of labelled planar break faces labelled fracture
    (:func:`mates.relabel_planar_mates`), at the contact tolerance the registration will use,
    and, in a set that registers every pair, the smooth regions with a mate on another
    fragment whatever their labels (:func:`surface_mates.relabel_surface_mates`)."""
    reg = with_noise(config.registration, noise=float(np.median([described.noise[k] for k in good])),
                     size=described.size)
    found = [segs[k] for k in good]
    relabelled, changed = relabel_planar_mates(
        [(described.matched[k], described.meshes[k][1]) for k in good], found, tol=reg.tolerance * described.size,
        min_area=reg.plane_area * float(np.median([s.fracture_area for s in found])),
        min_overlap=config.segment.mate_overlap, rng=np.random.default_rng(seed), jobs=jobs, scheduler=scheduler)
    log.info("planar mates: %d fragment(s) relabelled", len(changed))
    if not candidates_only(config.retrieval, len(described.names)):  # every pair of regions is compared
        relabelled, changed = relabel_surface_mates(
            [(described.matched[k], described.meshes[k][1]) for k in good], relabelled,
            tol=reg.tolerance * described.size, min_area=SURFACE_MATE_AREA * float(np.median([s.area for s in relabelled])),
            min_overlap=config.segment.mate_overlap, crease=config.segment.crease_angle,
            rng=np.random.default_rng(seed))
        log.info("surface mates: %d fragment(s) relabelled", len(changed))
    out = list(segs)
    for k, s in zip(good, relabelled):
        out[k] = s
    return out


SURFACE_MATE_AREA = 0.02  # smooth regions under this share of the median fragment's area are not compared


def fracture_features(described: DescribedSet, segs: list, thickness: dict[int, np.ndarray], *, shell: bool,
                      config: Config, seed: int) -> list[PreparedFragment]:
    """The features step: each fragment's keypoints, signatures and samples (:func:`features.fracture_surface`)."""
    params = config.features
    n_signature = params.signature_radii or len(config.radii)  # one width for every fragment's signatures
    # on sherds one keypoint pair is a hypothesis: the cost grows as the product of the
    # keypoint counts (at the solids' spacing ~700 per vessel sherd)
    spacing = params.keypoint_spacing * described.size * (params.shell_spacing if shell else 1.0)
    notes, smoothing = dict(described.notes), described.smoothing
    rngs = np.random.default_rng(seed).spawn(len(described.names))
    out = []
    for k, (name, (given, f), v, d, s, rng, sigma) in enumerate(zip(
            described.names, described.meshes, described.matched, described.descriptors, segs, rngs,
            described.noise)):
        if s is None:
            s = Segmentation(np.zeros(len(f), bool), np.zeros(len(f)), np.zeros(len(f), int),
                             np.full(len(f), -1), 0.0, float(face_areas(v, f).sum()))
            surf = empty_surface(v, f, n_radii=n_signature, n_samples=params.samples, rng=rng)
            log.warning("%s: %s", name, notes[name])
        else:
            surf = fracture_surface(v, f, s, d, spacing=spacing, n_samples=params.samples,
                                    signature_radii=n_signature, rng=rng)
            if shell and len(surf.keypoints):
                n, t = strip_frames(v, f, thickness[k], surf.keypoints, surf.keypoint_normals, rng=rng)
                # no rims: a strip's two rims are its wall edges, a wall thickness apart (a
                # few tolerances), and its frames already fix where along it a mate lies
                surf = dataclasses.replace(surf, keypoint_normals=n, keypoint_tangents=t, rim=None,
                                           rim_directions=None)
            if surf.fracture_area == 0.0:
                notes[name] = "no fracture surface found; it can only be placed by others"
                log.warning("%s: %s", name, notes[name])
        out.append(PreparedFragment(name, given, f, d, s, surf, notes.get(name, ""), sigma, smoothing,
                                    v if smoothing else None, shell))
    return out


def set_noise(fragments: list[PreparedFragment]) -> float:
    """The vertex noise of a fragment set (mesh units): the median of its fragments'."""
    return float(np.median([f.noise for f in fragments])) if fragments else 0.0


def thin_walled(fragments: list[PreparedFragment]) -> bool:
    """Whether the set was prepared as thin-walled sherds (:func:`prepare_fragments` decides for all)."""
    return bool(fragments) and all(f.shell for f in fragments)

