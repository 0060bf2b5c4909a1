"""Synthetic top-camera RGB-D and side-camera RGB frames with known geometry (tests and benchmark).

Top view: a nadir pinhole camera ``camera_height_m`` above the belt, the roller
edge ``edge_offset_m`` downstream of the optical axis, the floor
``FLOOR_DROP_M`` below the belt beyond it. World coordinates here are x
downstream with the edge at x = 0, y across the belt (image +u) and z up from
the belt top. A fillet is a teardrop strip (narrow tip leading) of 40 segments
whose overhang beyond the edge droops: its bend angle grows as
``tip_angle + curvature_per_m · d`` over the overhang length d, where
``tip_angle`` starts growing once half the fillet is over the edge. Each
segment is projected through the pinhole and painted far-to-near.

Side view: a uniform background, the grey roller disc around the axle pixel,
the belt top line, and pink strips that either drape around the roller
(flexible) or stay straight past it (rigid cantilever).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from woody_common.line import REFERENCE_SPEED_MPS, SIDE_ROLLER_RADIUS_PX, TOP_CAMERA_HEIGHT_M, TOP_EDGE_OFFSET_M
from woody_vision.camera_model import Intrinsics, edge_row, intrinsics_from_k

TOP_WIDTH = 672
TOP_HEIGHT = 376
TOP_FX = (TOP_WIDTH / 2.0) / math.tan(math.radians(85.0) / 2.0)
DEFAULT_TOP_K = (TOP_FX, 0.0, TOP_WIDTH / 2.0, 0.0, TOP_FX, TOP_HEIGHT / 2.0, 0.0, 0.0, 1.0)
FLOOR_DROP_M = 0.60
REMOVE_DROP_M = 0.35
"""A fillet entirely this far below the belt has fallen and is no longer drawn (as in the simulator)."""
SPEED_100_FPM = REFERENCE_SPEED_MPS
SEGMENTS = 40
MAX_BEND_RAD = 2.3

BELT_RGB = (90, 90, 95)
FLOOR_RGB = (40, 40, 40)
FILLET_RGB = (235, 160, 165)


def teardrop_half_widths(q: np.ndarray, tip_exponent: float = 0.8, tail_exponent: float = 0.5) -> np.ndarray:
    """Half-width as a fraction of the maximum at relative length q (0 = leading tip, 1 = trailing end)."""
    q = np.clip(np.asarray(q, dtype=float), 0.0, 1.0)
    peak = tip_exponent / (tip_exponent + tail_exponent)
    scale = peak**tip_exponent * (1.0 - peak) ** tail_exponent
    return q**tip_exponent * (1.0 - q) ** tail_exponent / scale


def teardrop_polygon(
    center_uv: tuple[float, float],
    length_px: float,
    width_px: float,
    tip_down: bool = True,
    samples: int = 120,
    tip_exponent: float = 0.8,
    tail_exponent: float = 0.5,
) -> np.ndarray:
    """(N, 2) float polygon of a flat teardrop; ``center_uv`` is the middle of its length, the tip leads in +v."""
    q = np.linspace(0.0, 1.0, samples)
    half = 0.5 * width_px * teardrop_half_widths(q, tip_exponent, tail_exponent)
    along = (0.5 - q) * length_px if tip_down else (q - 0.5) * length_px
    u0, v0 = center_uv
    right = np.stack([u0 + half, v0 + along], axis=1)
    left = np.stack([u0 - half, v0 + along], axis=1)[::-1]
    return np.concatenate([right, left])


@dataclass(frozen=True)
class TopFillet:
    """One fillet on the belt; positions in metres relative to the roller edge at time 0."""

    lead_m: float
    """Flow position of the leading tip at t = 0 (negative: upstream of the edge)."""
    across_m: float
    """World y of the centreline (image +u)."""
    length_m: float = 0.19
    width_m: float = 0.095
    thickness_m: float = 0.025
    curvature_per_m: float = 0.0
    """How fast the overhang droops (rad per metre of overhang): 0 rigid, ~15 very flexible."""
    tip_rate_per_m: float = 12.0
    """How fast the fillet tips once half of it is over the edge (rad per metre)."""
    speed_mps: float = SPEED_100_FPM


@dataclass(frozen=True)
class TopScene:
    """A top-camera view of fillets moving downstream and over the roller edge."""

    fillets: Sequence[TopFillet]
    k: tuple[float, ...] = DEFAULT_TOP_K
    camera_height_m: float = TOP_CAMERA_HEIGHT_M
    edge_offset_m: float = TOP_EDGE_OFFSET_M
    width: int = TOP_WIDTH
    height: int = TOP_HEIGHT

    @property
    def intrinsics(self) -> Intrinsics:
        return intrinsics_from_k(self.k)

    @property
    def edge_row(self) -> float:
        return edge_row(self.k, self.camera_height_m, self.edge_offset_m)

    def background_depth(self) -> np.ndarray:
        """Empty-belt depth: the belt up to the edge row, the floor beyond it."""
        depth = np.full((self.height, self.width), self.camera_height_m, np.float32)
        depth[int(math.ceil(self.edge_row)) :] = self.camera_height_m + FLOOR_DROP_M
        return depth

    def background_rgb(self) -> np.ndarray:
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        rgb[:] = BELT_RGB
        rgb[int(math.ceil(self.edge_row)) :] = FLOOR_RGB
        return rgb

    def render(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(rgb8, depth 32F metres) at time ``t`` seconds."""
        depth = self.background_depth()
        rgb = self.background_rgb()
        quads: list[tuple[float, np.ndarray]] = []
        for fillet in self.fillets:
            quads.extend(self._quads(fillet, t))
        for mean_depth, corners in sorted(quads, key=lambda item: -item[0]):
            fixed = np.round(corners * 16.0).astype(np.int32)
            cv2.fillConvexPoly(depth, fixed, float(mean_depth), cv2.LINE_8, 4)
            shade = min(1.0, max(0.5, 1.2 - 0.5 * (mean_depth - self.camera_height_m)))
            cv2.fillConvexPoly(rgb, fixed, tuple(int(c * shade) for c in FILLET_RGB), cv2.LINE_8, 4)
        return rgb, depth

    def _quads(self, fillet: TopFillet, t: float) -> list[tuple[float, np.ndarray]]:
        """(mean depth, 4x2 pixel corners) of each segment of one fillet."""
        intr = self.intrinsics
        lead = fillet.lead_m + fillet.speed_mps * t
        s = np.linspace(0.0, fillet.length_m, SEGMENTS + 1)
        q = s / fillet.length_m
        x_flat = lead - s
        x, z = _bent_centreline(
            x_flat,
            fillet.curvature_per_m,
            fillet.tip_rate_per_m * max(0.0, lead - 0.5 * fillet.length_m),
        )
        if z.max() < -REMOVE_DROP_M:
            return []
        half = 0.5 * fillet.width_m * np.maximum(teardrop_half_widths(q), 0.02)
        top = z + fillet.thickness_m * (0.35 + 0.65 * np.sqrt(np.sin(np.pi * q)))
        depth = self.camera_height_m - top
        v = intr.cy + intr.fy * (x + self.edge_offset_m) / depth
        u_left = intr.cx + intr.fx * (fillet.across_m - half) / depth
        u_right = intr.cx + intr.fx * (fillet.across_m + half) / depth
        quads = []
        for j in range(SEGMENTS):
            corners = np.array(
                [[u_left[j], v[j]], [u_right[j], v[j]], [u_right[j + 1], v[j + 1]], [u_left[j + 1], v[j + 1]]]
            )
            quads.append((0.5 * (depth[j] + depth[j + 1]), corners))
        return quads


def _bent_centreline(x_flat: np.ndarray, curvature: float, tip_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """World (x, z) of centreline points whose flat position is ``x_flat``; the overhang (x_flat > 0) bends down."""
    overhang = np.maximum(x_flat, 0.0)
    if overhang.max() <= 0.0:
        return x_flat.copy(), np.zeros_like(x_flat)
    d = np.linspace(0.0, float(overhang.max()), 200)
    theta = np.minimum(tip_angle + curvature * d, MAX_BEND_RAD)
    step = np.diff(d)
    along = np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(theta[1:]) + np.cos(theta[:-1])) * step)])
    drop = np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(theta[1:]) + np.sin(theta[:-1])) * step)])
    x = np.where(x_flat > 0.0, np.interp(overhang, d, along), x_flat)
    z = np.where(x_flat > 0.0, -np.interp(overhang, d, drop), 0.0)
    return x, z


def lane_streams(
    lanes: int,
    per_lane: int,
    pitch_m: float,
    lane_pitch_m: float = 0.16,
    seed: int = 0,
    touching_probability: float = 0.15,
    woody_probability: float = 0.5,
    speed_mps: float = SPEED_100_FPM,
    start_lead_m: float = -0.45,
) -> list[TopFillet]:
    """Random fillets in ``lanes`` lanes, ``per_lane`` each, spaced ~``pitch_m`` apart lead to lead.

    Sizes, lateral offsets and stiffness vary; some fillets follow their
    predecessor tip-to-tail with no gap so the segmentation must split them.
    """
    rng = np.random.default_rng(seed)
    fillets = []
    for lane in range(lanes):
        across = ((lanes - 1) / 2.0 - lane) * lane_pitch_m
        lead = start_lead_m - rng.uniform(0.0, pitch_m)
        for _ in range(per_lane):
            length = rng.uniform(0.17, 0.22)
            woody = rng.random() < woody_probability
            fillets.append(
                TopFillet(
                    lead_m=lead,
                    across_m=across + rng.uniform(-0.01, 0.01),
                    length_m=length,
                    width_m=rng.uniform(0.08, 0.11),
                    thickness_m=rng.uniform(0.02, 0.035),
                    curvature_per_m=rng.uniform(1.0, 3.0) if woody else rng.uniform(8.0, 16.0),
                    speed_mps=speed_mps,
                )
            )
            # Touching followers overlap the leader's trailing end by 5 mm in the top view.
            touching = rng.random() < touching_probability
            lead -= length - 0.005 if touching else max(length + 0.03, rng.uniform(0.5, 1.5) * pitch_m)
    return fillets


# ---------------------------------------------------------------- side view

SIDE_WIDTH = 960
SIDE_HEIGHT = 696
SIDE_BACKGROUND_RGB = (210, 215, 220)
ROLLER_RGB = (128, 128, 128)
BELT_LINE_RGB = (60, 60, 60)


@dataclass(frozen=True)
class SideStrip:
    """A fillet seen from the side: a strip of given length and thickness following the belt path.

    ``lead_px`` is the arc position of its leading end along the path, 0 at the
    top of the roller; the path runs flat along the belt top before that and,
    past it, either wraps around the roller (``drape``) or continues straight.
    """

    lead_px: float
    length_px: float = 180.0
    thickness_px: float = 24.0
    drape: bool = True


@dataclass(frozen=True)
class SideScene:
    """The side camera's fixed scenery."""

    axle_uv: tuple[float, float] = (480.0, 300.0)
    roller_radius_px: float = SIDE_ROLLER_RADIUS_PX
    width: int = SIDE_WIDTH
    height: int = SIDE_HEIGHT

    def background(self) -> np.ndarray:
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        rgb[:] = SIDE_BACKGROUND_RGB
        au, av = self.axle_uv
        cv2.circle(rgb, (round(au), round(av)), round(self.roller_radius_px), ROLLER_RGB, -1)
        belt_v = round(av - self.roller_radius_px)
        cv2.line(rgb, (0, belt_v), (round(au), belt_v), BELT_LINE_RGB, 2)
        return rgb

    def render(self, strips: Sequence[SideStrip]) -> np.ndarray:
        rgb = self.background()
        for strip in strips:
            cv2.fillPoly(rgb, [np.round(self.strip_polygon(strip) * 16.0).astype(np.int32)], FILLET_RGB, cv2.LINE_8, 4)
        return rgb

    def strip_polygon(self, strip: SideStrip) -> np.ndarray:
        """(N, 2) pixel outline of a strip."""
        au, av = self.axle_uv
        radius = self.roller_radius_px + strip.thickness_px / 2.0
        p = np.linspace(strip.lead_px - strip.length_px, strip.lead_px, 181)
        phi = np.clip(p / radius, 0.0, None) if strip.drape else np.zeros_like(p)
        wrapped = strip.drape & (p > 0.0)
        cu = np.where(wrapped, au + radius * np.sin(phi), au + p)
        cv = np.where(wrapped, av - radius * np.cos(phi), av - radius)
        nu, nv = np.sin(phi), -np.cos(phi)
        half = strip.thickness_px / 2.0
        top = np.stack([cu + half * nu, cv + half * nv], axis=1)
        bottom = np.stack([cu - half * nu, cv - half * nv], axis=1)
        return np.concatenate([top, bottom[::-1]])
