"""One experiment run without ROS: identical fillets side by side in every lane, scored like the line does.

`woody sweep` and `woody calibrate` call :func:`evaluate_run` in worker
processes. It drives the same modules the nodes use — LineWorld (pybullet),
LineRenderer, segmentation, tracking, FilletGrader (Φ) and
SidePassageTracker (NMDM, MDM, BE) — but simulates and renders only what the
scores need:

* one chain, in the watched lane: the other lanes show copies of it shifted
  across the belt (:class:`_LaneCopies`). The lanes of a run are the same
  fillet spawned at the same moment on a belt and roller that are uniform
  across the lanes, so what tells them apart is the top camera's
  perspective, and that is still rendered and scored per lane. (Three
  independent chains drift 2-9 mm apart during a run through rounding in
  pybullet's contacts alone; simulating one costs a third.)

* top-down frames at the camera rate ``TOP_RATE_HZ`` (on the absolute time
  grid) only once some fillet's leading end is within ``TOP_START_X`` of the
  roller edge: Φ's reference is the last flat contour before the leading edge
  reaches the edge, and its window closes when the virtual centroid crosses
  it, so earlier frames never enter the score;
* side frames at ``SIDE_FAR_RATE_HZ`` while the watched fillet rides the belt
  (enough to follow it and measure its flat height h), then at
  ``SIDE_RATE_HZ`` once it is a live chain at the roller (where the minimum
  MDM and the BE frame are).

The side tracker gets the empty-scene side frame as its background (the
fillets are already in the side camera's view at spawn, so learning the
background from the first frame, as the node does on a line that starts
empty, would bake a fillet into it). One LineRenderer per geometry (lane count, top camera) is kept
per process and reused (its construction renders both backgrounds); the
pybullet world is rebuilt per run (cheap) so every run starts identically.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from woody_common.calibration import resolved_calibration
from woody_common.line import LANE_PITCH_M, fpm_to_mps
from woody_experiments.conditions import TIDY, run_placement
from woody_experiments.runs_csv import RUN_COLUMNS  # noqa: F401 - the rows' columns, importable from here too
from woody_sim.line_conditions import FilletPlacement, place_mesh
from woody_sim.line_geometry import LineGeometry, top_camera_preset
from woody_sim.line_world import LineWorld, PhysicsConfig, calibrated_config, seed_dynamic_friction
from woody_sim.meshes import FilletMesh
from woody_sim.rendering import LineRenderer, camera_info_fields
from woody_sim.sensor_model import sensor_preset
from woody_vision.belt_view import BeltView, CameraModel
from woody_vision.camera_model import LaneLayout, belt_outline
from woody_vision.grader_core import FilletGrader, TrackObservation, calibrated_rules
from woody_vision.grading import GradingRules
from woody_vision.segmentation import REAL_CAMERA_FILTERS, BackgroundModel, SegmentationParams, segment_depth
from woody_vision.side_view import SidePassageTracker
from woody_vision.static_frames import Pose
from woody_vision.tracking import CentroidTracker

SPAWN_X = -0.42
"""Sweeps spawn just inside the top camera's view (fillet centre, m): only the approach the scores need."""

TOP_RATE_HZ = 30.0
TOP_START_X = -0.12
"""Top frames start once a fillet's leading end is this close to the roller edge.

In metres; >= 7 frames before the edge at 130 FPM."""
SIDE_RATE_HZ = 200.0
SIDE_FAR_RATE_HZ = 20.0
SIDE_DONE_DISTANCE = 0.12
"""The side passage is closed once the watched fillet's centre of mass is below the axle and this far (m) from it:
the centroid only moves away from the axle from then on (it falls), so no later frame can lower the MDM."""
MAX_SIM_S = 4.0
REAL_CAMERA_SEGMENTATION = SegmentationParams(**REAL_CAMERA_FILTERS)
BACKGROUND_FRAMES = 5
"""Noisy empty-belt frames the background is learned from (the segmenter's default ``background_frames``)."""

_RENDERERS: dict[tuple[LineGeometry, bool, bool], tuple[LineRenderer, tuple | None, np.ndarray | None]] = {}


@dataclass(frozen=True)
class RunSpec:
    """One run of the grid: a mesh in every lane at one stiffness and line speed."""

    mesh: str
    k: float
    speed_fpm: float
    lanes: int = 3
    mass: float | None = None
    side: bool = True
    top: bool = True
    top_camera: str = "default"
    """Top camera preset (woody_sim.line_geometry.TOP_CAMERA_PRESETS)."""
    damping: float | None = None
    """Hinge damper c; None = the calibrated one (``calibration``)."""
    friction_static: float | None = None
    """Drive friction cap (mu_dynamic keeps the seed's 0.75 ratio); None = the calibrated one."""
    sensor: str = "ideal"
    """Top camera error model (woody_sim.sensor_model preset), seeded per run."""
    yaw_deg: float = 0.0
    """An extra turn about the vertical (woody_sim.meshes.yawed), on top of the condition's placement."""
    condition: str = TIDY
    """How fillets lie on the line (woody_experiments.conditions): tidy, turned, blunt, size, messy or wide."""
    calibration: str | None = None
    """The calibration file the run's physics and cuts come from (a path, so a worker process reads the same
    file); None = the resolved one (woody_common.calibration.resolve_calibration)."""
    lane_pitch_m: float = LANE_PITCH_M
    """Distance between lane centres (m): the lanes' copies lie this far apart, seen in perspective."""
    speed_change_fpm: float = 0.0
    """A belt speed change during the run (FPM; 0 = none), at ``speed_change_at_s`` of sim time."""
    speed_change_at_s: float = 0.0
    spawn_offset_m: float = 0.0
    """Moves the spawn downstream (m): the same fillet meets the camera's frame grid at another phase, as fillets of
    a line do from one to the next (the run-to-run spread of a score)."""

    def physics_overrides(self) -> dict:
        """PhysicsConfig fields this run sets itself (the rest come from the calibration)."""
        out = {} if self.damping is None else {"damping": self.damping}
        if self.friction_static is not None:
            out.update(friction_static=self.friction_static,
                       friction_dynamic=seed_dynamic_friction(self.friction_static))
        return out

    @property
    def key(self) -> tuple[str, float, float, float | None, str]:
        return (self.mesh, float(self.k), float(self.speed_fpm), self.mass, self.condition)

    @property
    def placement(self) -> FilletPlacement:
        """How the run's fillet lies (its condition's draw, plus ``yaw_deg``)."""
        drawn = run_placement(self.mesh, self.condition, self.speed_fpm)
        return dataclasses.replace(drawn, yaw_deg=drawn.yaw_deg + self.yaw_deg)


def _renderer(geometry: LineGeometry, top: bool, side: bool):
    key = (geometry, top, side)
    if key not in _RENDERERS:
        renderer = LineRenderer(geometry, render_top=top, render_side=side)
        top_bg = renderer.render_top({}) if top else None
        side_bg = renderer.render_side({}) if side else None
        _RENDERERS[key] = (renderer, top_bg, side_bg)
    renderer, top_bg, side_bg = _RENDERERS[key]
    renderer.clear()
    return renderer, top_bg, side_bg


def run_geometry(spec: RunSpec) -> LineGeometry:
    """The line of one run: its lanes, lane pitch and top camera, fillets spawned at ``SPAWN_X`` (and the run's
    offset)."""
    return LineGeometry(lanes=spec.lanes, lane_pitch=spec.lane_pitch_m, spawn_x=SPAWN_X + spec.spawn_offset_m,
                        **top_camera_preset(spec.top_camera))


def evaluate_run(spec: RunSpec, mesh: FilletMesh, config: PhysicsConfig | None = None,
                 side_rate_hz: float = SIDE_RATE_HZ, top_start_x: float | None = TOP_START_X,
                 stats: dict | None = None, on_top_frame: Callable[[TopFrame], None] | None = None,
                 side_frames: bool = False) -> list[dict]:
    """Simulate one run and return one row per lane (RUN_COLUMNS, and "trace": the lane's Φ window per frame).

    ``top_start_x=None`` renders top frames from the start, as does a run whose belt changes speed (the fillet's
    position is then no longer speed × time) and one with ``on_top_frame``: it gets every top frame the camera
    delivered with the renderer's truth (:class:`TopFrame`, with ``side_frames`` its side view too); ``stats``
    (if given) receives frame counts.
    """
    top_start_x = None if spec.speed_change_fpm or on_top_frame else top_start_x
    geometry = run_geometry(spec)
    placement = spec.placement
    mesh = place_mesh(mesh, placement)
    renderer, top_bg, side_bg = _renderer(geometry, spec.top, spec.side or side_frames)
    calibration = resolved_calibration(spec.calibration)
    world = LineWorld(geometry, config or calibrated_config(calibration, **spec.physics_overrides()))
    speed = fpm_to_mps(spec.speed_fpm)
    mass = (spec.mass if spec.mass is not None else calibration.total_mass_kg) * placement.scale ** 3
    top, side, n_top = None, None, 0
    try:
        top = (_TopView(spec, geometry, top_bg, calibrated_rules(calibration), keep_color=on_top_frame is not None)
               if spec.top else None)
        lanes = _LaneCopies(world, renderer, geometry, world.spawn(mesh, k=spec.k, lane=geometry.watched_lane,
                                                                   mass=mass, speed_mps=speed,
                                                                   lateral_offset=placement.lateral_offset_m))
        if spec.speed_change_fpm:
            world.change_speed(fpm_to_mps(spec.speed_change_fpm), spec.speed_change_at_s)
        side = _SideView(geometry, side_bg, side_rate_hz, lanes.fillet_id) if spec.side else None
        model = world.model(lanes.fillet_id)
        lead_offset = float(model.box_centers[-1, 0] + model.box_half_extents[-1, 0])
        top_dt, next_top = 1.0 / TOP_RATE_HZ, 0.0
        top_done = top is None
        while world.time < MAX_SIM_S and world.fillets:
            now = world.step()
            if world.take_removed():
                lanes.remove()
            poses = None
            if not top_done and now + 1e-9 >= next_top:
                next_top += top_dt * max(1, math.floor((now + 1e-9 - next_top) / top_dt) + 1)
                if top_start_x is None or n_top or geometry.spawn_x + speed * now + lead_offset >= top_start_x:
                    poses = lanes.poses()
                    _top_step(top, renderer, poses, now, on_top_frame, lanes, side_frames)
                    n_top += 1
                    top_done = len(top.results) >= spec.lanes
            if side is not None and side.due(now):
                side.on_step(world, renderer, poses, now)  # the side camera draws the watched lane: the chain
            if top_done and (side is None or side.result is not None):
                break
        if side is not None:
            side.finish(world.time)
    finally:
        world.close()
        renderer.clear()
    if stats is not None:
        stats.update(top_frames=n_top, side_frames=side.frames if side is not None else 0, sim_s=world.time)
    return _lane_rows(spec, placement, mass, geometry.watched_lane, top.results if top is not None else {},
                      side.result if side is not None else None)


@dataclass(frozen=True)
class TopFrame:
    """One top frame as the camera delivered it, and the truth only the renderer knows."""

    stamp: float
    """Sim time (s)."""
    color: np.ndarray
    """rgb8 (H, W, 3), the camera's colour (its pixel noise applied)."""
    depth: np.ndarray
    """float32 (H, W) metres along the optical axis, the camera's depth (its error model applied; NaN holes)."""
    instances: np.ndarray
    """int64 (H, W): the render id of the fillet seen at each pixel, woody_sim.rendering.NO_FILLET elsewhere."""
    lanes: dict[int, int]
    """Render id -> lane."""
    poses: dict[int, np.ndarray]
    """Render id -> segment poses (N, 7): x, y, z (m, world) and a quaternion."""
    side_color: np.ndarray | None = None
    """The side camera's rgb8 frame of the same moment (watched lane only), when asked for."""
    side_instances: np.ndarray | None = None


def _top_step(top: _TopView, renderer, poses: dict, now: float, on_top_frame: Callable[[TopFrame], None] | None,
              lanes: _LaneCopies, side: bool) -> None:
    """Render one top frame into the vision path; hand it to ``on_top_frame`` (if given) with the renderer's
    instance image, and with ``side`` the side view of the same poses."""
    instances = renderer.instance_image() if on_top_frame else None
    sensed = top.on_frame(*renderer.render_top(poses, instances), now)
    if on_top_frame is None or sensed is None:
        return
    side_rgb, side_instances = None, None
    if side:
        side_instances = renderer.instance_image(top=False)
        side_rgb = renderer.render_side(poses, side_instances)
    on_top_frame(TopFrame(now, sensed[1], sensed[0], instances, dict(lanes.lane_of), poses, side_rgb, side_instances))


class _LaneCopies:
    """The run's fillet in every lane: one chain in the watched lane, posed into the others shifted across the belt.

    Render ids: the chain's own in its lane, ``COPY_ID_BASE + lane`` for the copies.
    """

    COPY_ID_BASE = 1_000_000

    def __init__(self, world: LineWorld, renderer, geometry: LineGeometry, fillet_id: int) -> None:
        self.world, self.renderer, self.fillet_id = world, renderer, fillet_id
        watched = geometry.watched_lane
        self.shifts: dict[int, float] = {}
        """Render id -> its lane's offset (m) across the belt from the chain's lane."""
        self.lane_of: dict[int, int] = {}
        for lane in range(geometry.lanes):
            render_id = fillet_id if lane == watched else self.COPY_ID_BASE + lane
            renderer.add_fillet(render_id, lane, world.model(fillet_id).visuals)
            self.shifts[render_id] = geometry.lane_y(lane) - geometry.lane_y(watched)
            self.lane_of[render_id] = lane

    def poses(self) -> dict[int, np.ndarray]:
        """Segment poses of every lane's copy (empty once the chain is gone)."""
        chain = self.world.segment_poses().get(self.fillet_id)
        if chain is None:
            return {}
        out = {}
        for render_id, shift in self.shifts.items():
            out[render_id] = chain.copy()
            out[render_id][:, 1] += shift
        return out

    def remove(self) -> None:
        """The chain left the world: so do its copies."""
        for render_id in self.shifts:
            self.renderer.remove_fillet(render_id)
        self.shifts = {}


class _TopView:
    """The top camera of one run as the segmenter and grader see it: sensor model, segmentation, tracking, Φ."""

    def __init__(self, spec: RunSpec, geometry: LineGeometry, background: tuple[np.ndarray, np.ndarray],
                 rules: GradingRules, keep_color: bool = False) -> None:
        top_cam = geometry.top_camera()
        layout = LaneLayout(tuple(top_cam.k.reshape(-1)), geometry.top_height, spec.lanes, geometry.lane_pitch)
        self.grader = FilletGrader(geometry.top_edge_row(), rules, watched_lane=None,
                                   pixels_per_metre=float(top_cam.k[1, 1]) / geometry.top_height,
                                   fitted_range=None)  # rows are measurements: the reports apply the range
        self.tracker = CentroidTracker(lane_layout=layout)
        self.k, self.height = tuple(top_cam.k.reshape(-1)), geometry.top_height
        self.camera, self.rng = sensor_preset(spec.sensor), np.random.default_rng(_sensor_seed(spec))
        self.color_rng = np.random.default_rng((_sensor_seed(spec), 1))
        """Colour noise has its own stream, so the depth noise of a run does not depend on whether colour is used."""
        self.background = BackgroundModel(1 if self.camera.ideal else BACKGROUND_FRAMES)
        self.segmentation = SegmentationParams() if self.camera.ideal else REAL_CAMERA_SEGMENTATION
        self.keep_color = keep_color
        """Deliver the colour frame even when the segmentation does not use it."""
        self.view = BeltView(CameraModel.of(camera_info_fields(top_cam)),
                             Pose(np.array(top_cam.position), np.array(top_cam.rotation)))
        """The camera's frames as the segmenter works on them (its belt view, woody_vision.belt_view)."""
        while not self.background.ready:
            depth, color = self._sense(*background)
            self.background.add(self.view.depth(depth), self.view.color(color))
        self.results: dict[int, dict] = {}
        """Lane -> its first graded fillet's row fields."""

    def _sense(self, rgb: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The camera's depth, and its colour when the segmentation uses colour."""
        noisy = self.camera.depth(depth, self.rng)
        wanted = self.segmentation.color_threshold or self.keep_color
        return noisy, self.camera.color(rgb, self.color_rng) if wanted else None

    def on_frame(self, rgb: np.ndarray, depth: np.ndarray, now: float) -> tuple[np.ndarray, np.ndarray] | None:
        """One rendered RGB-D frame through the sensor model and the vision path; the depth and colour the
        camera delivered (None: it dropped the frame)."""
        if self.camera.drop(self.rng):
            return None
        noisy, color = self._sense(rgb, depth)
        seen = self.view.depth(noisy)
        used = self.view.color(color) if self.segmentation.color_threshold else None
        blobs = segment_depth(seen, self.background.depth, self.segmentation, used, self.background.color,
                              self.tracker.predicted_outlines(now))
        update = self.tracker.update(blobs, now)
        observations = [TrackObservation(t.track_id, t.lane, belt_outline(t.blob.contour, seen, self.k, self.height),
                                         t.unseen, t.blob.contour) for t in update.active]
        for graded in self.grader.on_tracks(now, observations, [t.track_id for t in update.ended]):
            self.results.setdefault(graded.lane, _shape_row(graded))
        return noisy, color


class _SideView:
    """The side camera on the watched lane: fast frames while its fillet is near the roller, slow ones before."""

    def __init__(self, geometry: LineGeometry, background: np.ndarray, rate_hz: float, fillet_id: int) -> None:
        self.tracker = SidePassageTracker(axle_px=geometry.side_axle_pixel(),
                                          roller_radius_px=geometry.side_roller_radius_px(), background=background)
        self.background, self.rate_hz, self.fillet_id = background, rate_hz, fillet_id
        self.axle = geometry.roller_axle
        self.next_time = 0.0
        self.frames = 0
        self.result = None
        self._planned = False
        """The step into the coming frame is one at the far rate: frames skipped on purpose, not lost."""

    def due(self, now: float) -> bool:
        return self.result is None and now + 1e-9 >= self.next_time

    def on_step(self, world: LineWorld, renderer, poses, now: float) -> None:
        """Render (or, once the fillet has fallen past the roller, reuse the empty background) and measure."""
        gone = self.fillet_id not in world.fillets
        near = gone or world.is_dynamic(self.fillet_id)
        self.next_time += 1.0 / (self.rate_hz if near else SIDE_FAR_RATE_HZ)
        planned, self._planned = self._planned, not near
        if not gone and near:
            com = world.center_of_mass(self.fillet_id)
            ax, az = self.axle
            gone = com[2] < az and math.hypot(com[0] - ax, com[2] - az) > SIDE_DONE_DISTANCE
        frame = self.background if gone else renderer.render_side(poses or world.segment_poses())
        self.frames += 0 if gone else 1
        self._measure(frame, now, planned)

    def finish(self, now: float) -> None:
        """The run ended with the passage still open: close it with empty frames."""
        if self.result is None:
            for _ in range(self.tracker.end_frames):
                self._measure(self.background, now)

    def _measure(self, frame: np.ndarray, now: float, planned: bool = False) -> None:
        for measurement in self.tracker.update(frame, now, planned):
            self.result = measurement


def _lane_rows(spec: RunSpec, placement: FilletPlacement, mass: float, watched: int, results: dict[int, dict],
               side_result) -> list[dict]:
    """One RUN_COLUMNS row per lane from the top-view results and the watched lane's side measurement."""
    rows = []
    for lane in range(spec.lanes):
        row = {"mesh": spec.mesh, "k": spec.k, "speed_fpm": spec.speed_fpm, "condition": spec.condition,
               "lane": lane, "mass": mass, "yaw_deg": placement.yaw_deg, "blunt_first": int(placement.blunt_first),
               "scale": placement.scale, "phi": math.nan, "hu_term": math.nan, "solidity_term": math.nan,
               "line_phi": math.nan, "speed_mps": math.nan, "leading_end": "", "turn_deg": math.nan,
               "length_m": math.nan, "rejected": 0, "nmdm": math.nan,
               "mdm": math.nan, "be": math.nan, "status": "unscored" if spec.top else "", "reason": ""}
        if spec.top:
            row.update(results.get(lane, {"reason": "no verdict before the run ended"}))
        if spec.side and lane == watched:
            if side_result is not None:
                row.update(nmdm=float(side_result.nmdm), mdm=float(side_result.mdm_min_px),
                           be=float(side_result.be))
            elif not spec.top:
                row.update(status="unscored", reason="no side-view measurement")
        rows.append(row)
    return rows


def _sensor_seed(spec: RunSpec) -> int:
    """The camera model's seed for a run: fixed by the run itself, so results do not depend on job order."""
    return zlib.crc32(f"{spec.mesh}|{spec.k:g}|{spec.speed_fpm:g}|{spec.sensor}{_condition_suffix(spec)}".encode())


def _shape_row(graded) -> dict:
    """The lane's top-down columns, plus under "trace" its window frame by frame as the paper's Φ_t (the image
    outline; time relative to the window's close)."""
    shape = graded.shape
    close = shape.paper_trace[-1].stamp if shape.paper_trace else math.nan
    trace = [{"t_rel_s": f.stamp - close, "phi": f.phi, "hu_term": f.hu_term, "solidity_term": f.solidity_term,
              "overhang": f.overhang} for f in shape.paper_trace]
    paper = shape.window_closed
    return {"phi": float(shape.phi) if paper else math.nan, "hu_term": float(shape.hu_term) if paper else math.nan,
            "solidity_term": float(shape.solidity_term) if paper else math.nan, "line_phi": float(shape.line_phi),
            "speed_mps": graded.conditions.speed_mps, "leading_end": shape.leading_end,
            "turn_deg": graded.conditions.turn_deg, "length_m": graded.conditions.length_m,
            "rejected": shape.rejected_frames, "status": shape.status, "reason": shape.reason, "trace": trace,
            "reference_stamp": shape.reference_stamp,
            "window_stamps": [f.stamp for f in shape.trace + shape.extra_trace]}


def _condition_suffix(spec: RunSpec) -> str:
    """The condition's part of the sensor seed ('' on the tidy line, so tidy runs keep their noise)."""
    return "" if spec.condition == TIDY else f"|{spec.condition}"
