"""The top camera's frames as a camera straight above the belt would take them: any mount, any lens.

The vision works in the belt's frame (REP 103: x downstream, z up, origin on the belt surface at the roller
edge). Its working view is a *belt camera*: the real camera's intrinsics K, at the real camera's height and
position along the flow, centred across the belt (y = 0, the middle of the lanes), looking straight down with
image rows downstream (woody_vision.static_frames.STRAIGHT_DOWN). A plant's camera is a few degrees off, turned,
beside the belt's middle, and its lens distorts. :class:`BeltView` resamples each of its depth and colour frames
into the belt camera with maps computed once from ``camera_info`` (K, D) and the camera's pose from
``tf_static``, so segmentation, tracking, lanes, the roller edge and the shape score see the same view whatever
the mount.

Each belt-camera pixel takes the real camera's pixel that sees the same point of the belt plane (the maps run
through the lens model, so distortion is undone there), and a depth reading becomes the belt camera's z-depth of
the same 3D point: the reading times the cosine between that pixel's ray and straight down, a per-pixel factor.
That is exact on the belt plane; a point above it (a fillet's top, a few cm) is taken from where its ray meets
the belt, a parallax of height × tan(tilt) (3 mm for a 4 cm-high top under 5 deg). A camera straight down,
centred, with no distortion is the belt camera itself: its frames pass unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import SimpleNamespace

import cv2
import numpy as np

from woody_vision.static_frames import STRAIGHT_DOWN, Pose, camera_mount, mount_problem

DISTORTION_MODELS = ("plumb_bob", "rational_polynomial")
"""camera_info distortion models the maps can undo (OpenCV's 5- and 8-coefficient models); an empty model with
all-zero D is no distortion."""
IDEAL_TOLERANCE = 1e-9


@dataclass(frozen=True)
class CameraModel:
    """What ``camera_info`` says of a camera: size, intrinsics and lens distortion."""

    width: int
    height: int
    k: tuple[float, ...]
    """Row-major 3x3 K."""
    d: tuple[float, ...] = ()
    distortion_model: str = "plumb_bob"

    @classmethod
    def of(cls, info) -> CameraModel:
        """From a sensor_msgs/CameraInfo, anything with its fields, or a mapping of them."""
        if isinstance(info, Mapping):
            info = SimpleNamespace(**info)
        return cls(int(info.width), int(info.height), tuple(float(v) for v in info.k),
                   tuple(float(v) for v in info.d), str(info.distortion_model))

    @property
    def distorted(self) -> bool:
        return any(abs(v) > IDEAL_TOLERANCE for v in self.d)

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.k, dtype=float).reshape(3, 3)


def rays(camera: CameraModel) -> np.ndarray:
    """(H, W, 3) undistorted rays with z = 1 in the camera's optical frame: a pixel's 3D point is its z-depth
    times its ray."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    normalised = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), camera.matrix, np.asarray(camera.d, float))
    xy = normalised.reshape(camera.height, camera.width, 2)
    return np.concatenate([xy, np.ones(xy.shape[:2] + (1,))], axis=-1)


def view_problem(camera: CameraModel, pose: Pose) -> str:
    """Why a camera with this model and pose in the belt frame cannot be turned into the belt camera ('' if it can)."""
    if camera.distorted and camera.distortion_model not in DISTORTION_MODELS:
        return (f"distortion model '{camera.distortion_model}' is not one of {', '.join(DISTORTION_MODELS)}; "
                "feed rectified images (image_proc) with D all 0")
    if camera.distorted and len(camera.d) not in (4, 5, 8):
        return f"distortion D has {len(camera.d)} coefficients, not 4, 5 or 8"
    return mount_problem(camera_mount(pose))


class BeltView:
    """Resamples a camera's depth and colour frames into its belt camera (module doc); ValueError on a camera it
    cannot take (:func:`view_problem`, one line)."""

    def __init__(self, camera: CameraModel, pose: Pose) -> None:
        problem = view_problem(camera, pose)
        if problem:
            raise ValueError(problem)
        self.camera = camera
        self.pose = pose
        self.height_m = float(pose.translation[2])
        self.identity = not camera.distorted and np.allclose(pose.rotation, STRAIGHT_DOWN, atol=IDEAL_TOLERANCE) \
            and abs(float(pose.translation[1])) < IDEAL_TOLERANCE
        if not self.identity:
            self._map_u, self._map_v = self._maps()
            self._depth_scale = self._cosines()

    def _maps(self) -> tuple[np.ndarray, np.ndarray]:
        """For each belt-camera pixel, the real camera's (u, v) seeing the same belt-plane point."""
        c = self.camera
        fx, fy, cx, cy = c.k[0], c.k[4], c.k[2], c.k[5]
        u, v = np.meshgrid(np.arange(c.width, dtype=float), np.arange(c.height, dtype=float))
        belt = np.stack([self.pose.translation[0] + (v - cy) * self.height_m / fy,
                         (u - cx) * self.height_m / fx, np.zeros_like(u)], axis=-1).reshape(-1, 3)
        optical = (belt - self.pose.translation) @ self.pose.rotation
        pixels, _ = cv2.projectPoints(optical, np.zeros(3), np.zeros(3), c.matrix, np.asarray(c.d, float))
        pixels = pixels.reshape(c.height, c.width, 2).astype(np.float32)
        behind = (optical[:, 2] <= 0.0).reshape(c.height, c.width)
        pixels[behind] = -1.0
        return pixels[..., 0].copy(), pixels[..., 1].copy()

    def _cosines(self) -> np.ndarray:
        """Per real-camera pixel: belt-camera z-depth per unit of the real camera's z-depth along its ray."""
        return (-(rays(self.camera) @ self.pose.rotation.T)[..., 2]).astype(np.float32)

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """A float32 metres depth frame of the real camera as the belt camera's (NaN where it sees nothing)."""
        if self.identity:
            return depth
        scaled = np.asarray(depth, np.float32) * self._depth_scale
        return cv2.remap(scaled, self._map_u, self._map_v, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=float("nan"))

    def color(self, color: np.ndarray | None) -> np.ndarray | None:
        """An (H, W, 3) colour frame registered to the depth frame, as the belt camera's (black off the image)."""
        if self.identity or color is None:
            return color
        return cv2.remap(color, self._map_u, self._map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)


def straight_down_pose(height_m: float, along_m: float = 0.0) -> Pose:
    """The pose of an ideal camera ``height_m`` above the belt, ``along_m`` along the flow, centred, straight down."""
    return Pose(np.array([along_m, 0.0, height_m]), STRAIGHT_DOWN.copy())
