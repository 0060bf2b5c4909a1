"""Setting the vision up from a recording of the real camera: belt plane, flow, speed, roller edge and lanes.

A few seconds of the top camera's depth (the empty belt, then fillets passing) hold everything the vision needs
to know of its mount, so a user measures nothing by hand:

* the **belt plane**, fitted (RANSAC, then least squares) to the background of the first frames in which nothing
  rises off the belt: the camera's height above it, and its lean;
* the **flow**: the direction and speed of the fillets' centroids on that plane, frame to frame;
* the **roller edge**: where the belt plane ends downstream (past it the depth falls to the floor);
* the **lanes**: where across the flow the fillets travel (clusters of their tracks' positions).

Together they give the camera's pose in the belt frame (REP 103: x downstream, z up, origin on the belt surface
at the roller edge, y = 0 in the middle of the lanes): what ``tf_static`` must carry, and the parameters of the
segmenter and grader. Each figure comes with its spread. What cannot be found is refused with one line
(:class:`SetupError`): no empty-belt frames at the start, no plane that fits the belt, no fillet moving on it,
the edge out of view or no fillet crossing it. Plain module (numpy, OpenCV); ``woody camera setup`` reads the
bag and writes the files.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from woody_common.line import MOUNT_EULER
from woody_vision.belt_view import CameraModel, rays
from woody_vision.static_frames import STRAIGHT_DOWN, Pose

RISE_M = 0.005
"""A pixel this far above the belt plane is something on the belt (a fillet), not the belt."""
PLANE_TOLERANCE_M = 0.004
"""A background point within this of the plane is belt (RANSAC inlier)."""
MIN_BELT_FRACTION = 0.15
"""The belt plane must hold at least this share of the background's valid pixels."""
BELT_SHARE = 0.3
"""A plane holding this share of the largest plane's points may be the belt (it is the nearest such plane)."""
MIN_EMPTY_FRAMES = 3
MIN_BLOB_PX = 300
MAX_STEP_M = 0.06
"""A centroid moving further than this between two frames is another fillet."""
MIN_MOTIONS = 10
TOP_SHARE = 0.5
"""A blob's centroid is taken over its pixels higher than this share of its highest: its top, not its sides."""
STEADY_SIZE = 0.03
"""A blob whose size changed less than this fraction between two frames moved with the belt."""
LANE_GAP_M = 0.05
"""Fillet tracks further apart across the flow than this belong to different lanes."""
REACH_M = 0.05
"""A fillet whose centroid on the belt came this close to the edge went over it (past it, it hangs below the belt
plane and leaves the blobs)."""
EDGE_BIN_M = 0.02
PROFILE_BIN_M = 0.002


@dataclass(frozen=True)
class Sighting:
    """A blob on the belt in one frame: its centroid on the belt plane (camera coordinates) and its size."""

    centroid: np.ndarray
    size: float
    """Its area on the belt plane (arbitrary units: the same in every frame of one camera)."""


class SetupError(ValueError):
    """What the recording cannot tell, in one line."""


@dataclass(frozen=True)
class BeltSetup:
    """The mount and the line found in a recording, each with its spread."""

    pose: Pose
    """The camera's optical frame in the belt frame."""
    height_m: float
    plane_rms_m: float
    speed_mps: float
    speed_sd_mps: float
    edge_sd_m: float
    lane_centres_m: tuple[float, ...]
    """Across the flow (belt y), in lane order 0.. (lane 0 most positive y)."""
    lane_sd_m: float
    tracks: int

    @property
    def lanes(self) -> int:
        return len(self.lane_centres_m)

    @property
    def lane_pitch_m(self) -> float:
        centres = np.sort(self.lane_centres_m)
        return float(np.median(np.diff(centres))) if len(centres) > 1 else math.nan

    @property
    def edge_offset_m(self) -> float:
        """The roller edge downstream of the optical centre along the flow (the grader's roller_edge_offset_m)."""
        return float(-self.pose.translation[0])

    def mount_deg(self) -> tuple[float, float, float]:
        """(tilt, roll, yaw) in degrees, as a camera description file gives them (woody_sim.camera_description)."""
        turn = self.pose.rotation @ STRAIGHT_DOWN.T
        lean, roll, yaw = Rotation.from_matrix(turn).as_euler(MOUNT_EULER, degrees=True)
        return float(-lean), float(roll), float(yaw)


def find_setup(camera: CameraModel, frames: Sequence[tuple[float, np.ndarray]], seed: int = 0) -> BeltSetup:
    """The belt setup from (stamp s, float metres depth) frames of the camera, the empty belt first."""
    ray = rays(camera)
    background, empty = _background(frames, ray)
    normal, offset, rms, belt = _belt_plane(ray * background[..., None], seed)
    points = [(stamp, ray * depth[..., None]) for stamp, depth in frames[empty:]]
    flow, speed, speed_sd, tracks = _flow(points, normal, offset)
    across = np.cross(normal, flow)
    edge, edge_sd = _edge(ray * background[..., None], belt, normal, offset, flow, across)
    centres, lane_sd = _lanes(tracks, flow, across, edge)
    middle = float(np.mean(centres))
    rotation = np.stack([flow, across, normal])  # rows: belt axes in camera coordinates
    pose = Pose(np.array([-edge, -middle, offset]), rotation)
    return BeltSetup(pose, offset, rms, speed, speed_sd, edge_sd,
                     tuple(float(c - middle) for c in sorted(centres, reverse=True)), lane_sd, len(tracks))


def _background(frames: Sequence[tuple[float, np.ndarray]], ray: np.ndarray) -> tuple[np.ndarray, int]:
    """The median depth of the leading frames in which nothing rises off the rest, and how many they are."""
    if len(frames) < MIN_EMPTY_FRAMES + 2:
        raise SetupError(f"the bag has {len(frames)} depth frames; it needs the empty belt, then fillets passing")
    first = _median([depth for _, depth in frames[:MIN_EMPTY_FRAMES]])
    empty = 0
    for _, depth in frames:
        if _blobs(_smoothed((first - depth) * ray[..., 2]))[0] > 1:
            break
        empty += 1
    if empty < MIN_EMPTY_FRAMES:
        raise SetupError(f"no empty-belt frames at the start: something rises off the belt within its first "
                         f"{empty + 1} frames; record a few seconds of the empty belt first")
    return _median([depth for _, depth in frames[:empty]]), empty


def _median(depths: list[np.ndarray]) -> np.ndarray:
    """The per-pixel median of depth frames, NaN where none measured (out of range, holes)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(np.stack(depths), axis=0)


def _belt_plane(points: np.ndarray, seed: int) -> tuple[np.ndarray, float, float, np.ndarray]:
    """(unit normal towards the camera, the camera's height d above the plane (a point's height is normal·p + d),
    rms residual, inlier mask): RANSAC over the background's points, refined by least squares on the inliers."""
    valid = np.isfinite(points).all(axis=-1)
    cloud = points[valid]
    if len(cloud) < 1000:
        raise SetupError("the background has almost no valid depth; is the camera covered or out of range?")
    normal, offset = _nearest_large_plane(cloud, np.random.default_rng(seed))
    inliers = np.abs(cloud @ normal + offset) < PLANE_TOLERANCE_M
    if inliers.mean() < MIN_BELT_FRACTION:
        raise SetupError(f"no belt plane fits: the best plane holds {inliers.mean():.0%} of the background "
                         f"(needs {MIN_BELT_FRACTION:.0%}); is the belt in view and flat?")
    centre = cloud[inliers].mean(axis=0)
    normal = np.linalg.svd(cloud[inliers] - centre, full_matrices=False)[2][2]
    normal = normal if normal @ centre < 0 else -normal  # towards the camera, at the origin
    offset = float(-normal @ centre)
    residual = cloud[inliers] @ normal + offset
    mask = np.zeros(valid.shape, bool)
    mask[valid] = np.abs(cloud @ normal + offset) < PLANE_TOLERANCE_M
    return normal, offset, float(np.sqrt(np.mean(residual ** 2))), mask


def _nearest_large_plane(cloud: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """The belt's plane (normal towards the camera, offset): planes found one after another (RANSAC, each on the
    points the earlier ones left), and of those holding at least BELT_SHARE of the first one's points the nearest
    to the camera; the floor past the roller and beside the belt can be the larger plane."""
    points = cloud[rng.choice(len(cloud), min(len(cloud), 20000), replace=False)]
    planes = []
    for _ in range(3):
        if len(points) < 100:
            break
        count, normal, offset = _ransac_plane(points, rng)
        if planes and count < BELT_SHARE * planes[0][0]:
            break
        planes.append((count, normal, offset))
        points = points[np.abs(points @ normal + offset) >= PLANE_TOLERANCE_M]
    _, normal, offset = min(planes, key=lambda plane: plane[2])
    return normal, offset


def _ransac_plane(points: np.ndarray, rng: np.random.Generator, tries: int = 200) -> tuple[int, np.ndarray, float]:
    """(inliers, normal towards the camera, offset) of the plane through three points holding most points."""
    best = (-1, np.array([0.0, 0.0, -1.0]), 0.0)
    for _ in range(tries):
        a, b, c = points[rng.choice(len(points), 3, replace=False)]
        normal = np.cross(b - a, c - a)
        if np.linalg.norm(normal) < 1e-9:
            continue
        normal /= np.linalg.norm(normal)
        normal = normal if normal @ a < 0 else -normal
        count = int(np.count_nonzero(np.abs(points @ normal - a @ normal) < PLANE_TOLERANCE_M))
        if count > best[0]:
            best = (count, normal, float(-a @ normal))
    return best


def _flow(points: list[tuple[float, np.ndarray]], normal: np.ndarray,
          offset: float) -> tuple[np.ndarray, float, float, list[list[Sighting]]]:
    """(flow direction on the plane, speed m/s, its sd, tracks of centroids): fillets' centroids matched frame to
    frame by nearest neighbour."""
    tracks: list[list[Sighting]] = []
    open_tracks: list[list[Sighting]] = []
    motions: list[np.ndarray] = []
    previous = None
    for stamp, cloud in points:
        step = stamp - previous if previous is not None else math.nan
        open_tracks = _extend(open_tracks, _centroids(cloud, normal, offset), motions, step, tracks)
        previous = stamp
    if len(motions) < MIN_MOTIONS:
        raise SetupError(f"no fillet moving on the belt: {len(motions)} centroid steps between frames (needs "
                         f"{MIN_MOTIONS}); record fillets passing after the empty belt")
    motions = np.array(motions)
    direction = np.median(motions / np.linalg.norm(motions, axis=1, keepdims=True), axis=0)
    direction -= (direction @ normal) * normal
    direction /= np.linalg.norm(direction)
    speeds = motions @ direction
    return direction, float(np.median(speeds)), float(np.std(speeds) / math.sqrt(len(speeds))), tracks


def _smoothed(height: np.ndarray) -> np.ndarray:
    """A height map with a real camera's speckle and holes taken out (5 x 5 median; a hole counts as 0)."""
    return cv2.medianBlur(np.nan_to_num(height, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32), 5)


def _blobs(height: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """(labels, label image, stats) of the regions rising RISE_M to 0.1 m off the belt."""
    mask = ((height > RISE_M) & (height < 0.1)).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    big = [label for label in range(1, count) if stats[label, cv2.CC_STAT_AREA] >= MIN_BLOB_PX]
    return len(big) + 1, labels, np.array(big, int)


def _centroids(cloud: np.ndarray, normal: np.ndarray, offset: float) -> list[Sighting]:
    """The centroid (on the belt plane) of each blob rising off it."""
    with np.errstate(invalid="ignore"):
        _, labels, big = _blobs(_smoothed(cloud @ normal + offset))
    out = []
    for label in big:
        blob = cloud[labels == label]
        blob = blob[np.isfinite(blob).all(axis=1)]
        height = blob @ normal + offset
        top = blob[height > TOP_SHARE * height.max()] if len(blob) else blob
        if len(top):
            # the top only: the camera sees the sides of a fillet facing its axis, which would pull the centroid
            # towards the axis, and each pixel weighs the belt area it sees (a tilted camera samples far parts sparser)
            weight = top[:, 2] ** 3 / np.abs(top @ normal)
            foot = top - np.outer(top @ normal + offset, normal)
            out.append(Sighting(weight @ foot / weight.sum(), float(weight.sum())))
    return out


def _extend(open_tracks: list[list[Sighting]], sightings: list[Sighting], motions: list, step: float,
            tracks: list[list[Sighting]]) -> list[list[Sighting]]:
    """Each open track takes the nearest sighting within MAX_STEP_M; the rest open tracks. A step whose blob kept
    its size is a motion of the belt (a fillet entering the image or tipping over the edge changes its size and
    moves its centroid slower than the belt)."""
    still, free = [], list(sightings)
    for track in open_tracks:
        if not free:
            break
        distances = [np.linalg.norm(s.centroid - track[-1].centroid) for s in free]
        nearest = int(np.argmin(distances))
        if distances[nearest] <= MAX_STEP_M and math.isfinite(step) and step > 0:
            sighting = free.pop(nearest)
            if abs(sighting.size / track[-1].size - 1.0) < STEADY_SIZE:
                motions.append((sighting.centroid - track[-1].centroid) / step)
            track.append(sighting)
            still.append(track)
    for centroid in free:
        track = [centroid]
        tracks.append(track)
        still.append(track)
    return still


def _edge(background: np.ndarray, belt: np.ndarray, normal: np.ndarray, offset: float, flow: np.ndarray,
          across: np.ndarray) -> tuple[float, float]:
    """(the roller edge's place along the flow in camera-centred plane coordinates, the spread of the belt's end
    across its width). Past the edge the belt wraps round the roller: the height profile along the flow (the
    median across the belt, PROFILE_BIN_M bins) falls as h = −(x − e)² / 2R, so sqrt(−h) is a line in x that
    meets 0 at the edge e (the plane's own tolerance would place it where the roller has already dropped by it)."""
    points = background[np.isfinite(background).all(-1)]
    along, side, height = points @ flow, points @ across, points @ normal + offset
    inlier_side, inlier_along = background[belt] @ across, background[belt] @ flow
    low, high = np.percentile(inlier_side, [5, 95])
    end = float(np.percentile(inlier_along, 99))
    on_belt = (side > low) & (side < high)
    if np.count_nonzero(on_belt & (along > end + 0.03) & (height > -2.0 * PLANE_TOLERANCE_M)) >= 200:
        raise SetupError("the roller edge is not in view: the belt plane goes on to the image's border")
    near = on_belt & (along > end - 0.02) & (along < end + 0.03)
    bins = np.floor((along[near] - end) / PROFILE_BIN_M).astype(int)
    profile = np.array([(end + (b + 0.5) * PROFILE_BIN_M, float(np.median(height[near][bins == b])))
                        for b in np.unique(bins) if np.count_nonzero(bins == b) >= 20]).reshape(-1, 2)
    falling = profile[(profile[:, 1] < -0.001) & (profile[:, 1] > -0.015)]
    if len(falling) < 3:
        raise SetupError("the roller edge is not in view: the belt does not fall away round a roller in the image")
    slope, intercept = np.polyfit(falling[:, 0], np.sqrt(-falling[:, 1]), 1)
    side_bins = np.floor(inlier_side / EDGE_BIN_M)
    ends = [float(np.max(inlier_along[side_bins == b])) for b in np.unique(side_bins)
            if np.count_nonzero(side_bins == b) > 50]
    return float(-intercept / slope), float(np.std(ends))


def _lanes(tracks: list[list[Sighting]], flow: np.ndarray, across: np.ndarray,
           edge: float) -> tuple[list[float], float]:
    """Lane centres across the flow (plane coordinates) from the tracks of fillets that crossed the edge, and the
    spread of a track about its lane's centre."""
    reached = [[s.centroid for s in track] for track in tracks if len(track) >= 3]
    reached = [track for track in reached if max(p @ flow for p in track) > edge - REACH_M]
    if not reached:
        raise SetupError("no fillet crossing the roller edge: record until fillets pass over it")
    sides = sorted(float(np.median([p @ across for p in track])) for track in reached)
    groups = [[sides[0]]]
    for side in sides[1:]:
        if side - groups[-1][-1] > LANE_GAP_M:
            groups.append([])
        groups[-1].append(side)
    centres = [float(np.mean(g)) for g in groups]
    spread = float(np.sqrt(np.mean([(s - c) ** 2 for g, c in zip(groups, centres) for s in g])))
    return centres, spread
