"""Publish every woody_msgs sample on /samples/<Type> and serve /spawn_fillet, until killed."""

import sys
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from msg_samples import samples  # noqa: E402

from woody_msgs.srv import SpawnFillet  # noqa: E402


class SamplePublisher(Node):
    def __init__(self) -> None:
        super().__init__("sample_publisher")
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.publishers_ = {name: (self.create_publisher(type(msg), f"/samples/{name}", qos), msg)
                            for name, msg in samples().items()}
        self.create_service(SpawnFillet, "/spawn_fillet", self.on_spawn)
        self.create_timer(0.2, self.publish_all)

    def publish_all(self) -> None:
        for publisher, msg in self.publishers_.values():
            publisher.publish(msg)

    def on_spawn(self, request: SpawnFillet.Request, response: SpawnFillet.Response) -> SpawnFillet.Response:
        response.success = True
        response.message = (f"{request.mesh} k={request.stiffness} lane={request.lane} "
                            f"v={request.line_speed} m={request.mass}")
        response.fillet_id = 99
        return response


def main() -> None:
    rclpy.init()
    node = SamplePublisher()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
