"""The QoS of the vision nodes' camera subscriptions, chosen by the ``image_qos`` parameter.

Camera drivers publish images best effort (sensor-data QoS) or reliable. A
best-effort subscription matches both, a reliable one only reliable
publishers, so ``sensor_data`` is the default; ``reliable`` asks a reliable
publisher to resend lost fragments (never a dropped frame in transit, at the
cost of latency on a lossy network).
"""

from __future__ import annotations

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from woody_common.ros_params import declare

CHOICES = {"sensor_data": ReliabilityPolicy.BEST_EFFORT, "reliable": ReliabilityPolicy.RELIABLE}


def declare_image_qos(node, depth: int = 10) -> QoSProfile:
    """Declare ``image_qos`` on the node and return the subscription profile it selects."""
    choice = declare(node, "image_qos", "sensor_data", "QoS of the camera image and camera_info subscriptions: "
                     "sensor_data (best effort; matches best-effort and reliable publishers) or reliable.")
    if choice not in CHOICES:
        raise ValueError(f"image_qos must be one of {', '.join(CHOICES)}, got '{choice}'")
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=CHOICES[choice])
