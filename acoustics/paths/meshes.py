"""Build the triangle meshes a scene asks for, in the sonar frame, and check them.

Procedural shapes are built with trimesh; files are read with trimesh. Every mesh is checked:
an unreadable or missing file, an empty mesh or non-finite vertices are errors; degenerate faces,
duplicate vertices and inconsistent winding are repaired when ``repair`` is on (the default) and
the repair is reported as a :class:`~acoustics.scene.SceneWarning` naming the file and the mesh.
Meshes end in the sonar frame (coordinates local to the sonar), which is what keeps Embree's
float32 arithmetic accurate near the sonar.
"""
from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from acoustics.frames import Pose, transform_rotation
from acoustics.seeds import ping_rng

__all__ = ["SceneMesh", "MeshSources", "build_mesh", "scene_meshes", "MeshError", "mesh_file_faces",
           "mesh_file_read_bytes", "grid_file_shape"]


class MeshError(ValueError):
    """A mesh that cannot be used; the message names the mesh, its key and file."""


@dataclass(frozen=True, eq=False)
class SceneMesh:
    """A built mesh and what it is.

    Attributes
    ----------
    name : str
    kind : {"boundary", "target"}
    role : str
        "surface", "floor", "obstacle" (boundaries) or "rigid"/"pressure_release" (targets).
    mesh : trimesh.Trimesh
        In the sonar frame (m).
    spec : object
        The boundary or mesh-target spec it came from.
    key : str
        Its key path in the scene file, for messages.
    surface : MovingSurface, optional
        A sea surface that moves between pings (acoustics/paths/sea_surface.py).
    placement : ndarray, shape (4, 4), optional
        The surface's frame (world, after the shape's transform) into the sonar frame.
    normals : ndarray, shape (n_v, 3), optional
        Unit vertex normals of the smooth surface the mesh samples, when known exactly
        (sea surfaces); else estimated from the facets where needed.
    time_s : float
        The sea's time this mesh shows.
    """

    name: str
    kind: str
    role: str
    mesh: trimesh.Trimesh
    spec: object
    key: str
    surface: object = None
    placement: np.ndarray | None = None
    normals: np.ndarray | None = None
    time_s: float = 0.0

    @property
    def moving(self) -> bool:
        return self.surface is not None

    def at_time(self, time_s: float) -> "SceneMesh":
        """This sea surface at sea time ``time_s`` (s); itself when it does not move."""
        if self.surface is None or time_s == self.time_s:
            return self
        v, n = self.surface.grid(time_s)
        rot, shift = self.placement[:3, :3], self.placement[:3, 3]
        m = trimesh.Trimesh(v @ rot.T + shift, self.mesh.faces, process=False)
        n = n @ rot.T
        n /= np.linalg.norm(n, axis=1)[:, None]
        return SceneMesh(self.name, self.kind, self.role, m, self.spec, self.key, self.surface,
                         self.placement, n, float(time_s))

    @property
    def n_faces(self) -> int:
        """Its facets (a tiled floor's without building it)."""
        from acoustics.paths.tiles import is_tiled
        return int(self.mesh.n_faces) if is_tiled(self.mesh) else int(len(self.mesh.faces))

    @property
    def plane(self):
        """(unit normal (3,), offset d) with n·x = d if the mesh is flat, else None (a tiled
        floor: a rough floor, never flat)."""
        from acoustics.paths.tiles import is_tiled
        if is_tiled(self.mesh):
            return None
        m = self.mesh
        n = m.face_normals
        if len(n) == 0:
            return None
        ref = n[np.argmax(m.area_faces)]
        if np.max(1.0 - np.abs(n @ ref)) > 1e-9:
            return None
        d = float(np.mean(m.vertices @ ref))
        if np.max(np.abs(m.vertices @ ref - d)) > 1e-6 * max(1.0, m.scale):
            return None
        return ref, d


def _grid_mesh(x, y, z):
    """Triangulated height field z[j, i] over x[i], y[j]."""
    xx, yy = np.meshgrid(x, y)
    v = np.column_stack([xx.ravel(), yy.ravel(), np.asarray(z, float).ravel()])
    nx, ny = x.size, y.size
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    b, c, d = a + 1, a + nx, a + nx + 1
    faces = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    return trimesh.Trimesh(v, faces, process=False)


def _rough_floor(spec, seed: int):
    nx = int(np.ceil(spec.size_m[0] / spec.resolution_m)) + 1
    ny = int(np.ceil(spec.size_m[1] / spec.resolution_m)) + 1
    if nx * ny > 4_000_000:
        raise MeshError(f"rough_floor of {nx} x {ny} vertices is too fine to build whole (limit 4 "
                        f"million): raise resolution_m, shrink size_m, or stream it in tiles "
                        f"(effects.floor_tiles.memory_mb)")
    x = spec.center_m[0] + np.linspace(-spec.size_m[0] / 2, spec.size_m[0] / 2, nx)
    y = spec.center_m[1] + np.linspace(-spec.size_m[1] / 2, spec.size_m[1] / 2, ny)
    h = np.zeros((ny, nx))
    if spec.rms_height_m > 0:
        # Gaussian random field: white noise filtered by a Gaussian spectrum, normalised to the RMS
        rng = ping_rng(seed + spec.seed, 2**31 - 2, "reverberation", 0)
        w = rng.standard_normal((ny, nx))
        kx = np.fft.fftfreq(nx, spec.resolution_m) * 2 * np.pi
        ky = np.fft.fftfreq(ny, spec.resolution_m) * 2 * np.pi
        kk = kx[None, :] ** 2 + ky[:, None] ** 2
        filt = np.exp(-kk * spec.correlation_length_m**2 / 4)
        h = np.real(np.fft.ifft2(np.fft.fft2(w) * filt))
        h *= spec.rms_height_m / max(h.std(), 1e-300)
    z = spec.depth_m + spec.slope[0] * (x[None, :] - spec.center_m[0]) + spec.slope[1] * (
        y[:, None] - spec.center_m[1]) + h
    return _grid_mesh(x, y, z)


def moving_surface(spec, seed: int = 0):
    """The :class:`~acoustics.paths.sea_surface.MovingSurface` of a ``wind_sea`` or ``swell``
    shape (before its transform): :func:`acoustics.paths.sea_surface.surface_of`."""
    from acoustics.paths.sea_surface import surface_of
    return surface_of(spec, seed)


def _transform_matrix(t):
    mat = np.eye(4)
    mat[:3, :3] = transform_rotation(t.rotate_deg) * t.scale
    mat[:3, 3] = t.translate_m
    return mat


_GRID_ACCEPTS = "a height grid (a .npy array of numbers or a CSV of numbers, one row per y)"


def _gate(file, folder, what, accepts):
    """A mesh or grid file read through the file gate (:mod:`processing.base.files`)."""
    from acoustics.scene.load import MAX_MESH_FILE_BYTES
    from processing.base.files import FileRefused, read_bytes
    try:
        return read_bytes(file, folder=folder, max_bytes=MAX_MESH_FILE_BYTES, what=what,
                          accepts=accepts)
    except FileRefused as exc:
        raise MeshError(str(exc)) from None


def _npy_header(fh):
    """(shape, dtype, offset of the data) of a .npy file's header, or None if it has none."""
    from numpy.lib import format as npy
    try:
        version = npy.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = npy.read_array_header_1_0(fh)
        elif version in ((2, 0), (3, 0)):
            shape, _, dtype = npy.read_array_header_2_0(fh)
        else:
            return None
    except (ValueError, OSError, EOFError, SyntaxError, TypeError):
        return None
    return tuple(int(n) for n in shape), dtype, fh.tell()


def mesh_file_read_bytes(path) -> float:
    """Memory of reading a mesh or grid file: its bytes and what the reader makes of them (3 x
    the size for a binary format: .npy, GLB, binary STL and PLY; 11 x for text, whose parsers
    hold the text, its lines and its numbers at once). 0 for a file that cannot be opened."""
    import os
    p = Path(path)
    suffix = p.suffix.lower()
    try:
        size = os.stat(p).st_size
        with open(p, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return 0.0
    binary = suffix in (".npy", ".glb")
    if suffix == ".stl" and len(head) >= 84:
        binary = 84 + 50 * int.from_bytes(head[80:84], "little") == size
    if suffix == ".ply":
        parsed = _ply_header(head)
        binary = parsed is not None and parsed[0]
    return float(size) * (3.0 if binary else 11.0)


class _GridRefused(ValueError):
    """Why a .npy grid is refused (our words, never the file's)."""


def _load_grid(f, data: bytes):
    """The heights of a grid file's bytes: a .npy whose header is checked before any array is
    made (numbers only — no pickles —, the shape the bytes hold), else comma-separated text."""
    if f.path.suffix.lower() == ".npy":
        head = _npy_header(io.BytesIO(data))
        if head is None:
            raise _GridRefused("it has no .npy header")
        shape, dtype, offset = head
        if dtype.kind not in "biuf" or dtype.hasobject:
            raise _GridRefused("it holds no array of numbers (objects are never unpickled)")
        if int(np.prod(shape, dtype=object)) * dtype.itemsize != len(data) - offset:
            raise _GridRefused(f"its header's shape {shape} is not what its {len(data) - offset:,} "
                               f"bytes of data hold")
        return np.load(io.BytesIO(data), allow_pickle=False)
    text = data.decode("utf-8-sig")
    return np.loadtxt(io.StringIO(text), delimiter=",", comments=None, ndmin=2)


def grid_file_shape(path) -> tuple[int, ...] | None:
    """The shape a height-grid file holds, from its header before it is read (.npy, when the
    header's shape is what the file's bytes hold), else None (text, or a header that does not
    match the file: bounded by its size, see :func:`mesh_file_faces`)."""
    import os
    p = Path(path)
    if p.suffix.lower() != ".npy":
        return None
    try:
        size = os.stat(p).st_size
        with open(p, "rb") as fh:
            head = _npy_header(fh)
    except OSError:
        return None
    if head is None:
        return None
    shape, dtype, offset = head
    if int(np.prod(shape, dtype=object)) * dtype.itemsize != size - offset:
        return None    # a header that lies about the bytes: the grid's reader refuses it
    return shape


_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2,
              "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
              "double": 8, "float64": 8}


def _ply_header(head: bytes):
    """(binary, [(element, count, fixed bytes of one, list (count bytes, item bytes) or None)],
    bytes of the header) of a PLY file's first bytes, or None."""
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    stop = head.find(b"\n", end)
    binary, elements = True, []
    for line in head[:end].decode("ascii", "replace").split("\n"):
        w = line.split()
        if w[:2] == ["format", "ascii"]:
            binary = False
        elif len(w) == 3 and w[0] == "element" and w[2].isdigit():
            elements.append([w[1], int(w[2]), 0, None])
        elif len(w) >= 5 and w[:2] == ["property", "list"] and elements:
            elements[-1][3] = (_PLY_SIZES.get(w[2], 1), _PLY_SIZES.get(w[3], 4))
        elif len(w) == 3 and w[0] == "property" and elements:
            elements[-1][2] += _PLY_SIZES.get(w[1], 8)
    return binary, elements, (stop + 1 if stop >= 0 else len(head))


def _ply_triangles(head: bytes, size: int):
    """The most triangles a PLY file gives, from its header and size, or None (no header).
    Binary, with one list (the faces'): the bytes left for the faces' vertex indices, each
    polygon of k indices k − 2 triangles; else the face count, bounded by the size."""
    parsed = _ply_header(head)
    if parsed is None:
        return None
    binary, elements, header_bytes = parsed
    faces = [e for e in elements if e[0] == "face"]
    if not faces:
        return None
    _, n_faces, fixed, lst = faces[0]
    lists = [e for e in elements if e[3] is not None]
    if binary and lst is not None and len(lists) == 1:
        other = sum(n * b for name, n, b, _ in elements if name != "face")
        indices = (size - header_bytes - other - n_faces * (fixed + lst[0])) / lst[1]
        return float(max(indices - 2.0 * n_faces, 0.0))
    per_index = lst[1] if (binary and lst is not None) else 2
    room = size / per_index - 2.0 * n_faces
    return float(min(max(n_faces, room), size / per_index))   # a header may lie


def mesh_file_faces(path) -> float:
    """The most triangles a mesh or height-grid file can give, found without loading it: from
    the header where the format has one (binary STL: its face count; PLY and OFF: the face
    count and, for polygons, the bytes left for their vertex indices; .npy grids: the shape),
    else from its size (ASCII STL: 80 bytes a facet; OBJ: a face line's index at least 2 bytes,
    each beyond the second a triangle; glTF: 3 bytes a triangle; CSV grids: 2 bytes a value,
    2 triangles a value). An upper bound: the estimate of memory
    (:mod:`acoustics.simulation.budget`) must never be below what the file makes. 0 for a file
    that cannot be opened (the file gate reports it)."""
    import os
    p = Path(path)
    suffix = p.suffix.lower()
    try:
        size = os.stat(p).st_size
        if suffix in (".npy", ".csv", ".txt"):
            shape = grid_file_shape(p)
            if shape is not None:
                if len(shape) != 2:
                    return 0.0
                return 2.0 * max(shape[0] - 1, 0) * max(shape[1] - 1, 0)
            return float(size) / (4.0 if suffix == ".npy" else 1.0)
        with open(p, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return 0.0
    if suffix == ".stl" and len(head) >= 84:
        n = int.from_bytes(head[80:84], "little")
        if 84 + 50 * n == size:
            return float(n)
        return size / 80.0
    if suffix == ".ply":
        bound = _ply_triangles(head, size)
        if bound is not None:
            return bound
    if suffix == ".off":
        words = head.decode("ascii", "replace").split()
        if words and words[0].endswith("OFF") and len(words) >= 3 and words[2].isdigit():
            faces = int(words[2])
            return float(min(max(faces, size / 2.0 - 2.0 * faces), size / 2.0))
    if suffix in (".glb", ".gltf"):
        return size / 3.0
    return size / 2.0     # OBJ and anything unrecognised: 2 bytes an index, a triangle each


def _suffixes():
    from acoustics.scene.meshes_spec import MESH_SUFFIXES
    return MESH_SUFFIXES


def build_mesh(spec, *, name: str, key: str, resolve, seed: int = 0,
               folder=None) -> trimesh.Trimesh:
    """Build one mesh in the frame its spec is written in (before the pose).

    Parameters
    ----------
    spec : MeshSpec
    name, key : str
        For messages.
    resolve : callable(str) -> Path
        Turns a path written in the scene into a file path.
    seed : int
        The scene's seed (rough floors).
    folder : str or Path, optional
        The folder files must lie in (the file gate, :mod:`processing.base.files`); default
        ``resolve(".")``, the scene file's folder.

    Raises
    ------
    MeshError
    """
    shape = spec.shape
    folder = resolve(".") if folder is None else folder
    where = f"{key} ({name!r})"
    try:
        if shape == "plane":
            n = np.asarray(spec.normal, float)
            if np.linalg.norm(n) == 0:
                raise MeshError(f"{where}: plane normal must be a non-zero vector")
            nx, ny = spec.segments
            x = np.linspace(-spec.size_m[0] / 2, spec.size_m[0] / 2, nx + 1)
            y = np.linspace(-spec.size_m[1] / 2, spec.size_m[1] / 2, ny + 1)
            m = _grid_mesh(x, y, np.zeros((ny + 1, nx + 1)))
            # rotate +z onto the normal, then move to the centre
            m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], n / np.linalg.norm(n)))
            m.apply_translation(spec.center_m)
        elif shape == "rough_floor":
            m = _rough_floor(spec, seed)
        elif shape == "height_grid":
            f, data = _gate(spec.file, folder, "height grid file", _GRID_ACCEPTS)
            path = f.path
            try:
                z = np.asarray(_load_grid(f, data), float)
            except (ValueError, OSError, EOFError, UnicodeDecodeError) as exc:
                # never echo the file's contents (a reader's message may): it may not be the user's
                why = f": {exc}" if isinstance(exc, _GridRefused) else ""
                raise MeshError(f"{where}: {path} is not a height grid (a .npy array or a CSV "
                                f"of numbers, one row per y){why}") from None
            del data
            if z.ndim != 2 or min(z.shape) < 2:
                raise MeshError(f"{where}: {path} must hold a 2-D grid of at least 2 x 2 heights")
            x = spec.origin_m[0] + np.arange(z.shape[1]) * spec.spacing_m[0]
            y = spec.origin_m[1] + np.arange(z.shape[0]) * spec.spacing_m[1]
            m = _grid_mesh(x, y, z)
        elif shape in ("wind_sea", "swell"):
            try:
                surf = moving_surface(spec, seed)
            except ValueError as exc:
                raise MeshError(f"{where}: {exc}") from None
            v, _ = surf.grid(spec.time_offset_s)
            m = _grid_mesh(surf.x_m, surf.y_m, v[:, 2].reshape(surf.y_m.size, surf.x_m.size))
        elif shape == "sphere":
            m = trimesh.creation.icosphere(subdivisions=spec.subdivisions, radius=spec.radius_m)
            m.apply_translation(spec.center_m)
        elif shape == "spheroid":
            m = trimesh.creation.icosphere(subdivisions=spec.subdivisions, radius=1.0)
            m.apply_scale(spec.semi_axes_m)
            m.apply_translation(spec.center_m)
        elif shape == "box":
            m = trimesh.creation.box(extents=spec.size_m)
            m.apply_translation(spec.center_m)
        else:
            f, data = _gate(spec.file, folder, "mesh file",
                            f"a mesh file ({', '.join(s.lstrip('.') for s in _suffixes())})")
            path = f.path
            try:
                # from the bytes the gate read, with no resolver: a file that names others (an
                # OBJ's material library, a glTF's buffers) cannot make trimesh read them
                loaded = trimesh.load(io.BytesIO(data), file_type=path.suffix.lower().lstrip("."),
                                      force="mesh", process=False)
            except Exception as exc:  # any reader failure is the user's file; never echo it
                raise MeshError(f"{where}: cannot read mesh file {path} as "
                                f"{path.suffix.lstrip('.').upper() or 'a mesh'} "
                                f"({exc.__class__.__name__})") from None
            del data
            if not isinstance(loaded, trimesh.Trimesh):
                raise MeshError(f"{where}: {path} holds no triangle mesh")
            m = loaded
    except MeshError:
        raise
    except (ValueError, OSError) as exc:
        raise MeshError(f"{where}: cannot build the mesh ({exc.__class__.__name__})") from None
    source = getattr(spec, "file", None)
    label = f"{where}" + (f", file {resolve(source)}" if source else "")
    v = np.asarray(m.vertices, float)
    if len(m.faces) == 0 or len(v) == 0:
        raise MeshError(f"{label}: the mesh is empty (no faces)")
    if not np.all(np.isfinite(v)):
        raise MeshError(f"{label}: the mesh has non-finite vertex coordinates (NaN or inf)")
    if np.any(m.faces < 0) or np.any(m.faces >= len(v)):
        raise MeshError(f"{label}: faces refer to vertices that do not exist")
    # a moving sea keeps its grid's vertex order (it is updated in place every ping)
    repaired = m if shape in ("wind_sea", "swell") else _repair(m, label, getattr(spec, "repair", True))
    t = spec.transform
    if t.scale != 1.0 or any(t.rotate_deg) or any(t.translate_m):
        repaired.apply_transform(_transform_matrix(t))
    return repaired


def _repair(m, label, allowed: bool):
    """Drop degenerate faces, merge duplicate vertices, make winding consistent — and say so."""
    area = m.area_faces
    degenerate = ~(area > 1e-14 * max(m.scale, 1e-12) ** 2)
    notes = []
    if degenerate.any():
        if not allowed:
            raise MeshError(f"{label}: {int(degenerate.sum())} degenerate (zero-area) faces; set "
                            f"repair: true or fix the file")
        m = trimesh.Trimesh(m.vertices, m.faces[~degenerate], process=False)
        notes.append(f"removed {int(degenerate.sum())} degenerate faces")
        if len(m.faces) == 0:
            raise MeshError(f"{label}: every face is degenerate: the mesh is empty")
    before = len(m.vertices)
    m.merge_vertices()
    if len(m.vertices) < before:
        notes.append(f"merged {before - len(m.vertices)} duplicate vertices")
    if not m.is_winding_consistent:
        if not allowed:
            raise MeshError(f"{label}: inconsistent face winding (normals); set repair: true")
        _fix_winding(m)
        notes.append("made the face winding consistent")
    if m.is_watertight and m.volume < 0:
        m.invert()
        notes.append("turned the normals outwards")
    if notes:
        from acoustics.scene import SceneWarning
        warnings.warn(f"{label}: repaired: {'; '.join(notes)}", SceneWarning, stacklevel=3)
    return m


@dataclass(frozen=True, eq=False)
class MeshSources:
    """A scene's boundaries and mesh targets, and where their files are read from.

    Attributes
    ----------
    boundaries, targets : tuple
        The boundary and mesh-target specs, as validated.
    folder : Path or None
        The scene file's folder: a relative path in a spec is read from there (None: a scene
        built from text, whose paths are taken as they are).
    source : str
        The scene file, for messages.
    seed : int
        The scene's seed (rough floors, sea surfaces).
    floor_tiles : FloorTilesSpec, optional
        ``effects.floor_tiles``: rough floors streamed in tiles when it is enabled
        (acoustics/paths/tiles.py); None: built whole.
    """

    boundaries: tuple = ()
    targets: tuple = ()
    folder: Path | None = None
    source: str = "<scene>"
    seed: int = 0
    floor_tiles: object = None

    def resolve_path(self, path) -> Path:
        """A path written in the scene, relative to the scene file's folder."""
        p = Path(path)
        if p.is_absolute() or self.folder is None:
            return p
        return self.folder / p


def scene_meshes(sources: MeshSources, pose: Pose) -> list[SceneMesh]:
    """Every boundary and mesh target, built and moved into the sonar frame of ``pose``.

    Raises
    ------
    acoustics.scene.SceneError
        A mesh that cannot be used (the message names the mesh, its key and its file).
    """
    from acoustics.scene import SceneError
    out = []
    items = [("boundary", f"boundaries[{i}]", b, b.role) for i, b in enumerate(sources.boundaries)]
    items += [("target", f"targets.meshes[{i}]", t, t.boundary)
              for i, t in enumerate(sources.targets)]
    src = sources.source
    tiles = sources.floor_tiles
    for kind, key, spec, role in items:
        mat = np.eye(4)
        if spec.frame == "world":
            mat[:3, :3] = pose.rotation.T
            mat[:3, 3] = -pose.rotation.T @ pose.position_m
        if tiles is not None and tiles.enabled and spec.mesh.shape == "rough_floor":
            # streamed in tiles (acoustics/paths/tiles.py), never built whole
            from acoustics.paths.tiles import FloorTiles, TileMemoryError
            try:
                m = FloorTiles(spec.mesh, sources.seed, mat @ _transform_matrix(spec.mesh.transform),
                               memory_mb=tiles.memory_mb, tile_vertices=tiles.tile_vertices,
                               key=f"{key}.mesh")
            except TileMemoryError as exc:
                raise SceneError(f"{src}: {exc}") from None
            out.append(SceneMesh(spec.name, kind, role, m, spec, key))
            continue
        try:
            m = build_mesh(spec.mesh, name=spec.name, key=f"{key}.mesh",
                           resolve=sources.resolve_path, seed=sources.seed)
        except MeshError as exc:
            raise SceneError(f"{src}: {exc}") from None
        if spec.frame == "world":
            m.apply_transform(mat)
        sm = SceneMesh(spec.name, kind, role, m, spec, key)
        if spec.mesh.shape in ("wind_sea", "swell"):
            place = mat @ _transform_matrix(spec.mesh.transform)
            t0 = spec.mesh.time_offset_s
            sm = SceneMesh(spec.name, kind, role, m, spec, key, moving_surface(spec.mesh, sources.seed),
                           place, None, np.nan).at_time(t0)
        out.append(sm)
    return out


def _fix_winding(m) -> None:
    """Make the face winding consistent, in place: each connected patch takes the winding of its
    first face, walking breadth-first over shared edges; a neighbour that traverses a shared edge
    in the same direction as the face it is reached from is flipped. (trimesh's
    ``repair.fix_winding`` does the same through networkx, which abacus does not install.)"""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components
    n = len(m.faces)
    adj = np.asarray(m.face_adjacency)
    if adj.size == 0:
        return
    g = coo_matrix((np.ones(len(adj)), (adj[:, 0], adj[:, 1])), shape=(n, n)).tocsr()
    _, labels = connected_components(g, directed=False)
    faces = np.asarray(m.faces).copy()
    for root in np.unique(labels, return_index=True)[1]:
        order, pred = breadth_first_order(g, int(root), directed=False, return_predecessors=True)
        for f in order[1:]:
            a, b = faces[pred[f]], faces[f]
            edges = {(a[i], a[(i + 1) % 3]) for i in range(3)}
            if any((b[i], b[(i + 1) % 3]) in edges for i in range(3)):
                faces[f] = b[::-1]
    m.faces = faces
