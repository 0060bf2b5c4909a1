"""Fillet meshes: load and orient them, generate new ones, import scans the paper's way.

Every fillet lives in one *canonical frame* so the physics, the renderer and the
experiments agree on what "length" and "leading end" mean:

* x = length, the flow direction on the belt; the narrow tip points to +x, so it
  leads over the roller edge and the wide, rigid end trails (the paper's vision
  cuts the tip off the contour and tracks the trailing edge);
* y = width, z = thickness; the flat bottom lies in the plane z = 0;
* the footprint's bounding box is centred on x = y = 0.

The paper's data set is depth-map based (PCA-aligned scans projected to depth
maps, a GAN generating new depth maps, rebuilt as watertight meshes with a flat
bottom). :func:`depth_map_to_mesh` rebuilds depth maps that way and
:func:`scan_to_depth_map` imports point clouds; in place of the GAN,
:func:`generate_fillet` builds a procedural fillet from a seed (a blunt,
irregular outline with a smooth rim on a ringed mesh, ``docs/physics.md``, "Generated fillets").
Every fillet also exposes a :class:`HeightMap` (its top surface seen from
above), which is what :mod:`woody_sim.fillet_model` slices into segments.
"""

from __future__ import annotations

import contextlib
import functools
import math
import sys
import warnings
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numba
import numpy as np
import trimesh
from scipy import interpolate, ndimage, spatial

from woody_sim.disk_cache import cached, digest

MESH_SUFFIXES = (".obj", ".ply", ".stl")
DERIVED_MARK = "@"
"""Joins a turned or scaled copy's source to its original's (``seed0000.obj@yaw+12.0``)."""
BUILTIN_DIR = Path(__file__).resolve().parent / "meshes"
BUILTIN_REFERENCE_NAMES = ("seed0000", "seed0001", "seed0002")
BUILTIN_GENERATED_SEEDS = (0, 1, 2)
"""Seeds of the generated fillets that ``builtin`` adds to the three reference meshes."""

LENGTH_RANGE = (0.17, 0.208)
WIDTH_RANGE = (0.094, 0.110)
THICKNESS_RANGE = (0.021, 0.031)
"""Fillet dimensions (m) the generator draws from: they bracket the reference meshes (docs/physics.md)."""
RIM_HEIGHT_RANGE = (0.0015, 0.003)
"""Height (m) of the rounded-off rim above the belt (the reference meshes: 2-3 mm)."""
RIM_WIGGLE_RANGE = (0.0007, 0.0013)
"""Standard deviation (m) of the rim's small irregularities across the outline."""
OUTLINE_POINTS = 512
"""Rays (outline vertices) of a generated fillet."""
RINGS = 14
"""Rings of top-surface vertices between the centre and the rim of a generated fillet."""

HEIGHT_MAP_PIXEL = 0.0005
"""Resolution (m) of the height map rasterised from a loaded mesh."""
MAX_HOLE_EDGES = 12
"""Holes with at most this many boundary edges are closed on load; larger ones make the mesh unusable."""
MIN_EXTENT = 0.005
"""A fillet thinner than this (m) along any axis is rejected as degenerate."""


class MeshError(ValueError):
    """A mesh file that cannot become a fillet; the message is one line naming the file and the reason."""


@dataclass(frozen=True, eq=False)
class HeightMap:
    """The top surface of a fillet seen from above: height above the flat bottom on a square grid."""

    heights: np.ndarray
    """(ny, nx) metres; 0 outside the footprint. Row index follows y, column index follows x."""
    x0: float
    """x of the centre of pixel column 0 (m)."""
    y0: float
    """y of the centre of pixel row 0 (m)."""
    pixel: float
    """Pixel size (m)."""

    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear height at world points (arrays broadcast); 0 outside the grid."""
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        coords = np.stack([(y - self.y0) / self.pixel, (x - self.x0) / self.pixel])
        flat = ndimage.map_coordinates(self.heights, coords.reshape(2, -1), order=1, mode="constant", cval=0.0)
        return flat.reshape(x.shape)

    def y_range(self) -> tuple[float, float]:
        """Full y extent covered by the grid (m)."""
        return self.y0 - 0.5 * self.pixel, self.y0 + (self.heights.shape[0] - 0.5) * self.pixel

    def footprint_interval(self, x: float, threshold: float = 1e-4) -> tuple[float, float] | None:
        """(y_min, y_max) of the footprint at one x, with sub-pixel edges; None where the fillet is absent."""
        return self.footprint_intervals([x], threshold)[0]

    def footprint_intervals(self, xs, threshold: float = 1e-4) -> list[tuple[float, float] | None]:
        """:meth:`footprint_interval` at each of ``xs``, sampled in one pass."""
        lo, hi = self.y_range()
        ys = np.arange(lo, hi + 1e-12, self.pixel / 2.0)
        heights = self.sample(np.asarray(xs, dtype=float)[:, None], ys[None, :]) - threshold
        return [_interval(ys, h) for h in heights]


def _interval(ys: np.ndarray, h: np.ndarray) -> tuple[float, float] | None:
    """Where the heights ``h`` over ``ys`` are above 0, each end interpolated between samples; None if nowhere."""
    inside = np.flatnonzero(h > 0.0)
    if inside.size == 0:
        return None
    first, last = inside[0], inside[-1]
    step = ys[1] - ys[0]
    y_min = ys[first] if first == 0 else ys[first - 1] + step * h[first - 1] / (h[first - 1] - h[first])
    y_max = ys[last] if last == ys.size - 1 else ys[last] + step * h[last] / (h[last] - h[last + 1])
    return float(y_min), float(y_max)


@dataclass(frozen=True, eq=False)
class FilletMesh:
    """A fillet surface in the canonical frame (see the module docstring). Treat it as read-only."""

    name: str
    mesh: trimesh.Trimesh
    source: str = ""
    """Where it came from: a file path, ``generated:<seed>`` or ``scan``."""

    @property
    def length(self) -> float:
        return float(self.mesh.extents[0])

    @property
    def width(self) -> float:
        return float(self.mesh.extents[1])

    @property
    def thickness(self) -> float:
        return float(self.mesh.extents[2])

    @cached_property
    def height_map(self) -> HeightMap:
        """Top surface rasterised at :data:`HEIGHT_MAP_PIXEL`; the slicer and the visuals read it."""
        return rasterize_top(self.mesh.vertices, self.mesh.faces, HEIGHT_MAP_PIXEL)


# --------------------------------------------------------------------------- rasterising


def rasterize_top(vertices: np.ndarray, faces: np.ndarray, pixel: float) -> HeightMap:
    """Upper envelope of a triangle soup seen from +z, like a nadir depth camera.

    Barycentric rasterisation of each triangle over the pixels of its bounding box, compiled: a placed fillet
    of a messy line (turned, sized) needs its own height map, so this runs once per fillet on the line. It
    needs no ray-casting library and works for any winding. Heights are measured from the lowest vertex.
    """
    vertices = np.asarray(vertices, dtype=float)
    z_min = vertices[:, 2].min()
    lo = vertices[:, :2].min(axis=0) - pixel
    hi = vertices[:, :2].max(axis=0) + pixel
    nx = int(math.ceil((hi[0] - lo[0]) / pixel)) + 1
    ny = int(math.ceil((hi[1] - lo[1]) / pixel)) + 1
    tri = vertices[np.asarray(faces)]
    u = np.ascontiguousarray((tri[:, :, 0] - lo[0]) / pixel)
    v = np.ascontiguousarray((tri[:, :, 1] - lo[1]) / pixel)
    z = np.ascontiguousarray(tri[:, :, 2] - z_min)
    heights = np.full((ny, nx), -np.inf)
    _upper_envelope(u, v, z, heights)
    heights = np.where(np.isfinite(heights), np.maximum(heights, 0.0), 0.0)
    return HeightMap(heights=heights, x0=float(lo[0]), y0=float(lo[1]), pixel=float(pixel))


@numba.njit(cache=True, nogil=True)
def _upper_envelope(u: np.ndarray, v: np.ndarray, z: np.ndarray, heights: np.ndarray) -> None:
    """Raise ``heights`` (ny, nx) to each triangle's height at every pixel centre inside it (on an edge within
    1e-9 of a barycentric weight counts); u, v are pixel coordinates, (T, 3) each."""
    ny, nx = heights.shape
    eps = 1e-9
    for t in range(u.shape[0]):
        u0, u1, u2, v0, v1, v2 = u[t, 0], u[t, 1], u[t, 2], v[t, 0], v[t, 1], v[t, 2]
        det = (u1 - u0) * (v2 - v0) - (u2 - u0) * (v1 - v0)
        i0, i1 = int(math.ceil(min(u0, u1, u2))), int(math.floor(max(u0, u1, u2)))
        j0, j1 = int(math.ceil(min(v0, v1, v2))), int(math.floor(max(v0, v1, v2)))
        if abs(det) <= 1e-12 or i1 < i0 or j1 < j0:
            continue
        for j in range(max(j0, 0), min(j1, ny - 1) + 1):
            for i in range(max(i0, 0), min(i1, nx - 1) + 1):
                w1 = ((i - u0) * (v2 - v0) - (u2 - u0) * (j - v0)) / det
                w2 = ((u1 - u0) * (j - v0) - (i - u0) * (v1 - v0)) / det
                w0 = 1.0 - w1 - w2
                if w0 >= -eps and w1 >= -eps and w2 >= -eps:
                    heights[j, i] = max(heights[j, i], w0 * z[t, 0] + w1 * z[t, 1] + w2 * z[t, 2])


# --------------------------------------------------------------------------- orientation


def canonical_rotation(points: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Rotation (3x3, rows = new x, y, z axes) taking a fillet-shaped cloud to the canonical frame.

    PCA gives the axes (largest spread = length, smallest = thickness). Signs:
    the footprint rim must sit low (a dome, or a flat bottom under a dome, has
    its outline near the bottom), and the end of the length axis with less
    surface (the narrow tip) goes to +x. y completes a right-handed frame, so a
    fillet is never mirrored.
    """
    pts = np.asarray(points, dtype=float)
    w = np.ones(len(pts)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    centred = pts - w @ pts
    _, vecs = np.linalg.eigh((centred * w[:, None]).T @ centred)
    x_axis, z_axis = vecs[:, 2], vecs[:, 0]
    local = centred @ np.stack([x_axis, np.cross(z_axis, x_axis), z_axis]).T
    if _rim_is_high(local, w):
        z_axis = -z_axis
    x_coord = centred @ x_axis
    span = x_coord.max() - x_coord.min()
    low_end = w[x_coord < x_coord.min() + 0.25 * span].sum()
    high_end = w[x_coord > x_coord.max() - 0.25 * span].sum()
    if high_end > low_end:
        x_axis = -x_axis
    return np.stack([x_axis, np.cross(z_axis, x_axis), z_axis])


def _rim_is_high(local: np.ndarray, w: np.ndarray) -> bool:
    """True if points near the footprint outline sit higher than those near its centre (upside down)."""
    half = np.maximum(0.5 * (local[:, :2].max(axis=0) - local[:, :2].min(axis=0)), 1e-12)
    mid = 0.5 * (local[:, :2].max(axis=0) + local[:, :2].min(axis=0))
    radius = np.sqrt((((local[:, :2] - mid) / half) ** 2).sum(axis=1))
    rim = radius >= np.quantile(radius, 0.8)
    core = radius <= np.quantile(radius, 0.5)
    z = local[:, 2]
    return bool(np.average(z[rim], weights=w[rim]) > np.average(z[core], weights=w[core]))


def _level_bottom(points: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Rotation (rows = new axes) that makes a flat bottom, if the cloud has one, exactly horizontal.

    Expects a cloud already roughly in the canonical frame. PCA's thinnest
    axis is a few degrees off when the dome is lopsided; the flat bottom, when
    there is one (a dense plane of points at the lowest level), is the better
    reference for "down". Without one the rotation is the identity.
    """
    z = points[:, 2]
    near = z < z.min() + 0.1 * (z.max() - z.min())
    if near.sum() < 3 or weights[near].sum() < 0.15 * weights.sum():
        return np.eye(3)
    base = points[near] - np.average(points[near], axis=0, weights=weights[near])
    normal = np.linalg.svd(base * np.sqrt(weights[near, None]), full_matrices=False)[2][2]
    if np.sqrt(np.average((base @ normal) ** 2, weights=weights[near])) > 0.02 * (z.max() - z.min()):
        return np.eye(3)
    z_axis = normal if normal[2] > 0 else -normal
    x_axis = np.array([1.0, 0.0, 0.0]) - z_axis[0] * z_axis
    x_axis /= np.linalg.norm(x_axis)
    return np.stack([x_axis, np.cross(z_axis, x_axis), z_axis])


def orient_canonical(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy of the mesh moved into the canonical frame (module docstring)."""
    weights = mesh.area_faces
    if weights.sum() <= 0.0:
        weights = np.ones(len(mesh.faces))
    centres = mesh.triangles_center
    rot = canonical_rotation(centres, weights)
    rot = _level_bottom(centres @ rot.T, weights) @ rot
    out = mesh.copy()
    out.apply_transform(_homogeneous(rot))
    return _centre(out)


def yawed(fillet: FilletMesh, degrees: float) -> FilletMesh:
    """The fillet turned by ``degrees`` about the vertical (positive towards +y), re-centred: how it lies on the
    belt when it does not arrive straight. The chain is still sliced along the flow (x), as the paper's system
    slices its meshes along their file's x axis whatever their outline's own axis."""
    angle = math.radians(float(degrees))
    if not math.isfinite(angle):
        raise ValueError(f"yaw must be a finite number of degrees, got {degrees!r}")
    c, s = math.cos(angle), math.sin(angle)
    mesh = fillet.mesh.copy()
    mesh.apply_transform(_homogeneous(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])))
    return FilletMesh(name=fillet.name, mesh=_centre(mesh),
                      source=f"{fillet.source}{DERIVED_MARK}yaw{float(degrees):+.1f}")


def scaled(fillet: FilletMesh, factor: float) -> FilletMesh:
    """The fillet ``factor`` times the size in every direction, re-centred (its volume, and so its mass at a
    given density, times factor**3)."""
    factor = float(factor)
    if not (math.isfinite(factor) and factor > 0.0):
        raise ValueError(f"scale must be a positive finite number, got {factor!r}")
    mesh = fillet.mesh.copy()
    mesh.apply_scale(factor)
    return FilletMesh(name=fillet.name, mesh=_centre(mesh), source=f"{fillet.source}{DERIVED_MARK}x{factor:.3f}")


MAX_YAW_SD_DEG = 45.0
"""Widest yaw spread accepted: wider, fillets would lie across the belt rather than turned on it."""


def mesh_yaw(name: str, sd_deg: float) -> float:
    """How far the mesh called ``name`` lies turned on the belt for a yaw spread ``sd_deg``: ``sd_deg`` times a
    normal draw seeded by the name, so a mesh lies the same way at every k and speed, in a sweep and on the
    line, and in every rerun (0 for ``sd_deg`` 0). The sweep's and calibrate's turn; line_sim draws a turn per
    fillet instead (:mod:`woody_sim.line_conditions`)."""
    if not 0.0 <= sd_deg <= MAX_YAW_SD_DEG:
        raise ValueError(f"yaw spread must be within 0..{MAX_YAW_SD_DEG:g} degrees, got {sd_deg!r}")
    if not sd_deg:
        return 0.0
    return float(sd_deg * np.random.default_rng(zlib.crc32(name.encode())).standard_normal())


def _homogeneous(rot: np.ndarray) -> np.ndarray:
    mat = np.eye(4)
    mat[:3, :3] = rot
    return mat


def _centre(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Centre the footprint's bounding box on x = y = 0 and put the bottom at z = 0."""
    lo, hi = mesh.bounds
    mesh.apply_translation([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
    return mesh


# --------------------------------------------------------------------------- loading


def _boundary_loops(faces: np.ndarray) -> list[list[int]] | None:
    """Directed boundary loops of a triangle mesh; None if the boundary is not a set of simple loops."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, inverse, counts = np.unique(np.sort(directed, axis=1), axis=0, return_inverse=True, return_counts=True)
    boundary = directed[counts[inverse.ravel()] == 1]
    nxt: dict[int, int] = {}
    for a, b in boundary.tolist():
        if a in nxt:
            return None
        nxt[a] = b
    loops = []
    while nxt:
        start, loop = next(iter(nxt)), []
        vertex = start
        while vertex in nxt:
            loop.append(vertex)
            vertex = nxt.pop(vertex)
        if vertex != start:
            return None
        loops.append(loop)
    return loops


def _repair(mesh: trimesh.Trimesh, label: str) -> trimesh.Trimesh:
    """Merge coincident vertices, drop degenerate and duplicate faces, close small holes; MeshError if still open.

    STL has no shared vertices and PLY/OBJ exporters may split them, so the same surface
    arrives with coincident vertices, and faces that collapse onto an edge once they are
    merged; dropping those makes it the surface it was (slivers with distinct vertices stay).
    """
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    faces = mesh.faces
    mesh.update_faces((faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0]))
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise MeshError(f"{label}: every triangle is degenerate (repeats a vertex)")
    loops = _boundary_loops(mesh.faces)
    if loops is None:
        raise MeshError(f"{label}: open mesh with a non-manifold boundary")
    too_big = [len(loop) for loop in loops if len(loop) > MAX_HOLE_EDGES]
    if too_big:
        raise MeshError(f"{label}: open mesh (hole of {max(too_big)} edges, at most {MAX_HOLE_EDGES} can be closed)")
    if loops:
        patches = [[loop[0], loop[i + 1], loop[i]] for loop in loops for i in range(1, len(loop) - 1)]
        faces = np.vstack([mesh.faces, np.asarray(patches, dtype=np.int64)])
        mesh = trimesh.Trimesh(mesh.vertices, faces, process=False)
    if not mesh.is_watertight:
        raise MeshError(f"{label}: non-manifold mesh (edges shared by more than two faces)")
    return mesh


FILLET_LENGTH_M = (0.1, 0.3)
"""How long a real fillet is (m); a mesh this long in mm or cm is converted, anything else refused."""
UNITS = (("m", 1.0), ("cm", 0.01), ("mm", 0.001))


class MeshWarning(UserWarning):
    """A mesh was usable only after a conversion (e.g. millimetres to metres); one line naming the file."""


@contextlib.contextmanager
def conversions_noted() -> Iterator[list[str]]:
    """Each mesh conversion (MeshWarning) inside becomes a line ``converted mesh <file>: ...`` of the list yielded
    (filled on leaving), for the program to say with its name, not a Python warning with this file's path and line.
    Other warnings are given again outside."""
    notes: list[str] = []
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeshWarning)  # every file converted, not the first per code line
            yield notes
    finally:
        for warning in caught:
            if issubclass(warning.category, MeshWarning):
                notes.append(f"converted mesh {warning.message}")
            else:
                warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)


def _to_metres(mesh: trimesh.Trimesh, label: str) -> trimesh.Trimesh:
    """Scale a mesh drawn in cm or mm (the usual scanner unit) to metres, judged from its length."""
    length = float(mesh.extents.max())
    low, high = FILLET_LENGTH_M
    for unit, scale in UNITS:
        if low * 0.5 <= length * scale <= high * 2.0:
            if scale != 1.0:
                mesh.apply_scale(scale)
                warnings.warn(f"{label}: {length:g} units long, taken as {unit} and converted to metres "
                              f"({length * scale:.3f} m)", MeshWarning, stacklevel=3)
            return mesh
    raise MeshError(f"{label}: {length:g} units long, not a fillet ({low:g}-{high:g} m) in m, cm or mm")


def _check_stl(path: Path, label: str) -> None:
    """A binary STL's size follows from its triangle count; anything else must be ASCII ``solid ...`` text."""
    data = path.read_bytes()
    if len(data) >= 84:
        count = int.from_bytes(data[80:84], "little")
        if len(data) == 84 + 50 * count:
            return
    head = data[:512].lstrip()
    if head[:5].lower() == b"solid" and all(b in b"\t\n\r" or 32 <= b < 127 for b in head):
        return
    raise MeshError(f"{label}: not a valid STL (neither ASCII 'solid ...' text nor a binary STL whose size "
                    f"matches its triangle count)")


def _read(path: Path, label: str) -> trimesh.Trimesh:
    """The file's triangles as stored (no processing yet, so bad coordinates are seen as they are)."""
    if path.suffix.lower() == ".stl":
        _check_stl(path, label)
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        reason = str(exc).splitlines()[0] if str(exc) and not isinstance(exc, ImportError) else "unparseable data"
        raise MeshError(f"{label}: not a readable {path.suffix.lstrip('.').upper()} mesh ({reason})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise MeshError(f"{label}: no triangles in file")
    bad = ~np.isfinite(loaded.vertices).all(axis=1)
    if bad.any():
        raise MeshError(f"{label}: {int(bad.sum())} vertices with NaN or infinite coordinates "
                        f"(first: vertex {int(np.argmax(bad))})")
    return loaded


def load_mesh(path: str | Path) -> FilletMesh:
    """Load an OBJ/PLY/STL fillet (m, cm or mm), repair small defects and move it to the canonical frame; a file
    loaded before (same path, size and modification time) comes from the disk cache (:mod:`woody_sim.disk_cache`)."""
    path = Path(path)
    try:
        stat = path.stat()
    except OSError:
        return _load_mesh(path)  # says why, in its words
    key = digest((sys.modules[__name__],), str(path), str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    return cached("meshes", key, lambda: _load_mesh(path), FilletMesh)


def _load_mesh(path: Path) -> FilletMesh:
    label = str(path)
    if not path.is_file():
        raise MeshError(f"{label}: file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{label}: unsupported format '{path.suffix}' (use {', '.join(MESH_SUFFIXES)})")
    if path.stat().st_size == 0:
        raise MeshError(f"{label}: empty file")
    mesh = orient_canonical(_repair(_to_metres(_read(path, label), label), label))
    if mesh.extents.min() < MIN_EXTENT:
        dims = " x ".join(f"{e * 1000:.1f}" for e in mesh.extents)
        raise MeshError(f"{label}: degenerate mesh ({dims} mm; every side must be at least {MIN_EXTENT * 1000:.0f} mm)")
    return FilletMesh(name=path.stem, mesh=mesh, source=label)


# --------------------------------------------------------------------------- depth maps


def _clean_mask(depth: np.ndarray) -> np.ndarray:
    """Depth map restricted to one solid, 4-connected footprint without diagonal pinches.

    Pinches (two pixels touching only at a corner) would make a non-manifold
    edge in the rebuilt mesh; they are closed with the mean of the neighbours.
    """
    depth = np.where(np.isfinite(depth) & (depth > 0.0), depth, 0.0)
    labels, count = ndimage.label(depth > 0.0)
    if count == 0:
        raise ValueError("depth map has no pixel above zero")
    largest = 1 + int(np.argmax(ndimage.sum_labels(np.ones_like(depth), labels, index=np.arange(1, count + 1))))
    mask = ndimage.binary_fill_holes(labels == largest)
    kernel = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], dtype=float)
    depth = np.where(mask, depth, 0.0)
    for _ in range(depth.size):
        m = np.pad(mask, 1)
        a, b, c, d = m[:-1, :-1], m[:-1, 1:], m[1:, 1:], m[1:, :-1]
        pinch_ac = a & c & ~b & ~d
        pinch_bd = b & d & ~a & ~c
        if not (pinch_ac.any() or pinch_bd.any()):
            break
        add = np.zeros_like(m)
        add[:-1, 1:] |= pinch_ac
        add[:-1, :-1] |= pinch_bd
        add = add[1:-1, 1:-1] & ~mask
        sums = ndimage.convolve(depth, kernel, mode="constant")
        counts = ndimage.convolve(mask.astype(float), kernel, mode="constant")
        depth = np.where(add, sums / np.maximum(counts, 1.0), depth)
        mask = mask | add
    return np.where(mask, np.maximum(depth, 1e-6), 0.0)


def depth_map_to_mesh(depth: np.ndarray, pixel_size: float | tuple[float, float]) -> trimesh.Trimesh:
    """Watertight fillet mesh from a height map: top surface from the depths, flat bottom, stitched rim.

    ``depth`` is (ny, nx) heights in metres above the bottom (0 = no fillet);
    rows follow y and columns x, pixel centres are centred on the origin.
    Pixels are the cells of the mesh; each grid node takes the mean height of
    the fillet pixels around it, and the outline is closed by vertical walls.
    """
    dx, dy = (pixel_size, pixel_size) if np.isscalar(pixel_size) else pixel_size
    if not (dx > 0 and dy > 0):
        raise ValueError(f"pixel size must be positive, got {pixel_size}")
    depth = _clean_mask(np.asarray(depth, dtype=float))
    mask = depth > 0.0
    ny, nx = depth.shape
    padded = np.pad(depth, 1)
    pm = np.pad(mask, 1).astype(float)
    node_sum = padded[:-1, :-1] + padded[:-1, 1:] + padded[1:, :-1] + padded[1:, 1:]
    node_cnt = pm[:-1, :-1] + pm[:-1, 1:] + pm[1:, :-1] + pm[1:, 1:]
    used = node_cnt > 0
    node_height = np.where(used, node_sum / np.maximum(node_cnt, 1.0), 0.0)
    rows, cols = np.nonzero(used)
    n_used = rows.size
    top_id = np.full(used.shape, -1)
    top_id[rows, cols] = np.arange(n_used)
    bottom_id = top_id + n_used
    xs = (cols - 0.5 - (nx - 1) / 2.0) * dx
    ys = (rows - 0.5 - (ny - 1) / 2.0) * dy
    vertices = np.vstack(
        [np.column_stack([xs, ys, node_height[rows, cols]]), np.column_stack([xs, ys, np.zeros(n_used)])]
    )
    pi, pj = np.nonzero(mask)
    a, b = (pi, pj), (pi, pj + 1)
    c, d = (pi + 1, pj + 1), (pi + 1, pj)
    ta, tb, tc, td = top_id[a], top_id[b], top_id[c], top_id[d]
    ba, bb, bc, bd = bottom_id[a], bottom_id[b], bottom_id[c], bottom_id[d]
    faces = [
        np.column_stack([ta, tb, tc]),
        np.column_stack([ta, tc, td]),
        np.column_stack([ba, bc, bb]),
        np.column_stack([ba, bd, bc]),
    ]
    mp = np.pad(mask, 1)
    sides = [  # (outside neighbour, directed edge p -> q with the pixel on its left)
        (~mp[pi, pj + 1], (ta, tb), (ba, bb)),  # y- side
        (~mp[pi + 1, pj + 2], (tb, tc), (bb, bc)),  # x+ side
        (~mp[pi + 2, pj + 1], (tc, td), (bc, bd)),  # y+ side
        (~mp[pi + 1, pj], (td, ta), (bd, ba)),  # x- side
    ]
    for open_side, (tp, tq), (bp, bq) in sides:
        faces.append(np.column_stack([tp, bp, bq])[open_side])
        faces.append(np.column_stack([tp, bq, tq])[open_side])
    return trimesh.Trimesh(vertices, np.vstack(faces), process=False)


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, ...], sigma: float, mode: str = "reflect") -> np.ndarray:
    """Low-frequency noise with unit standard deviation (Gaussian-filtered white noise)."""
    field = ndimage.gaussian_filter(rng.standard_normal(shape), sigma, mode=mode)
    return field / max(field.std(), 1e-12)


def _bumps(rng: np.random.Generator, t: np.ndarray, count: int, amplitude: float) -> np.ndarray:
    """Sum of ``count`` Gaussian bumps of random sign, place and width along t in [0, 1]: lobes and shoulders."""
    out = np.zeros_like(t)
    for _ in range(count):
        centre, spread = rng.uniform(0.08, 0.92), rng.uniform(0.05, 0.15)
        out += rng.uniform(-amplitude, amplitude) * np.exp(-(((t - centre) / spread) ** 2))
    return out


def _base_outline(rng: np.random.Generator, n: int) -> np.ndarray:
    """A blunt fillet outline (n points per side, unit length along x, tip at +x) as a closed CCW polygon.

    The full width follows a monotone spline through random widths at fixed
    stations (wide trailing end, broad shoulders, a blunt leading end that
    stays wide), rounded off at both ends by quarter-ellipse caps; each side
    gets its own lobes and the centre line a slight bend.
    """
    t = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, n))
    knots = np.array([0.35, 0.55, 0.88, 0.90, 0.85, 0.58, 0.38, 0.28]) + rng.uniform(0.0, 1.0, 8) * np.array(
        [0.25, 0.25, 0.12, 0.10, 0.15, 0.24, 0.22, 0.2])
    body = interpolate.PchipInterpolator([0.0, 0.1, 0.25, 0.4, 0.55, 0.75, 0.9, 1.0], np.minimum(knots, 1.0))(t)
    tail_cap, tip_cap = rng.uniform(0.08, 0.18), rng.uniform(0.04, 0.10)
    cap = np.sqrt(1.0 - (1.0 - np.clip(t / tail_cap, 0.0, 1.0)) ** 2)
    cap *= np.sqrt(1.0 - (1.0 - np.clip((1.0 - t) / tip_cap, 0.0, 1.0)) ** 2)
    half = 0.5 * body * cap / rng.uniform(1.75, 2.05)
    centre = rng.uniform(-0.03, 0.03) * np.sin(np.pi * t)
    upper = centre + half * (1.0 + _bumps(rng, t, 3, 0.12))
    lower = centre - half * (1.0 + _bumps(rng, t, 3, 0.12))
    return np.vstack([np.column_stack([t, lower]), np.column_stack([t[::-1], upper[::-1]])[1:-1]])


def _polar_radii(polygon: np.ndarray, centre: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Distance from ``centre`` to the farthest crossing of the polygon along each ray (a star-shaped envelope)."""
    a = polygon - centre
    b = np.roll(a, -1, axis=0)
    d = np.column_stack([np.cos(theta), np.sin(theta)])
    e = b - a
    denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / denom
        along = (a[None, :, 0] * d[:, None, 1] - a[None, :, 1] * d[:, None, 0]) / denom
    valid = (np.abs(denom) > 1e-12) & (along >= 0.0) & (along <= 1.0) & (dist > 0.0)
    return np.where(valid, dist, 0.0).max(axis=1)


def _rim_wiggle(rng: np.random.Generator, outline: np.ndarray, length: float) -> np.ndarray:
    """Unit-sd irregularity at each outline point, correlated over millimetres of rim (not over rays)."""
    closed = np.vstack([outline, outline[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))]) * length
    count = int(arc[-1] / 0.0005)
    noise = _smooth_noise(rng, (count,), 8.0, "wrap") + 0.6 * _smooth_noise(rng, (count,), 3.0, "wrap")
    return np.interp(arc[:-1], np.arange(count) * arc[-1] / count, noise / noise.std(), period=arc[-1])


def _fillet_outline(rng: np.random.Generator, length: float, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Outline (OUTLINE_POINTS, 2) in metres, star-shaped about the returned centre, with a wiggly rim.

    The base outline is resampled on rays from its centroid, so every later
    step (rim wiggle, scaling to length x width) keeps it star-shaped and the
    mesh built on the rays cannot fold.
    """
    base = _base_outline(rng, OUTLINE_POINTS // 2)
    centre = base.mean(axis=0)
    theta = np.linspace(0.0, 2.0 * np.pi, OUTLINE_POINTS, endpoint=False)
    radii = _polar_radii(base, centre, theta)
    rays = np.column_stack([np.cos(theta), np.sin(theta)])
    radii = radii + rng.uniform(*RIM_WIGGLE_RANGE) / length * _rim_wiggle(rng, centre + radii[:, None] * rays, length)
    points = centre + radii[:, None] * rays
    lo, hi = points.min(axis=0), points.max(axis=0)
    scale = np.array([length, width]) / (hi - lo)
    return (points - 0.5 * (lo + hi)) * scale, (centre - 0.5 * (lo + hi)) * scale


def _top_heights(rng: np.random.Generator, points: np.ndarray, outline: np.ndarray, thickness: float) -> np.ndarray:
    """Heights (m) of the top surface at points inside the outline, peaking at exactly ``thickness``.

    Edges round off over a random margin from the rim (measured as distance to
    the outline, so the rounding is as wide at the ends as at the sides); along
    the length the thickness peaks in the wide half and thins to both ends,
    across it follows an off-centre ridge; a lopsided hump and smooth lumps
    make every profile different.
    """
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    t = (points[:, 0] - lo[0]) / (hi[0] - lo[0])
    v = 2.0 * (points[:, 1] - 0.5 * (lo[1] + hi[1])) / (hi[1] - lo[1])
    dense = np.vstack([np.linspace(p, q, 4, endpoint=False) for p, q in zip(outline, np.roll(outline, -1, axis=0))])
    margin = np.clip(spatial.cKDTree(dense).query(points)[0] / rng.uniform(0.022, 0.038), 0.0, 1.0)
    edge = 1.0 - (1.0 - margin) ** rng.uniform(1.8, 2.8)
    floor = rng.uniform(0.12, 0.32)
    along = floor + (1.0 - floor) * np.exp(-(((t - rng.uniform(0.28, 0.55)) / rng.uniform(0.35, 0.55)) ** 2))
    ridge = v - rng.uniform(-0.4, 0.4) - rng.uniform(-0.4, 0.4) * (t - 0.5)
    across = 1.0 - rng.uniform(0.3, 0.6) * np.clip(ridge, -1.2, 1.2) ** 2
    hump_t, hump_v = rng.uniform(0.2, 0.7), rng.uniform(-0.5, 0.5)
    hump = 1.0 + rng.uniform(0.1, 0.4) * np.exp(-(((t - hump_t) / 0.25) ** 2) - ((v - hump_v) / 0.35) ** 2)
    field = _smooth_noise(rng, (24, 48), 3.0)
    lumps = 1.0 + rng.uniform(0.05, 0.14) * ndimage.map_coordinates(
        field, [(v + 1.0) * 11.5, t * 47.0], order=1, mode="nearest")
    core = edge * along * across * hump * lumps
    rim = rng.uniform(*RIM_HEIGHT_RANGE)
    return rim + (thickness - rim) * np.clip(core, 0.0, None) / core.max()


def _ring_mesh(outline: np.ndarray, centre: np.ndarray, heights) -> trimesh.Trimesh:
    """Watertight mesh on rays from ``centre`` to a star-shaped outline: ringed top, flat bottom, vertical rim wall.

    ``heights(points)`` gives the top surface; rings are denser towards the rim,
    where the surface rounds off. The bottom repeats the top's rings at z = 0,
    so no triangle is large (the height-map rasteriser's cost grows with it).
    """
    n = len(outline)
    rho = (np.arange(1, RINGS + 1) / RINGS) ** 0.7
    plan = np.vstack([centre[None, :], (centre + rho[:, None, None] * (outline - centre)).reshape(-1, 2)])
    vertices = np.vstack([np.column_stack([plan, heights(plan)]), np.column_stack([plan, np.zeros(len(plan))])])
    k = np.arange(n)
    k1 = (k + 1) % n
    inner, outer = 1 + np.arange(RINGS - 1)[:, None] * n, 1 + np.arange(1, RINGS)[:, None] * n
    top = np.vstack([
        np.column_stack([np.zeros(n, int), 1 + k, 1 + k1]),
        np.column_stack([(inner + k).ravel(), (outer + k).ravel(), (outer + k1).ravel()]),
        np.column_stack([(inner + k).ravel(), (outer + k1).ravel(), (inner + k1).ravel()]),
    ])
    rim, rim1, down = 1 + (RINGS - 1) * n + k, 1 + (RINGS - 1) * n + k1, len(plan)
    wall = np.vstack([np.column_stack([rim, rim + down, rim1 + down]), np.column_stack([rim, rim1 + down, rim1])])
    return trimesh.Trimesh(vertices, np.vstack([top, top[:, ::-1] + down, wall]), process=False)


def generate_fillet(seed: int) -> FilletMesh:
    """A reproducible synthetic fillet (same seed, same mesh) with a realistic outline and real-fillet size.

    Procedural, not a statistical shape model: three reference meshes cannot
    estimate the modes of real shape variation, so the parameter ranges are
    chosen to bracket them instead (``docs/physics.md``, "Generated fillets").
    """
    if int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    length, width, thickness = (rng.uniform(*r) for r in (LENGTH_RANGE, WIDTH_RANGE, THICKNESS_RANGE))
    outline, centre = _fillet_outline(rng, length, width)
    height_rng = np.random.default_rng(rng.integers(2**63))  # own stream: outline changes keep the thickness draws
    mesh = _ring_mesh(outline, centre, lambda plan: _top_heights(height_rng, plan, outline, thickness))
    return FilletMesh(name=f"generated-{int(seed):04d}", mesh=_centre(mesh), source=f"generated:{int(seed)}")


# --------------------------------------------------------------------------- scans


@dataclass(frozen=True, eq=False)
class ScanDepthMap:
    """A scan in the paper's normalised form: PCA-aligned, unit-sphere scaled, projected to a depth map."""

    depth: np.ndarray
    """(n, n) heights divided by the data-set-wide maximum height, in [0, 1]."""
    pixel: float
    """Pixel size in unit-sphere units (the grid spans [-1, 1] in x and y)."""
    scale: float
    """Metres per unit-sphere unit: the radius the scan was divided by."""
    max_height: float
    """The data-set-wide maximum height (unit-sphere units) the depths are normalised by."""


def _align_scan(points: np.ndarray) -> tuple[np.ndarray, float]:
    """PCA-aligned points scaled into the unit sphere (about the centroid), bottom at z = 0, and the scale."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 100 or not np.isfinite(pts).all():
        raise ValueError("a scan must be an (n >= 100, 3) array of finite points")
    centred = pts - pts.mean(axis=0)
    rot = canonical_rotation(centred)
    rot = _level_bottom(centred @ rot.T, np.ones(len(centred))) @ rot
    aligned = centred @ rot.T
    scale = float(np.linalg.norm(aligned, axis=1).max())
    if scale <= 0.0:
        raise ValueError("scan points are all identical")
    unit = aligned / scale
    unit[:, 2] -= unit[:, 2].min()
    return unit, scale


def scan_height(points: np.ndarray) -> float:
    """Height of one scan in unit-sphere units; the data-set-wide maximum of these normalises depth maps."""
    return float(_align_scan(points)[0][:, 2].max())


def scan_to_depth_map(points: np.ndarray, max_height: float | None = None, grid: int = 128) -> ScanDepthMap:
    """Project a fillet point cloud to a depth map the way the paper prepares its scans.

    PCA alignment removes the pose, scaling into the unit sphere removes the
    size, and heights are divided by ``max_height`` (the largest
    :func:`scan_height` over the data set, so relative thickness between
    fillets survives; defaults to this scan's own height). Pixels without
    points inside the footprint are closed from their neighbours.
    """
    unit, scale = _align_scan(points)
    height = float(unit[:, 2].max())
    max_height = height if max_height is None else float(max_height)
    if max_height <= 0.0:
        raise ValueError(f"max_height must be positive, got {max_height}")
    if grid < 16:
        raise ValueError(f"grid must be at least 16 pixels, got {grid}")
    pixel = 2.0 / grid
    col = np.clip(((unit[:, 0] + 1.0) / pixel).astype(int), 0, grid - 1)
    row = np.clip(((unit[:, 1] + 1.0) / pixel).astype(int), 0, grid - 1)
    top = np.full(grid * grid, -np.inf)
    np.maximum.at(top, row * grid + col, unit[:, 2])
    top = top.reshape(grid, grid)
    seen = np.isfinite(top)
    footprint = ndimage.binary_fill_holes(ndimage.binary_closing(seen, iterations=2) | seen)
    closed = ndimage.grey_closing(np.where(seen, top, 0.0), size=(3, 3))
    depth = np.where(footprint, np.maximum(np.where(seen, top, 0.0), closed), 0.0)
    return ScanDepthMap(depth=np.clip(depth / max_height, 0.0, 1.0), pixel=pixel, scale=scale, max_height=max_height)


def scan_depth_map_to_fillet(scan: ScanDepthMap, name: str = "scan") -> FilletMesh:
    """Rebuild a normalised scan depth map as a watertight fillet at its physical size."""
    heights = scan.depth * scan.max_height * scan.scale
    mesh = _centre(depth_map_to_mesh(heights, scan.pixel * scan.scale))
    return FilletMesh(name=name, mesh=mesh, source="scan")


def scan_to_fillet(
    points: np.ndarray, max_height: float | None = None, grid: int = 128, name: str = "scan"
) -> FilletMesh:
    """Import a point-cloud scan as a fillet: :func:`scan_to_depth_map` then the depth-map rebuild."""
    return scan_depth_map_to_fillet(scan_to_depth_map(points, max_height, grid), name)


# --------------------------------------------------------------------------- mesh sets


@functools.cache
def _builtin_reference(name: str) -> FilletMesh:
    return load_mesh(BUILTIN_DIR / f"{name}.obj")


@functools.cache
def _cached_generated(seed: int) -> FilletMesh:
    return generate_fillet(seed)


def _parse_generated(item: str) -> list[int]:
    parts = item.split(":")
    try:
        count = int(parts[1])
        base = int(parts[2]) if len(parts) == 3 else 0
    except (IndexError, ValueError):
        raise ValueError(f"mesh spec '{item}': expected generated:N or generated:N:SEED") from None
    if len(parts) > 3 or count < 1 or base < 0:
        raise ValueError(f"mesh spec '{item}': N must be >= 1 and SEED >= 0")
    return [base * 10_000 + i for i in range(count)]


def load_mesh_set(spec: str) -> tuple[list[FilletMesh], list[str]]:
    """Fillets named by a comma-separated spec, plus one error line per file that could not be used.

    Items: ``builtin`` (the three reference meshes and three generated ones),
    ``generated:N`` / ``generated:N:SEED`` (N fillets with seeds SEED*10000 + i),
    a folder (every .obj/.ply/.stl in it, sorted) or a single mesh file.
    A malformed spec, a missing path or two files giving one name (``a.obj`` and
    ``a.stl``) raises ValueError; bad files inside a folder are reported and
    skipped so one broken scan does not stop a run.
    """
    fillets: list[FilletMesh] = []
    errors: list[str] = []
    items = [item.strip() for item in spec.split(",") if item.strip()]
    if not items:
        raise ValueError("empty mesh spec")
    for item in items:
        if item == "builtin":
            fillets += [_builtin_reference(name) for name in BUILTIN_REFERENCE_NAMES]
            fillets += [_cached_generated(seed) for seed in BUILTIN_GENERATED_SEEDS]
        elif item.startswith("generated:"):
            fillets += [_cached_generated(seed) for seed in _parse_generated(item)]
        else:
            path = Path(item).expanduser()
            if path.is_dir():
                files = sorted(f for f in path.iterdir() if f.is_file() and f.suffix.lower() in MESH_SUFFIXES)
                if not files:
                    errors.append(f"{path}: no {', '.join(MESH_SUFFIXES)} files in folder")
                for file in files:
                    try:
                        fillets.append(load_mesh(file))
                    except MeshError as exc:
                        errors.append(str(exc))
            elif path.is_file():
                fillets.append(load_mesh(path))
            else:
                raise ValueError(f"mesh spec '{item}': not 'builtin', 'generated:N[:SEED]', a folder or a mesh file")
    _check_names(fillets)
    return fillets, errors


def _check_names(fillets: list[FilletMesh]) -> None:
    """ValueError when two files give one name (``a.obj`` and ``a.stl``): verdicts and runs are keyed by it."""
    sources: dict[str, str] = {}
    for fillet in fillets:
        first = sources.setdefault(fillet.name, fillet.source)
        if first != fillet.source:
            raise ValueError(f"meshes {first} and {fillet.source} share the name '{fillet.name}' (a mesh is named "
                             "by its file's stem); rename one")


def checked_mesh_set(spec: str) -> tuple[list[FilletMesh], list[str]]:
    """`load_mesh_set` for a program to report: the usable meshes and one line per file skipped (``skipped mesh
    <file>: <why>``) or converted (``converted mesh <file>: ...``); ValueError, one line naming every file and
    why, when none is usable."""
    with conversions_noted() as converted:
        fillets, errors = load_mesh_set(spec)
    if not fillets:
        raise ValueError(f"mesh spec '{spec}': no loadable mesh ({'; '.join(errors)})")
    return fillets, [f"skipped mesh {error}" for error in errors] + converted
