"""results_qos: a subscriber that matches after the first results went out still gets them, if it asks."""

from __future__ import annotations

from conftest import spin_until
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from woody_bag.qos import subscription_qos
from woody_msgs.msg import FilletVerdict
from woody_vision.result_qos import RESULTS_DEPTH, results_qos


def test_a_recorder_that_subscribes_after_the_first_verdicts_still_records_them_and_a_gate_hears_new_ones(ros_node):
    publisher = ros_node.create_publisher(FilletVerdict, "late/verdicts", results_qos())
    for fillet_id in range(3):
        publisher.publish(FilletVerdict(fillet_id=fillet_id))
    recorder_qos = subscription_qos(ros_node.get_publishers_info_by_topic("/late/verdicts"), RESULTS_DEPTH)
    assert recorder_qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
    recorded, heard = [], []
    ros_node.create_subscription(FilletVerdict, "late/verdicts", lambda m: recorded.append(m.fillet_id), recorder_qos)
    gate_qos = QoSProfile(depth=RESULTS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)  # volatile, as reject_gate's
    ros_node.create_subscription(FilletVerdict, "late/verdicts", lambda m: heard.append(m.fillet_id), gate_qos)
    assert spin_until(ros_node, lambda: len(recorded) == 3, timeout=10.0) and recorded == [0, 1, 2]
    publisher.publish(FilletVerdict(fillet_id=3))
    assert spin_until(ros_node, lambda: heard == [3] and recorded[-1] == 3, timeout=10.0), (heard, recorded)
