"""One experiment run without ROS: identical fillets side by side in every lane, scored like the line does.

`woody sweep` and `woody calibrate` call :func:`evaluate_run` in worker
processes. It drives the same modules the nodes use — LineWorld (pybullet),
LineRenderer, segmentation, tracking, FilletGrader (Φ) and
SidePassageTracker (NMDM, MDM, BE) — but renders only the frames the scores
need: top-down frames while some fillet is near the roller edge, side frames
while the watched lane's fillet is in the side camera's view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from woody_sim.line_geometry import LineGeometry, fpm_to_mps
from woody_sim.line_world import LineWorld, PhysicsConfig
from woody_sim.meshes import FilletMesh
from woody_sim.rendering import LineRenderer
from woody_vision.camera_model import LaneLayout
from woody_vision.grader_core import FilletGrader, TrackObservation
from woody_vision.segmentation import BackgroundModel, segment_depth
from woody_vision.side_view import SidePassageTracker
from woody_vision.tracking import CentroidTracker

RUN_COLUMNS = ["mesh", "k", "speed_fpm", "lane", "mass", "phi", "hu_term", "solidity_term", "nmdm", "mdm", "be",
               "status", "reason"]

SPAWN_X = -0.42
"""Sweeps spawn just inside the top camera's view (fillet centre, m): only the approach the scores need."""

TOP_RATE_HZ = 30.0
SIDE_RATE_HZ = 100.0
MAX_SIM_S = 4.0


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

    @property
    def key(self) -> tuple[str, float, float, float | None]:
        return (self.mesh, float(self.k), float(self.speed_fpm), self.mass)


def evaluate_run(spec: RunSpec, mesh: FilletMesh, config: PhysicsConfig | None = None) -> list[dict]:
    """Simulate one run and return one row per lane (RUN_COLUMNS)."""
    geometry = LineGeometry(lanes=spec.lanes, spawn_x=SPAWN_X)
    world = LineWorld(geometry, config or PhysicsConfig())
    renderer = LineRenderer(geometry, render_top=spec.top, render_side=spec.side)
    speed = fpm_to_mps(spec.speed_fpm)
    mass = spec.mass if spec.mass is not None else _default_mass()
    top_cam = geometry.top_camera()
    k_matrix = tuple(top_cam.k.reshape(-1))
    layout = LaneLayout(k_matrix, geometry.top_height, spec.lanes, geometry.lane_pitch)
    grader = FilletGrader(geometry.top_edge_row(), watched_lane=None)
    tracker = CentroidTracker(lane_layout=layout)
    background = BackgroundModel(1)
    side = SidePassageTracker(axle_px=geometry.side_axle_pixel(), roller_radius_px=geometry.side_roller_radius_px())
    results: dict[int, dict] = {}
    side_result = None
    try:
        if spec.top:
            background.add(renderer.render_top({})[1])
        for lane in range(spec.lanes):
            fid = world.spawn(mesh, k=spec.k, lane=lane, mass=mass, speed_mps=speed)
            renderer.add_fillet(fid, lane, world.model(fid).visuals)
        next_top, next_side = 0.0, 0.0
        top_done = not spec.top
        while world.time < MAX_SIM_S and world.fillets:
            now = world.step()
            for fid in world.take_removed():
                renderer.remove_fillet(fid)
            if not top_done and now + 1e-9 >= next_top:
                next_top += 1.0 / TOP_RATE_HZ
                _, depth = renderer.render_top(world.segment_poses())
                update = tracker.update(segment_depth(depth, background.depth))
                observations = [TrackObservation(t.track_id, t.lane, t.blob.contour, t.unseen) for t in update.active]
                for graded in grader.on_tracks(now, observations, [t.track_id for t in update.ended]):
                    results.setdefault(graded.lane, _shape_row(graded))
                top_done = len(results) >= spec.lanes
            if spec.side and side_result is None and now + 1e-9 >= next_side:
                next_side += 1.0 / SIDE_RATE_HZ
                for measurement in side.update(renderer.render_side(world.segment_poses()), now):
                    side_result = measurement
            if top_done and (not spec.side or side_result is not None):
                break
    finally:
        world.close()
    rows = []
    for lane in range(spec.lanes):
        row = {"mesh": spec.mesh, "k": spec.k, "speed_fpm": spec.speed_fpm, "lane": lane, "mass": mass,
               "phi": math.nan, "hu_term": math.nan, "solidity_term": math.nan, "nmdm": math.nan, "mdm": math.nan,
               "be": math.nan, "status": "unscored" if spec.top else "", "reason": ""}
        if spec.top:
            row.update(results.get(lane, {"reason": "no verdict before the run ended"}))
        if lane == geometry.watched_lane and side_result is not None:
            row.update(nmdm=side_result.nmdm, mdm=side_result.mdm_min_px, be=side_result.be)
        rows.append(row)
    return rows


def _shape_row(graded) -> dict:
    shape = graded.shape
    return {"phi": shape.phi, "hu_term": shape.hu_term, "solidity_term": shape.solidity_term,
            "status": shape.status, "reason": shape.reason}


def _default_mass() -> float:
    from woody_sim.fillet_model import DEFAULT_TOTAL_MASS

    return DEFAULT_TOTAL_MASS

