"""Pictures and report.html: renders are not blank, colours follow labels, `view` works
from a run folder, and without OpenGL everything but the pictures still completes."""

import html
import re
import shutil
from html.parser import HTMLParser

import numpy as np
import pytest

from reassemble.errors import ReassembleError
from reassemble.viz.colors import BACKGROUND_RGB, FRACTURE_RGB, ORIGINAL_RGB, diverging, fragment_colors
from reassemble.viz.render import gl_problem

from .test_cli import assert_one_line_error, run


@pytest.fixture(scope="module")
def gl():
    problem = gl_problem()
    if problem:
        pytest.skip(f"cannot render here: {problem}")


def _box():
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 0.8, 0.6))
    return np.asarray(box.vertices), np.asarray(box.faces), np.asarray(box.face_normals)


def _share(image, rgb, tol=60):
    """Share of the non-background pixels whose hue is that of ``rgb`` (lit or shaded)."""
    fg = np.any(image != BACKGROUND_RGB, axis=2)
    pix = image[fg].astype(float)
    target = np.asarray(rgb, float)
    # compare directions in colour space: shading scales a colour, it does not turn it
    cos = pix @ target / (np.linalg.norm(pix, axis=1) * np.linalg.norm(target) + 1e-9)
    return float(np.mean(cos > np.cos(np.radians(tol / 6)))) if len(pix) else 0.0


def test_diverging_colours():
    c = diverging(np.array([-2.0, -1.0, 0.0, 1.0, 2.0, np.nan]), 1.0)
    assert c.dtype == np.uint8 and c.shape == (6, 3)
    assert np.array_equal(c[0], c[1]) and np.array_equal(c[3], c[4])  # clipped
    assert c[1, 2] > c[1, 0] and c[3, 0] > c[3, 2]  # blue below, red above
    assert np.all(c[2] > 240) and np.array_equal(c[5], ORIGINAL_RGB)
    k = fragment_colors(12)
    assert len({tuple(x) for x in k}) == 12 and np.array_equal(k, fragment_colors(12))


def test_render_is_not_blank_and_colours_follow_labels(gl):
    from reassemble.viz.pictures import label_colors
    from reassemble.viz.render import Renderer, Shape

    v, f, n = _box()
    fracture = n[:, 2] > 0.5  # the top is the "fracture"
    shape = Shape(v, f, label_colors(fracture))
    with Renderer(width=200, height=150) as r:
        top = r.render([shape], front=(0, 0, 1), up=(0, 1, 0))
        bottom = r.render([shape], front=(0, 0, -1), up=(0, 1, 0))
    assert top.shape == (150, 200, 3) and top.dtype == np.uint8
    for image in (top, bottom):
        assert np.mean(np.any(image != BACKGROUND_RGB, axis=2)) > 0.1  # not blank
    assert _share(top, FRACTURE_RGB) > 0.9 and _share(top, ORIGINAL_RGB) < 0.05
    assert _share(bottom, ORIGINAL_RGB) > 0.9 and _share(bottom, FRACTURE_RGB) < 0.05


def test_match_picture_draws_both_fragments_and_lines(gl):
    from reassemble.viz.pictures import match_picture
    from reassemble.viz.render import Renderer

    v, f, n = _box()
    T_b = np.eye(4)
    T_b[0, 3] = 1.0  # b touches a's +x face
    points_a = np.array([[0.5, y, z] for y in (-0.3, 0.0, 0.3) for z in (-0.2, 0.2)])
    points_b = points_a - [1.0, 0.0, 0.0]
    red, blue = np.array([230, 40, 40], np.uint8), np.array([40, 40, 230], np.uint8)
    with Renderer(width=240, height=180) as r:
        image = match_picture(r, ((v, f), (v, f)), (np.eye(4), T_b), points=(points_a, points_b),
                              colors=(red, blue), title="a + b")
    assert image.shape == (180, 480, 3)
    apart, together = image[:, :240], image[:, 240:]
    for half in (apart, together):
        assert _share(half, red) > 0.2 and _share(half, blue) > 0.2
    # the lines: dark pixels between the pulled-apart fragments, none in the contact view
    dark = lambda im: np.count_nonzero(np.all(im[30:] < 60, axis=2))  # noqa: E731 (below the caption)
    assert dark(apart) > 5 * max(dark(together), 1)


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags, self.images, self.frames, self.scripts = [], [], [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "img":
            self.images.append(a.get("src", ""))
        if tag == "iframe":
            self.frames.append(a.get("srcdoc", ""))
        if tag == "script":
            self.scripts.append(a.get("src"))


@pytest.mark.slow
def test_view_writes_pictures_and_a_self_contained_report(gl, run_dir, puzzle_dir, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(run_dir, folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    rc, out, err = run("view", folder, "--truth", puzzle_dir / "ground_truth.json", "--quiet")
    assert rc == 0, err
    names = sorted(p.stem for p in (puzzle_dir / "fragments").iterdir())
    pictures = folder / "pictures"
    assert {p.stem for p in (pictures / "fragments").iterdir()} == set(names)
    assert (pictures / "assembly.png").is_file() and (pictures / "exploded.png").is_file()
    report = __import__("json").loads((folder / "report.json").read_text())
    assert len(list((pictures / "matches").iterdir())) == len(report["contacts"]) > 0
    from PIL import Image

    for p in pictures.rglob("*.png"):
        im = np.asarray(Image.open(p).convert("RGB"))
        assert np.mean(np.any(im != BACKGROUND_RGB, axis=2)) > 0.02, p  # not blank
    # the run's own files are untouched
    assert before == {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and p.name in before}

    text = (folder / "report.html").read_text()
    page = _Page()
    page.feed(text)
    assert page.scripts == []  # no script of the page itself, let alone one fetched from a network
    assert len(page.frames) == 1 and "THREE" in page.frames[0] and "$B64GLTF" not in page.frames[0]
    viewer = _Page()
    viewer.feed(page.frames[0])
    assert all(src is None for src in viewer.scripts)  # three.js is inlined, nothing fetched
    assert not re.search(r"""(src|href)\s*=\s*["']?https?:""", page.frames[0] + text)
    assert len(page.images) == 2 + len(names) + len(report["contacts"])
    assert all(src.startswith("data:image/png;base64,") for src in page.images)
    for name in names:
        assert html.escape(name) in text
    assert "strict part accuracy" in text and "Accepted matches" in text


@pytest.mark.slow
def test_view_without_gl_still_writes_the_report(run_dir, tmp_path, monkeypatch, caplog):
    import reassemble.viz.render as render
    from reassemble.view import view_folder

    folder = tmp_path / "run"
    shutil.copytree(run_dir, folder)
    monkeypatch.setattr(render, "gl_problem", lambda: "no OpenGL context (test)")
    summary = view_folder(folder)
    assert summary["pictures"] == 0 and summary["skipped"] == "no OpenGL context (test)"
    assert not (folder / "pictures").exists()
    assert "Pictures skipped: no OpenGL context (test)." in (folder / "report.html").read_text()
    warnings = [r for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and "pictures skipped" in warnings[0].getMessage()


@pytest.mark.slow
def test_view_bad_input(run_dir, tmp_path):
    rc, _, err = run("view", tmp_path / "nothing")
    assert_one_line_error(rc, err, "nothing", "reassemble run")
    (tmp_path / "empty").mkdir()
    rc, _, err = run("view", tmp_path / "empty")
    assert_one_line_error(rc, err, "transforms.json", "reassemble run")
    folder = tmp_path / "run"
    shutil.copytree(run_dir, folder)
    rc, _, err = run("view", folder, "--radius", "0.5", "--no-pictures")
    assert_one_line_error(rc, err, "--radius", "0.04")
    (folder / "analysis.npz").write_bytes(b"not a zip")
    rc, _, err = run("view", folder, "--no-pictures")
    assert_one_line_error(rc, err, "analysis.npz")
    with pytest.raises(ReassembleError, match="display"):
        import os

        from reassemble.viz.render import show_interactive

        if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
            pytest.skip("a display exists here: --viewer would open a window")
        show_interactive([])


def test_decimate_for_the_viewer():
    import trimesh

    from reassemble.geometry import decimate

    s = trimesh.creation.icosphere(subdivisions=5)  # 20480 faces
    v, f = np.asarray(s.vertices), np.asarray(s.faces)
    small_v, small_f = decimate(v, f, 2000)
    assert 1500 <= len(small_f) <= 2000
    assert np.allclose(np.linalg.norm(small_v, axis=1), 1.0, atol=0.02)  # still the sphere
    same_v, same_f = decimate(v, f, 50000)
    assert np.array_equal(same_f, f) and np.array_equal(same_v, v) and same_v is not v
