"""`woody camera setup BAG --out PARAMS.yaml`: set the vision up from a recording of the real camera.

Reads the first seconds of the top camera's depth and camera_info from a bag (the empty belt, then fillets
passing), finds the belt plane, the flow and its speed, the roller edge and the lanes
(woody_vision.camera_setup), prints them with their spread, and writes the segmenter's and grader's parameters
file, the ``static_transform_publisher`` line that puts the camera on ``tf_static``, and a picture of what was
found over the image. What it cannot find is refused with one line (exit 2).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from woody_common import topics
from woody_common.line import DEPTH_UNIT_M, mps_to_fpm

DEFAULT_SECONDS = 20.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    setup = sub.add_parser("setup", help="find the camera's mount, the flow, the roller edge and the lanes in a bag; "
                                         "write the vision's parameters")
    setup.add_argument("bag", help="an MCAP bag of the top camera: a few seconds of the empty belt, then fillets")
    setup.add_argument("--out", required=True, metavar="PARAMS.yaml",
                       help="the parameters file to write (a picture PARAMS.png goes beside it)")
    setup.add_argument("--depth-topic", default=topics.TOP_DEPTH_IMAGE, help="depth image topic (a namespaced "
                       f"recording's is found by its end; default {topics.TOP_DEPTH_IMAGE})")
    setup.add_argument("--info-topic", default=topics.TOP_DEPTH_INFO, help="its camera_info topic")
    setup.add_argument("--seconds", type=float, default=DEFAULT_SECONDS,
                       help=f"how much of the bag to read from its first depth frame (default {DEFAULT_SECONDS:g} s)")
    setup.add_argument("--depth-unit-m", type=float, default=DEPTH_UNIT_M,
                       help="one step of a 16UC1 depth image (default 0.001)")
    setup.add_argument("--frame-id", default="", help="the camera's optical frame for tf_static (default: the "
                                                      "images' frame_id)")


def run(args: argparse.Namespace) -> int:
    from woody_bag.errors import BagError
    from woody_vision.camera_setup import find_setup

    try:
        camera, frames, frame_id = _read(args)
        found = find_setup(camera, frames)
    except (BagError, ValueError) as exc:  # SetupError is a ValueError
        print(f"woody camera setup: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    transform = _static_transform(found, args.frame_id or frame_id)
    out.write_text(_parameters_yaml(found, transform, args.depth_unit_m))
    picture = out.with_suffix(".png")
    cv2.imwrite(str(picture), _picture(camera, frames[0][1], found))
    for line in _report(found, len(frames)):
        print(line)
    print(f"tf_static: {transform}")
    print(f"wrote {out} and {picture}")
    return 0


def _read(args: argparse.Namespace):
    """(camera model, [(stamp, depth m)], frame_id) of the bag's first ``seconds`` of depth."""
    from woody_bag.reader import read_bag
    from woody_bag.schemas import decode
    from woody_bag.summary import bag_topics
    from woody_vision.belt_view import CameraModel
    from woody_vision.image_encodings import depth_metres

    if not 1.0 <= args.seconds <= 600.0 or not 1e-5 <= args.depth_unit_m <= 0.01:
        raise ValueError("--seconds must be within 1..600 and --depth-unit-m within 0.00001..0.01")
    names = set(bag_topics(args.bag))
    depth_topic, info_topic = (_topic(args.bag, name, names) for name in (args.depth_topic, args.info_topic))
    info, frames, frame_id, first = None, [], "", None
    for message in read_bag(args.bag, [depth_topic, info_topic]):
        msg = decode(message.type_name, message.data)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if message.topic == info_topic:
            info = info or msg
            continue
        first = stamp if first is None else first
        if stamp - first > args.seconds:
            break
        frames.append((stamp, depth_metres(msg, args.depth_unit_m)))
        frame_id = msg.header.frame_id
    if info is None:
        raise ValueError(f"{args.bag}: no camera_info on {info_topic}")
    return CameraModel.of(info), frames, frame_id


def _topic(bag: str, name: str, names: set[str]) -> str:
    """The bag's topic ``name`` names: itself, or the one topic ending in it (a namespaced recording)."""
    matches = [t for t in names if t == "/" + name.lstrip("/")] or [t for t in names if t.endswith("/" + name)]
    if len(matches) != 1:
        raise ValueError(f"{bag}: {'no' if not matches else 'more than one'} topic {name} (it has "
                         f"{', '.join(sorted(names))})")
    return matches[0]


def _report(found, frames: int) -> list[str]:
    tilt, roll, yaw = found.mount_deg()
    x, y, z = found.pose.translation
    return [
        f"from {frames} depth frames, {found.tracks} fillet tracks:",
        f"  camera height   {z:.3f} m above the belt plane (plane fit rms {found.plane_rms_m * 1e3:.1f} mm)",
        f"  camera place    {x:+.3f} m along the flow from the roller edge, {y:+.3f} m across from the lanes' middle",
        f"  mount           tilt {tilt:+.2f} deg (downstream), roll {roll:+.2f} deg (to lane 0), yaw {yaw:+.2f} deg",
        f"  roller edge     {found.edge_offset_m:.3f} m downstream of the optical centre (the belt's end varies "
        f"{found.edge_sd_m * 1e3:.1f} mm across its width)",
        f"  belt speed      {found.speed_mps:.3f} ± {found.speed_sd_mps:.3f} m/s "
        f"({mps_to_fpm(found.speed_mps):.0f} FPM)",
        f"  lanes           {found.lanes}, pitch {found.lane_pitch_m:.3f} m (a track lies "
        f"{found.lane_sd_m * 1e3:.1f} mm from its lane's centre, rms)" if found.lanes > 1 else
        f"  lanes           1 (a track lies {found.lane_sd_m * 1e3:.1f} mm from its centre, rms)",
    ]


def _mount(found) -> list[float]:
    """The found camera pose as [x, y, z, qx, qy, qz, qw] in the belt frame."""
    return [round(float(c), 5) for c in (*found.pose.translation, *Rotation.from_matrix(found.pose.rotation).as_quat())]


def _static_transform(found, frame_id: str) -> str:
    x, y, z, qx, qy, qz, qw = _mount(found)
    return (f"ros2 run tf2_ros static_transform_publisher --x {x:.4f} --y {y:.4f} --z {z:.4f} --qx {qx:.5f} "
            f"--qy {qy:.5f} --qz {qz:.5f} --qw {qw:.5f} --frame-id {topics.WORLD_FRAME} --child-frame-id "
            f"{frame_id or 'CAMERA_OPTICAL_FRAME'}")


def _parameters_yaml(found, transform: str, depth_unit_m: float) -> str:
    """The segmenter's and grader's parameters; line_sim's, for the twin, publish the found mount on tf_static
    (``woody run --vision-setup``), as the static_transform_publisher line does on a real line."""
    pitch = found.lane_pitch_m if math.isfinite(found.lane_pitch_m) else 0.16
    vision = {"lanes": found.lanes, "camera_height_m": round(found.height_m, 4)}
    params = {"/**/segmenter": {"ros__parameters": {**vision, "lane_pitch_m": round(pitch, 4),
                                                    "depth_unit_m": depth_unit_m}},
              "/**/grader": {"ros__parameters": {**vision, "roller_edge_offset_m": round(found.edge_offset_m, 4)}},
              "/**/line_sim": {"ros__parameters": {"top_camera_mount": _mount(found)}}}
    header = "".join(f"# {line}\n" for line in ["written by woody camera setup", *_report(found, 0)[1:],
                                                 "the camera's pose for tf_static (the nodes take the mount from it):",
                                                 f"  {transform}",
                                                 "line_sim's top_camera_mount puts the same pose on the twin's "
                                                 "tf_static (woody run --vision-setup)"])
    return header + yaml.safe_dump(params, sort_keys=False)


def _picture(camera, depth: np.ndarray, found) -> np.ndarray:
    """The first depth frame in grey with the roller edge (red), the lane centres (green) and the flow (arrow)."""
    finite = np.isfinite(depth)
    low, high = (np.percentile(depth[finite], [1, 99]) if finite.any() else (0.0, 1.0))
    grey = np.clip((depth - low) / max(high - low, 1e-6) * 255.0, 0, 255)
    image = cv2.cvtColor(np.nan_to_num(grey).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    half = max(abs(c) for c in found.lane_centres_m) + 0.1
    lines = [((0.0, -half), (0.0, half), (0, 0, 255))]
    lines += [((-1.0, c), (0.0, c), (0, 200, 0)) for c in found.lane_centres_m]
    for (x0, y0), (x1, y1), colour in lines:
        points = np.array([[x0 + (x1 - x0) * t, y0 + (y1 - y0) * t, 0.0] for t in np.linspace(0, 1, 50)])
        pixels = _project(camera, found.pose, points)
        cv2.polylines(image, [pixels.astype(np.int32).reshape(-1, 1, 2)], False, colour, 2)
    tail, head = _project(camera, found.pose, np.array([[-0.25, 0.0, 0.0], [-0.1, 0.0, 0.0]]))
    cv2.arrowedLine(image, tuple(int(v) for v in tail), tuple(int(v) for v in head), (255, 128, 0), 2)
    return image


def _project(camera, pose, points: np.ndarray) -> np.ndarray:
    """Belt-frame points to the camera's (distorted) pixels."""
    optical = (points - pose.translation) @ pose.rotation
    pixels, _ = cv2.projectPoints(optical, np.zeros(3), np.zeros(3), camera.matrix, np.asarray(camera.d, float))
    return pixels.reshape(-1, 2)
