"""The top camera's mount from ``/tf_static``: its height above the belt and the roller edge's offset (no rclpy).

A line publishes its fixed frames on ``tf_static`` (``line_sim`` does; on a real line a camera driver publishes
its own frames and a ``static_transform_publisher`` places the camera in the belt frame). The belt frame (REP
103, ``world`` on woody's line) has x downstream along the flow, z up and its origin on the belt surface at the
roller edge. From the chain of static transforms between it and the camera's optical frame (the images'
``frame_id``) the vision takes the camera's pose: the segmenter turns the frames of a camera mounted off straight
down, turned or beside the belt's middle into its belt view (woody_vision.belt_view), and both nodes take the camera
height and the edge offset instead of their parameters. A mount leaning further than MAX_CAMERA_TILT_DEG from
straight down is refused, in one line, and the parameters are kept.

No tf2 wheel exists on PyPI, so the few lines of tf2 this needs are here: a tree of static transforms, and the
composition of the transforms along the path between two of its frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from woody_common.line import MAX_CAMERA_TILT_DEG, STRAIGHT_DOWN_AXES

STRAIGHT_DOWN = np.array(STRAIGHT_DOWN_AXES)
"""The optical axes (columns) in the belt frame of a camera looking straight down, image rows downstream."""


@dataclass(frozen=True)
class Pose:
    """A frame in its parent: origin (m) and axes (the columns of ``rotation``)."""

    translation: np.ndarray
    rotation: np.ndarray

    def then(self, child: Pose) -> Pose:
        """The pose of ``child`` (given in this frame) in this frame's parent."""
        return Pose(self.translation + self.rotation @ child.translation, self.rotation @ child.rotation)

    def inverse(self) -> Pose:
        return Pose(-self.rotation.T @ self.translation, self.rotation.T)


@dataclass(frozen=True)
class CameraMount:
    """What the vision takes from the camera's pose in the belt frame."""

    height_m: float
    """The optical centre above the belt surface."""
    edge_offset_m: float
    """The roller edge's distance downstream of the optical centre along the flow."""
    tilt_deg: float
    """The angle between the optical axis and straight down."""


class StaticFrames:
    """A tree of static transforms, as /tf_static builds it (a later transform of a child replaces the earlier)."""

    def __init__(self) -> None:
        self._parent: dict[str, tuple[str, Pose]] = {}

    def add(self, parent: str, child: str, translation, quaternion_xyzw) -> None:
        self._parent[child] = (parent, Pose(np.asarray(translation, float),
                                            Rotation.from_quat(quaternion_xyzw).as_matrix()))

    def add_message(self, msg) -> None:
        """Every transform of a tf2_msgs/TFMessage."""
        for t in msg.transforms:
            v, q = t.transform.translation, t.transform.rotation
            self.add(t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/"), (v.x, v.y, v.z),
                     (q.x, q.y, q.z, q.w))

    def _to_root(self, frame: str) -> tuple[list[str], Pose]:
        """The frames from ``frame`` up to its root, and ``frame``'s pose in that root."""
        path, pose = [frame], Pose(np.zeros(3), np.eye(3))
        while path[-1] in self._parent and len(path) <= len(self._parent):
            parent, step = self._parent[path[-1]]
            pose = step.then(pose)
            path.append(parent)
        return path, pose

    def lookup(self, target: str, source: str) -> Pose | None:
        """The pose of frame ``source`` in frame ``target`` (None when no chain of transforms joins them)."""
        target_path, target_pose = self._to_root(target.lstrip("/"))
        source_path, source_pose = self._to_root(source.lstrip("/"))
        if target_path[-1] != source_path[-1]:
            return None
        return target_pose.inverse().then(source_pose)


def tilt_deg(pose: Pose) -> float:
    """The angle between a camera's optical axis (at ``pose`` in the belt frame) and straight down."""
    return math.degrees(math.acos(float(np.clip(-pose.rotation[2, 2], -1.0, 1.0))))


def camera_mount(pose: Pose) -> CameraMount:
    """The mount of a camera whose optical frame has ``pose`` in the belt frame."""
    x, _, z = pose.translation
    return CameraMount(float(z), float(-x), tilt_deg(pose))


def mount_problem(mount: CameraMount) -> str:
    """Why the vision cannot use this mount ('' when it can)."""
    if mount.height_m <= 0.0:
        return f"the camera is {mount.height_m:.3f} m above the belt, not above it"
    if mount.tilt_deg > MAX_CAMERA_TILT_DEG:
        return (f"the camera looks {mount.tilt_deg:.1f} deg from straight down (the vision takes at most "
                f"{MAX_CAMERA_TILT_DEG:g} deg)")
    return ""
