"""The fracture generator: closed fragments, conserved volume, zero gaps, exact labels, seeds."""

import json

import numpy as np
import pytest

from data_synth.verify import check_puzzle
from reassemble.errors import ReassembleError
from reassemble.geometry import face_areas, signed_volume, transform_points
from reassemble.files import load_mesh, resolve_mesh_path
from reassemble.pipeline import break_to_folder, read_puzzle
from reassemble.synth import BreakParams, break_mesh, fractal_heightfield

from .conftest import tree_digest


def _volume(puzzle):
    return sum(signed_volume(f.vertices, f.faces) for f in puzzle.fragments)


def _original(name):
    return load_mesh(resolve_mesh_path(name))


@pytest.mark.parametrize(
    "mesh,pieces,seed",
    [("spot_low_resolution", 4, 1), ("torus", 5, 2), ("angle_block", 3, 0), ("featuretype", 6, 4)],
)
@pytest.mark.slow
def test_puzzle_is_exact(tmp_path, mesh, pieces, seed):
    out = tmp_path / "p"
    break_to_folder(mesh, out, params=BreakParams(pieces=pieces), seed=seed)
    puzzle = read_puzzle(out / "ground_truth.json")
    assert len(puzzle.meshes) == pieces
    for name in puzzle.meshes:  # every fragment file is a closed manifold on its own
        load_mesh(out / "fragments" / f"{name}.ply", require_closed=True)
    original = _original(mesh)
    checks = check_puzzle(puzzle, original.vertices, original.faces)
    assert checks["volume_rel_error"] < 1e-5
    # put back by the ground truth, every fracture face lies on another fragment
    assert checks["max_gap_over_diag"] < 1e-6
    # original-surface faces lie on the input mesh, fracture faces do not, and
    # original surface never touches another fragment: labels are exactly the cut faces
    assert checks["original_off_surface_over_diag"] < 1e-6
    assert checks["fracture_area_on_original"] < 1e-4
    assert checks["original_area_in_contact"] < 1e-4


def test_fragments_are_posed_and_named_at_random(puzzle):
    transforms = [np.array(e["transform"]) for e in puzzle.ground_truth["fragments"].values()]
    for T in transforms:
        assert not np.allclose(T[:3, :3], np.eye(3), atol=0.05)
    names = sorted(puzzle.meshes)
    assert names == [f"fragment_{k:02d}" for k in range(len(names))]


def test_cut_surfaces_are_rough_not_planar():
    mesh = _original("spot_low_resolution")
    p = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=2), rng=np.random.default_rng(0))
    fr = p.fragments[0]
    pts = transform_points(fr.T_world_fragment, fr.vertices)[np.unique(fr.faces[fr.labels == 1])]
    centered = pts - pts.mean(axis=0)
    residual = np.linalg.svd(centered, compute_uv=False)[-1] / np.sqrt(len(pts))
    diag = np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    assert residual > 0.005 * diag  # RMS distance from the best plane


def test_heightfield_is_multiscale(rng):
    h = fractal_heightfield(128, hurst=0.6, rng=rng)
    assert abs(h.mean()) < 1e-9 and abs(np.sqrt((h**2).mean()) - 1) < 1e-9
    # roughness at every scale: increments grow with lag like lag**hurst
    incr = [np.sqrt(np.mean((h[lag:] - h[:-lag]) ** 2)) for lag in (2, 8, 32)]
    assert incr[0] > 0.05 and incr[0] < incr[1] < incr[2]


def test_same_seed_same_bytes_other_seed_other_puzzle(tmp_path):
    params = BreakParams(pieces=3)
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        break_to_folder("torus", tmp_path / name, params=params, seed=seed)
    a, b, c = (tree_digest(tmp_path / n) for n in "abc")
    assert a == b
    assert a["ground_truth.json"] != c["ground_truth.json"]


def test_labels_and_contacts_are_readable(puzzle):
    for name, mesh in puzzle.meshes.items():
        lab = puzzle.labels[name]
        assert lab.shape == (len(mesh.faces),) and set(np.unique(lab)) == {0, 1}
        entry = puzzle.ground_truth["fragments"][name]
        assert entry["n_fracture_faces"] == int(lab.sum())
        assert np.isclose(entry["fracture_area"], face_areas(mesh.vertices, mesh.faces)[lab == 1].sum())
    contacts = puzzle.ground_truth["contacts"]
    assert contacts, "fragments of one object must touch"
    touching = {n for c in contacts for n in c["fragments"]}
    assert touching == set(puzzle.meshes)
    for c in contacts:  # the shared area is at most the smaller fracture area
        a, b = (puzzle.ground_truth["fragments"][n]["fracture_area"] for n in c["fragments"])
        assert 0 < c["area"] <= min(a, b) * 1.001


def test_scale_option_scales_everything(tmp_path):
    for name, scale in (("m", 1.0), ("mm", 1000.0)):
        break_to_folder("torus", tmp_path / name, params=BreakParams(pieces=3, scale=scale), seed=3)
    m, mm = (json.loads((tmp_path / n / "ground_truth.json").read_text()) for n in ("m", "mm"))
    assert np.isclose(mm["object"]["volume"], m["object"]["volume"] * 1e9, rtol=1e-9)
    assert np.isclose(mm["object"]["diagonal"], m["object"]["diagonal"] * 1e3, rtol=1e-9)


def test_realism_options(tmp_path):
    mesh = _original("spot_low_resolution")
    diag = np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    base = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=3), rng=np.random.default_rng(5))
    chipped = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=3, chips=3), rng=np.random.default_rng(5))
    assert chipped.stats["chips"] >= 1
    assert _volume(chipped) < _volume(base) * 0.9999
    dec = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=3, decimate=0.002), rng=np.random.default_rng(5))
    assert sum(len(f.faces) for f in dec.fragments) < 0.9 * sum(len(f.faces) for f in base.fragments)
    noisy = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=3, noise=0.001), rng=np.random.default_rng(5))
    for f0, f1 in zip(base.fragments, noisy.fragments):
        assert f0.faces.shape == f1.faces.shape
        offset = f1.vertices - f0.vertices
        assert abs(offset.std() / diag - 0.001) < 0.0002


def test_bad_parameters_are_named():
    mesh = _original("torus")
    for kwargs, word in (({"pieces": 1}, "--pieces"), ({"pieces": 3, "roughness": -1}, "--roughness"),
                         ({"pieces": 3, "scale": 0}, "--scale")):
        with pytest.raises(ReassembleError, match=word):
            break_mesh(mesh.vertices, mesh.faces, BreakParams(**kwargs), rng=np.random.default_rng(0))


def test_gap_option_moves_mating_surfaces_apart():
    from reassemble.geometry import make_scene

    mesh = _original("spot_low_resolution")
    diag = np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    base = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=2), rng=np.random.default_rng(5))
    gapped = break_mesh(mesh.vertices, mesh.faces, BreakParams(pieces=2, gap=0.01), rng=np.random.default_rng(5))
    assert [c.area for c in gapped.contacts] == [c.area for c in base.contacts]  # the true neighbours
    assert _volume(gapped) < _volume(base)
    a, b = gapped.fragments
    world = [transform_points(f.T_world_fragment, f.vertices) for f in (a, b)]
    import open3d as o3d

    scene = make_scene(world[1], b.faces)
    on_break = np.unique(a.faces[a.labels == 1])
    d = scene.compute_distance(o3d.core.Tensor(world[0][on_break].astype(np.float32))).numpy()
    assert abs(np.median(d) / diag - 0.01) < 0.002  # mating surfaces about the gap apart
    with pytest.raises(ReassembleError, match="--gap"):
        BreakParams(pieces=2, gap=-1).check()


def test_a_mesh_with_floating_specks_still_breaks():
    # a simplified scan often keeps a crumb or a cavity as a shell of its own; every cut
    # would decompose into it too and fail the sliver test
    import trimesh

    body = _original("torus")
    crumb = trimesh.creation.icosphere(subdivisions=1, radius=1e-3 * np.ptp(body.vertices, axis=0).max())
    vertices = np.vstack([body.vertices, crumb.vertices + body.vertices.max(axis=0) * 1.1])
    faces = np.vstack([body.faces, crumb.faces + len(body.vertices)])
    puzzle = break_mesh(vertices, faces, BreakParams(pieces=3), rng=np.random.default_rng(0))
    assert len(puzzle.fragments) == 3
