"""One filled-in instance of every woody_msgs type, with values that survive a round trip."""

from __future__ import annotations

import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from std_msgs.msg import Header

from woody_msgs.msg import FilletSpawn, FilletTrack, FilletTrackArray, FilletVerdict, GateCommand, SideMetrics
from woody_msgs.srv import SpawnFillet


def header(frame_id: str = "top_camera_optical_frame") -> Header:
    return Header(stamp=Time(sec=12, nanosec=345_000_000), frame_id=frame_id)


def track(track_id: int = 7) -> FilletTrack:
    return FilletTrack(
        id=track_id, lane=2, centroid_u=101.5, centroid_v=220.25, bbox_u=80, bbox_v=190, bbox_width=45,
        bbox_height=90, area=3120.0, mean_height=0.021, age=14, unseen=0,
        contour_uv=[80, 190, 125, 190, 100, 280],
    )


def samples() -> dict[str, object]:
    verdict = FilletVerdict(
        header=header(), fillet_id=7, lane=2, classification=FilletVerdict.CLASS_WOODY, grade="severe",
        unscored_reason="", phi=5.4, hu_term=0.05, solidity_term=0.004, threshold=10.0,
        moderate_threshold=12.0, severe_threshold=8.0, reference_stamp=Time(sec=12, nanosec=0),
        frames_in_window=6,
    )
    return {
        "FilletTrack": track(),
        "FilletTrackArray": FilletTrackArray(header=header(), image_width=672, image_height=376,
                                             tracks=[track(7), track(8)], ended_ids=[3, 4]),
        "FilletVerdict": verdict,
        "FilletSpawn": FilletSpawn(header=header("world"), fillet_id=42, lane=1, mesh="seed0001", stiffness=100.0,
                                   damping=0.01, mass=100.0, line_speed=0.508, segments=40, length=0.19,
                                   width=0.1, thickness=0.024, position=Point(x=-1.0, y=0.0, z=0.0)),
        "GateCommand": GateCommand(header=header(), lane=2, fillet_id=7, actuation_time=Time(sec=13, nanosec=5),
                                   open_duration=0.35, phi=5.4),
        "SideMetrics": SideMetrics(header=header("side_camera_optical_frame"), fillet_id=7, lane=1, measured=True,
                                   reason="", nmdm=0.78, mdm=68.3, be=19.3),
    }


def message_types() -> dict[str, type]:
    return {name: type(msg) for name, msg in samples().items()}


def spawn_request() -> SpawnFillet.Request:
    return SpawnFillet.Request(mesh="seed0002", stiffness=60.0, lane=1, line_speed=0.66, mass=math.pi)
