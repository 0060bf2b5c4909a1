"""Where everything on the line sits: one source of truth for the sim, renderer and defaults.

Frames follow REP 103. The world frame ``world`` has x downstream along the
belt, y to the left across the belt, z up; SI units throughout. The flat belt
top is the plane z = 0 and ends at x = 0 (the *roller edge*), where it wraps
around the end roller whose axle runs along y at (x = 0, z = -R).

Camera optical frames follow REP 103's ``_optical_frame`` convention (z
forward, x right, y down in the image):

* top camera, nadir, at (x_c, 0, H): optical x = world +y, optical y = world
  +x, optical z = world -z. Fillets therefore move *down* the image and the
  roller edge is the image row v = cy + fy * (0 - x_c) / H. Lane 0 (the
  most positive y) is on the right of the image.
* side camera at (x_s, y_lane - D, z_s) looking along +y at one lane: optical
  x = world +x (downstream to the right), optical y = world -z (down is down),
  optical z = world +y.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from woody_common.line import (
    BELT_MARGIN_M,
    LANE_PITCH_M,
    LANES,
    MAX_CAMERA_TILT_DEG,
    MAX_LANES,
    MOUNT_EULER,
    ROLLER_RADIUS_M,
    STRAIGHT_DOWN_AXES,
    TOP_CAMERA_HEIGHT_M,
    TOP_EDGE_OFFSET_M,
    watched_lane,
)
from woody_sim.camera_description import is_camera_file, load_camera

TOP_CAMERA_PRESETS: dict[str, dict[str, float | int]] = {
    "default": {},
    # The seed system's top camera (the paper's own system): 960 x 696 px, 86.6 deg field of view over
    # its 696-px axis, ~0.33 m above the belt, nadir. Its flow runs along the 960 px; here flow runs down the image
    # rows, so the image is 696 wide (across the belt, the 86.6 deg axis) and 960 tall. The optical axis stays
    # top_center_x, 0.20 m upstream of the roller edge (the seed's position along the flow is not known).
    "paper": {"top_width": 696, "top_height_px": 960, "top_hfov": math.radians(86.6), "top_height": 0.33},
}
"""Named top-camera geometries: LineGeometry top_* field overrides."""


def top_camera_preset(name: str) -> dict:
    """The LineGeometry field overrides of a named top camera or of a camera description file (``*.yaml``,
    woody_sim.camera_description); ValueError names the known presets or what is wrong with the file."""
    if is_camera_file(name):
        return load_camera(name).geometry_overrides()
    if name not in TOP_CAMERA_PRESETS:
        raise ValueError(f"unknown top camera preset {name!r}; known: {', '.join(TOP_CAMERA_PRESETS)}, or a camera "
                         "description file (*.yaml)")
    return dict(TOP_CAMERA_PRESETS[name])


@dataclass(frozen=True)
class PinholeCamera:
    """An ideal pinhole camera: intrinsics plus its pose in the world frame."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    position: tuple[float, float, float]
    """Optical centre in the world frame (m)."""
    rotation: tuple[tuple[float, float, float], ...]
    """3x3 matrix whose columns are the optical x, y, z axes in world coordinates."""
    near: float = 0.05
    far: float = 3.0
    distortion: tuple[float, ...] = ()
    """Lens distortion, OpenCV's order (k1, k2, p1, p2[, k3[, k4, k5, k6]]); empty: none."""

    @property
    def k(self) -> np.ndarray:
        """The 3x3 intrinsic matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def world_to_optical(self, points: np.ndarray) -> np.ndarray:
        """Transform (N, 3) world points into the optical frame."""
        r = np.asarray(self.rotation, dtype=float)
        return (np.asarray(points, dtype=float) - np.asarray(self.position)) @ r

    def project(self, points: np.ndarray) -> np.ndarray:
        """Project (N, 3) world points to (N, 2) pixel coordinates (u, v)."""
        p = self.world_to_optical(points)
        return np.stack([self.fx * p[:, 0] / p[:, 2] + self.cx, self.fy * p[:, 1] / p[:, 2] + self.cy], axis=1)


@dataclass(frozen=True)
class LineGeometry:
    """Dimensions of the conveyor, lanes and cameras (metres, radians)."""

    lanes: int = LANES
    lane_pitch: float = LANE_PITCH_M
    roller_radius: float = ROLLER_RADIUS_M
    """The seed system's end roller: 48 px at its side camera's 0.431 mm/px."""
    belt_length: float = 1.4
    belt_margin: float = BELT_MARGIN_M
    """Extra belt width beyond the outer lanes, each side."""
    floor_z: float = -0.6
    """The catch floor below the roller: what the top camera sees past the edge."""
    spawn_x: float = -1.0
    """Centre of a freshly spawned fillet along the belt."""
    remove_z: float = -0.35
    """A fillet whose every segment is below this height has fallen and is removed."""

    top_height: float = TOP_CAMERA_HEIGHT_M
    top_center_x: float = -TOP_EDGE_OFFSET_M
    top_width: int = 672
    top_height_px: int = 376
    top_hfov: float = math.radians(85.0)
    top_intrinsics: tuple[float, float, float, float] | None = None
    """(fx, fy, cx, cy) in pixels; None: square pixels from ``top_hfov``, principal point in the image centre."""
    top_distortion: tuple[float, ...] = ()
    top_center_y: float = 0.0
    """The top camera's optical centre across the belt (world y, towards lane 0)."""
    top_tilt: float = 0.0
    """The top camera's optical axis leaning downstream (rad, about world -y)."""
    top_roll: float = 0.0
    """The top camera's optical axis leaning towards lane 0 (rad, about world x)."""
    top_yaw: float = 0.0
    """The top camera's image rows turned from downstream towards lane 0 (rad, about world z)."""

    side_distance: float = 50.0
    """The seed's side camera is orthographic; ours is a telephoto this far away (m), whose scale varies by
    under 0.1 % across a fillet's width, so the image is orthographic to a fraction of a pixel."""
    side_pixel: float = 0.30 / 696.0
    """Side-camera pixel size at the watched lane (m): the seed's 0.30 m image height over 696 rows."""
    side_center_x: float = 0.0
    side_center_z: float | None = None
    """Height of the side image centre (m); None centres it on the roller axle, as the seed does."""
    side_width: int = 960
    side_height_px: int = 696
    side_lane: int = -1
    """Lane the side camera watches; -1 means the centre lane."""

    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not 1 <= self.lanes <= MAX_LANES:
            raise ValueError(f"lanes must be 1..{MAX_LANES}, got {self.lanes}")

    @property
    def belt_width(self) -> float:
        return self.lanes * self.lane_pitch + 2.0 * self.belt_margin

    def lane_y(self, lane: int) -> float:
        """Centre of a lane across the belt; lane 0 is the most positive y (left)."""
        if not 0 <= lane < self.lanes:
            raise ValueError(f"lane must be 0..{self.lanes - 1}, got {lane}")
        return ((self.lanes - 1) / 2.0 - lane) * self.lane_pitch

    def lane_of_y(self, y: float) -> int:
        """The lane whose centre is nearest to a world y coordinate."""
        lane = round((self.lanes - 1) / 2.0 - y / self.lane_pitch)
        return int(min(max(lane, 0), self.lanes - 1))

    @property
    def watched_lane(self) -> int:
        return watched_lane(self.lanes, self.side_lane)

    @property
    def roller_axle(self) -> tuple[float, float]:
        """(x, z) of the roller axle in the world frame."""
        return (0.0, -self.roller_radius)

    def top_camera(self) -> PinholeCamera:
        fx = (self.top_width / 2.0) / math.tan(self.top_hfov / 2.0)
        fx, fy, cx, cy = self.top_intrinsics or (fx, fx, self.top_width / 2.0, self.top_height_px / 2.0)
        turn = Rotation.from_euler(MOUNT_EULER, [-self.top_tilt, self.top_roll, self.top_yaw]).as_matrix()
        return PinholeCamera(
            width=self.top_width,
            height=self.top_height_px,
            fx=fx,
            fy=fy,
            cx=cx,
            cy=cy,
            position=(self.top_center_x, self.top_center_y, self.top_height),
            rotation=tuple(tuple(row) for row in (turn @ np.array(STRAIGHT_DOWN_AXES)).tolist()),
            near=0.05,
            far=(self.top_height - self.floor_z) / math.cos(math.radians(MAX_CAMERA_TILT_DEG)) + 0.5,
            distortion=tuple(self.top_distortion),
        )

    def side_camera(self) -> PinholeCamera:
        fx = self.side_distance / self.side_pixel
        y = self.lane_y(self.watched_lane) - self.side_distance
        z = self.roller_axle[1] if self.side_center_z is None else self.side_center_z
        return PinholeCamera(
            width=self.side_width,
            height=self.side_height_px,
            fx=fx,
            fy=fx,
            cx=self.side_width / 2.0,
            cy=self.side_height_px / 2.0,
            position=(self.side_center_x, y, z),
            rotation=((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)),
            near=self.side_distance - 1.0,
            far=self.side_distance + 1.0,
        )

    def top_edge_row(self) -> float:
        """Image row of the roller edge in the top camera's belt view (woody_vision.belt_view: the camera as if it
        looked straight down from its height and place along the flow)."""
        cam = self.top_camera()
        return cam.cy + cam.fy * (0.0 - self.top_center_x) / self.top_height

    def side_axle_pixel(self) -> tuple[float, float]:
        """(u, v) of the roller axle in the side camera image."""
        cam = self.side_camera()
        ax, az = self.roller_axle
        uv = cam.project(np.array([[ax, self.lane_y(self.watched_lane), az]]))[0]
        return float(uv[0]), float(uv[1])

    def side_roller_radius_px(self) -> float:
        """Roller radius in side-camera pixels at the watched lane's depth."""
        cam = self.side_camera()
        return cam.fx * self.roller_radius / self.side_distance
