"""Frame-to-frame fillet tracking: each fillet's blob predicted from the belt's motion (paper: Euclidean centroid
distance).

Blobs are matched to tracks with a minimum-total-distance assignment
(``scipy.optimize.linear_sum_assignment``) between each track's predicted
position and the blobs', gated by ``max_distance_px``; within the gate
a track seen in the previous frame is preferred over a stale one (being unseen
costs 2 × the gate in the assignment), an established track over one opened in
the last frames (half the gate), and among stale ones the nearer prediction
wins, however many frames each went unseen. A position is the blob's centroid
column and the row of the end of it that rides the belt: its trailing edge,
or while the blob still reaches the image's first row (the fillet entering the
view) its leading edge. The centroid's row is not used: a fillet tipping over
the roller shortens its visible outline from the front, so its centroid slows
and jumps while its trailing edge, still on the belt, keeps the belt's speed,
and a fillet entering the view grows from the border at half its speed. The
prediction is that end's last observed motion along the rows times the time
since that sighting (the fillet's own latest motion, so a belt speed change is
followed from the next frame); there is no motion across the rows: fillets
ride the belt along the image rows, and a blob that merged with a neighbour's
for a frame jumps sideways, which is no motion (extrapolated, it handed the
track to the neighbour in the next lane). The time comes from the frames'
stamps: a frame the camera or the network dropped never reaches the tracker,
so counting updates would predict one frame's motion across a gap of several,
and a burst of 5–8 lost frames split every fillet in view into two unscored
tracks. Unmatched blobs open tracks with new, never reused integer ids; a
track ends once it has gone ``max_unseen`` consecutive frames without a match
(paper: 15).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from woody_vision.camera_model import LaneLayout
from woody_vision.segmentation import Blob

DEFAULT_MAX_UNSEEN = 15
"""Frames a track may go unmatched before it ends (paper: 15)."""
DEFAULT_MAX_DISTANCE_PX = 40.0
"""Association gate around the predicted centroid (belt motion is 8–11 px/frame at 30 Hz; neighbouring fillets'
centroids are ≥ ~75 px apart)."""
GAP_GATE_GROWTH = 0.5
"""The gate widens by this fraction of the predicted motion since the last sighting: a track's velocity comes
from its last two sightings, which a merge or a split in one of them skews, so after a burst of lost frames the
prediction can fall that much short."""
ENTRY_ROWS = 1
"""A blob reaching this close to the image's first row (rows) is a fillet still entering the view: its trailing
edge is the border, and its leading edge rides the belt."""
NO_LANE = -1
BELT_SPEED_MIN_AGE = 3
"""Updates a track must have lived before its motion tells the belt's speed (it has none on the frame it opens)."""
NEWBORN_PENALTY = 0.5
"""A track younger than BELT_SPEED_MIN_AGE costs this fraction of the gate more in the assignment. A fillet
reaching the edge while the one ahead still hangs there merges with it for a frame: its centroid jumps ahead (and
so does its next prediction) while a piece split off the merged blob opens a track beside it; the next frame the
fillet's blob must stay with the fillet's own track, not pass to the piece's track that happens to lie nearer."""


@dataclass(frozen=True)
class Track:
    """A snapshot of one tracked fillet after an update."""

    track_id: int
    blob: Blob
    """The most recently matched blob (stale while ``unseen`` > 0)."""
    age: int
    """Updates since the track opened (1 on the frame it opened)."""
    unseen: int
    """Consecutive updates without a match; 0 means ``blob`` is from this frame."""
    lane: int
    """Lane from the mean centroid column over the track's matches; -1 without a lane layout."""
    velocity: tuple[float, float]
    """Last observed motion along the rows of the blob's (trailing, leading) edge in px per second."""
    stamp: float
    """Time (s) of the frame ``blob`` is from."""


@dataclass(frozen=True)
class TrackUpdate:
    """What one :meth:`CentroidTracker.update` produced."""

    active: list[Track]
    """Tracks still alive, sorted by id (including ones unseen this frame)."""
    ended: list[Track]
    """Tracks that ended at this update."""


def _entering(blob: Blob) -> bool:
    """Whether the blob still reaches the image's first row (ENTRY_ROWS): its fillet is entering the view."""
    return blob.bbox[1] <= ENTRY_ROWS


def _ends(blob: Blob) -> np.ndarray:
    """The blob's (trailing, leading) edge rows: its first and last row."""
    return np.array([blob.bbox[1], blob.bbox[1] + blob.bbox[3] - 1], dtype=float)


def _riding_end(blob: Blob) -> int:
    """Which end of the blob rides the belt (0 trailing, 1 leading; see the module doc)."""
    return 1 if _entering(blob) else 0


def _position(blob: Blob, end: int) -> tuple[float, float]:
    """Where a blob lies for the assignment: its centroid column and the row of its ``end``."""
    return blob.centroid[0], float(_ends(blob)[end])


def _speed(track: Track) -> float:
    """The track's last observed speed along the rows (px/s), of the end of its blob that rides the belt."""
    return track.velocity[_riding_end(track.blob)]


def _belt_speed(tracks: Sequence[Track]) -> float:
    """The belt's speed along the image rows now (px/s): the median speed of the established tracks seen in their
    latest frame, 0 when none tells. A track that went unseen is predicted to move at least this fast down the
    flow: its own last motion may have stalled (a fillet whose trailing edge reached the roller), and a ghost that
    stays at the edge takes the next fillet of its lane when it arrives there."""
    moving = [_speed(t) for t in tracks if t.unseen == 0 and t.age >= BELT_SPEED_MIN_AGE]
    return float(np.median(moving)) if moving else 0.0


def _distance(tracks: Sequence[Track], ends: Sequence[int], advance: np.ndarray, blobs: Sequence[Blob]) -> np.ndarray:
    """Tracks x blobs: how far each blob lies from where each track's blob should be, its riding end moved
    ``advance`` rows down the flow (px)."""
    predicted = np.array([_position(t.blob, end) for t, end in zip(tracks, ends)])
    predicted[:, 1] += advance
    positions = np.array([[_position(b, end) for b in blobs] for end in (0, 1)])
    return np.linalg.norm(predicted[:, None, :] - positions[list(ends)], axis=2)


def _may_take(ends: Sequence[int], blobs: Sequence[Blob]) -> np.ndarray:
    """Tracks x blobs: whether the track may take the blob. A fillet that has left the image border never reaches
    it again, so its track does not take a blob that does (a fillet entering behind it): that would hand its own
    blob to a ghost of an earlier sighting predicted onto it."""
    left_border = np.array(ends)[:, None] == 0
    return ~(left_border & np.array([_entering(b) for b in blobs])[None, :])


def _motion(tracks: Sequence[Track], stamp: float) -> tuple[np.ndarray, np.ndarray]:
    """Each track's time since its last sighting (s) and its predicted speed along the rows (px/s; an unseen
    track at least at the belt's speed, :func:`_belt_speed`)."""
    elapsed = np.array([max(stamp - t.stamp, 0.0) for t in tracks])
    speed = np.array([_speed(t) for t in tracks], dtype=float)
    unseen = np.array([t.unseen > 0 for t in tracks], dtype=bool)
    speed[unseen] = np.maximum(speed[unseen], _belt_speed(tracks))
    return elapsed, speed


class CentroidTracker:
    """Multi-object tracker with stable integer ids, each fillet predicted by the end of its blob that rides the belt
    (the name keeps the paper's nearest-centroid tracker it grew from)."""

    def __init__(
        self,
        max_distance_px: float = DEFAULT_MAX_DISTANCE_PX,
        max_unseen: int = DEFAULT_MAX_UNSEEN,
        lane_layout: LaneLayout | None = None,
    ) -> None:
        if not max_distance_px > 0.0:
            raise ValueError(f"max_distance_px must be > 0, got {max_distance_px}")
        if max_unseen < 1:
            raise ValueError(f"max_unseen must be >= 1, got {max_unseen}")
        self.max_distance_px = float(max_distance_px)
        self.max_unseen = int(max_unseen)
        self.lane_layout = lane_layout
        self._tracks: dict[int, Track] = {}
        self._sum_u: dict[int, float] = {}
        self._hits: dict[int, int] = {}
        self._next_id = 0

    def reset(self) -> None:
        """Drop every track (ids keep counting up so they are never reused)."""
        self._tracks.clear()
        self._sum_u.clear()
        self._hits.clear()

    def update(self, blobs: Sequence[Blob], stamp: float) -> TrackUpdate:
        """Associate the blobs of the frame taken at ``stamp`` (s) with the tracks; open, age and end tracks."""
        ids = list(self._tracks)
        matches = self._associate(ids, blobs, stamp)
        matched_blobs = set(matches.values())
        ended: list[Track] = []
        for track_id in ids:
            track = self._tracks[track_id]
            if track_id in matches:
                self._tracks[track_id] = self._matched(track, blobs[matches[track_id]], stamp)
                continue
            track = replace(track, age=track.age + 1, unseen=track.unseen + 1)
            if track.unseen >= self.max_unseen:
                ended.append(track)
                del self._tracks[track_id], self._sum_u[track_id], self._hits[track_id]
            else:
                self._tracks[track_id] = track
        for index, blob in enumerate(blobs):
            if index not in matched_blobs:
                self._open(blob, stamp)
        return TrackUpdate(active=[self._tracks[i] for i in sorted(self._tracks)], ended=ended)

    def predicted_outlines(self, stamp: float) -> list[np.ndarray]:
        """Where the outline of each established track seen in the latest frame should lie in the frame taken at
        ``stamp``: its last outline moved by its predicted motion. The segmentation splits a blob that holds
        several of them into those fillets (woody_vision.segmentation.segment_mask)."""
        tracks = [t for t in self._tracks.values() if t.unseen == 0 and t.age >= BELT_SPEED_MIN_AGE]
        if not tracks:
            return []
        elapsed, speed = _motion(tracks, stamp)
        return [t.blob.contour + np.array([0, round(v * e)], np.int32) for t, v, e in zip(tracks, speed, elapsed)]

    def _associate(self, ids: list[int], blobs: Sequence[Blob], stamp: float) -> dict[int, int]:
        """Track id -> blob index for the minimum-distance assignment within the gate."""
        if not ids or not blobs:
            return {}
        tracks = [self._tracks[i] for i in ids]
        elapsed, speed = _motion(tracks, stamp)
        unseen = np.array([t.unseen > 0 for t in tracks])
        ends = [_riding_end(t.blob) for t in tracks]
        distance = _distance(tracks, ends, speed * elapsed, blobs)
        # Live tracks come first: a stale track's extrapolated ghost (e.g. of a fillet that fell off the edge
        # moving backwards in the image) must not take the blob of the live track right behind it. Among stale
        # tracks the nearer prediction wins, however long each went unseen: a fillet whose blob merged with its
        # neighbour's for a few frames takes its blob back from the ghost of the fillet that left ahead of it.
        newborn = np.array([t.age < BELT_SPEED_MIN_AGE for t in tracks], dtype=float)
        penalty = self.max_distance_px * (2.0 * unseen + NEWBORN_PENALTY * newborn)[:, None]
        gate = (self.max_distance_px + GAP_GATE_GROWTH * np.abs(speed) * elapsed)[:, None]
        allowed = (distance <= gate) & _may_take(ends, blobs)
        gated = np.where(allowed, distance + penalty, 1e9)
        rows, cols = linear_sum_assignment(gated)
        return {ids[r]: int(c) for r, c in zip(rows, cols) if allowed[r, c]}

    def _matched(self, track: Track, blob: Blob, stamp: float) -> Track:
        elapsed = stamp - track.stamp
        velocity = track.velocity if elapsed <= 0.0 else _end_velocity(track.blob, blob, elapsed)
        self._sum_u[track.track_id] += blob.centroid[0]
        self._hits[track.track_id] += 1
        return replace(
            track,
            blob=blob,
            age=track.age + 1,
            unseen=0,
            lane=self._lane(track.track_id),
            velocity=velocity,
            stamp=stamp,
        )

    def _open(self, blob: Blob, stamp: float) -> None:
        track_id = self._next_id
        self._next_id += 1
        self._sum_u[track_id] = blob.centroid[0]
        self._hits[track_id] = 1
        self._tracks[track_id] = Track(
            track_id=track_id, blob=blob, age=1, unseen=0, lane=self._lane(track_id), velocity=(0.0, 0.0),
            stamp=stamp,
        )

    def _lane(self, track_id: int) -> int:
        if self.lane_layout is None:
            return NO_LANE
        return self.lane_layout.lane_of_u(self._sum_u[track_id] / self._hits[track_id])


def _end_velocity(before: Blob, after: Blob, elapsed: float) -> tuple[float, float]:
    """The (trailing, leading) edges' motion between two sightings (px/s); a trailing edge that came into view
    between them (the fillet left the image border) moved as the leading one."""
    trailing, leading = (_ends(after) - _ends(before)) / elapsed
    return (leading if _entering(before) and not _entering(after) else trailing), leading
