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

from . import arbiter, assembly
from .config import Config
from .descriptors import DescriptorParams, integral_invariants
from .errors import ReassembleError
from .files import check_output_folder, load_mesh, mesh_warning, resolve_mesh_path, write_npz
from .inputs import load_fragments
from .outputs import pairs_json, run_report, write_match_folder, write_run_folder
from .pairs import PairMemo, match_pairs, match_set, registration_params
from .prepare import (DescribedSet, PreparedFragment, describe_fragments, fracture_features, prepare_fragments,
                      reference_size, thin_walled)
from .puzzle import PuzzleFiles, break_to_folder, evaluate_files, read_puzzle
from .retrieval import candidates_only, first_pairs, more_pairs, partner_votes
from .segmentation import all_fracture, labels_from_contact

log = logging.getLogger(__name__)

__all__ = [  # the stages' entry points, and the puzzle files, importable from here
    "Config", "DescribedSet", "PreparedFragment", "PuzzleFiles", "Result", "break_to_folder",
    "describe_fragments", "describe_to_file", "evaluate_files", "match_pairs", "match_set", "match_to_folder",
    "prepare_fragments", "read_puzzle", "reassemble", "reference_size", "registration_params", "run_to_folder",
]


@dataclasses.dataclass
class Result:
    """What :func:`reassemble` found; lists are in sorted fragment-name order.

    Attributes
    ----------
    config : the Config of the run, with what was decided from the data filled in
        (``thin_walls``; ``gap`` and the registration tolerance measured): run again with
        it, the same fragments give the same result
    fragments : PreparedFragment per fragment (descriptors, segmentation, fracture features)
    size : reference size (:func:`prepare.reference_size`), mesh units
    pairs : (source, target) index pair -> registration.PairResult
    assembly : assembly.Assembly, None when only the pairs were matched
    T_world : (n, 4, 4) T_world_fragment per fragment (:func:`assembly.world_poses`)
    touching : per contact of the assembly, the touching points of either fragment
    fracture : (faces,) bool per fragment, its break surface after the assembly: the
        segmentation's labels where the fragment is not placed with others (the evidence's,
        for a fragment matched by its whole surface), else the
        faces in contact (:func:`segmentation.labels_from_contact`)
    timings : seconds per step
    fallback : when the set was segmented again (planar mates, ``config.segment.fallback``):
        the segmentation kept, whether it is not the first, and each tried assembly's
        whole-surface (contact, penetration) areas over the reference size squared; else None
    fallback_contact : that (contact, penetration) of this assembly, when compared
    votes : (n, n) partner votes (:func:`retrieval.partner_votes`) when only candidate
        pairs were registered (``config.retrieval``), else None (every pair was)
    """

    config: Config
    fragments: list[PreparedFragment]
    size: float
    pairs: dict
    assembly: assembly.Assembly | None = None
    T_world: np.ndarray | None = None
    touching: list | None = None
    fracture: list | None = None
    timings: dict = dataclasses.field(default_factory=dict)
    fallback: dict | None = None
    fallback_contact: list | None = None
    votes: np.ndarray | None = None


def reassemble(
    meshes: dict[str, tuple[np.ndarray, np.ndarray]], config: Config = Config(), *, assemble: bool = True,
    jobs: int = 1, scheduler: str | None = None, progress: bool = False,
) -> Result:
    """Reassemble fragments given as name -> (vertices (n, 3), faces (f, 3)), in memory.

    ``assemble`` False stops after matching the pairs (what ``reassemble match`` writes).
    ``jobs`` > 1 describes fragments and registers pairs in that many processes; the
    result does not depend on it, nor on ``scheduler`` (the address of a Dask cluster to do
    that work on instead). When the assembly leaves fragments unplaced, the set is
    segmented again, with the planar mates of its break faces labelled too and then with
    ``config.segment.fallback`` evidence, and matched and assembled again; the assembly
    with most whole-surface contact is kept (:mod:`arbiter`); a fragment still unplaced is
    then matched by its whole surface (``config.segment.whole_retry``), kept the same way; a
    set found thin-walled by the
    automatic test (``config.thin_walls`` None) is matched as solids too, kept the same way. With
    ``config.retrieval.min_fragments`` set, a large set registers candidate pairs only;
    fragments still unplaced in the kept assembly then ask for more partners until placed
    or registered against every other.
    """
    config.check()
    t0 = time.perf_counter()
    described = describe_fragments(meshes, config=config, jobs=jobs, scheduler=scheduler, progress=progress)
    describing = time.perf_counter() - t0
    memo = PairMemo()  # a retry registers again only the pairs a relabelled fragment is in
    groups = assembly.GroupMemo()  # ... and sub-assemblies of relabelled fragments
    first, retries = _segmentations(config, len(described.names))
    result = _match(described, first, jobs=jobs, scheduler=scheduler, progress=progress, memo=memo)
    result.timings["prepare"] += describing
    if not assemble:
        return result
    more = dict(jobs=jobs, scheduler=scheduler, progress=progress, memo=memo, groups=groups)
    _assemble(result, limit=config.retrieval.max_partners, **more)
    t0, tried = time.perf_counter(), [result]
    sherds = thin_walled(result.fragments)
    if sherds:
        _assemble(result, limit=None, **more)
        if config.thin_walls is not None:
            return result
        # an automatic verdict: flat sherds (tiles, plates) whose breaks are planar faces
        # match as solids too, where the strips' frames are no better than their faces;
        # the arbiter keeps the assembly with more contact, as for every retry
        log.info("thin-walled by the automatic test: matching the fragments as solids too")
        first, *retries = [dataclasses.replace(c, thin_walls=False) for c in [first, *retries]]
        again = _match(described, first, jobs=jobs, scheduler=scheduler, progress=progress, memo=memo)
        _assemble(again, limit=config.retrieval.max_partners, **more)
        tried.append(again)
        result = _better(result, again, config=config)
    for retry in retries:
        # another segmentation can only help a fragment that was described and still not placed
        if not any(not p and f.descriptors is not None for p, f in zip(result.assembly.placed, result.fragments)):
            break
        log.info("%d of %d fragments unplaced: segmenting with %s too",
                 np.count_nonzero(~result.assembly.placed), len(result.fragments), _label(retry))
        again = _match(described, retry, jobs=jobs, scheduler=scheduler, progress=progress, unless=tried,
                       memo=memo)
        if again is None:
            continue
        _assemble(again, limit=config.retrieval.max_partners, **more)
        tried.append(again)
        result = _better(result, again, config=config)
    if config.segment.whole_retry and not result.config.thin_walls and result.votes is None:
        result = _whole_surfaces(described, result, config=config, tried=tried, **more)
    if result is not tried[0] or first is not config:
        # what config.json records: this segmentation, with no retries (--config reproduces the run)
        segment = dataclasses.replace(result.config.segment, mates=bool(result.config.segment.mates), fallback=None,
                                      whole_retry=False)
        result.config = dataclasses.replace(result.config, segment=segment)
    if len(tried) > 1:
        result.timings = {**tried[0].timings, "fallback": time.perf_counter() - t0}
        result.fallback = {"method": _label(result.config), "kept": result is not tried[0],
                           "contact": {_label(r.config): r.fallback_contact for r in tried}}
    if not (sherds and result is tried[0]):  # the sherds' assembly above already asked every partner
        _assemble(result, limit=None, **more)
    return result


def _segmentations(config: Config, n: int) -> tuple[Config, list[Config]]:
    """The segmentation a run of ``n`` fragments starts with, and those it tries when
    fragments stay unplaced, in order.

    With ``segment.mates`` None: a set that registers every pair starts without planar
    mates and tries them next; a set that registers candidate pairs only
    (``config.retrieval``) starts with them and tries without. Then ``segment.fallback``.

    Notes
    -----
    A retry segments, registers and assembles the set again: with every pair registered
    the retry costs only the pairs of the relabelled fragments, but a candidate set spends
    rounds of asking for partners on a segmentation that missed its planar break faces (50
    Voronoi cells: 4.5 minutes of rounds ending with 33 of 50 unplaced, then solved with
    the mates). Labelling mates needs no threshold on roughness (:mod:`mates`), and a
    break face without a planar mate is left as it was.
    """
    seg = config.segment
    first, out = config, []
    if seg.mates is None:
        with_mates = dataclasses.replace(config, segment=dataclasses.replace(seg, mates=True))
        if candidates_only(config.retrieval, n):
            first = with_mates
            out.append(dataclasses.replace(config, segment=dataclasses.replace(seg, mates=False)))
        else:
            out.append(with_mates)
    if seg.fallback not in (None, seg.method):
        out.append(dataclasses.replace(config, segment=dataclasses.replace(seg, method=seg.fallback)))
    return first, out


def _whole_surfaces(described: DescribedSet, result: Result, *, config: Config, tried: list[Result], jobs: int,
                    scheduler: str | None, progress: bool, memo: PairMemo, groups: assembly.GroupMemo) -> Result:
    """The whole-surface retry (``segment.whole_retry``): each fragment ``result`` leaves
    unplaced, largest first, matched by its whole surface (``segment.whole``) beside the
    others' labels, and the set assembled again; the assembly with more whole-surface
    contact is kept (:mod:`arbiter`). Only the pairs of the relabelled fragment are
    registered again (``memo``). Each assembly tried is appended to ``tried``."""
    areas = [f.surface.area for f in result.fragments]
    for k in sorted(range(len(areas)), key=lambda k: (-areas[k], k)):
        if result.assembly.placed[k] or result.fragments[k].descriptors is None:
            continue
        segment = result.config.segment
        whole = tuple(sorted({*(segment.whole or ()), described.names[k]}))
        log.info("%s unplaced: matching it by its whole surface", described.names[k])
        asked = dataclasses.replace(config, thin_walls=False, segment=dataclasses.replace(segment, whole=whole))
        # the set's segmentation is the kept one's but for this fragment: only the features again
        segs = [f.segmentation for f in result.fragments]
        segs[k] = all_fracture(segs[k])
        frags = fracture_features(described, segs, {}, shell=False, config=asked, seed=asked.seed)
        again = _match(described, asked, jobs=jobs, scheduler=scheduler, progress=progress, memo=memo,
                       fragments=frags)
        _assemble(again, limit=config.retrieval.max_partners, jobs=jobs, scheduler=scheduler, progress=progress,
                  memo=memo, groups=groups)
        tried.append(again)
        result = _better(result, again, config=config)
    return result


def _label(config: Config) -> str:
    seg = config.segment
    return (("sherds" if config.thin_walls else seg.method) + ("+mates" if seg.mates else "")
            + (f"+whole:{','.join(seg.whole)}" if seg.whole else ""))


def _better(first: Result, second: Result, *, config: Config) -> Result:
    """The assembly with more whole-surface contact less penetration (:mod:`arbiter`),
    ``first`` on a tie; both assemblies' (contact, penetration) areas over the size squared
    are kept in ``fallback_contact``. The same described meshes and size in both: one set of
    whole-surface samples; each assembly scored at the gap it was made with."""
    scores = arbiter.assembly_contact([first.assembly, second.assembly], [f.mesh for f in first.fragments],
                                      size=first.size, params=[first.config.registration, second.config.registration],
                                      seed=config.seed)
    for r, score in zip((first, second), scores):
        r.fallback_contact = [round(float(c) / r.size**2, 6) for c in score]
    return second if arbiter.better(*scores, penetration_weight=config.registration.penetration_weight) else first


def _match(described: DescribedSet, config: Config, *, jobs: int, scheduler: str | None, progress: bool,
           unless: list[Result] = (), memo: PairMemo | None = None,
           fragments: list[PreparedFragment] | None = None) -> Result | None:
    """The segment, features and pairs steps on a described set; None when the fracture
    labels are those of a result in ``unless`` (matching them again would change nothing).
    ``fragments``: the set already segmented and featured with ``config`` (the pairs step only).
    With ``config.retrieval.min_fragments`` set, a set of that many fragments or more
    registers only candidate pairs: each fragment's best partners by votes (:mod:`retrieval`)."""
    t0 = time.perf_counter()
    if fragments is None:
        frags, size = prepare_fragments({}, config=config, seed=config.seed, jobs=jobs, scheduler=scheduler,
                                        described=described)
    else:
        frags, size = fragments, described.size
    if any(all(np.array_equal(a.segmentation.fracture, b.segmentation.fracture) for a, b in zip(frags, r.fragments)
               if a.segmentation is not None and b.segmentation is not None) for r in unless):
        return None
    registration = registration_params(frags, size=size, params=config.registration)
    votes = candidates = None
    if candidates_only(config.retrieval, len(frags)):
        votes = partner_votes([f.surface for f in frags], neighbours=config.retrieval.neighbours)
        candidates = first_pairs(votes, partners=config.retrieval.partners)
        log.info("%d fragments: registering %d candidate pairs of %d", len(frags), len(candidates),
                 len(frags) * (len(frags) - 1) // 2)
    t1 = time.perf_counter()
    pairs, registration = match_set(frags, size=size, params=registration, gap=config.gap, seed=config.seed,
                                    pairs=candidates, jobs=jobs, scheduler=scheduler, progress=progress, memo=memo)
    resolved = dataclasses.replace(config, thin_walls=thin_walled(frags), gap=registration.gap,
                                   registration=registration)
    return Result(resolved, frags, size, pairs, timings={"prepare": t1 - t0, "pairs": time.perf_counter() - t1},
                  votes=votes)


def _assemble(result: Result, *, limit: int | None, jobs: int = 1, scheduler: str | None = None,
              progress: bool = False, memo: PairMemo | None = None,
              groups: assembly.GroupMemo | None = None) -> None:
    """The assemble step: global assembly, world poses, touching points of every contact.

    With candidate pairs only (``result.votes``), a fragment left unplaced asks for its
    next ``config.retrieval.more`` partners (:func:`retrieval.more_pairs`); they are
    registered and the set assembled again, until every fragment is placed or has been
    registered against ``limit`` partners (None: every other). A placed fragment with
    less than ``config.retrieval.confidence`` of its break in contact asks too, up to
    ``config.retrieval.max_partners``. Called again on an assembled result, it only asks
    for more (and changes nothing when none are asked for).

    The assemblies that only decide who asks leave out the rounds of registering
    sub-assemblies against each other (``assembly.group_rounds``); the last assembly, on
    every pair registered by then, has them. They can only add merges to the greedy ones,
    and on 100 Voronoi cells they made an assembly of 1 s take 338 s
    (``benchmarks/studies/assembly_rounds.py``), paid again in every round.
    """
    t0 = time.perf_counter()
    again = result.assembly is not None
    frags, size, config = result.fragments, result.size, result.config
    if progress and not again:
        log.info("assembling %d fragments", len(frags))
    surfaces, meshes = [f.surface for f in frags], [f.mesh for f in frags]
    deferred = result.votes is not None and config.assembly.group_rounds > 0

    def assemble_now(*, groups_too: bool = True):
        params = config.assembly if groups_too else dataclasses.replace(config.assembly, group_rounds=0)
        return assembly.assemble(surfaces, meshes, result.pairs, size=size, params=params,
                                 reg_params=config.registration, seed=config.seed, jobs=jobs, scheduler=scheduler,
                                 memo=groups)

    if not again:
        result.assembly = assemble_now(groups_too=not deferred)
    asked = False
    retrieval = config.retrieval
    while result.votes is not None:
        # a fragment with no fracture keypoints matches nothing (register_pair): no use asking
        can = np.array([len(f.surface.keypoints) >= 3 for f in frags])
        placed = result.assembly.placed
        unplaced = np.flatnonzero(~placed & can)
        open_break = np.flatnonzero(placed & can & (result.assembly.confidence < retrieval.confidence))
        registered = set(result.pairs)
        new = sorted(set(more_pairs(result.votes, unplaced, registered, count=retrieval.more, limit=limit))
                     | set(more_pairs(result.votes, open_break, registered, count=retrieval.more,
                                      limit=retrieval.max_partners)))
        if not new:
            break
        asked = True
        log.info("%d fragments unplaced, %d placed with most of the break open: registering %d more candidate "
                 "pairs", len(unplaced), len(open_break), len(new))
        t1 = time.perf_counter()
        added = match_pairs(frags, size=size, pairs=new, params=config.registration, seed=config.seed, jobs=jobs,
                            scheduler=scheduler, progress=progress, memo=memo)
        result.pairs = dict(sorted({**result.pairs, **added}.items()))
        result.timings["pairs"] += time.perf_counter() - t1
        t0 += time.perf_counter() - t1  # the registration counts as pairs, not assembly
        result.assembly = assemble_now(groups_too=False)
    if again and not asked:
        return
    if deferred:
        result.assembly = assemble_now()
    reg = config.registration
    result.T_world = assembly.world_poses(result.assembly, surfaces, gap=config.assembly.world_gap * size)
    result.touching = assembly.contact_points(result.assembly, surfaces, meshes, tol=reg.tolerance * size,
                                              normal_angle=reg.normal_angle, count=config.assembly.touching_points,
                                              gap=reg.gap * size)
    result.fracture = _break_surfaces(result)
    result.timings["assembly"] = result.timings.get("assembly", 0.0) * again + time.perf_counter() - t0


def _break_surfaces(result: Result) -> list[np.ndarray]:
    """Each fragment's fracture faces after the assembly (``Result.fracture``)."""
    reg, size, a = result.config.registration, result.size, result.assembly
    touching = assembly.contact_faces(a, [f.mesh for f in result.fragments], tol=reg.tolerance * size,
                                      gap=reg.gap * size)
    out = []
    for k, f in enumerate(result.fragments):
        seg = f.segmentation
        together = np.count_nonzero(a.group == a.group[k])
        if seg is None or together < 2:  # alone: the evidence's labels (not a whole-surface retry's)
            out.append(np.zeros(len(f.faces), bool) if seg is None else
                       np.asarray(seg.fracture if seg.original is None else ~seg.original, bool).copy())
            continue
        out.append(labels_from_contact(seg, touching[k], keep_open=together < len(a.group)))
    return out


def _load(inputs, out, *, config: Config, seed: int | None, force: bool):
    """The set-up of run and match: refuse an existing output first (before minutes of
    work, not after), then read the fragments. Returns (meshes, warnings, config with
    ``seed``, seconds)."""
    t0 = time.perf_counter()
    check_output_folder(out, force=force)
    meshes, warnings = load_fragments(inputs, fill_holes=config.fill_holes, split=config.split_bodies)
    config = config if seed is None else dataclasses.replace(config, seed=seed)
    return meshes, warnings, config, time.perf_counter() - t0


def match_to_folder(
    inputs: list[str | Path], out: str | Path, *, config: Config = Config(), seed: int | None = None,
    force: bool = False, debug: bool = False, jobs: int = 1, scheduler: str | None = None,
    progress: bool = False,
) -> dict:
    """Segment the fragments, register every pair, and write ``pairs.json`` (+ debug files).

    Writes into ``out`` (built aside, moved into place when complete): ``pairs.json`` with
    each pair's ranked candidates (``T_target_source``, score, contact and penetration
    areas) and verdict, ``fragments.json`` (fracture area, regions, warnings per fragment),
    ``config.json`` (the resolved configuration); with ``debug``, ``labels/NAME.ply``
    (fracture faces' vertices red) and ``matches/SOURCE__TARGET.npz`` (matched keypoints of
    the best candidate, each in its own fragment's frame). ``seed``: instead of ``config.seed``.
    """
    meshes, warnings, config, _ = _load(inputs, out, config=config, seed=seed, force=force)
    result = reassemble(meshes, config, assemble=False, jobs=jobs, scheduler=scheduler, progress=progress)
    write_match_folder(out, result, warnings=warnings, force=force, debug=debug)
    pairs = pairs_json(result.fragments, result.pairs)
    return {"fragments": len(result.fragments), "pairs": len(pairs), "touching": sum(p["touching"] for p in pairs),
            "warnings": warnings, "pair_list": pairs}


def run_to_folder(
    inputs: list[str | Path], out: str | Path, *, config: Config = Config(), seed: int | None = None,
    force: bool = False, debug: bool = False, jobs: int = 1, scheduler: str | None = None,
    progress: bool = False,
) -> dict:
    """The main job: fragments in, the assembled object and its report out.

    Writes into ``out`` (built aside, moved into place only when complete, so no
    half-written ``transforms.json`` is ever left): ``transforms.json`` (per file stem
    ``T_world_fragment``, ``placed``, ``confidence``, ``group``), ``assembled.glb`` (one
    named node per fragment, its pose as the node transform), ``assembled.ply`` (the placed
    fragments in world coordinates, one colour each), ``report.json``, ``pairs.json``,
    ``config.json`` (:func:`config.read_config` reads it back), ``analysis.npz`` (what
    :func:`view.view_folder` draws: per-face fracture labels and mean curvature, the
    touching points of every contact); with ``debug`` the files of :func:`match_to_folder`'s
    ``debug``. ``seed``: instead of ``config.seed``.

    Returns the report (a dict).
    """
    meshes, warnings, config, seconds = _load(inputs, out, config=config, seed=seed, force=force)
    result = reassemble(meshes, config, jobs=jobs, scheduler=scheduler, progress=progress)
    result.timings["prepare"] += seconds  # reading the files counts as preparing them
    report = run_report(result, warnings=warnings)
    write_run_folder(out, result, report=report, force=force, debug=debug)
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
                  H=d.H, H_rob=d.H_rob, K2=d.K2, SA=d.SA, D=d.D, SD2=d.SD2, normal_area=d.normal_area)
    if d.K2_cov is not None:
        arrays.update(K2_cov=d.K2_cov, k1=d.k1, k2=d.k2, dir1=d.dir1, normal=d.normal)
    write_npz(out, compress=False, **arrays)
    return {"vertices": len(d.points), "radii": d.radii.tolist(), "diagonal": diag, "timings": d.timings}


