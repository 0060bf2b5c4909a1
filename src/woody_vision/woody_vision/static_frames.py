"""The top camera's mount from ``/tf_static``: its height above the belt and the roller edge's offset (no rclpy).

A line publishes its fixed frames on ``tf_static`` (``line_sim`` does; on a real line a camera driver publishes
its own frames and a ``static_transform_publisher`` places the camera in the belt frame). The belt frame (REP
103, ``world`` on woody's line) has x downstream along the flow, z up and its origin on the belt surface at the
roller edge. From the chain of static transforms between it and the camera's optical frame (the images'
``frame_id``) the vision takes the camera height and the edge offset instead of its parameters. The vision
assumes a camera looking straight down with image rows running downstream; a mount further than
``MOUNT_TOLERANCE_DEG`` from that is refused, in one line, and the parameters are kept.

No tf2 wheel exists on PyPI, so the few lines of tf2 this needs are here: a tree of static transforms, and the
composition of the transforms along the path between two of its frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

STRAIGHT_DOWN = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""The optical axes (columns) in the belt frame of a camera looking straight down, image rows downstream."""
MOUNT_TOLERANCE_DEG = 1.0


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
    off_straight_down_deg: float
    """The rotation between the camera's axes and a straight-down mount with rows downstream."""


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


def camera_mount(pose: Pose) -> CameraMount:
    """The mount of a camera whose optical frame has ``pose`` in the belt frame."""
    turn = Rotation.from_matrix(STRAIGHT_DOWN.T @ pose.rotation).magnitude()
    x, _, z = pose.translation
    return CameraMount(float(z), float(-x), math.degrees(turn))


def mount_problem(mount: CameraMount) -> str:
    """Why the vision cannot use this mount ('' when it can)."""
    if mount.height_m <= 0.0:
        return f"the camera is {mount.height_m:.3f} m above the belt, not above it"
    if mount.off_straight_down_deg > MOUNT_TOLERANCE_DEG:
        return (f"the camera is turned {mount.off_straight_down_deg:.1f} deg from straight down with image rows "
                f"downstream (the vision takes at most {MOUNT_TOLERANCE_DEG:g} deg)")
    return ""
