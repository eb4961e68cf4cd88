"""Reading meshes and writing results, the only place that knows file formats.

Every writer is atomic: data goes to a temporary file beside the target and is
renamed over it, so a crash never leaves a half-written file behind.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from glob import escape as glob_escape
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .errors import ReassembleError, first_line
from .geometry import is_rigid

log = logging.getLogger(__name__)

MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".glb", ".gltf")
BUNDLED_DIR = Path(__file__).parent / "data" / "meshes"
TRANSFORMS_CONVENTION = "T_world_fragment"


@dataclass(frozen=True)
class MeshData:
    """A welded triangle mesh.

    Attributes
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64, counter-clockwise seen from outside (the outer surface: possibly
        open or non-manifold when the file was not a clean closed mesh)
    path : where it was read from
    filled_holes : the extent of every hole closed on reading (``fill_holes``), a fraction
        of the mesh's diagonal, largest first
    repairs : what was found and done to get the surface of a solid, "" for a clean closed
        mesh (:meth:`repair.Repair.summary`)
    """

    vertices: np.ndarray
    faces: np.ndarray
    path: Path
    filled_holes: tuple[float, ...] = ()
    repairs: str = ""


def bundled_meshes() -> dict[str, Path]:
    """Names (file stems, lower case) of the meshes shipped with the package."""
    return {
        p.stem.lower(): p for p in sorted(BUNDLED_DIR.iterdir()) if p.suffix.lower() in MESH_SUFFIXES
    }


def resolve_mesh_path(spec: str | os.PathLike) -> Path:
    """A path as given, or the bundled mesh of that name (``spot``, ``torus``, ...)."""
    path = Path(spec)
    if path.exists():
        return path
    bundled = bundled_meshes()
    if str(spec).lower() in bundled:
        return bundled[str(spec).lower()]
    names = ", ".join(bundled)
    raise ReassembleError(f"{spec}: no such file (nor a bundled mesh; bundled: {names})")


def load_mesh(
    path: str | os.PathLike, *, require_closed: bool = True, weld: bool = True, fill_holes: float | None = None
) -> MeshData:
    """Read a mesh file, weld coincident vertices and find the surface of its solid.

    Vertices are welded by position only, so OBJ files whose UV seams split vertices
    close up again; faces that collapse (repeated vertex) are dropped, thin but valid
    slivers kept. A clean closed mesh is kept as it is (flipped if its faces point
    inwards). Anything else is repaired (:func:`repair.repair_surface`): duplicate faces,
    walls between cells (a face kept once per side, as Breaking Bad's pieces do) and faces
    inside overlapping shells or self-intersections are removed, flipped faces turned
    over; what remains, possibly open or non-manifold, is the surface, and its winding
    number the inside. ``MeshData.repairs`` says what was found and done, in one line.

    Parameters
    ----------
    path : a .ply .obj .stl .off .glb or .gltf file
    require_closed : find the surface of a solid as above, refusing a file that has no
        inside at all (a single open sheet); False reads the faces as they are
    weld : weld and clean as above; ``False`` keeps vertices and faces exactly as stored
        (for files whose per-face data must stay aligned, such as puzzle fragments)
    fill_holes : close holes (open scans) up to this extent, a fraction of the mesh's
        diagonal, with flat patches (:func:`holes.fill_holes`); None leaves them open
        (the winding number bridges them)

    Raises
    ------
    ReassembleError
        One line naming the file and the problem.
    """
    import trimesh

    path = Path(path)
    vertices, faces = _read_triangles(path)
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=weld, validate=False)
    if weld:
        f = mesh.faces
        collapsed = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
        mesh.update_faces(~collapsed)
        mesh.remove_unreferenced_vertices()
        if len(mesh.faces) == 0:
            raise ReassembleError(f"{path}: all triangles are degenerate")

    filled: tuple[float, ...] = ()
    repairs = ""
    if require_closed:
        mesh, filled, repairs = _solid_surface(mesh, path, fill_holes)
    return MeshData(
        vertices=np.asarray(mesh.vertices, dtype=np.float64).copy(),
        faces=np.asarray(mesh.faces, dtype=np.int64).copy(),
        path=path,
        filled_holes=filled,
        repairs=repairs,
    )


def _read_triangles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (n, 3) float64 and triangles (m, 3) int64 of a mesh file, as stored.

    Raises
    ------
    ReassembleError
        One line naming the file and the problem (missing, empty, unreadable, no valid
        triangles).
    """
    import trimesh

    if not path.is_file():
        raise ReassembleError(f"{path}: no such file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ReassembleError(
            f"{path}: unsupported file type {path.suffix!r} (use one of {' '.join(MESH_SUFFIXES)})"
        )
    if path.stat().st_size == 0:
        raise ReassembleError(f"{path}: file is empty")
    try:
        loaded = trimesh.load(path, force="mesh", process=False, skip_materials=True)
        vertices = np.asarray(loaded.vertices, dtype=np.float64)
        faces = np.asarray(loaded.faces, dtype=np.int64)
    except Exception as exc:  # trimesh raises many types for corrupt files
        first = first_line(exc) or type(exc).__name__
        raise ReassembleError(f"{path}: cannot read mesh ({first})") from None
    if faces.ndim != 2 or len(faces) == 0 or len(vertices) < 3:
        raise ReassembleError(f"{path}: contains no triangles (a point cloud has no inside)")
    if faces.shape[1] != 3:
        raise ReassembleError(f"{path}: faces are not triangles")
    if not np.all(np.isfinite(vertices)):
        raise ReassembleError(f"{path}: has NaN or infinite vertex coordinates")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ReassembleError(f"{path}: faces refer to missing vertices")
    return vertices, faces


def _solid_surface(mesh, path: Path, fill_holes: float | None):
    """The surface of the solid of a welded mesh (:func:`load_mesh`'s ``require_closed``).

    Parameters
    ----------
    mesh : trimesh.Trimesh, welded
    path : the file it was read from (for messages)
    fill_holes : as in :func:`load_mesh`

    Returns
    -------
    mesh : trimesh.Trimesh, repaired, holes filled, outward
    filled : the extent of every hole closed, largest first
    repairs : one line of what was found and done, "" for a clean closed mesh
    """
    import trimesh

    from .repair import is_closed_solid, repair_surface

    filled: tuple[float, ...] = ()
    repairs = ""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    repair = repair_surface(np.asarray(mesh.vertices), faces)
    if len(repair.faces) == 0 or repair.dangling > 2 * len(repair.faces):  # mostly sheets bounding nothing
        raise ReassembleError(f"{path}: has no inside (an open sheet: its faces bound no solid, "
                              "nothing is behind them)")
    if repair.changed:
        mesh = trimesh.Trimesh(vertices=np.asarray(mesh.vertices), faces=repair.faces, process=False,
                               validate=False)
        mesh.remove_unreferenced_vertices()
    if fill_holes is not None:
        from .holes import fill_holes as close

        vertices, faces, sizes = close(np.asarray(mesh.vertices), np.asarray(mesh.faces), max_size=fill_holes)
        if sizes and sizes[0] > fill_holes:
            raise ReassembleError(
                f"{path}: has a hole spanning {sizes[0]:.0%} of its size, more than --fill-holes "
                f"{fill_holes:g} closes (raise it, or leave --fill-holes out: open meshes are read as they are)"
            )
        filled = tuple(sizes)
        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
        if filled:
            repair = dataclasses.replace(repair, holes=0)
    if is_closed_solid(mesh.faces) and mesh.volume < 0:
        mesh.invert()
    inverted_only = repair.reoriented == len(faces) and not (
        repair.duplicates or repair.paired or repair.interior or repair.dangling)
    if not (inverted_only or not repair.changed and is_closed_solid(faces)):
        repairs = repair.summary()  # (a clean solid turned inside out is only turned back)
    return mesh, filled, repairs


def load_solid(path: str | os.PathLike, *, fill_holes: float | None = None) -> MeshData:
    """:func:`load_mesh`, and where the surface it finds is not closed (holes left open,
    seams of overlapping shells), the closed surface of its solid remeshed from the
    winding number (:func:`repair.solid_mesh`), for what needs a closed 2-manifold
    (breaking it with booleans). ``MeshData.repairs`` says so."""
    from .repair import is_closed_solid, solid_mesh

    mesh = load_mesh(path, fill_holes=fill_holes)
    if is_closed_solid(mesh.faces):
        return mesh
    v, f, h = solid_mesh(mesh.vertices, mesh.faces)
    diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    note = f"remeshed as the closed surface of its solid (marching cubes, voxel {h / diag:.2%} of its size)"
    return dataclasses.replace(mesh, vertices=v, faces=f, repairs="; ".join(x for x in (mesh.repairs, note) if x))


def mesh_warning(mesh: MeshData) -> str:
    """The one warning line about a mesh read by :func:`load_mesh` ("" when it was clean)."""
    notes = []
    if mesh.repairs:
        notes.append(f"not a clean closed surface: {mesh.repairs}")
    if mesh.filled_holes:
        notes.append(f"closed {len(mesh.filled_holes)} hole(s), the largest {mesh.filled_holes[0]:.1%} of its "
                     "size, with flat patches (an open scan)")
    return f"{mesh.path}: {'; '.join(notes)}" if notes else ""


DEBRIS_SHARE = 0.01  # a body under this share of the largest body's volume is scan debris


def split_bodies(mesh: MeshData) -> tuple[list[MeshData], int]:
    """The separate closed bodies of a mesh, largest volume first, and how many tiny ones
    (under 1 % of the largest's volume: scan debris) were dropped.

    A fragment file normally holds one body; several usually mean several fragments saved
    together, and each is then a fragment of its own. A shell facing inwards is a cavity of
    the solid around it, not a body: a mesh with one is kept whole.
    """
    from .geometry import connected_components, face_adjacency, signed_volume

    _, labels = connected_components(len(mesh.faces), face_adjacency(mesh.faces)[0])
    ids = np.unique(labels)
    if len(ids) == 1:
        return [mesh], 0
    bodies = []
    for k in ids:
        faces = mesh.faces[labels == k]
        used, inverse = np.unique(faces, return_inverse=True)
        v, f = mesh.vertices[used], inverse.reshape(-1, 3)
        bodies.append((signed_volume(v, f), MeshData(vertices=v.copy(), faces=f.astype(np.int64), path=mesh.path)))
    if any(vol < 0 for vol, _ in bodies):
        return [mesh], 0
    bodies.sort(key=lambda b: -b[0])
    largest = bodies[0][0]
    kept = [m for vol, m in bodies if vol >= DEBRIS_SHARE * largest]
    return kept, len(bodies) - len(kept)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are for sharing
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


_NUMBER_LIST = re.compile(r"\[\s*(-?[\d.eE+-]+(?:\s*,\s*-?[\d.eE+-]+)*)\s*\]")


def dumps_json(obj: Any) -> str:
    """JSON with one key per line but short lists of numbers (matrix rows) kept on one line."""
    text = json.dumps(obj, indent=1, allow_nan=False)
    return _NUMBER_LIST.sub(lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text)


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write JSON atomically, with a trailing newline, keys in insertion order."""
    _atomic_write(Path(path), (dumps_json(obj) + "\n").encode())


def write_npz(path: str | os.PathLike, *, compress: bool = True, **arrays: np.ndarray) -> None:
    """Write an ``.npz`` atomically (byte-identical for identical arrays), compressed unless
    ``compress`` is False (large float64 arrays gain little from deflate and cost seconds)."""
    import io
    import zipfile

    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    buf = io.BytesIO()
    # np.savez stamps the current time into the zip; a fixed date keeps output reproducible.
    with zipfile.ZipFile(buf, "w", compression=method) as zf:
        for name, arr in arrays.items():
            b = io.BytesIO()
            np.save(b, np.ascontiguousarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = method
            zf.writestr(info, b.getvalue())
    _atomic_write(Path(path), buf.getvalue())


def write_ply(
    path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray, *, colors: np.ndarray | None = None
) -> None:
    """Write a binary little-endian PLY (float64 positions, int32 indices) atomically.

    ``colors``: optional (n, 3) uint8 vertex colours.
    """
    vertices = np.asarray(vertices, dtype="<f8")
    faces = np.asarray(faces)
    color_props = "property uchar red\nproperty uchar green\nproperty uchar blue\n" if colors is not None else ""
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(vertices)}\n"
        "property double x\nproperty double y\nproperty double z\n" + color_props +
        f"element face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode()
    if colors is not None:
        rec = np.empty(len(vertices), dtype=[("p", "<f8", (3,)), ("c", "u1", (3,))])
        rec["p"], rec["c"] = vertices, colors
        vertices = rec
    face_rec = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_rec["n"] = 3
    face_rec["i"] = faces
    _atomic_write(Path(path), header + vertices.tobytes() + face_rec.tobytes())


def file_in(path: str | os.PathLike, name: str) -> Path:
    """``path``, or ``path / name`` when ``path`` is a folder (a run's output folder for its
    ``transforms.json``, a puzzle's folder for its ``ground_truth.json``)."""
    path = Path(path)
    return path / name if path.is_dir() else path


def read_json(path: str | os.PathLike, *, what: str) -> Any:
    """Read a JSON file, with a one-line error that says what the file should have been."""
    path = Path(path)
    if not path.is_file():
        raise ReassembleError(f"{path}: no such file (expected {what})")
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ReassembleError(f"{path}: not valid JSON ({exc}); expected {what}") from None


def read_transforms(path: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """Read a ``transforms.json`` (or a ``ground_truth.json``, which has the same layout).

    Returns
    -------
    dict
        file stem -> ``{"transform": (4, 4) ndarray, "placed": bool, "confidence": float}``
    """
    path = Path(path)
    data = read_json(path, what="a transforms.json with per-fragment T_world_fragment")
    if not isinstance(data, dict) or not isinstance(data.get("fragments"), dict):
        raise ReassembleError(f"{path}: no 'fragments' object (expected a transforms.json)")
    convention = data.get("convention", TRANSFORMS_CONVENTION)
    if convention != TRANSFORMS_CONVENTION:
        raise ReassembleError(
            f"{path}: convention {convention!r} is not supported (use {TRANSFORMS_CONVENTION!r})"
        )
    out: dict[str, dict[str, Any]] = {}
    for name, entry in data["fragments"].items():
        if not isinstance(entry, dict) or "transform" not in entry:
            raise ReassembleError(f"{path}: fragment {name!r} has no 'transform'")
        try:
            T = np.asarray(entry["transform"], dtype=np.float64)
        except (TypeError, ValueError):
            raise ReassembleError(f"{path}: fragment {name!r}: transform is not numeric") from None
        if not is_rigid(T, atol=1e-4):
            raise ReassembleError(
                f"{path}: fragment {name!r}: transform is not a 4x4 rigid motion (row-major)"
            )
        out[name] = {
            "transform": T,
            "placed": bool(entry.get("placed", True)),
            "confidence": float(entry.get("confidence", 1.0)),
        }
    return out


def check_output_folder(out: str | os.PathLike, *, force: bool = False) -> None:
    """Refuse, before any work, an output folder that exists (without ``force``) or that
    cannot be made (its parent is a file, or not writable)."""
    out = Path(out)
    if out.exists() and not force:
        raise ReassembleError(f"{out}: output folder exists (use --force to replace it)")
    existing = (out.parent if str(out.parent) else Path(".")).absolute()
    while not existing.exists() and existing != existing.parent:  # made later, with the result
        existing = existing.parent
    if not existing.is_dir():
        raise ReassembleError(f"{out}: cannot create output folder ({existing} is a file)")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", suffix=".probe", dir=existing))
    except OSError as exc:
        raise ReassembleError(f"{out}: cannot create output folder ({exc.strerror})") from None


def _remove_stale(parent: Path, name: str) -> None:
    """Remove the hidden staging folders of earlier runs into ``parent/name`` whose process
    is gone (killed midway: SIGKILL, power loss), so they do not pile up."""
    if not parent.is_dir():
        return
    for p in parent.glob(f".{glob_escape(name)}.*"):
        m = re.fullmatch(rf"\.{re.escape(name)}\.(\d+)\.[^.]+\.(partial|old)", p.name)
        if not m or not p.is_dir():
            continue
        pid = int(m.group(1))
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(p, ignore_errors=True)
        except OSError:
            pass  # alive (or not ours to judge)


@contextlib.contextmanager
def staged_directory(out: str | os.PathLike, *, force: bool = False) -> Iterator[Path]:
    """Build an output folder in a temporary sibling and move it into place on success.

    An existing ``out`` is refused unless ``force``; with ``force`` it is replaced only
    once the new folder is complete, so a failure never destroys earlier results.
    """
    out = Path(out)
    check_output_folder(out, force=force)
    parent = out.parent if str(out.parent) else Path(".")
    _remove_stale(parent, out.name)
    try:
        parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", suffix=".partial", dir=parent))
        os.chmod(staging, 0o777 & ~_umask())
    except OSError as exc:
        raise ReassembleError(f"{out}: cannot create output folder ({exc.strerror})") from None
    try:
        yield staging
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", suffix=".old", dir=parent))
            os.replace(out, old / "previous")
            os.replace(staging, out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(staging, out)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)


def glb_bytes(
    meshes: dict[str, tuple[np.ndarray, np.ndarray]],
    T_world_fragment: dict[str, np.ndarray],
    *,
    colors: dict[str, np.ndarray] | None = None,
) -> bytes:
    """A binary glTF scene: one node per fragment, named by it, holding the fragment's mesh
    in its own coordinates and ``T_world_fragment`` as its transform (so a viewer shows the
    assembly and the file keeps the poses). ``colors``: optional name -> (3,) uint8."""
    import trimesh

    scene = trimesh.Scene()
    for name, (vertices, faces) in meshes.items():
        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
        if colors is not None and name in colors:
            rgba = np.r_[np.asarray(colors[name], np.uint8), 255].astype(np.uint8)
            mesh.visual = trimesh.visual.TextureVisuals(
                material=trimesh.visual.material.PBRMaterial(baseColorFactor=rgba, metallicFactor=0.0,
                                                             roughnessFactor=0.8, name=name))
        scene.add_geometry(mesh, node_name=name, geom_name=name,
                           transform=np.asarray(T_world_fragment[name], dtype=np.float64))
    return scene.export(file_type="glb")


def write_glb(
    path: str | os.PathLike,
    meshes: dict[str, tuple[np.ndarray, np.ndarray]],
    T_world_fragment: dict[str, np.ndarray],
    *,
    colors: dict[str, np.ndarray] | None = None,
) -> None:
    """Write :func:`glb_bytes` of the fragments atomically."""
    _atomic_write(Path(path), glb_bytes(meshes, T_world_fragment, colors=colors))


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write bytes atomically (e.g. an encoded picture)."""
    _atomic_write(Path(path), data)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 text atomically."""
    _atomic_write(Path(path), text.encode("utf-8"))


def png_bytes(image: np.ndarray) -> bytes:
    """PNG encoding of an (h, w, 3) uint8 image (no timestamp: the same image, the same bytes)."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def read_glb(path: str | os.PathLike) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The fragments of a scene written by :func:`write_glb`: name -> (vertices (n, 3),
    faces (m, 3), T_world_fragment (4, 4)), in the file's node order."""
    import trimesh

    path = Path(path)
    try:
        scene = trimesh.load(path, file_type="glb", force="scene", process=False)
    except Exception as exc:  # trimesh raises many types on a damaged file
        raise ReassembleError(f"{path}: cannot read ({type(exc).__name__}: {exc})") from None
    out = {}
    for node in scene.graph.nodes_geometry:
        T, geom = scene.graph[node]
        mesh = scene.geometry[geom]
        out[str(node)] = (np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64),
                          np.asarray(T, np.float64))
    return out
