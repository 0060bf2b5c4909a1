"""Fast CPU rendering of the line's two cameras (no rclpy; numpy + a compiled rasteriser).

What the cameras see is split into a static part and a moving part:

* the static scene (belt, roller, floor for the top camera; backdrop, belt
  side and roller disc for the side camera) is ray-cast analytically ONCE per
  camera when the renderer is built, giving a background colour image and,
  for the top camera, a metric z-depth image;
* the fillets (chains of segment meshes posed by the physics) are rasterised
  every frame by a compiled z-buffer scan-converter (:mod:`woody_sim.raster`)
  and composited over the background by depth.

Vertices are posed and projected with numpy (a few array operations per
fillet); the per-triangle, per-pixel work happens in compiled code. Depth is
perspective-correct (1/z is interpolated in screen space) in float64, so a
planar surface comes out exact to float32 precision.

Conventions: images follow REP 118 (``rgb8`` as uint8 (H, W, 3), depth
``32FC1`` in metres along the optical axis). OpenCV/ROS pixel convention:
the centre of pixel (row v, column u) projects to (u, v) exactly, so with
``K`` from :func:`camera_info_fields` a world point maps to the pixel whose
index is the rounded projection.

Side camera: the rig is modelled as a single-lane side view with a plain
backdrop. The belt side and the roller are drawn as a flat profile in the
plane of the watched lane (so the roller is a disc of radius
``geometry.side_roller_radius_px()`` centred at ``geometry.side_axle_pixel()``),
and the watched lane's fillets are rendered in true perspective and always in
front of that profile (the near side plate of the rig is cut away). The side
camera sits below the belt top (``side_center_z`` < 0), so a physically
modelled belt of any width would hide the lower part of a fillet lying on it;
the profile model keeps the whole silhouette visible, as on the real rig.

A :class:`RenderProcess` runs a :class:`LineRenderer` in a child process
(frames come back through shared memory) so rendering of frame *k* overlaps
physics stepping of frame *k + 1* on the second core.
"""

from __future__ import annotations

import collections
import math
import multiprocessing as mp
import multiprocessing.connection as mpc
import time
import traceback
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numpy as np

from woody_sim.child_process import ChildProcess, parent_messages
from woody_sim.line_geometry import LineGeometry, PinholeCamera
from woody_sim.raster import ZBuffer

__all__ = [
    "FRAMES_IN_FLIGHT",
    "BELT_RGB",
    "FILLET_RGB",
    "FLOOR_RGB",
    "ROLLER_RGB",
    "SIDE_BACKDROP_RGB",
    "SIDE_BELT_RGB",
    "SIDE_FRAME_RGB",
    "SIDE_HUB_RGB",
    "SIDE_ROLLER_RGB",
    "Frames",
    "LineRenderer",
    "NO_FILLET",
    "RenderProcess",
    "camera_info_fields",
    "fillet_color",
    "quaternions_to_matrices",
    "visuals_from_mesh",
]

NO_FILLET = -1
"""An instance image's value where no fillet is seen (the scene behind)."""
FRAMES_IN_FLIGHT = 3
"""Frames a :class:`RenderProcess` renders ahead of collection (one shared buffer set each). Three, not two: with
two, line_sim waited ~4 % of its wall time for a frame while both were in flight."""

# --------------------------------------------------------------------------- colours
# Base (unlit) colours. Lambert shading multiplies them by AMBIENT + DIFFUSE * cos.
BELT_RGB = (58, 64, 82)
"""Top view: belt top (dark blue-grey)."""
ROLLER_RGB = (150, 152, 158)
"""Top view: roller surface beyond the edge (steel grey)."""
FLOOR_RGB = (96, 88, 80)
"""Top view: catch floor beyond the edge and beside the belt."""
FILLET_RGB = (226, 150, 138)
"""Mean fillet colour (pink); each fillet is jittered around it."""
SIDE_BACKDROP_RGB = (34, 92, 70)
"""Side view: plain backdrop (dark green, far from any fillet pink)."""
SIDE_FRAME_RGB = (92, 96, 104)
"""Side view: side plate of the conveyor bed under the belt (x < 0)."""
SIDE_BELT_RGB = (40, 44, 56)
"""Side view: the belt's edge, a strip along the top of the bed."""
SIDE_ROLLER_RGB = (176, 178, 184)
"""Side view: roller end disc."""
SIDE_HUB_RGB = (70, 72, 78)
"""Side view: axle hub at the roller centre."""

AMBIENT = 0.35
DIFFUSE = 0.65
_LIGHT_DIR = np.array([-0.3, 0.35, 1.0])
_LIGHT_DIR = _LIGHT_DIR / np.linalg.norm(_LIGHT_DIR)
"""Unit vector towards a distant light, world frame (above, slightly upstream and left)."""

_SIDE_BELT_THICKNESS = 0.006


# --------------------------------------------------------------------------- helpers
def camera_info_fields(camera: PinholeCamera) -> dict:
    """Values for a ``sensor_msgs/CameraInfo`` of a pinhole camera and its lens distortion."""
    k = [float(camera.fx), 0.0, float(camera.cx), 0.0, float(camera.fy), float(camera.cy), 0.0, 0.0, 1.0]
    p = [float(camera.fx), 0.0, float(camera.cx), 0.0, 0.0, float(camera.fy), float(camera.cy), 0.0, 0.0, 0.0, 1.0, 0.0]
    d = [float(c) for c in camera.distortion] + [0.0] * (5 - len(camera.distortion))
    return {
        "width": int(camera.width),
        "height": int(camera.height),
        "distortion_model": "rational_polynomial" if len(d) == 8 else "plumb_bob",
        "d": d,
        "k": k,
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": p,
        # Upper-case aliases (the brief's spelling).
        "D": list(d),
        "K": list(k),
        "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "P": list(p),
    }


def quaternions_to_matrices(q: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions [qx, qy, qz, qw] (pybullet order) to (N, 3, 3) rotation matrices.

    Quaternions are normalised; a zero quaternion raises ValueError.
    """
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=1)
    if np.any(n < 1e-9):
        raise ValueError("pose quaternion of (near) zero norm")
    x, y, z, w = (q / n[:, None]).T
    m = np.empty((q.shape[0], 3, 3))
    m[:, 0, 0] = 1 - 2 * (y * y + z * z)
    m[:, 0, 1] = 2 * (x * y - z * w)
    m[:, 0, 2] = 2 * (x * z + y * w)
    m[:, 1, 0] = 2 * (x * y + z * w)
    m[:, 1, 1] = 1 - 2 * (x * x + z * z)
    m[:, 1, 2] = 2 * (y * z - x * w)
    m[:, 2, 0] = 2 * (x * z - y * w)
    m[:, 2, 1] = 2 * (y * z + x * w)
    m[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def fillet_color(fillet_id: int) -> tuple[int, int, int]:
    """A pink slightly varied per fillet, deterministic in the id."""
    rng = np.random.default_rng(0x5EED + int(fillet_id) * 7919)
    base = np.array(FILLET_RGB, dtype=float)
    jitter = rng.uniform(-1.0, 1.0, 3) * np.array([10.0, 14.0, 12.0]) + rng.uniform(-8.0, 8.0)
    c = np.clip(base + jitter, 0, 255)
    return int(c[0]), int(c[1]), int(c[2])


def _lambert(rgb: Sequence[float], cos: np.ndarray) -> np.ndarray:
    shade = AMBIENT + DIFFUSE * np.clip(cos, 0.0, 1.0)
    return np.asarray(rgb, dtype=np.float64)[None, :] * shade[..., None]


@dataclass
class _PreparedFillet:
    """Render-ready geometry of one fillet (link-frame vertices padded per segment)."""

    fillet_id: int
    lane: int
    n_segments: int
    verts: np.ndarray  # (N, maxn, 3) float64, zero-padded
    faces: np.ndarray  # (T, 3) int64 indices into verts.reshape(-1, 3)
    seg_radius: np.ndarray  # (N,) bounding radius of each segment about its link origin
    color: np.ndarray  # (3,) float64


def _check_visuals(visuals: Sequence[Any]) -> list[tuple[np.ndarray, np.ndarray]]:
    if visuals is None or len(visuals) == 0:
        raise ValueError("add_fillet: visuals must be a non-empty sequence of SegmentVisual")
    out = []
    for i, sv in enumerate(visuals):
        try:
            v = np.asarray(sv.vertices if hasattr(sv, "vertices") else sv[0], dtype=np.float64)
            f = np.asarray(sv.faces if hasattr(sv, "faces") else sv[1])
        except (TypeError, IndexError) as exc:
            raise ValueError(f"add_fillet: visual {i} has no vertices/faces ({exc})") from None
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise ValueError(f"add_fillet: visual {i} vertices must have shape (n, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"add_fillet: visual {i} faces must have shape (m, 3), got {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"add_fillet: visual {i} faces must be integer, got {f.dtype}")
        if f.size and (f.min() < 0 or f.max() >= v.shape[0]):
            raise ValueError(f"add_fillet: visual {i} faces index outside its {v.shape[0]} vertices")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"add_fillet: visual {i} has non-finite vertices")
        out.append((v, f.astype(np.int64)))
    return out


def _prepare_fillet(
    fillet_id: int,
    lane: int,
    visuals: Sequence[tuple[np.ndarray, np.ndarray]],
    color: tuple[int, int, int] | None,
) -> _PreparedFillet:
    n = len(visuals)
    maxn = max(v.shape[0] for v, _ in visuals)
    verts = np.zeros((n, maxn, 3))
    faces = []
    for i, (v, f) in enumerate(visuals):
        verts[i, : v.shape[0]] = v
        faces.append(f + i * maxn)
    faces_arr = np.concatenate(faces, axis=0) if faces else np.zeros((0, 3), np.int64)
    c = _check_color(fillet_color(fillet_id) if color is None else color)
    return _PreparedFillet(int(fillet_id), int(lane), n, verts, faces_arr, _segment_radii(visuals), c)


def _check_color(color: Any) -> np.ndarray:
    c = np.asarray(color, dtype=np.float64)
    if c.shape != (3,) or np.any(c < 0) or np.any(c > 255):
        raise ValueError(f"add_fillet: color must be three ints 0..255, got {color!r}")
    return c


class _View:
    """One camera: intrinsics, pose, static background."""

    def __init__(self, camera: PinholeCamera, bg_rgb: np.ndarray, bg_depth: np.ndarray | None) -> None:
        self.shape = (int(camera.height), int(camera.width))
        """The images' (rows, columns) as the camera delivers them."""
        self.lens: tuple[np.ndarray, np.ndarray] | None = None
        """(rows, columns) of the undistorted canvas each pixel of the camera's image shows; None: no distortion."""
        if any(camera.distortion):
            camera, self.lens = _undistorted_canvas(camera)
        self.camera = camera
        self.w = int(camera.width)
        self.h = int(camera.height)
        self.fx, self.fy, self.cx, self.cy = float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy)
        self.rot = np.asarray(camera.rotation, dtype=np.float64)  # columns: optical axes in world
        self.pos = np.asarray(camera.position, dtype=np.float64)
        self.near = float(camera.near)
        self.bg_rgb = bg_rgb
        self.bg_depth = bg_depth
        self.light_opt = _LIGHT_DIR @ self.rot  # light direction in the optical frame
        self.zbuffer = ZBuffer(self.w, self.h, (self.fx, self.fy, self.cx, self.cy), self.near, self.light_opt,
                               AMBIENT, DIFFUSE)

    def distort(self, image: np.ndarray) -> np.ndarray:
        """An image rendered on the undistorted canvas as the camera's lens shows it (the image itself without
        distortion)."""
        return image if self.lens is None else image[self.lens]

    def pixel_rays(self) -> np.ndarray:
        """(H, W, 3) world directions of the pixel-centre rays, scaled so optical z = 1."""
        u = np.arange(self.w, dtype=np.float64)
        v = np.arange(self.h, dtype=np.float64)
        uu, vv = np.meshgrid(u, v)
        d_opt = np.stack([(uu - self.cx) / self.fx, (vv - self.cy) / self.fy, np.ones_like(uu)], axis=-1)
        return d_opt @ self.rot.T


def _undistorted_canvas(camera: PinholeCamera) -> tuple[PinholeCamera, tuple[np.ndarray, np.ndarray]]:
    """An ideal pinhole camera (same pose and focal lengths) large enough to hold every ray the distorted camera
    sees (a barrel lens's corners reach beyond its own ideal image), and for each pixel of the distorted image the
    nearest canvas pixel seeing the same ray."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    k = camera.k
    ideal = cv2.undistortPoints(np.stack([u, v], axis=-1).reshape(-1, 1, 2), k, np.asarray(camera.distortion),
                                P=k).reshape(camera.height, camera.width, 2)
    left, top = (max(0, int(np.ceil(-ideal[..., i].min()))) + 1 for i in (0, 1))
    right = max(0, int(np.ceil(ideal[..., 0].max() - (camera.width - 1)))) + 1
    bottom = max(0, int(np.ceil(ideal[..., 1].max() - (camera.height - 1)))) + 1
    canvas = replace(camera, width=camera.width + left + right, height=camera.height + top + bottom,
                     cx=camera.cx + left, cy=camera.cy + top, distortion=())
    cols = np.clip(np.rint(ideal[..., 0]) + left, 0, canvas.width - 1).astype(np.intp)
    rows = np.clip(np.rint(ideal[..., 1]) + top, 0, canvas.height - 1).astype(np.intp)
    return canvas, (rows, cols)


# --------------------------------------------------------------------------- backgrounds
def _top_background(g: LineGeometry, view: _View) -> tuple[np.ndarray, np.ndarray]:
    d = view.pixel_rays()  # t along d is exactly the z-depth
    o = view.pos
    half_w = g.belt_width / 2.0
    r = g.roller_radius
    inf = np.full(d.shape[:2], np.inf)

    with np.errstate(divide="ignore", invalid="ignore"):
        # belt top z = 0, x in [-L, 0], |y| <= w/2
        t_belt = (0.0 - o[2]) / d[..., 2]
        px = o[0] + t_belt * d[..., 0]
        py = o[1] + t_belt * d[..., 1]
        ok = (t_belt > 0) & (px >= -g.belt_length) & (px <= 0.0) & (np.abs(py) <= half_w)
        t_belt = np.where(ok, t_belt, inf)
        # roller: x^2 + (z + R)^2 = R^2, |y| <= w/2 (only the part beyond the edge is not under the belt)
        ax, az = 0.0, -r
        ox, oz = o[0] - ax, o[2] - az
        a = d[..., 0] ** 2 + d[..., 2] ** 2
        b = 2.0 * (ox * d[..., 0] + oz * d[..., 2])
        c = ox * ox + oz * oz - r * r
        disc = b * b - 4 * a * c
        t_rol = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a)
        ry = o[1] + t_rol * d[..., 1]
        ok = (disc >= 0) & (t_rol > 0) & (np.abs(ry) <= half_w)
        t_rol = np.where(ok, t_rol, inf)
        # floor
        t_floor = (g.floor_z - o[2]) / d[..., 2]
        t_floor = np.where(t_floor > 0, t_floor, inf)

    t = np.minimum(np.minimum(t_belt, t_rol), t_floor)
    rgb = np.zeros(d.shape[:2] + (3,))
    up_cos = float(_LIGHT_DIR[2])
    sel = t == t_floor
    rgb[sel] = _lambert(FLOOR_RGB, np.full(int(sel.sum()), up_cos))
    sel = t == t_rol
    if sel.any():
        p = o + t[sel][:, None] * d[sel]
        nrm = np.stack([p[:, 0] - ax, np.zeros(len(p)), p[:, 2] - az], axis=1) / r
        rgb[sel] = _lambert(ROLLER_RGB, nrm @ _LIGHT_DIR)
    sel = t == t_belt
    rgb[sel] = _lambert(BELT_RGB, np.full(int(sel.sum()), up_cos))
    depth = np.where(np.isfinite(t), t, np.nan).astype(np.float32)
    return np.clip(np.rint(rgb), 0, 255).astype(np.uint8), depth


def _side_background(g: LineGeometry, view: _View) -> np.ndarray:
    """Profile of the watched lane's belt and roller at the lane plane, over a backdrop."""
    u = np.arange(view.w, dtype=np.float64)
    v = np.arange(view.h, dtype=np.float64)
    uu, vv = np.meshgrid(u, v)
    dist = g.lane_y(g.watched_lane) - view.pos[1]  # depth of the lane plane
    x = view.pos[0] + (uu - view.cx) / view.fx * dist
    z = view.pos[2] - (vv - view.cy) / view.fy * dist
    ax, az = g.roller_axle
    r = g.roller_radius
    rgb = np.empty((view.h, view.w, 3), np.uint8)
    rgb[:] = SIDE_BACKDROP_RGB
    bed = (x <= ax) & (x >= -g.belt_length) & (z <= 0.0) & (z >= -2.0 * r)
    rgb[bed] = SIDE_FRAME_RGB
    belt = (x <= ax) & (x >= -g.belt_length) & (z <= 0.0) & (z >= -_SIDE_BELT_THICKNESS)
    rgb[belt] = SIDE_BELT_RGB
    rr = np.hypot(x - ax, z - az)
    rgb[rr <= r] = SIDE_ROLLER_RGB
    rgb[rr <= 0.15 * r] = SIDE_HUB_RGB
    return rgb


# --------------------------------------------------------------------------- renderer
class Frames(NamedTuple):
    """One render result; fields not requested are None."""

    top_rgb: np.ndarray | None
    top_depth: np.ndarray | None
    side_rgb: np.ndarray | None


class LineRenderer:
    """Renders the top RGB-D camera and the side camera of a :class:`LineGeometry`."""

    def __init__(self, geometry: LineGeometry, *, render_top: bool = True, render_side: bool = True) -> None:
        self.geometry = geometry
        self._fillets: dict[int, _PreparedFillet] = {}
        self._top: _View | None = None
        self._side: _View | None = None
        if render_top:
            cam = geometry.top_camera()
            view = _View(cam, np.zeros(0), None)
            view.bg_rgb, view.bg_depth = _top_background(geometry, view)
            self._top = view
        if render_side:
            cam = geometry.side_camera()
            view = _View(cam, np.zeros(0), None)
            view.bg_rgb = _side_background(geometry, view)
            self._side = view

    # ---- fillets
    @property
    def fillet_ids(self) -> list[int]:
        return sorted(self._fillets)

    def n_segments(self, fillet_id: int) -> int:
        return self._get(fillet_id).n_segments

    def add_fillet(
        self,
        fillet_id: int,
        lane: int,
        visuals: Sequence[Any],
        color: tuple[int, int, int] | None = None,
    ) -> None:
        """Register a fillet: its lane and one SegmentVisual per chain segment (link frame)."""
        fid, lane_i = _validate_add(self.geometry, self._fillets, fillet_id, lane)
        self._add_checked(fid, lane_i, _check_visuals(visuals), color)

    def _add_checked(self, fillet_id: int, lane: int, vis: list, color: tuple[int, int, int] | None) -> None:
        self._fillets[fillet_id] = _prepare_fillet(fillet_id, lane, vis, color)

    def remove_fillet(self, fillet_id: int) -> None:
        self._get(fillet_id)
        del self._fillets[int(fillet_id)]

    def clear(self) -> None:
        self._fillets.clear()

    def _get(self, fillet_id: int) -> _PreparedFillet:
        try:
            return self._fillets[int(fillet_id)]
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"unknown fillet id {fillet_id!r} (known: {sorted(self._fillets)})") from None

    # ---- rendering
    def render_top(self, poses: Mapping[int, np.ndarray],
                   instances: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Top camera: rgb uint8 (H, W, 3) and depth float32 (H, W), metres along the optical axis. With
        ``instances`` ((H, W) int64), each pixel a fillet is seen in gets its fillet id, the rest are left as
        they were (:data:`NO_FILLET` from :meth:`instance_image`)."""
        if self._top is None:
            raise RuntimeError("this LineRenderer was built with render_top=False")
        checked = self._check_poses(poses)
        view = self._top
        rgb = view.bg_rgb.copy()
        depth = view.bg_depth.copy()
        drawn = instances if instances is None or view.lens is None else np.full(depth.shape, NO_FILLET, np.int64)
        self._draw(view, checked, lane=None, rgb=rgb, depth=depth, instances=drawn)
        if drawn is not instances:
            instances[...] = view.distort(drawn)
        return view.distort(rgb), view.distort(depth)

    def render_side(self, poses: Mapping[int, np.ndarray], instances: np.ndarray | None = None) -> np.ndarray:
        """Side camera: rgb uint8 (H, W, 3) of the watched lane (other lanes are not drawn); ``instances`` as for
        :meth:`render_top`."""
        if self._side is None:
            raise RuntimeError("this LineRenderer was built with render_side=False")
        checked = self._check_poses(poses)
        view = self._side
        rgb = view.bg_rgb.copy()
        self._draw(view, checked, lane=self.geometry.watched_lane, rgb=rgb, depth=None, instances=instances)
        return rgb

    def instance_image(self, top: bool = True) -> np.ndarray:
        """An empty instance image of the top (or side) camera: every pixel :data:`NO_FILLET`."""
        view = self._top if top else self._side
        return np.full(view.shape, NO_FILLET, np.int64)

    def render(self, poses: Mapping[int, np.ndarray], want_top: bool = True, want_side: bool = True) -> Frames:
        top = self.render_top(poses) if want_top else (None, None)
        side = self.render_side(poses) if want_side else None
        return Frames(top[0], top[1], side)

    def _check_poses(self, poses: Mapping[int, np.ndarray]) -> list[tuple[_PreparedFillet, np.ndarray]]:
        return [(self._fillets[fid], p) for fid, p in _validate_poses(self._fillets, poses)]

    def _draw(
        self,
        view: _View,
        checked: list[tuple[_PreparedFillet, np.ndarray]],
        lane: int | None,
        rgb: np.ndarray,
        depth: np.ndarray | None,
        instances: np.ndarray | None = None,
    ) -> None:
        """Draw the fillets (of ``lane`` only, if given) over ``rgb`` and in front of ``depth`` in place, and
        their ids into ``instances`` if given."""
        colors, ids = [], []
        for fl, pose in checked:
            if lane is not None and fl.lane != lane:
                continue
            t_opt = (pose[:, :3] - view.pos) @ view.rot  # link origins in the optical frame
            if not _in_view(view.camera, t_opt, fl.seg_radius):
                continue
            m = np.matmul(view.rot.T[None, :, :], quaternions_to_matrices(pose[:, 3:7]))  # link -> optical
            view.zbuffer.draw(fl.verts, fl.faces, m, t_opt, len(colors))
            colors.append(fl.color)
            ids.append(fl.fillet_id)
        if colors:
            labels = None if instances is None else (np.array(ids), instances)
            view.zbuffer.compose(np.array(colors), rgb, depth, labels)


def _in_view(camera: PinholeCamera, t_opt: np.ndarray, radius: np.ndarray) -> bool:
    """Whether any segment's bounding sphere (centres ``t_opt`` in the optical frame) may show in the image."""
    z = t_opt[:, 2]
    if np.all(z + radius < camera.near):
        return False
    zn = np.maximum(z - radius, camera.near)
    zf = np.maximum(z + radius, camera.near)
    # Conservative pixel extent of each segment's bounding sphere.
    us = [camera.fx * (t_opt[:, 0] + sx * radius) / zz for sx in (-1, 1) for zz in (zn, zf)]
    vs = [camera.fy * (t_opt[:, 1] + sy * radius) / zz for sy in (-1, 1) for zz in (zn, zf)]
    u0 = np.min(us, axis=0) + camera.cx
    u1 = np.max(us, axis=0) + camera.cx
    v0 = np.min(vs, axis=0) + camera.cy
    v1 = np.max(vs, axis=0) + camera.cy
    vis = (u1 >= -1) & (u0 <= camera.width) & (v1 >= -1) & (v0 <= camera.height)
    return bool(vis.any())


def _segment_radii(visuals: Sequence[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Bounding radius of each segment about its link origin."""
    return np.array([float(np.sqrt((v * v).sum(axis=1).max())) for v, _ in visuals])


def _validate_add(geometry: LineGeometry, known: Mapping[int, Any], fillet_id: int, lane: int) -> tuple[int, int]:
    try:
        fid = int(fillet_id)
    except (TypeError, ValueError):
        raise ValueError(f"add_fillet: fillet id must be an int, got {fillet_id!r}") from None
    if fid in known:
        raise ValueError(f"add_fillet: fillet id {fid} is already registered")
    if not isinstance(lane, (int, np.integer)) or not 0 <= int(lane) < geometry.lanes:
        raise ValueError(f"add_fillet: lane must be 0..{geometry.lanes - 1}, got {lane!r}")
    return fid, int(lane)


def _validate_poses(known: Mapping[int, Any], poses: Mapping[int, np.ndarray]) -> list[tuple[int, np.ndarray]]:
    if not isinstance(poses, Mapping):
        raise ValueError(f"poses must be a mapping fillet_id -> (N, 7) array, got {type(poses).__name__}")
    out = []
    for fid, p in poses.items():
        fl = known.get(fid)
        if fl is None:
            raise ValueError(f"unknown fillet id {fid!r} in poses (known: {sorted(known)})")
        n = fl.n_segments if hasattr(fl, "n_segments") else int(fl)
        arr = np.asarray(p, dtype=np.float64)
        if arr.shape != (n, 7):
            raise ValueError(
                f"poses[{fid}] must have shape ({n}, 7) rows [x, y, z, qx, qy, qz, qw], got {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"poses[{fid}] contains non-finite values")
        if np.any(np.linalg.norm(arr[:, 3:7], axis=1) < 1e-9):
            raise ValueError(f"poses[{fid}] has a zero quaternion")
        out.append((fid, arr))
    return out


# --------------------------------------------------------------------------- process wrapper
def _child_main(conn: mpc.Connection, geometry: LineGeometry, flags: tuple[bool, bool], buffers: list[dict]) -> None:
    renderer = LineRenderer(geometry, render_top=flags[0], render_side=flags[1])
    arrays = [{name: np.frombuffer(buf, dtype=dtype).reshape(shape) for name, (buf, dtype, shape) in slot.items()}
              for slot in buffers]
    pending_error: str | None = None
    shapes: dict[int, list] = {}  # visuals sent once per chain shape, then referred to by key
    for msg in parent_messages(conn, b"woody-render"):
        op = msg[0]
        try:
            if op == "shape":
                _, key, vis = msg
                shapes[key] = vis
            elif op == "add":
                _, fid, lane, key, color = msg
                renderer._add_checked(fid, lane, shapes[key], color)
            elif op == "remove":
                renderer._fillets.pop(msg[1], None)
            elif op == "forget":
                shapes.pop(msg[1], None)
            elif op == "render":
                _, slot, poses, want_top, want_side = msg
                t0 = time.perf_counter()
                if pending_error is not None:
                    err, pending_error = pending_error, None
                    conn.send(("err", err))
                    continue
                if want_top:
                    rgb, depth = renderer.render_top(poses)
                    arrays[slot]["top_rgb"][...] = rgb
                    arrays[slot]["top_depth"][...] = depth
                t1 = time.perf_counter()
                if want_side:
                    arrays[slot]["side_rgb"][...] = renderer.render_side(poses)
                t2 = time.perf_counter()
                conn.send(("ok", (t1 - t0, t2 - t1)))
        except Exception:  # noqa: BLE001 - reported to the parent
            err = traceback.format_exc()
            if op == "render":
                conn.send(("err", err))
            else:
                pending_error = err


class RenderProcess:
    """A :class:`LineRenderer` in a child process, for overlapping rendering with physics.

    ``submit(poses, want_top, want_side)`` starts a frame and returns at once;
    ``collect()`` waits for the oldest frame in flight and returns :class:`Frames`
    (copies, safe to keep). Up to :data:`FRAMES_IN_FLIGHT` frames are in flight,
    each in its own shared buffers, so the simulation runs on while a slow frame
    renders. ``add_fillet`` / ``remove_fillet`` are validated here and applied
    in order in the child. The child is a daemon that also exits as soon as the
    parent process dies.
    """

    def __init__(
        self,
        geometry: LineGeometry,
        *,
        render_top: bool = True,
        render_side: bool = True,
        start_method: str = "spawn",
        timeout: float = 30.0,
    ) -> None:
        self.geometry = geometry
        self._flags = (bool(render_top), bool(render_side))
        self._known: dict[int, int] = {}  # id -> n_segments
        self._lanes: dict[int, int] = {}
        self._radii: dict[int, np.ndarray] = {}
        self._shapes: dict[int, tuple[Sequence[Any], int, np.ndarray]] = {}  # id(visuals) -> visuals, n, radii
        self._side_camera = geometry.side_camera()
        self._inflight: collections.deque[tuple[int, bool, bool]] = collections.deque()
        self._submitted = 0
        self.last_render_s: tuple[float, float] = (0.0, 0.0)
        ctx = mp.get_context(start_method)
        shapes: dict[str, tuple[str, tuple[int, ...]]] = {}
        if render_top:
            shapes["top_rgb"] = ("u1", (geometry.top_height_px, geometry.top_width, 3))
            shapes["top_depth"] = ("f4", (geometry.top_height_px, geometry.top_width))
        if render_side:
            shapes["side_rgb"] = ("u1", (geometry.side_height_px, geometry.side_width, 3))
        self._buffers: list[dict] = [{} for _ in range(FRAMES_IN_FLIGHT)]
        self._arrays: list[dict[str, np.ndarray]] = [{} for _ in range(FRAMES_IN_FLIGHT)]
        for slot in range(FRAMES_IN_FLIGHT):
            for name, (dtype, shape) in shapes.items():
                buf = ctx.RawArray("B", int(np.prod(shape)) * np.dtype(dtype).itemsize)
                self._buffers[slot][name] = (buf, dtype, shape)
                self._arrays[slot][name] = np.frombuffer(buf, dtype=dtype).reshape(shape)
        self._child = ChildProcess(_child_main, (geometry, self._flags, self._buffers), "render",
                                   start_method=start_method, timeout=timeout)

    # ---- lifecycle
    def close(self) -> None:
        self._child.close()

    def __enter__(self) -> RenderProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _send(self, msg: tuple) -> None:
        self._child.send(msg)

    # ---- fillets
    @property
    def fillet_ids(self) -> list[int]:
        return sorted(self._known)

    def add_fillet(
        self,
        fillet_id: int,
        lane: int,
        visuals: Sequence[Any],
        color: tuple[int, int, int] | None = None,
    ) -> None:
        """Register a fillet's segment visuals; a visuals object seen before is not checked or sent again."""
        fid, lane_i = _validate_add(self.geometry, self._known, fillet_id, lane)
        if color is not None:
            color = tuple(int(c) for c in _check_color(color))
        key = id(visuals)
        shape = self._shapes.get(key)
        if shape is None:  # the cache keeps the visuals object alive, so its id cannot be reused
            vis = _check_visuals(visuals)
            self._send(("shape", key, vis))
            shape = self._shapes[key] = (visuals, len(vis), _segment_radii(vis))
        self._send(("add", fid, lane_i, key, color))
        self._known[fid] = shape[1]
        self._lanes[fid] = lane_i
        self._radii[fid] = shape[2]

    def remove_fillet(self, fillet_id: int) -> None:
        try:
            fid = int(fillet_id)
            self._known[fid]
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"unknown fillet id {fillet_id!r} (known: {sorted(self._known)})") from None
        self._send(("remove", fid))
        del self._known[fid]
        del self._lanes[fid]
        del self._radii[fid]

    def release(self, visuals: Sequence[Any]) -> None:
        """Forget visuals no later fillet uses (a placed fillet's own), here and in the child."""
        key = id(visuals)
        if self._shapes.pop(key, None) is not None:
            self._send(("forget", key))

    def side_view_occupied(self, poses: Mapping[int, np.ndarray]) -> bool:
        """Whether a fillet of the watched lane may show in the side camera's image (else the frame is the
        static background, which a consumer has seen already)."""
        cam = self._side_camera
        rot, pos = np.asarray(cam.rotation, dtype=np.float64), np.asarray(cam.position, dtype=np.float64)
        for fid, pose in poses.items():
            if self._lanes.get(fid) == self.geometry.watched_lane:
                if _in_view(cam, (np.asarray(pose)[:, :3] - pos) @ rot, self._radii[fid]):
                    return True
        return False

    # ---- rendering
    def submit(self, poses: Mapping[int, np.ndarray], want_top: bool = True, want_side: bool = True) -> None:
        """Start rendering a frame in the child; returns immediately."""
        if not self.can_submit:
            raise RuntimeError(f"{FRAMES_IN_FLIGHT} frames are already in flight: collect() one first")
        if want_top and not self._flags[0]:
            raise RuntimeError("this RenderProcess was built with render_top=False")
        if want_side and not self._flags[1]:
            raise RuntimeError("this RenderProcess was built with render_side=False")
        checked = _validate_poses(self._known, poses)
        if want_side and not want_top:
            lane = self.geometry.watched_lane
            checked = [(f, p) for f, p in checked if self._lanes[f] == lane]
        slot = self._submitted % FRAMES_IN_FLIGHT
        self._send(("render", slot, dict(checked), bool(want_top), bool(want_side)))
        self._inflight.append((slot, bool(want_top), bool(want_side)))
        self._submitted += 1

    @property
    def busy(self) -> bool:
        """A frame is in flight."""
        return bool(self._inflight)

    @property
    def can_submit(self) -> bool:
        """Fewer than :data:`FRAMES_IN_FLIGHT` frames are in flight."""
        return len(self._inflight) < FRAMES_IN_FLIGHT

    def ready(self) -> bool:
        """True when the oldest frame in flight can be collected without waiting."""
        return bool(self._inflight) and self._child.poll()

    def collect(self, copy: bool = True) -> Frames:
        """Wait for the oldest frame in flight. With copy=False the arrays alias shared
        buffers that a later submit() overwrites."""
        if not self._inflight:
            raise RuntimeError("collect() without a submitted frame")
        slot, want_top, want_side = self._inflight.popleft()
        try:
            status, payload = self._child.recv()
        except (RuntimeError, TimeoutError):
            self._inflight.clear()
            raise
        if status != "ok":
            raise RuntimeError(f"render process failed:\n{payload}")
        self.last_render_s = payload
        a = self._arrays[slot]

        def get(name: str) -> np.ndarray:
            return a[name].copy() if copy else a[name]

        return Frames(
            get("top_rgb") if want_top else None,
            get("top_depth") if want_top else None,
            get("side_rgb") if want_side else None,
        )

    def render(self, poses: Mapping[int, np.ndarray], want_top: bool = True, want_side: bool = True) -> Frames:
        self.submit(poses, want_top, want_side)
        return self.collect()

    def render_top(self, poses: Mapping[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        f = self.render(poses, True, False)
        return f.top_rgb, f.top_depth

    def render_side(self, poses: Mapping[int, np.ndarray]) -> np.ndarray:
        return self.render(poses, False, True).side_rgb


# --------------------------------------------------------------------------- demo geometry + benchmark
@dataclass(frozen=True)
class _Visual:
    vertices: np.ndarray
    faces: np.ndarray


_MESH_DIR = Path(__file__).resolve().parent / "meshes"


def visuals_from_mesh(
    vertices: np.ndarray, faces: np.ndarray, n_segments: int = 40
) -> tuple[list[_Visual], np.ndarray]:
    """Cut a fillet mesh (x length, y thickness with flat bottom at y=0, z width) into
    ``n_segments`` slabs along its length, for tests and benchmarks.

    Triangles are assigned whole to the slab of their centroid. Each segment's
    link frame has world-like axes (x along the length, y across, z up) with its
    origin on the bottom plane at the slab's centre, so identity quaternions mean
    "lying flat". Returns the visuals and the (N,) link-origin x offsets from the
    fillet centre.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    # mesh (x, y=up, z) -> link axes (x, y=-z, z=y)
    w = np.stack([v[:, 0], -v[:, 2], v[:, 1] - v[:, 1].min()], axis=1)
    w[:, 1] -= 0.5 * (w[:, 1].min() + w[:, 1].max())
    xmin, xmax = w[:, 0].min(), w[:, 0].max()
    w[:, 0] -= 0.5 * (xmin + xmax)
    length = xmax - xmin
    edges = np.linspace(-length / 2, length / 2, n_segments + 1)
    centres = 0.5 * (edges[:-1] + edges[1:])
    cx = w[f].mean(axis=1)[:, 0]
    seg = np.clip(np.searchsorted(edges, cx, side="right") - 1, 0, n_segments - 1)
    out = []
    for i in range(n_segments):
        fi = f[seg == i]
        used, inv = np.unique(fi.reshape(-1), return_inverse=True)
        vi = w[used] - np.array([centres[i], 0.0, 0.0])
        out.append(_Visual(vi.astype(np.float32), inv.reshape(-1, 3).astype(np.int32)))
    return out, centres


def load_reference_visuals(index: int = 0, n_segments: int = 40) -> tuple[list[_Visual], np.ndarray]:
    """The built-in reference mesh seed000<index>.obj cut into segments (see visuals_from_mesh)."""
    import trimesh

    mesh = trimesh.load(_MESH_DIR / f"seed{index:04d}.obj", process=False, force="mesh")
    return visuals_from_mesh(mesh.vertices, mesh.faces, n_segments)


def flat_poses(offsets: np.ndarray, x: float, y: float) -> np.ndarray:
    """(N, 7) poses of a fillet lying flat on the belt, centre at (x, y)."""
    n = len(offsets)
    p = np.zeros((n, 7))
    p[:, 0] = x + np.asarray(offsets)
    p[:, 1] = y
    p[:, 6] = 1.0
    return p


def draped_poses(offsets: np.ndarray, x: float, y: float, roller_radius: float) -> np.ndarray:
    """(N, 7) poses of a fully limp fillet whose centre is at arc length ``x`` past the
    roller edge: flat on the belt for x < 0, wrapped on the roller up to 90°, then
    hanging straight down. ``x`` may be negative (then partly still on the belt)."""
    r = roller_radius
    s = x + np.asarray(offsets, dtype=np.float64)  # arc length of each link origin past the edge
    theta = np.clip(s / r, 0.0, math.pi / 2)
    px = np.where(s < 0, s, np.where(s <= r * math.pi / 2, r * np.sin(theta), r))
    pz = np.where(s < 0, 0.0, np.where(s <= r * math.pi / 2, -r + r * np.cos(theta), -r - (s - r * math.pi / 2)))
    p = np.zeros((len(s), 7))
    p[:, 0] = px
    p[:, 1] = y
    p[:, 2] = pz
    # rotation about +y by theta (x tilts down): q = (0, sin(θ/2), 0, cos(θ/2))
    p[:, 4] = np.sin(theta / 2)
    p[:, 6] = np.cos(theta / 2)
    return p
