"""Loading and writing: welding, validation, atomic outputs."""

import numpy as np
import pytest

from reassemble.errors import ReassembleError
from reassemble.geometry import signed_volume
from reassemble.files import bundled_meshes, load_mesh, read_transforms, staged_directory, write_json


@pytest.mark.parametrize("name", sorted(bundled_meshes()))
def test_bundled_meshes_are_closed_solids(name):
    mesh = load_mesh(bundled_meshes()[name])
    assert signed_volume(mesh.vertices, mesh.faces) > 0


def test_obj_uv_seams_are_welded(tmp_path):
    # a tetrahedron whose OBJ splits one vertex in two by texture coordinates
    (tmp_path / "t.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 0 0 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n"
        "f 1/1 3/3 2/2\nf 5/4 2/2 4/4\nf 1/1 4/4 3/3\nf 2/2 3/3 4/4\n"
    )
    mesh = load_mesh(tmp_path / "t.obj")
    assert len(mesh.vertices) == 4 and len(mesh.faces) == 4


def test_inward_mesh_is_flipped(tmp_path):
    import trimesh

    box = trimesh.creation.box()
    trimesh.Trimesh(box.vertices, box.faces[:, ::-1]).export(tmp_path / "inv.stl")
    mesh = load_mesh(tmp_path / "inv.stl")
    assert signed_volume(mesh.vertices, mesh.faces) > 0


def test_failed_build_leaves_nothing(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with staged_directory(out) as tmp:
            write_json(tmp / "a.json", {"x": 1})
            raise RuntimeError("boom")
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_failed_rebuild_keeps_old_results(tmp_path):
    out = tmp_path / "out"
    with staged_directory(out) as tmp:
        write_json(tmp / "a.json", {"v": 1})
    with pytest.raises(RuntimeError):
        with staged_directory(out, force=True) as tmp:
            write_json(tmp / "a.json", {"v": 2})
            raise RuntimeError("boom")
    assert (out / "a.json").read_text().strip().endswith("}")
    assert '"v": 1' in (out / "a.json").read_text()


def test_transforms_are_validated(tmp_path):
    p = tmp_path / "t.json"
    write_json(p, {"convention": "T_fragment_world", "fragments": {}})
    with pytest.raises(ReassembleError, match="convention"):
        read_transforms(p)
    write_json(p, {"fragments": {"a": {"transform": (2 * np.eye(4)).tolist()}}})
    with pytest.raises(ReassembleError, match="rigid"):
        read_transforms(p)
    write_json(p, {"fragments": {"a": {"transform": np.eye(4).tolist(), "placed": False}}})
    assert read_transforms(p)["a"]["placed"] is False


def test_non_manifold_and_degenerate_faces(tmp_path):
    import trimesh

    # two cubes sharing one edge: every edge closed, but the shared one has four faces
    a = trimesh.creation.box()
    b = trimesh.creation.box()
    b.apply_translation([1.0, 1.0, 0.0])
    both = trimesh.util.concatenate([a, b])
    both.merge_vertices()
    both.export(tmp_path / "bowtie.ply")
    pinched = load_mesh(tmp_path / "bowtie.ply")  # still bounds a solid, as decimation leaves them
    assert trimesh.Trimesh(pinched.vertices, pinched.faces).volume == pytest.approx(2.0)
    # a fin: one extra triangle on an edge of the cube, three faces there
    box = trimesh.creation.box()
    fin = np.vstack([box.vertices, [[2.0, 2.0, 2.0]]])
    e = box.edges_unique[0]
    trimesh.Trimesh(fin, np.vstack([box.faces, [[e[0], e[1], 8]]]), process=False).export(tmp_path / "fin.ply")
    finned = load_mesh(tmp_path / "fin.ply")  # the fin bounds nothing: removed, with a warning
    assert len(finned.faces) == len(box.faces) and "1 dangling faces" in finned.repairs
    # one face flipped: closed, but not an oriented solid: turned back, with a warning
    flipped = box.faces.copy()
    flipped[0] = flipped[0, ::-1]
    trimesh.Trimesh(box.vertices, flipped, process=False).export(tmp_path / "flipped.ply")
    turned = load_mesh(tmp_path / "flipped.ply")
    assert "reoriented 1 flipped faces" in turned.repairs
    assert trimesh.Trimesh(turned.vertices, turned.faces).volume == pytest.approx(1.0)
    # a collapsed face (repeated vertex) and a duplicate face are dropped, the solid stays closed
    box = trimesh.creation.box()
    faces = np.vstack([box.faces, [[0, 0, 1]], box.faces[:1]])
    trimesh.Trimesh(box.vertices, faces, process=False).export(tmp_path / "dirty.ply")
    mesh = load_mesh(tmp_path / "dirty.ply")
    assert len(mesh.faces) == len(box.faces)
