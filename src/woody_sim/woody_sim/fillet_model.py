"""The paper's fillet model: a fillet sliced along its length into a chain of rigid segments.

Each of the N slices becomes one rigid body: its collision shape is the box
bounding that slice, its mass is the total mass M shared in proportion to the
slice's actual volume (the paper shares it by the bounding box's height x
width, which overweights tapering ends), and neighbours are hinged about the
width axis (y) at their common face. The slice of the fillet surface is kept
as the segment's visual, expressed in the segment's own frame, so a renderer
that poses each piece with the physics bends the fillet continuously.

Frames: the fillet frame is the canonical frame of :mod:`woody_sim.meshes`
(x = length with the tip at +x, y = width, z = thickness, bottom at z = 0).
A segment frame has the fillet frame's axes and its origin at the centre of
the segment's collision box; :mod:`woody_sim.line_world` reports exactly these
frames, so ``world_vertex = pose * visual.vertices``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from woody_sim.meshes import FilletMesh, HeightMap

DEFAULT_SEGMENTS = 24
"""Slices of a chain unless asked otherwise: with the hinges scaled (PhysicsConfig.hinge_scale) the paper's chain
at a coarser resolution, its scores inside their run-to-run spread and its step 2.7x cheaper with the 360 Hz step
(docs/physics.md, "What each setting costs and what it changes")."""
NOMINAL_MASS = 1.0
"""kg the geometry is built with; masses scale linearly, and LineWorld sets each fillet's calibrated M."""
VISUAL_ROWS = 20
"""Points across the width in each visual cross-section."""
VISUAL_STATIONS = 2
"""Cross-sections per segment length, so the top surface keeps its slope inside a segment."""
MIN_WIDTH = 0.002
"""Narrowest cross-section (m) at the very ends of a fillet, where the outline closes to a point."""
MIN_HEIGHT = 0.0005
"""Thinnest cross-section edge (m), so no visual wall collapses to zero height."""


@dataclass(frozen=True)
class SegmentVisual:
    """One segment's piece of the fillet surface, for the renderer to pose with the physics."""

    # (n, 3) float32, metres, in the segment's pybullet link frame (the frame whose pose line_world reports)
    vertices: np.ndarray
    faces: np.ndarray  # (m, 3) int32


@dataclass(frozen=True, eq=False)
class FilletModel:
    """A fillet ready for the physics: per-segment boxes, masses, hinges and visuals (fillet frame)."""

    name: str
    edges: np.ndarray
    """(N + 1,) x of the slice boundaries."""
    box_centers: np.ndarray
    """(N, 3) centre of each collision box = origin of each segment frame."""
    box_half_extents: np.ndarray
    """(N, 3) half sizes of the collision boxes."""
    masses: np.ndarray
    """(N,) kg, summing to the total mass."""
    joint_positions: np.ndarray
    """(N - 1, 3) hinge point between segment i and i + 1; the hinge axis is +y."""
    visuals: list[SegmentVisual]

    @property
    def n_segments(self) -> int:
        return len(self.masses)

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())

    def with_mass(self, total_mass: float) -> FilletModel:
        """The same geometry with the masses rescaled to a new total (the cross-section shares stay)."""
        if not total_mass > 0.0:
            raise ValueError(f"mass must be positive, got {total_mass}")
        return replace(self, masses=self.masses * (float(total_mass) / self.masses.sum()))


def slab_volumes(height_map: HeightMap, edges: np.ndarray) -> np.ndarray:
    """(N,) volume (m^3) of the fillet between consecutive x ``edges``: the height map integrated per slab.

    The paper shares M by each slice's bounding box (height x width); a tapering
    end fills a small part of its box, so box shares overweight the tip. Here
    each slab weighs what the fillet holds between its edges (a pixel column
    split between two slabs is shared by overlap).
    """
    columns = height_map.heights.sum(axis=0) * height_map.pixel**2  # m^3 per pixel column
    left = height_map.x0 - 0.5 * height_map.pixel + height_map.pixel * np.arange(columns.size)
    cumulative = np.concatenate([[0.0], np.cumsum(columns)])
    at = np.interp(edges, np.concatenate([left, [left[-1] + height_map.pixel]]), cumulative)
    return np.diff(at)


def volume_masses(volumes: np.ndarray, total_mass: float) -> np.ndarray:
    """m_i = M * V_i / sum(V), with a floor of 1e-3 of the mean so no slab of a ragged end is massless."""
    share = np.maximum(np.asarray(volumes, dtype=float), 1e-3 * float(np.mean(volumes)))
    return total_mass * share / share.sum()


def _section(height_map: HeightMap, x: float, interval: tuple[float, float] | None,
             rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Top profile (y, z) of the fillet at one x (its footprint ``interval`` there), as ``rows`` points from one
    edge to the other."""
    if interval is None or interval[1] - interval[0] < MIN_WIDTH:
        centre = 0.0 if interval is None else 0.5 * (interval[0] + interval[1])
        interval = (centre - MIN_WIDTH / 2.0, centre + MIN_WIDTH / 2.0)
    ys = np.linspace(interval[0], interval[1], rows)
    zs = np.maximum(height_map.sample(np.full(rows, x), ys), MIN_HEIGHT)
    return ys, zs


def _slab_visual(stations: list[tuple[float, np.ndarray, np.ndarray]], origin: np.ndarray) -> SegmentVisual:
    """Closed mesh swept through the cross-sections of one slab, with caps at both ends.

    Each cross-section is a ring: the top profile from one edge to the other,
    then the flat bottom back. Consecutive rings are joined by quads; the end
    rings are closed by strips between top and bottom points.
    """
    rows = len(stations[0][1])
    rings = []
    for x, ys, zs in stations:
        top = np.column_stack([np.full(rows, x), ys, zs])
        bottom = np.column_stack([np.full(rows, x), ys[::-1], np.zeros(rows)])
        rings.append(np.vstack([top, bottom]))
    vertices = np.vstack(rings) - origin
    size = 2 * rows
    faces = []
    k = np.arange(size)
    k1 = (k + 1) % size
    for s in range(len(rings) - 1):
        a, b = s * size + k, s * size + k1
        c, d = (s + 1) * size + k1, (s + 1) * size + k
        faces += [np.column_stack([a, b, c]), np.column_stack([a, c, d])]
    j = np.arange(rows - 1)
    for s, flip in ((0, True), (len(rings) - 1, False)):
        top_a, top_b = s * size + j, s * size + j + 1
        bot_a, bot_b = s * size + size - 1 - j, s * size + size - 2 - j
        cap = np.vstack([np.column_stack([top_a, top_b, bot_b]), np.column_stack([top_a, bot_b, bot_a])])
        faces.append(cap[:, ::-1] if flip else cap)
    faces = np.vstack(faces)
    tri = vertices[faces]
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0.0:
        faces = faces[:, ::-1]
    return SegmentVisual(vertices=vertices.astype(np.float32), faces=np.ascontiguousarray(faces, dtype=np.int32))


def build_fillet_model(
    fillet: FilletMesh,
    n_segments: int = DEFAULT_SEGMENTS,
    total_mass: float = NOMINAL_MASS,
    visual_rows: int = VISUAL_ROWS,
    visual_stations: int = VISUAL_STATIONS,
) -> FilletModel:
    """Slice a fillet into ``n_segments`` equal-length slabs along x (the paper's chain model).

    The slab bounding boxes and the visual cross-sections both come from the
    fillet's height map, so the boxes hug what the cameras see.
    """
    if int(n_segments) != n_segments or n_segments < 2:
        raise ValueError(f"number of segments must be an integer >= 2, got {n_segments}")
    if not total_mass > 0.0:
        raise ValueError(f"mass must be positive, got {total_mass}")
    if visual_rows < 3 or visual_stations < 1:
        raise ValueError("a visual needs at least 3 rows and 1 station per segment")
    n_segments = int(n_segments)
    hm = fillet.height_map
    x_min, x_max = fillet.mesh.bounds[:, 0]
    edges = np.linspace(x_min, x_max, n_segments + 1)
    station_x = np.linspace(x_min, x_max, n_segments * visual_stations + 1)
    sections = [_section(hm, x, interval, visual_rows)
                for x, interval in zip(station_x, hm.footprint_intervals(station_x))]
    centers = np.zeros((n_segments, 3))
    half = np.zeros((n_segments, 3))
    for i in range(n_segments):
        a, b = edges[i], edges[i + 1]
        # the box bounds the slab as sampled on a fine grid and every visual point of the slab
        own = [sections[s] for s in range(i * visual_stations, (i + 1) * visual_stations + 1)]
        y_lo = min(ys[0] for ys, _ in own)
        y_hi = max(ys[-1] for ys, _ in own)
        top = max(zs.max() for _, zs in own)
        xs = np.linspace(a, b, max(3, int(np.ceil((b - a) / hm.pixel)) + 1))
        found = [(x, interval) for x, interval in zip(xs, hm.footprint_intervals(xs)) if interval is not None]
        if found:
            ends = np.array([interval for _, interval in found])
            y_lo, y_hi = min(y_lo, float(ends[:, 0].min())), max(y_hi, float(ends[:, 1].max()))
            ys = np.linspace(ends[:, 0], ends[:, 1], 4 * visual_rows, axis=1)
            top = max(top, float(hm.sample(np.array([x for x, _ in found])[:, None], ys).max()))
        centers[i] = (0.5 * (a + b), 0.5 * (y_lo + y_hi), 0.5 * top)
        half[i] = (0.5 * (b - a), 0.5 * (y_hi - y_lo), 0.5 * top)
    masses = volume_masses(slab_volumes(hm, edges), float(total_mass))
    hinge_z = np.minimum(half[:-1, 2], half[1:, 2])
    joints = np.column_stack([edges[1:-1], 0.5 * (centers[:-1, 1] + centers[1:, 1]), hinge_z])
    visuals = []
    for i in range(n_segments):
        chunk = range(i * visual_stations, (i + 1) * visual_stations + 1)
        visuals.append(_slab_visual([(station_x[s], *sections[s]) for s in chunk], centers[i]))
    return FilletModel(
        name=fillet.name,
        edges=edges,
        box_centers=centers,
        box_half_extents=half,
        masses=masses,
        joint_positions=joints,
        visuals=visuals,
    )
