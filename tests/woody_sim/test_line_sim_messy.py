"""line_sim on a messy line, through its entry point: each fillet placed by its own seeded draw, reproducibly."""

from __future__ import annotations

import pytest
from conftest import spin_until
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from woody_tools.processes import NodeProcess

pytestmark = pytest.mark.ros
"""Starts node entry points as processes."""

MESSY = {"line": "messy", "lane_pitch_m": 0.12, "spawn_spacing_m": 0.2, "speed_change_fpm": 130.0,
         "speed_change_at_s": 0.2, "duration_s": 0.5, "side_rate_hz": 0.0}


def ground_truth(ros_node, ros_domain, log_dir, params: dict, count: int = 6) -> list:
    """The FilletSpawn messages of one short run, in spawn order (the line waits for this node to listen: a run of
    0.5 s may end before discovery would match it)."""
    from sensor_msgs.msg import Image

    from woody_common import topics
    from woody_msgs.msg import FilletSpawn

    truths: list = []
    subscriptions = [ros_node.create_subscription(
        FilletSpawn, "/line/ground_truth", truths.append,
        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)),
        ros_node.create_subscription(Image, topics.TOP_DEPTH_IMAGE, lambda _: None, 10)]
    sim = NodeProcess("line_sim", dict(params, wait_for_subscribers=1), domain_id=ros_domain, log_dir=log_dir)
    try:
        assert spin_until(ros_node, lambda: len(truths) >= count, timeout=120.0), sim.log_tail()
    finally:
        assert sim.stop() == 0, sim.log_tail()
        for subscription in subscriptions:
            ros_node.destroy_subscription(subscription)
    if params.get("speed_change_fpm"):
        assert "belt speed 0.508 -> 0.660 m/s (130 FPM)" in sim.log_tail()
    return sorted(truths, key=lambda t: t.fillet_id)[:count]


def test_a_messy_line_places_each_fillet_by_its_seeded_draw(ros_node, ros_domain, tmp_path):
    from woody_common.calibration import resolved_calibration
    from woody_sim.line_conditions import LINE_PRESETS, place_mesh, placement_for
    from woody_sim.meshes import load_mesh_set

    first = ground_truth(ros_node, ros_domain, tmp_path / "a", MESSY)
    again = ground_truth(ros_node, ros_domain, tmp_path / "b", MESSY)
    fields = ("mesh", "lane", "length", "width", "mass", "line_speed")
    assert [[getattr(t, f) for f in fields] + [t.position.y] for t in first] == \
        [[getattr(t, f) for f in fields] + [t.position.y] for t in again]
    straight = {m.name: m for m in load_mesh_set("builtin")[0]}
    mass = resolved_calibration().total_mass_kg
    for truth in first:
        placement = placement_for(LINE_PRESETS["messy"], 7, truth.fillet_id)
        placed = place_mesh(straight[truth.mesh], placement)
        assert (truth.length, truth.width) == pytest.approx((placed.length, placed.width), abs=1e-6)
        assert truth.mass == pytest.approx(mass * placement.scale ** 3)
        assert truth.position.y == pytest.approx((1 - truth.lane) * 0.12 + placement.lateral_offset_m)
    assert len({round(t.length, 4) for t in first[:3]}) == 3  # the lanes of one spawn carry one mesh, laid apart
    assert len({round(t.mass, 6) for t in first}) == 6 and len({round(t.position.y, 6) for t in first}) == 6
    assert [t.line_speed for t in first] == pytest.approx([0.508] * 3 + [0.6604] * 3)


def test_yaw_sd_alone_turns_each_fillet_by_its_own_draw(ros_node, ros_domain, tmp_path):
    """``yaw_sd_deg`` (woody run --yaw-sd) on the tidy line: the lanes of one spawn carry one mesh turned apart."""
    from woody_sim.line_conditions import LineConditions, place_mesh, placement_for
    from woody_sim.meshes import load_mesh_set

    params = {"yaw_sd_deg": 20.0, "duration_s": 0.2, "side_rate_hz": 0.0}
    truths = ground_truth(ros_node, ros_domain, tmp_path, params, count=3)
    straight = {m.name: m for m in load_mesh_set("builtin")[0]}
    for truth in truths:
        placement = placement_for(LineConditions(yaw_sd_deg=20.0), 7, truth.fillet_id)
        assert 0.0 < abs(placement.yaw_deg) <= 40.0 and placement.scale == 1.0 and not placement.blunt_first
        turned = place_mesh(straight[truth.mesh], placement)
        assert (truth.length, truth.width) == pytest.approx((turned.length, turned.width), abs=1e-6)
    assert len({t.mesh for t in truths}) == 1 and len({round(t.length, 5) for t in truths}) == 3


def test_a_crowded_line_lays_no_fillet_into_another(ros_node, ros_domain, tmp_path):
    """Six lanes 8 cm apart with fillets 0.16 m apart in a lane: many placed footprints would overlap their
    neighbours' at the spawn point; each waits until it has room, so no two footprints ever overlap on the belt."""
    import numpy as np

    from woody_common.stamps import stamp_to_seconds
    from woody_sim.line_conditions import LINE_PRESETS, place_mesh, placement_for
    from woody_sim.meshes import load_mesh_set
    from woody_sim.spawn_clearance import OVERLAP_AREA_M2, footprint, overlap_area

    params = {"line": "messy", "lanes": 6, "lane_pitch_m": 0.08, "spawn_spacing_m": 0.16, "duration_s": 2.0,
              "side_rate_hz": 0.0}
    truths = ground_truth(ros_node, ros_domain, tmp_path, params, count=24)
    straight = {m.name: m for m in load_mesh_set("builtin")[0]}
    laid = []
    for truth in sorted(truths, key=lambda t: stamp_to_seconds(t.header.stamp)):
        placed = place_mesh(straight[truth.mesh], placement_for(LINE_PRESETS["messy"], 7, truth.fillet_id))
        shape = footprint(placed.mesh.vertices, truth.position.x, truth.position.y)
        at = stamp_to_seconds(truth.header.stamp)
        for other, other_at in laid:
            carried = other + np.array([truth.line_speed * (at - other_at), 0.0], dtype=np.float32)
            assert overlap_area(shape, carried) <= OVERLAP_AREA_M2
        laid.append((shape, at))
    assert sorted(t.fillet_id for t in truths) != [t.fillet_id for t in
                                                  sorted(truths, key=lambda t: stamp_to_seconds(t.header.stamp))]
