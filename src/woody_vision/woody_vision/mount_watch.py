"""The vision nodes' view of ``tf_static``: the top camera's mount, when the line publishes it.

Declares ``belt_frame`` (default ``world``, woody's line; '' ignores ``tf_static``). Where the chain of static
transforms joins it to the camera's optical frame, the camera height and the roller edge offset come from there
instead of the ``camera_height_m`` and ``roller_edge_offset_m`` parameters (woody_vision.static_frames).
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from woody_common import topics
from woody_common.ros_params import declare
from woody_vision.static_frames import CameraMount, Pose, StaticFrames, camera_mount, mount_problem

TF_STATIC_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""tf_static is latched: a late subscriber gets every publisher's transforms."""
TF_WAIT_S = 1.0


class MountWatch:
    """Keeps the static transforms a node has heard; tells the camera's mount in the belt frame."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.belt_frame = declare(node, "belt_frame", topics.WORLD_FRAME, "Frame of the belt on tf_static (x "
                                  "downstream, z up, origin on the belt at the roller edge): where tf_static joins it "
                                  "to the camera's optical frame, the camera height and roller edge offset come from "
                                  "there, not from camera_height_m and roller_edge_offset_m ('' ignores tf_static).")
        self.frames = StaticFrames()
        self.heard = False
        self._refused: set[str] = set()
        if self.belt_frame:
            node.create_subscription(TFMessage, topics.TF_STATIC, self._on_tf_static, TF_STATIC_QOS)

    def _on_tf_static(self, msg: TFMessage) -> None:
        self.frames.add_message(msg)
        self.heard = True

    def pose(self, camera_frame: str) -> Pose | None:
        """The camera's optical frame in the belt frame, or None (no transforms joining the frames, or a mount the
        vision cannot take, said once in the log)."""
        pose = self.frames.lookup(self.belt_frame, camera_frame) if self.belt_frame and camera_frame else None
        if pose is None:
            return None
        problem = mount_problem(camera_mount(pose))
        if problem and camera_frame not in self._refused:
            self._refused.add(camera_frame)
            self.node.get_logger().error(f"tf_static {self.belt_frame} -> {camera_frame}: {problem}; camera height "
                                         "and roller edge offset from the parameters")
        return None if problem else pose

    def mount(self, camera_frame: str) -> CameraMount | None:
        """The camera's mount, or None (as :meth:`pose`)."""
        pose = self.pose(camera_frame)
        return None if pose is None else camera_mount(pose)

    def geometry(self, camera_frame: str, height_m: float, edge_offset_m: float) -> tuple[float, float, str | None]:
        """(camera height m, roller edge offset m, the transform they came from): the mount's, else the given
        parameters' with None."""
        mount = self.mount(camera_frame)
        if mount is None:
            return height_m, edge_offset_m, None
        return mount.height_m, mount.edge_offset_m, f"tf_static {self.belt_frame} -> {camera_frame}"

    def waiting(self, since_s: float, now_s: float) -> bool:
        """Whether to wait longer for tf_static: nothing heard yet, less than TF_WAIT_S after the first camera_info
        (latched transforms may arrive just after the first camera_info)."""
        return bool(self.belt_frame) and not self.heard and now_s - since_s < TF_WAIT_S
