"""Global assembly and `reassemble run`: the smoke set solved, outputs, strays, determinism."""

import dataclasses
import json
import shutil

import numpy as np
import pytest

from data_synth.sets import PuzzleSpec, smoke_set
from reassemble.assembly import Assembly, refine, world_poses
from reassemble.errors import ReassembleError
from reassemble.geometry import invert_transform, make_transform, random_rotation, rotation_angle_deg
from reassemble.files import read_transforms
from reassemble.pipeline import break_to_folder, evaluate_files, read_puzzle, run_to_folder
from reassemble.synth import BreakParams

from .conftest import COW, SMALL_COW, shared_run, tree_digest


def _score(run_dir, puzzle_dir) -> dict:
    report = evaluate_files(run_dir / "transforms.json", puzzle_dir / "ground_truth.json")
    return report["alignments"]["anchor_largest"]["summary"]


@pytest.mark.parametrize("spec", [pytest.param(s, marks=shared_run((s.mesh, s.pieces, s.seed))) for s in smoke_set()],
                         ids=lambda s: s.name)
@pytest.mark.slow
def test_run_solves_smoke_set(spec, puzzles, request):
    key = (spec.mesh, spec.pieces, spec.seed)
    assert spec == PuzzleSpec(*key)  # plain breaks: the shared puzzles and runs are these
    if key == COW:
        request.getfixturevalue("run_dir")  # the suite's run of it, through the command line
    s = _score(puzzles.run(*key), puzzles.puzzle(*key))
    assert s["solved"], s
    assert s["rot_geodesic_rmse_deg"] < 0.5


@pytest.mark.slow
def test_run_outputs(run_dir, puzzle_dir):
    import trimesh

    names = sorted(p.stem for p in (puzzle_dir / "fragments").iterdir())
    T = read_transforms(run_dir / "transforms.json")
    assert sorted(T) == names
    assert all(t["placed"] and 0.5 < t["confidence"] <= 1.0 for t in T.values())
    # world = the largest placed fragment's file frame: one identity
    assert sum(np.allclose(t["transform"], np.eye(4)) for t in T.values()) == 1
    scene = trimesh.load(run_dir / "assembled.glb")
    for n in names:
        np.testing.assert_allclose(scene.graph.get(n)[0], T[n]["transform"], atol=1e-9)
    ply = trimesh.load(run_dir / "assembled.ply", process=False)
    mesh = sum(len(read_puzzle(puzzle_dir / "ground_truth.json", with_labels=False).meshes[n].faces) for n in names)
    assert len(ply.faces) == mesh
    report = json.loads((run_dir / "report.json").read_text())
    assert report["summary"]["placed"] == len(names) and report["groups"] == [names]
    contacts = {tuple(c["fragments"]) for c in report["contacts"]}
    truth = json.loads((puzzle_dir / "ground_truth.json").read_text())
    big = {tuple(sorted(c["fragments"])) for c in truth["contacts"] if c["area"] > 0.01 * truth["object"]["area"]}
    assert big <= contacts  # every large true contact is reported
    for c in report["contacts"]:
        assert c["penetration_area"] <= 0.02 * c["contact_area"] + 1e-12
    config = json.loads((run_dir / "config.json").read_text())
    assert {"describe", "segment", "features", "registration", "assembly", "reference_size"} <= set(config)


@pytest.mark.slow
@shared_run(SMALL_COW)
def test_run_recovers_a_moved_fragment(puzzles, tmp_path, rng):
    """Moving one input file by a known rigid motion moves its result by exactly the inverse."""
    import trimesh

    puzzle_dir, run_dir = puzzles.puzzle(*SMALL_COW), puzzles.run(*SMALL_COW)  # a smoke-set case: shared
    frags = tmp_path / "fragments"
    shutil.copytree(puzzle_dir / "fragments", frags)
    before = read_transforms(run_dir / "transforms.json")
    name = next(n for n, t in sorted(before.items()) if not np.allclose(t["transform"], np.eye(4)))  # not the anchor
    M = make_transform(random_rotation(rng), rng.normal(size=3))
    mesh = trimesh.load(frags / f"{name}.ply", process=False)
    mesh.apply_transform(M)
    mesh.export(frags / f"{name}.ply")
    run_to_folder([frags], tmp_path / "out", seed=0)
    after = read_transforms(tmp_path / "out" / "transforms.json")
    anchor = next(n for n, t in before.items() if np.allclose(t["transform"], np.eye(4)))
    assert anchor != name
    expected = before[name]["transform"] @ invert_transform(M)
    # not bit-identical: the descriptor grids are axis-aligned, so a moved input samples
    # differently; 0.2 % of the diagonal is 5x tighter than strict part accuracy
    diag = json.loads((puzzle_dir / "ground_truth.json").read_text())["object"]["diagonal"]
    assert rotation_angle_deg(after[name]["transform"][:3, :3], expected[:3, :3]) < 0.2
    assert np.linalg.norm(after[name]["transform"][:3, 3] - expected[:3, 3]) < 2e-3 * diag


@pytest.mark.slow
def test_stray_fragment_is_not_placed(puzzles, tmp_path):
    """A fragment of the torus among the 2-piece cow's: not placed (and says why), the cow solved."""
    puzzle_dir = puzzles.puzzle(*SMALL_COW)
    stray_puzzle = tmp_path / "torus"
    break_to_folder("torus", stray_puzzle, params=BreakParams(pieces=3), seed=4)
    frags = tmp_path / "fragments"
    shutil.copytree(puzzle_dir / "fragments", frags)
    shutil.copy(stray_puzzle / "fragments" / "fragment_00.ply", frags / "stray.ply")
    report = run_to_folder([frags], tmp_path / "out", seed=0)
    assert not report["fragments"]["stray"]["placed"]
    assert report["fragments"]["stray"]["notes"]
    T = read_transforms(tmp_path / "out" / "transforms.json")
    assert not T["stray"]["placed"]
    assert sum(t["placed"] for t in T.values()) == 2
    # the cow pieces alone, scored against their truth: both right
    from reassemble.files import write_json

    write_json(tmp_path / "cow.json", {"fragments": {n: {"transform": t["transform"].tolist(), "placed": True}
                                                     for n, t in T.items() if n != "stray"}})
    s = evaluate_files(tmp_path / "cow.json", puzzle_dir / "ground_truth.json")["alignments"]["anchor_largest"]
    assert s["summary"]["solved"]


@pytest.mark.slow
def test_run_refuses_existing_output_and_keeps_inputs(run_dir, puzzle_dir):
    before = tree_digest(puzzle_dir)
    with pytest.raises(ReassembleError, match="exists"):
        run_to_folder([puzzle_dir / "fragments"], run_dir, seed=0)
    assert tree_digest(puzzle_dir) == before


@pytest.mark.slow
def test_interrupted_run_leaves_nothing(puzzles, tmp_path, monkeypatch):
    import reassemble.assembly

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(reassemble.assembly, "assemble", boom)
    with pytest.raises(KeyboardInterrupt):  # the last stage before the writing: all else is done
        run_to_folder([puzzles.puzzle(*SMALL_COW) / "fragments"], tmp_path / "out", seed=0)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_refine_recovers_perturbed_poses(puzzle, prepared):
    frags, size = prepared
    truth = np.array([puzzle.ground_truth["fragments"][f.name]["transform"] for f in frags])
    rng = np.random.default_rng(7)
    noisy = truth.copy()
    for k in range(1, len(frags)):
        axis = rng.normal(size=3)
        R = make_transform(_axis_angle(axis / np.linalg.norm(axis), np.radians(1.0)), rng.normal(size=3) * 0.003 * size)
        centre = truth[k][:3, :3] @ frags[k].vertices.mean(axis=0) + truth[k][:3, 3]
        about = make_transform(np.eye(3), centre) @ R @ make_transform(np.eye(3), -centre)
        noisy[k] = about @ truth[k]
    out = refine(noisy, [f.surface for f in frags], tol=0.006 * size, anchor=0)
    assert not np.shares_memory(out, noisy)
    for k in range(1, len(frags)):
        assert rotation_angle_deg(out[k][:3, :3], truth[k][:3, :3]) < 0.1
        c = frags[k].vertices.mean(axis=0)
        assert np.linalg.norm(out[k][:3, :3] @ c + out[k][:3, 3] - truth[k][:3, :3] @ c - truth[k][:3, 3]) < 1e-3 * size


@pytest.mark.slow
def test_refine_converges_where_only_rims_fix_a_turn(tmp_path):
    """A torus in three by mixed cuts, with scan noise: each break is a disk whose turn about
    the tube is fixed by little relief, and contact alone has a minimum a few degrees off.
    The rims pull the joint refinement to the truth, slowly: a fixed 15 iterations left one
    fragment 2.3 degrees off (unsolved); iterated until it converges, it is solved."""
    from reassemble.files import bundled_meshes

    params = BreakParams(pieces=3, style="mixed", noise=0.001)
    break_to_folder(bundled_meshes()["torus"], tmp_path / "puzzle", params=params, seed=0)
    run_to_folder([tmp_path / "puzzle" / "fragments"], tmp_path / "out", seed=0)
    s = _score(tmp_path / "out", tmp_path / "puzzle")
    assert s["solved"], s
    assert s["rot_geodesic_rmse_deg"] < 0.5


def _axis_angle(axis, angle):
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_world_poses_put_unplaced_groups_apart():
    from reassemble.features import FractureSurface

    rng = np.random.default_rng(0)
    cube = rng.random((200, 3))
    empty = np.zeros((0, 3))
    surfs = [FractureSurface(empty, empty, np.zeros((0, 2)), empty, empty, 0.0, cube, 0.01, 0.0, 1.0)
             for _ in range(4)]
    shift = make_transform(np.eye(3), [0.5, 0, 0])
    A = Assembly(np.array([np.eye(4), shift, np.eye(4), np.eye(4)]), np.array([0, 0, 1, 2]),
                 np.array([True, True, False, False]), np.zeros(4))
    T = world_poses(A, surfs, gap=0.1)
    np.testing.assert_allclose(T[:2], A.T_group_fragment[:2])
    boxes = [(cube @ t[:3, :3].T + t[:3, 3]) for t in T]
    main_hi = max(boxes[0][:, 0].max(), boxes[1][:, 0].max())
    assert boxes[2][:, 0].min() >= main_hi + 0.1 - 1e-9
    assert boxes[3][:, 0].min() >= boxes[2][:, 0].max() + 0.1 - 1e-9


@pytest.mark.slow
def test_missing_fragment_others_still_right(puzzles, tmp_path):
    puzzle = puzzles.puzzle("torus", 5, 2)  # a smoke-set case
    frags = tmp_path / "fragments"
    frags.mkdir()
    names = sorted(p.stem for p in (puzzle / "fragments").iterdir())
    for n in names[1:]:  # one fragment lost
        shutil.copy(puzzle / "fragments" / f"{n}.ply", frags)
    # the learned evidence misses one smooth, rimless break face of this torus
    # (docs/method/segmentation.md, known failures): the fallback segmentation finds it
    report = run_to_folder([frags], tmp_path / "out", seed=0)
    assert report["summary"]["fallback"]["kept"], report["summary"]
    T = read_transforms(tmp_path / "out" / "transforms.json")
    truth = read_transforms(puzzle / "ground_truth.json")
    assert sorted(T) == names[1:] and all(t["placed"] for t in T.values())
    diag = json.loads((puzzle / "ground_truth.json").read_text())["object"]["diagonal"]
    ref = names[1]
    for n in names[2:]:
        got = invert_transform(T[ref]["transform"]) @ T[n]["transform"]
        want = invert_transform(truth[ref]["transform"]) @ truth[n]["transform"]
        assert rotation_angle_deg(got[:3, :3], want[:3, :3]) < 0.5
        assert np.linalg.norm(got[:3, 3] - want[:3, 3]) < 0.005 * diag


@pytest.mark.slow
@shared_run(SMALL_COW)
def test_units_do_not_matter(puzzles, tmp_path):
    """The same fragments in millimetres instead of metres: the same result, up to scale."""
    import trimesh

    puzzle_dir, run_dir = puzzles.puzzle(*SMALL_COW), puzzles.run(*SMALL_COW)  # a smoke-set case: shared
    scaled = tmp_path / "mm"
    scaled.mkdir()
    for p in sorted((puzzle_dir / "fragments").iterdir()):
        m = trimesh.load(p, process=False)
        trimesh.Trimesh(m.vertices * 1000.0, m.faces, process=False).export(scaled / p.name)
    run_to_folder([scaled], tmp_path / "out", seed=0)
    metres, millimetres = read_transforms(run_dir / "transforms.json"), read_transforms(tmp_path / "out" / "transforms.json")
    diag = max(np.linalg.norm(np.ptp(trimesh.load(p).vertices, axis=0)) for p in (puzzle_dir / "fragments").iterdir())
    assert sorted(metres) == sorted(millimetres)
    for name, m in metres.items():
        mm = millimetres[name]
        assert m["placed"] == mm["placed"]
        assert rotation_angle_deg(m["transform"][:3, :3], mm["transform"][:3, :3]) < 0.05
        assert np.linalg.norm(m["transform"][:3, 3] - mm["transform"][:3, 3] / 1000.0) < 1e-3 * diag
        assert abs(m["confidence"] - mm["confidence"]) < 0.02


@pytest.mark.slow
def test_gap_between_pieces_is_measured_and_kept(tmp_path):
    """Material lost at the break (mates 1.5 % of the diagonal apart): the gap is measured,
    every piece placed where it was, the gap kept (closing it would shift the pieces)."""
    puzzle = tmp_path / "puzzle"
    break_to_folder("torus", puzzle, params=BreakParams(pieces=4, gap=0.015), seed=0)
    report = run_to_folder([puzzle / "fragments"], tmp_path / "out", seed=0)
    gt = json.loads((puzzle / "ground_truth.json").read_text())
    size = json.loads((tmp_path / "out" / "config.json").read_text())["reference_size"]
    measured = report["summary"]["gap"] * size / gt["object"]["diagonal"]
    assert 0.011 < measured < 0.016, measured  # erosion along vertex normals: a bit under the nominal gap
    s = _score(tmp_path / "out", puzzle)
    assert s["solved"], s
    assert s["rot_geodesic_rmse_deg"] < 1.0


@pytest.mark.slow
def test_no_gap_is_found_where_there_is_none(run_dir):
    assert json.loads((run_dir / "report.json").read_text())["summary"]["gap"] == 0.0
    assert json.loads((run_dir / "config.json").read_text())["registration"]["gap"] == 0.0


@pytest.mark.slow
def test_estimate_gap_recovers_a_known_separation(puzzle, prepared, rng):
    """Two mating fragments moved a known distance apart along their contact, and started
    touching (as plain ICP leaves them): the separation and the pose are recovered."""
    from scipy.spatial import cKDTree

    from reassemble.features import offset_surface
    from reassemble.geometry import transform_points
    from reassemble.registration import estimate_gap, icp

    frags, size = prepared
    names = [f.name for f in frags]
    contact = max(puzzle.ground_truth["contacts"], key=lambda c: c["area"])
    i, j = (names.index(n) for n in contact["fragments"])
    T = {n: np.asarray(puzzle.ground_truth["fragments"][n]["transform"]) for n in names}
    T_true = invert_transform(T[names[j]]) @ T[names[i]]
    source, target = frags[i].surface, frags[j].surface
    gap = 0.02 * size
    # the target's fracture surface moved back by the gap: the mates are now `gap` apart at T_true
    shrunk = offset_surface(target, -gap)
    tol = 0.006 * size
    # touching, as plain ICP leaves them: moved onto it along the contact's mean normal (ICP
    # from the true pose itself reaches only 3 tolerances, 0.018 x size, across the gap: it
    # slid off on the 4-piece cow after a small change to the segmentation)
    near = cKDTree(transform_points(T_true, source.samples)).query(target.samples)[0] < 2 * gap
    normal = target.sample_normals[near].mean(axis=0)
    T_touch = make_transform(np.eye(3), -gap * normal / np.linalg.norm(normal)) @ T_true
    closed = icp(source, shrunk, T_touch, tol=tol)
    T_est, g = estimate_gap(source, shrunk, closed, tol=tol, max_gap=0.08 * size)
    assert abs(g - gap) < 0.15 * gap, (g / size, gap / size)
    assert rotation_angle_deg(T_est[:3, :3], T_true[:3, :3]) < 1.0
    assert np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]) < 0.005 * size


@pytest.mark.slow
def test_heavy_noise_is_matched_on_smoothed_copies(tmp_path):
    """Vertex noise of 0.5 % of the diagonal: matched on smoothed copies, all placed right,
    and the outputs keep the given (noisy) geometry."""
    import trimesh

    puzzle = tmp_path / "puzzle"
    break_to_folder("torus", puzzle, params=BreakParams(pieces=4, noise=0.005), seed=0)
    # under this noise the learned evidence misses breaks of the smooth torus (2 of 4 placed,
    # with a gap): the mixture fallback places all and must be kept (scored at its own gap)
    report = run_to_folder([puzzle / "fragments"], tmp_path / "out", seed=0)
    assert all(f["smoothing_iterations"] > 0 for f in report["fragments"].values())
    s = _score(tmp_path / "out", puzzle)
    assert s["solved"], s
    given = sum(len(trimesh.load(p, process=False).vertices) for p in (puzzle / "fragments").iterdir())
    placed = trimesh.load(tmp_path / "out" / "assembled.ply", process=False)
    T = read_transforms(tmp_path / "out" / "transforms.json")
    name = sorted(T)[0]
    mine = trimesh.load(puzzle / "fragments" / f"{name}.ply", process=False).vertices
    moved = mine @ T[name]["transform"][:3, :3].T + T[name]["transform"][:3, 3]
    assert len(placed.vertices) == given
    assert np.abs(placed.vertices[: len(moved)] - moved).max() < 1e-5 * np.ptp(moved)  # the given vertices


@pytest.mark.slow
def test_clean_sets_are_not_smoothed(run_dir):
    report = json.loads((run_dir / "report.json").read_text())
    assert all(f["smoothing_iterations"] == 0 for f in report["fragments"].values())


@pytest.mark.slow
def test_noisy_cell_break_is_laid_on_its_plane(tmp_path):
    """A Voronoi cell break is one plane on both mates: under vertex noise of 0.1 % the
    signatures say nothing there, and only the planes' placements (and a gap not read off
    a flat contact) put the two pieces together."""
    puzzle = tmp_path / "puzzle"
    break_to_folder("torus", puzzle, params=BreakParams(pieces=2, style="cells", noise=0.001), seed=0)
    report = run_to_folder([puzzle / "fragments"], tmp_path / "out", seed=0)
    assert report["summary"]["gap"] == 0.0
    s = _score(tmp_path / "out", puzzle)
    assert s["solved"], s


def _merge_inputs(prepared):
    """The 4-piece cow's proposals and merge options, as :func:`assembly.assemble` makes them."""
    from reassemble import assembly
    from reassemble.config import Config
    from reassemble.geometry import make_scene
    from reassemble.pairs import match_pairs, registration_params

    frags, size = prepared
    reg = registration_params(frags, size=size)
    results = match_pairs(frags, size=size, params=reg, seed=0)
    params = Config().assembly
    surfaces = [assembly._thinned(f.surface, params.verify_samples) for f in frags]
    centres, radii = assembly._spheres(surfaces)
    common = dict(surfaces=surfaces, scenes=[make_scene(*f.mesh) for f in frags],
                  areas=np.array([s.area for s in surfaces]), tol=reg.tolerance * size,
                  reach=reg.ransac_tolerance * size, params=params, reg_params=reg, centres=centres, radii=radii,
                  cache={}, gap=0.0)
    proposals = [(i, j, c.T_target_source, c.score) for (i, j), r in sorted(results.items())
                 for c in r.candidates[: params.candidates] if c.score >= params.min_gain]
    return frags, results, proposals, common


def _state(n):
    return np.arange(n), np.tile(np.eye(4), (n, 1, 1)), {k: [k] for k in range(n)}


def test_lazy_merge_makes_the_merges_of_weighing_every_proposal_each_time(prepared):
    # a proposal's verdict is kept while its two sub-assemblies are unchanged: the merges
    # and poses must be those of weighing every proposal again after every merge
    from reassemble import assembly

    frags, _, proposals, common = _merge_inputs(prepared)
    lazy = _state(len(frags))
    merges = assembly._merge(proposals, lazy, **common)
    eager = _state(len(frags))
    group, poses, _ = eager
    support = assembly._cycle_support(proposals, common["surfaces"], reach=common["reach"])
    weigh = {k: v for k, v in common.items() if k != "reach"}
    expected = []
    while True:
        best = None
        for x, (i, j, T_j_i, _) in enumerate(proposals):
            if group[i] == group[j]:
                continue
            ok, gain, priority = assembly._weigh(x, proposals[x], eager, support, **weigh)
            if ok and gain >= common["params"].min_gain and (best is None or priority > best[0]):
                best = (priority, gain, i, j, T_j_i)
        if best is None:
            break
        _, gain, i, j, T_j_i = best
        assembly._join(eager, i, j, T_j_i)
        expected.append((i, j, float(gain)))
    assert len(expected) >= 2  # sub-assemblies of several fragments were weighed
    assert merges == expected
    assert np.array_equal(lazy[0], group) and np.array_equal(lazy[1], poses)


def test_only_linked_sub_assemblies_are_registered(prepared, monkeypatch):
    # with candidate pairs, two sub-assemblies none of whose members were registered
    # together are not registered against each other
    from reassemble import assembly, registration

    frags, _, _, common = _merge_inputs(prepared)
    calls = []

    def register(source, target, **kwargs):
        calls.append((len(source.samples), len(target.samples)))
        return registration.PairResult([], False, np.zeros((0, 2), int))

    monkeypatch.setattr(registration, "register_pair", register)
    group, poses, members = _state(len(frags))
    group[1] = 0  # fragments 0 and 1 one sub-assembly, 2 and 3 alone
    members = {0: [0, 1], 2: [2], 3: [3]}
    kwargs = dict(surfaces=[f.surface for f in frags], meshes=[f.mesh for f in frags], size=prepared[1],
                  tol=common["tol"], gap=0.0, params=common["params"], reg_params=common["reg_params"], seed=0,
                  common=common)
    memo = assembly.GroupMemo()
    assembly._register_groups([], (group, poses, dict(members)), registered={(0, 1), (1, 2)}, memo=memo, **kwargs)
    assert len(calls) == 1  # {0, 1} against 2; not against 3, and 2 and 3 are both alone
    calls.clear()
    assembly._register_groups([], (group, poses, dict(members)), registered={(0, 1), (1, 2), (3, 0)}, memo=memo,
                              **kwargs)
    assert len(calls) == 1  # against 3 now; against 2 as before: from the memo
    calls.clear()
    assembly._register_groups([], (group, poses, dict(members)), registered={(0, 1), (1, 2), (3, 0)},
                              memo=assembly.GroupMemo(), **kwargs)
    assert len(calls) == 2
    calls.clear()
    # a new segmentation that relabelled fragment 2 (another surface) makes {0, 1} against 2
    # a new registration; against 3, whose members kept their surfaces, the memo's
    relabelled = [*kwargs["surfaces"]]
    relabelled[2] = dataclasses.replace(relabelled[2], samples=relabelled[2].samples + 1e-3)
    assembly._register_groups([], (group, poses, dict(members)), registered={(0, 1), (1, 2), (3, 0)}, memo=memo,
                              **{**kwargs, "surfaces": relabelled})
    assert len(calls) == 1


def test_sub_assembly_registrations_do_not_depend_on_jobs(prepared):
    # each registration of two sub-assemblies has its own random stream: in one process or
    # in two, the same candidates
    from reassemble import assembly

    frags, _, _, common = _merge_inputs(prepared)
    found = []
    for jobs in (1, 2):
        group, poses, _ = _state(len(frags))
        group[1] = 0
        members = {0: [0, 1], 2: [2], 3: [3]}
        proposals = []
        assembly._register_groups(proposals, (group, poses, members), surfaces=[f.surface for f in frags],
                                  meshes=[f.mesh for f in frags], size=prepared[1], tol=common["tol"], gap=0.0,
                                  params=common["params"], reg_params=common["reg_params"], seed=0,
                                  common={**common, "cache": {}}, registered={(0, 2), (1, 3)}, jobs=jobs,
                                  memo=assembly.GroupMemo())
        found.append(proposals)
    assert len(found[0]) >= 2  # {0, 1} against 2 and against 3
    assert len(found[0]) == len(found[1])
    for (i, j, T, s), (i2, j2, T2, s2) in zip(*found):
        assert (i, j, s) == (i2, j2, s2) and np.array_equal(T, T2)


def test_a_wrong_first_merge_is_undone_by_another_start(prepared, puzzle):
    # a decoy that outscores every true placement of its pair is merged first by plain
    # greedy and blocks the loops through it; another start closes them (every true contact
    # adds to the total) and keeps the true poses
    from reassemble import assembly
    from reassemble.geometry import transform_points

    frags, _, _, common = _merge_inputs(prepared)
    T = [np.asarray(puzzle.ground_truth["fragments"][f.name]["transform"]) for f in frags]
    n = len(frags)
    truth = [(i, j, invert_transform(T[j]) @ T[i], 0.4) for i in range(n) for j in range(i + 1, n)]
    c = frags[0].surface.surface.mean(axis=0)
    R = _axis_angle(np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2]), np.radians(25.0))
    turn = make_transform(R, c - R @ c)
    decoy = (0, 1, truth[0][2] @ turn, 5.0)  # fragment 0 turned 25 degrees about its break's centre
    proposals = [decoy] + truth

    def placed_right(state):
        group, poses, _ = state
        if len(set(group)) != 1:
            return False
        pts = frags[0].surface.surface
        T_1_0 = invert_transform(poses[1]) @ poses[0]
        return np.abs(transform_points(T_1_0, pts) - transform_points(truth[0][2], pts)).max() < 1e-6 * prepared[1]

    greedy = _state(n)
    merges = assembly._merge_from_starts(list(proposals), greedy, starts=1, common={**common, "cache": {}})
    assert merges[0][:2] == (0, 1) and not placed_right(greedy)  # the decoy first: the test can fail
    starts = _state(n)
    assembly._merge_from_starts(list(proposals), starts, starts=4, common={**common, "cache": {}})
    assert placed_right(starts)
    assert all(np.allclose(invert_transform(starts[1][j]) @ starts[1][i], invert_transform(T[j]) @ T[i], atol=1e-6)
               for i in range(n) for j in range(n))


def test_the_break_is_the_surface_in_contact(prepared, puzzle):
    # at the true poses, the faces in contact are the generator's fracture faces, whatever
    # the segmentation said: even labels inverted everywhere come out right
    from types import SimpleNamespace

    from reassemble.assembly import Contact, contact_faces
    from reassemble.geometry import face_areas
    from reassemble.pairs import registration_params
    from reassemble.segmentation import labels_from_contact

    frags, size = prepared
    T = np.array([puzzle.ground_truth["fragments"][f.name]["transform"] for f in frags])
    n = len(frags)
    together = SimpleNamespace(contacts=[Contact(p, q, 0.0, 0.0, 0.0) for p in range(n) for q in range(p + 1, n)],
                               T_group_fragment=T)
    reg = registration_params(frags, size=size)
    touching = contact_faces(together, [f.mesh for f in frags], tol=reg.tolerance * size)
    for k, f in enumerate(frags):
        truth = puzzle.labels[f.name].astype(bool)
        area = face_areas(*f.mesh)
        inverted = SimpleNamespace(fracture=~truth, region=np.where(truth, -1, 0))
        out = labels_from_contact(inverted, touching[k], keep_open=False)
        tp = area[out & truth].sum()
        f1 = 2 * tp / (area[out].sum() + area[truth].sum())
        assert f1 > 0.99, (f.name, f1)
    # a fragment with nothing in contact keeps its labelled regions only where asked to
    alone = SimpleNamespace(fracture=truth, region=np.where(truth, 0, -1))
    assert not labels_from_contact(alone, np.zeros(len(truth), bool), keep_open=False).any()
    assert np.array_equal(labels_from_contact(alone, np.zeros(len(truth), bool), keep_open=True), truth)
