"""The regression sets build from seeds, resume, and the bench set has the promised variety."""

import json

import pytest

from data_synth.make_sets import build_set
from data_synth.sets import BENCH_MESHES, bench_set, sherds_set, smoke_set
from reassemble.files import bundled_meshes, load_mesh


@pytest.mark.slow
def test_smoke_set_builds_and_resumes(tmp_path):
    results = build_set("smoke", tmp_path)
    assert len(results) == len(smoke_set()) and not any(r["cached"] for r in results)
    index = json.loads((tmp_path / "index.json").read_text())
    for entry in index["puzzles"]:
        gt = json.loads((tmp_path / entry["ground_truth"]).read_text())
        assert len(gt["fragments"]) == entry["pieces"]
    again = build_set("smoke", tmp_path)
    assert all(r["cached"] for r in again)
    # a puzzle made by another generator version (here: a parameter renamed) is rebuilt
    gt_path = tmp_path / index["puzzles"][0]["ground_truth"]
    gt = json.loads(gt_path.read_text())
    gt["parameters"]["resolution"] = gt["parameters"].pop("cut_edge")
    gt_path.write_text(json.dumps(gt))
    third = {r["name"]: r["cached"] for r in build_set("smoke", tmp_path)}
    assert not third[index["puzzles"][0]["name"]] and sum(third.values()) == len(third) - 1


def test_bench_set_spans_characters_and_sizes():
    specs = bench_set()
    assert set(BENCH_MESHES) <= set(bundled_meshes())
    assert len(BENCH_MESHES) >= 6
    assert {s.pieces for s in specs} == {2, 4, 8, 12, 20}
    assert any(s.noise > 0 for s in specs)
    assert len({s.name for s in specs}) == len(specs)


def test_bundled_vase_is_the_generated_one():
    """vase.ply is data_synth.shapes.vase_mesh() written out: rebuilt, it is the same pot."""
    import numpy as np

    from data_synth.shapes import is_closed_manifold, vase_mesh

    v, f = vase_mesh()
    mesh = load_mesh(bundled_meshes()["vase"])
    assert is_closed_manifold(f) and len(mesh.faces) == len(f)
    assert np.allclose(np.sort(mesh.vertices, axis=0), np.sort(v, axis=0))
    specs = sherds_set()
    assert {s.mesh for s in specs} == {"vase"} and len({s.name for s in specs}) == len(specs)


def test_field_sets_split_by_mesh_and_span_the_field():
    from data_synth.sets import FIELD_KINDS, FIELD_MESHES, FIELD_STYLES, field_set

    halves = {h: field_set(h) for h in ("tuning", "validation")}
    meshes = {h: {s.mesh for s in specs} for h, specs in halves.items()}
    assert not meshes["tuning"] & meshes["validation"]  # no mesh in both halves
    for h, specs in halves.items():
        assert {FIELD_MESHES[m].kind for m in meshes[h]} == set(FIELD_KINDS)
        assert all(FIELD_MESHES[m].half == h for m in meshes[h])
        assert {s.style for s in specs} == set(FIELD_STYLES)
        assert min(s.pieces for s in specs) == 2 and max(s.pieces for s in specs) == 20
        for style in FIELD_STYLES:  # every style clean and noisy, on every mesh
            for noisy in (False, True):
                assert {s.mesh for s in specs if s.style == style and bool(s.noise) == noisy} == meshes[h]
        assert any(s.roughness == 0.01 for s in specs)
        assert len({s.name for s in specs}) == len(specs)
    bundled = set(bundled_meshes())
    for m in FIELD_MESHES.values():  # every source is named in a form make_sets resolves
        assert m.source in bundled or m.source.split(":")[0] in ("shared", "shapes")


def test_a_field_puzzle_builds_from_a_bundled_mesh(tmp_path):
    """The field sets' path through make_sets (source prepared, style and roughness passed)."""
    from data_synth.make_sets import build_one, prepare_source
    from data_synth.sets import PuzzleSpec

    spec = PuzzleSpec("octagonal_pocket", 3, 0, style="cells")
    source = prepare_source("octagonal_pocket", tmp_path, tmp_path / "no-shared")
    assert source.is_file()
    r = build_one(spec, tmp_path, mesh=source)
    gt = json.loads((tmp_path / spec.name / "ground_truth.json").read_text())
    assert not r["cached"] and gt["parameters"]["style"] == "cells" and len(gt["fragments"]) == 3
    assert build_one(spec, tmp_path, mesh=source)["cached"]
