"""What a real RGB-D camera does to the rendered top-down frames: noise, quantisation, holes, drops.

The renderer gives exact depth; a real camera over the belt does not. A
:class:`SensorModel` turns an exact frame into what a camera of that kind
would publish, seeded so a run is reproducible:

- depth noise growing with distance, ``σ(z) = floor + σ_d · (z − z0)² / (f · b)``
  (triangulation: disparity noise σ_d in pixels, focal length f in pixels,
  baseline b), spatially correlated over ``noise_correlation_px``;
- quantisation of disparity (``disparity_step_px``: a structured-light camera's
  1/8-px disparity makes depth steps of ``z² · step / (f · b)``) and of the
  output (``depth_step_m``: 1 mm for 16UC1 drivers);
- invalid pixels at depth edges (the occluded or projector-shadowed band
  beside a step of more than ``edge_jump_m``) and in random holes;
- optional colour noise and dropped frames.

Invalid pixels are NaN in the returned depth; the node publishes them as NaN
(32FC1) or 0 (16UC1), as drivers do. Presets and their sources: docs/sensors.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from woody_common.line import DEPTH_UNIT_M

ENCODINGS = ("32FC1", "16UC1")


@dataclass(frozen=True)
class SensorModel:
    """One camera's error model; every effect is off at its default (the ``ideal`` camera)."""

    name: str = "ideal"
    focal_px: float = 1.0
    baseline_m: float = 1.0
    disparity_noise_px: float = 0.0
    noise_floor_m: float = 0.0
    noise_offset_m: float = 0.0
    noise_correlation_px: float = 0.0
    disparity_step_px: float = 0.0
    depth_step_m: float = 0.0
    edge_jump_m: float = 0.01
    edge_invalid_px: int = 0
    hole_fraction: float = 0.0
    hole_size_px: int = 8
    color_noise: float = 0.0
    drop_rate: float = 0.0
    encoding: str = "32FC1"

    def __post_init__(self) -> None:
        if self.focal_px <= 0 or self.baseline_m <= 0:
            raise ValueError(f"sensor {self.name}: focal_px and baseline_m must be > 0")
        if min(self.disparity_noise_px, self.noise_floor_m, self.noise_correlation_px, self.disparity_step_px,
               self.depth_step_m, self.edge_invalid_px, self.color_noise) < 0:
            raise ValueError(f"sensor {self.name}: noise, steps and band widths must be >= 0")
        if not (0.0 <= self.hole_fraction < 1.0 and 0.0 <= self.drop_rate < 1.0 and self.hole_size_px >= 1):
            raise ValueError(f"sensor {self.name}: hole_fraction and drop_rate must be in [0, 1), hole_size_px >= 1")
        if self.encoding not in ENCODINGS:
            raise ValueError(f"sensor {self.name}: encoding must be one of {', '.join(ENCODINGS)}")

    @property
    def ideal(self) -> bool:
        return self == SensorModel(name=self.name, encoding=self.encoding)

    def sigma(self, z: np.ndarray | float) -> np.ndarray | float:
        """Standard deviation of the depth noise (m) at depth ``z`` (m)."""
        return self.noise_floor_m + self.disparity_noise_px * (np.asarray(z) - self.noise_offset_m) ** 2 / (
            self.focal_px * self.baseline_m)

    def drop(self, rng: np.random.Generator) -> bool:
        """True when this frame is lost (USB / driver drop)."""
        return self.drop_rate > 0.0 and rng.random() < self.drop_rate

    def depth(self, exact: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The frame the camera reports for exact depth ``exact`` (m): float32, NaN where nothing was measured."""
        if self.ideal:
            return np.asarray(exact, dtype=np.float32)
        out = np.array(exact, dtype=np.float32)
        invalid = self._edge_band(out) | self._holes(out.shape, rng) | ~np.isfinite(out)
        if self.disparity_noise_px or self.noise_floor_m:
            out += (self.sigma(out) * self._noise_field(out.shape, rng)).astype(np.float32)
        if self.disparity_step_px:
            disparity = self.focal_px * self.baseline_m / np.maximum(out, 1e-3)
            step = self.disparity_step_px
            out = (self.focal_px * self.baseline_m / np.maximum(np.round(disparity / step) * step, step)).astype(
                np.float32)
        if self.depth_step_m:
            out = (np.round(out / self.depth_step_m) * self.depth_step_m).astype(np.float32)
        out[invalid] = np.nan
        return out

    def color(self, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The colour frame with the camera's pixel noise (uint8)."""
        if not self.color_noise:
            return rgb
        noisy = rgb.astype(np.float32) + rng.normal(0.0, self.color_noise, rgb.shape).astype(np.float32)
        return np.clip(np.round(noisy), 0, 255).astype(np.uint8)

    def _noise_field(self, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
        """Unit-variance Gaussian noise, smoothed over ``noise_correlation_px`` (matching windows correlate it)."""
        white = rng.standard_normal(shape).astype(np.float32)
        if self.noise_correlation_px <= 0:
            return white
        smooth = cv2.GaussianBlur(white, (0, 0), self.noise_correlation_px)
        return smooth / max(float(smooth.std()), 1e-6)

    def _edge_band(self, depth: np.ndarray) -> np.ndarray:
        """Pixels within ``edge_invalid_px`` of a depth step larger than ``edge_jump_m``."""
        if not self.edge_invalid_px:
            return np.zeros(depth.shape, bool)
        filled = np.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0)
        jump = np.zeros(depth.shape, np.uint8)
        across = (np.abs(np.diff(filled, axis=1)) > self.edge_jump_m).astype(np.uint8)
        along = (np.abs(np.diff(filled, axis=0)) > self.edge_jump_m).astype(np.uint8)
        jump[:, 1:] |= across  # both pixels of every pair that straddles a step
        jump[:, :-1] |= across
        jump[1:, :] |= along
        jump[:-1, :] |= along
        size = 2 * self.edge_invalid_px - 1
        return cv2.dilate(jump, np.ones((size, size), np.uint8)) > 0

    def _holes(self, shape: tuple[int, ...], rng: np.random.Generator) -> np.ndarray:
        """Random blobs of about ``hole_size_px`` covering ``hole_fraction`` of the frame (low texture, glare)."""
        if not self.hole_fraction:
            return np.zeros(shape, bool)
        coarse = (shape[0] // self.hole_size_px + 1, shape[1] // self.hole_size_px + 1)
        seeds = cv2.GaussianBlur(rng.standard_normal(coarse).astype(np.float32), (0, 0), 1.0)
        field = cv2.resize(seeds, (shape[1], shape[0]), interpolation=cv2.INTER_LINEAR)
        return field > np.quantile(field, 1.0 - self.hole_fraction)


STEREO_FOCAL_PX = 366.7
"""fx of the 672 x 376 top camera (85° horizontal field of view), the stereo preset's own focal length."""

PRESETS: dict[str, SensorModel] = {
    "ideal": SensorModel(),
    "stereo": SensorModel(
        name="stereo", focal_px=STEREO_FOCAL_PX, baseline_m=0.12, disparity_noise_px=0.15, noise_correlation_px=1.5,
        edge_invalid_px=2, hole_fraction=0.005, hole_size_px=8, color_noise=2.0, drop_rate=0.01, encoding="32FC1"),
    "structured_light": SensorModel(
        name="structured_light", focal_px=580.0, baseline_m=0.075, disparity_noise_px=0.0019 * 580.0 * 0.075,
        noise_floor_m=0.0012, noise_offset_m=0.4, noise_correlation_px=2.0, disparity_step_px=0.125,
        depth_step_m=0.001, edge_invalid_px=2, hole_fraction=0.01, hole_size_px=6, color_noise=3.0,
        drop_rate=0.01, encoding="16UC1"),
}
"""``ideal``; a ZED-class 672 x 376 passive stereo camera; a Kinect-class structured-light camera (docs/sensors.md)."""


def sensor_preset(name: str) -> SensorModel:
    """The preset of that name; ValueError naming the presets otherwise."""
    if name not in PRESETS:
        raise ValueError(f"unknown sensor '{name}': choose one of {', '.join(PRESETS)}")
    return PRESETS[name]


def to_message_array(depth: np.ndarray, encoding: str, unit_m: float = DEPTH_UNIT_M) -> np.ndarray:
    """Depth in metres as a driver publishes it: 32FC1 metres with NaN holes, or 16UC1 in steps of ``unit_m``
    (millimetres by default, REP 118) with 0 holes."""
    if encoding == "32FC1":
        return np.ascontiguousarray(depth, dtype=np.float32)
    steps = np.round(np.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0) / unit_m)
    return np.clip(steps, 0, 65535).astype(np.uint16)
