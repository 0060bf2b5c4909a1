"""A top camera described in a YAML file: what a plant's RGB-D camera is and where it hangs over the belt.

The twin renders and publishes exactly the camera a file describes (``line_sim``'s ``top_camera``, ``woody run
--top-camera FILE``), so a user sees what their own camera would see and can test the vision on it before it is
installed. ``config/cameras/`` holds the paper's camera, the default one and two common RGB-D cameras at
plausible mounts. A file reads (every key but ``width``, ``height`` and ``intrinsics`` optional)::

    width: 640                 # pixels
    height: 480
    intrinsics: {fx: 385.0, fy: 385.0, cx: 321.3, cy: 238.6}   # pixels
    distortion: [0.0, 0.0, 0.0, 0.0, 0.0]    # plumb_bob k1 k2 p1 p2 k3 (or 8 rational_polynomial)
    mount:
      height_m: 0.80           # optical centre above the belt surface
      along_m: -0.22           # along the flow from the roller edge (negative: upstream of it)
      across_m: 0.03           # across the belt from its middle, towards lane 0 (world +y)
      tilt_deg: 4.0            # optical axis leaning downstream (towards the roller)
      roll_deg: -2.5           # optical axis leaning towards lane 0
      yaw_deg: 1.5             # image rows turned from downstream towards lane 0
    frame_rate_hz: 30.0
    sensor: stereo             # error model: ideal, stereo, structured_light (woody_sim.sensor_model)
    depth_encoding: 16UC1      # 32FC1 (metres) or 16UC1 (default: the error model's)
    depth_unit_m: 0.001        # one 16UC1 step (REP 118: millimetres)
    color_stamp_offset_s: 0.0  # colour stamp minus depth stamp
    color_stamp_jitter_s: 0.0  # sd of a random part of it

Lengths in metres, angles in degrees (the user-facing unit of a mount), REP 103 frames: the belt frame has x
downstream, y to lane 0, z up. A wrong key or value is refused in one line naming the file and the key.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, fields
from pathlib import Path

import yaml

from woody_common.line import DEPTH_UNIT_M, MAX_CAMERA_TILT_DEG
from woody_sim.sensor_model import ENCODINGS, PRESETS

CAMERA_SUFFIXES = (".yaml", ".yml")
TOP_KEYS = {"width", "height", "intrinsics", "distortion", "mount", "frame_rate_hz", "sensor", "depth_encoding",
            "depth_unit_m", "color_stamp_offset_s", "color_stamp_jitter_s", "name"}
MOUNT_KEYS = {"height_m", "along_m", "across_m", "tilt_deg", "roll_deg", "yaw_deg"}


@dataclass(frozen=True)
class CameraDescription:
    """One top camera: image, lens, mount, timing and error model (module doc)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()
    height_m: float = 0.75
    along_m: float = -0.20
    across_m: float = 0.0
    tilt_deg: float = 0.0
    roll_deg: float = 0.0
    yaw_deg: float = 0.0
    frame_rate_hz: float = 30.0
    sensor: str = "ideal"
    depth_encoding: str = ""
    """32FC1 or 16UC1; '': the error model's."""
    depth_unit_m: float = DEPTH_UNIT_M
    color_stamp_offset_s: float = 0.0
    color_stamp_jitter_s: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        checks = [
            (self.width >= 16 and self.height >= 16, "width and height must be at least 16 px"),
            (min(self.fx, self.fy) > 0.0, "intrinsics fx and fy must be > 0"),
            (0.0 <= self.cx <= self.width and 0.0 <= self.cy <= self.height, "the principal point must lie in the "
                                                                              "image"),
            (len(self.distortion) in (0, 4, 5, 8), "distortion must have 4, 5 or 8 coefficients"),
            (0.1 <= self.height_m <= 3.0, "mount height_m must be within 0.1..3 m"),
            (math.hypot(self.tilt_deg, self.roll_deg) <= MAX_CAMERA_TILT_DEG,
             f"mount tilt_deg and roll_deg together must lean at most {MAX_CAMERA_TILT_DEG:g} deg from straight down"),
            (abs(self.yaw_deg) <= 180.0, "mount yaw_deg must be within -180..180"),
            (1.0 <= self.frame_rate_hz <= 120.0, "frame_rate_hz must be within 1..120"),
            (self.sensor in PRESETS, f"sensor must be one of {', '.join(PRESETS)}"),
            (self.depth_encoding in ("", *ENCODINGS), f"depth_encoding must be one of {', '.join(ENCODINGS)}"),
            (1e-5 <= self.depth_unit_m <= 0.01, "depth_unit_m must be within 0.00001..0.01 m"),
            (abs(self.color_stamp_offset_s) <= 1.0 and 0.0 <= self.color_stamp_jitter_s <= 0.1,
             "color_stamp_offset_s must be within -1..1 s and color_stamp_jitter_s within 0..0.1 s"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"camera {self.name or '(unnamed)'}: {message}")

    def geometry_overrides(self) -> dict:
        """The LineGeometry ``top_*`` fields that place and shape this camera (woody_sim.line_geometry)."""
        return {"top_width": self.width, "top_height_px": self.height, "top_intrinsics": (self.fx, self.fy, self.cx,
                                                                                          self.cy),
                "top_distortion": tuple(self.distortion), "top_height": self.height_m, "top_center_x": self.along_m,
                "top_center_y": self.across_m, "top_tilt": math.radians(self.tilt_deg),
                "top_roll": math.radians(self.roll_deg), "top_yaw": math.radians(self.yaw_deg)}


CAMERA_DEFAULTS = {f.name: f.default for f in fields(CameraDescription) if f.default is not MISSING}
"""What a camera without a file has: the values a file leaves out (frame rate, error model, depth unit, stamps)."""


def is_camera_file(name: str) -> bool:
    """Whether a top camera name is a description file rather than a preset."""
    return name.endswith(CAMERA_SUFFIXES)


def load_camera(path: str | Path) -> CameraDescription:
    """The camera a YAML file describes; ValueError with one line naming the file and what is wrong."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ValueError(f"camera file {path}: cannot read it ({str(exc).splitlines()[0]})") from None
    try:
        return _description(data, path.stem)
    except KeyError as exc:
        raise ValueError(f"camera file {path}: missing key {exc.args[0]}") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"camera file {path}: {exc}") from None


def _description(data, stem: str) -> CameraDescription:
    if not isinstance(data, dict):
        raise ValueError("expected a mapping of camera keys")
    unknown = set(data) - TOP_KEYS
    mount = data.get("mount") or {}
    unknown |= {f"mount.{key}" for key in set(mount) - MOUNT_KEYS}
    if unknown:
        raise ValueError(f"unknown keys {', '.join(sorted(unknown))}")
    intrinsics = data["intrinsics"]
    return CameraDescription(
        width=int(data["width"]), height=int(data["height"]), fx=float(intrinsics["fx"]),
        fy=float(intrinsics["fy"]), cx=float(intrinsics["cx"]), cy=float(intrinsics["cy"]),
        distortion=tuple(float(v) for v in data.get("distortion") or ()),
        **{key: float(mount[key]) for key in MOUNT_KEYS if key in mount},
        frame_rate_hz=float(data.get("frame_rate_hz", 30.0)), sensor=str(data.get("sensor", "ideal")),
        depth_encoding=str(data.get("depth_encoding", "")), depth_unit_m=float(data.get("depth_unit_m", DEPTH_UNIT_M)),
        color_stamp_offset_s=float(data.get("color_stamp_offset_s", 0.0)),
        color_stamp_jitter_s=float(data.get("color_stamp_jitter_s", 0.0)), name=str(data.get("name", stem)))
