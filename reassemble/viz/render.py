"""Headless pictures: Open3D's legacy ``Visualizer(visible=False)``, which renders through
Mesa EGL on a machine with no display and no GPU (a frame takes well under a second; the
newer ``OffscreenRenderer`` needs Vulkan and takes minutes on a CPU).

Everything here takes arrays and returns (h, w, 3) uint8 images; nothing reads or writes files.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass

import numpy as np

from ..errors import ReassembleError
from .colors import BACKGROUND_RGB, diverging


class RenderUnavailable(ReassembleError):
    """No OpenGL context can be made here (no display and no EGL)."""


@dataclass(frozen=True)
class Shape:
    """A triangle mesh to draw, in world coordinates.

    Attributes
    ----------
    vertices : (n, 3) float
    faces : (m, 3) int
    face_colors : (m, 3) uint8, one colour per face (drawn flat)
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_colors: np.ndarray


_PROBE = ("import sys, open3d as o3d\n"
          "o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)\n"
          "v = o3d.visualization.Visualizer()\n"
          "sys.exit(0 if v.create_window(visible=False, width=64, height=64) else 3)\n")


def gl_problem() -> str | None:
    """Why no picture can be rendered here, or None when one can.

    Probed in a child process: where neither a display nor EGL exists, making the context
    can abort the process instead of failing politely.
    """
    _quiet_mesa()
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"cannot start the OpenGL probe ({exc})"
    if proc.returncode == 0:
        return None
    lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
    return "no OpenGL context (no display and no EGL)" + (f": {lines[-1].strip()}" if lines else "")


def _o3d_mesh(shape: Shape):
    """An Open3D mesh with unshared vertices: flat shading, one colour per face."""
    import open3d as o3d

    tri = np.asarray(shape.vertices, dtype=np.float64)[np.asarray(shape.faces)].reshape(-1, 3)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(tri),
                                     o3d.utility.Vector3iVector(np.arange(len(tri)).reshape(-1, 3)))
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.repeat(np.asarray(shape.face_colors) / 255.0, 3, axis=0))
    mesh.compute_vertex_normals()
    return mesh


def _quiet_mesa() -> None:
    """Mesa complains on stderr when XDG_RUNTIME_DIR is unset (headless machines, CI)."""
    import os
    import tempfile

    if not os.environ.get("XDG_RUNTIME_DIR"):
        os.environ["XDG_RUNTIME_DIR"] = tempfile.mkdtemp(prefix="reassemble-xdg-")


class Renderer:
    """Headless pictures of given size: ``with Renderer() as r: image = r.render(...)``.

    Entering checks that an OpenGL context can be made (RenderUnavailable otherwise). Each
    picture gets a fresh hidden window (~0.03 s): the legacy view control keeps the union
    of every bounding box it has seen, which would shrink later, smaller scenes.
    """

    def __init__(self, *, width: int = 640, height: int = 480, point_size: float = 6.0):
        self.width, self.height, self.point_size = width, height, point_size

    def _window(self):
        import open3d as o3d

        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        vis = o3d.visualization.Visualizer()
        if not vis.create_window(visible=False, width=self.width, height=self.height):
            raise RenderUnavailable("no OpenGL context (no display and no EGL)")
        opt = vis.get_render_option()
        opt.background_color = BACKGROUND_RGB / 255.0
        opt.mesh_show_back_face = True
        opt.point_size = self.point_size
        opt.line_width = 2.0
        return vis

    def __enter__(self) -> "Renderer":
        _quiet_mesa()
        self._window().destroy_window()
        return self

    def __exit__(self, *exc) -> None:
        return None

    def render(
        self,
        shapes: list[Shape],
        *,
        front: np.ndarray,
        up: np.ndarray,
        lines: tuple[np.ndarray, np.ndarray] | None = None,
        line_color=(20, 20, 20),
        zoom: float = 0.8,
    ) -> np.ndarray:
        """(height, width, 3) uint8 picture of ``shapes`` seen from direction ``front``
        (pointing from the scene to the camera) with ``up`` upwards, the scene filling the
        frame at ``zoom`` 1 (smaller: closer).

        ``lines``: optional ((k, 3), (k, 3)) end points, drawn as segments with dots at both ends.
        """
        import open3d as o3d

        vis = self._window()
        try:
            lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
            for s in shapes:
                mesh = _o3d_mesh(s)
                vis.add_geometry(mesh)
                if len(s.faces):
                    lo, hi = np.minimum(lo, mesh.get_min_bound()), np.maximum(hi, mesh.get_max_bound())
            if lines is not None and len(lines[0]):
                a, b = (np.asarray(x, dtype=np.float64) for x in lines)
                ends = np.vstack([a, b])
                index = np.column_stack([np.arange(len(a)), np.arange(len(a)) + len(a)])
                segs = o3d.geometry.LineSet(o3d.utility.Vector3dVector(ends), o3d.utility.Vector2iVector(index))
                segs.paint_uniform_color(np.asarray(line_color) / 255.0)
                dots = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(ends))
                dots.paint_uniform_color(np.asarray(line_color) / 255.0)
                vis.add_geometry(segs)
                vis.add_geometry(dots)
            ctl = vis.get_view_control()
            if np.all(np.isfinite(lo)):
                ctl.set_lookat(0.5 * (lo + hi))
            ctl.set_front(np.asarray(front, dtype=np.float64))
            ctl.set_up(np.asarray(up, dtype=np.float64))
            ctl.set_zoom(zoom)
            image = np.asarray(vis.capture_screen_float_buffer(do_render=True))
        finally:
            vis.destroy_window()
        return np.round(np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)


def principal_axes(points: np.ndarray) -> np.ndarray:
    """(3, 3) rows: the principal directions of ``points`` (n, 3), largest spread first,
    each signed so its largest component is positive (deterministic)."""
    centred = np.asarray(points, dtype=float) - np.mean(points, axis=0)
    _, _, vt = np.linalg.svd(centred[:: max(1, len(centred) // 20000)], full_matrices=False)
    vt = vt * np.sign(vt[np.arange(3), np.argmax(np.abs(vt), axis=1)])[:, None]
    if np.linalg.det(vt) < 0:
        vt[2] = -vt[2]
    return vt


def views(points: np.ndarray) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Six (name, front, up) viewpoints around ``points`` in their principal frame: the
    broad side from both sides, both ends, above and a three-quarter view."""
    e1, e2, e3 = principal_axes(points)
    iso = e1 + e2 + e3
    return [("front", e3, e2), ("back", -e3, e2), ("left", -e1, e2), ("right", e1, e2), ("top", e2, -e3),
            ("three-quarter", iso / np.linalg.norm(iso), e2)]


def perpendicular(direction: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(front, up) of a camera that sees ``direction`` horizontally across the picture,
    looking at the broad side of ``points`` as far as that allows."""
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    for axis in principal_axes(points)[::-1]:
        front = axis - np.dot(axis, d) * d
        if np.linalg.norm(front) > 0.3:
            front /= np.linalg.norm(front)
            return front, np.cross(front, d)
    front = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    front /= np.linalg.norm(front)
    return front, np.cross(front, d)


# ---- composing pictures (Pillow) ---------------------------------------------------------

def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: one bitmap size
        return ImageFont.load_default()


def caption(image: np.ndarray, text: str, *, size: int = 18) -> np.ndarray:
    """``image`` with ``text`` written in its top-left corner."""
    from PIL import Image, ImageDraw

    pil = Image.fromarray(image)
    ImageDraw.Draw(pil).text((10, 8), text, fill=(40, 40, 40), font=_font(size))
    return np.asarray(pil)


def grid(images: list[np.ndarray], *, columns: int) -> np.ndarray:
    """Pictures of one size tiled row by row (blank tiles fill the last row)."""
    h, w = images[0].shape[:2]
    rows = -(-len(images) // columns)
    out = np.empty((rows * h, columns * w, 3), np.uint8)
    out[:] = BACKGROUND_RGB
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        out[r * h:(r + 1) * h, c * w:(c + 1) * w] = im
    return out


def with_colorbar(image: np.ndarray, *, limit: float, title: str, width: int = 150) -> np.ndarray:
    """``image`` with a vertical blue-white-red colour bar from -limit to +limit on its right."""
    from PIL import Image, ImageDraw

    h = image.shape[0]
    panel = np.empty((h, width, 3), np.uint8)
    panel[:] = BACKGROUND_RGB
    top, bottom, x0, x1 = int(0.15 * h), int(0.85 * h), 16, 40
    values = np.linspace(limit, -limit, bottom - top)
    panel[top:bottom, x0:x1] = diverging(values, limit)[:, None, :]
    panel[[top, bottom - 1], x0:x1] = 60
    panel[top:bottom, [x0, x1 - 1]] = 60
    pil = Image.fromarray(panel)
    draw = ImageDraw.Draw(pil)
    font = _font(14)
    for value, y in ((limit, top), (0.0, (top + bottom) // 2), (-limit, bottom - 1)):
        draw.line([(x1, y), (x1 + 5, y)], fill=(60, 60, 60))
        draw.text((x1 + 8, y - 8), f"{value:+.3g}", fill=(40, 40, 40), font=font)
    for k, line in enumerate(title.split("\n")):
        draw.text((6, 10 + 16 * k), line, fill=(40, 40, 40), font=font)
    return np.hstack([image, np.asarray(pil)])


def show_interactive(shapes: list[Shape], *, title: str = "reassemble") -> None:
    """Open an interactive Open3D window (needs a display)."""
    import os

    import open3d as o3d

    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ReassembleError("--viewer needs a display (DISPLAY is not set); the pictures and report.html "
                              "are written without one")
    o3d.visualization.draw_geometries([_o3d_mesh(s) for s in shapes], window_name=title)


__all__ = ["RenderUnavailable", "Renderer", "Shape", "caption", "gl_problem", "grid", "perpendicular",
           "principal_axes", "show_interactive", "views", "with_colorbar"]
