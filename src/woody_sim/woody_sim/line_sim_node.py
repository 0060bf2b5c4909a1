"""line_sim: the processing line as a ROS 2 node — pybullet physics, two cameras, ground truth, /clock.

The node owns the simulation loop instead of a wall-clock timer: it steps
physics, renders camera frames on the second core (RenderProcess) whenever a
camera is due in sim time, and publishes them stamped with that sim time, so
the graph is correct whether it runs paced (``realtime``) or as fast as it can.

The calibrated physics (mass, damping, drive friction) are parameters with
plain defaults: the params file `woody run` passes is their source; started
without them, the node reads the resolved calibration once before declaring
(woody_common.ros_params.calibrated_defaults).
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header
from tf2_msgs.msg import TFMessage

from woody_common import topics
from woody_common.diagnostics import OK, WARN, DiagnosticsPublisher, Health
from woody_common.images import serialized_image
from woody_common.line import (
    BELT_MARGIN_M,
    CLASS_K,
    LANE_PITCH_M,
    LANE_PITCH_RANGE_M,
    LANES,
    MAX_BELT_WIDTH_M,
    MAX_FILLETS,
    MAX_LANES,
    MAX_PHYSICS_WORKERS,
    MAX_SEED,
    MAX_SIDE_RATE_HZ,
    MAX_SPAWN_DURATION_S,
    MAX_SPAWN_SPACING_M,
    MIN_SPAWN_SPACING_M,
    REFERENCE_SPEED_FPM,
    SPEED_RANGE_FPM,
    check_lane_pitch,
    fpm_to_mps,
    max_fillets_per_minute,
    spacing_at_rate,
)
from woody_common.ros_params import calibrated_defaults, check_overrides, declare, run_node
from woody_common.stamps import seconds_to_stamp, stamp_to_seconds
from woody_msgs.msg import FilletSpawn, FilletTrackArray
from woody_msgs.srv import SpawnFillet
from woody_sim.camera_description import CAMERA_DEFAULTS, is_camera_file, load_camera
from woody_sim.frame_schedule import FrameSchedule
from woody_sim.line_conditions import (
    MAX_LATERAL_M,
    MAX_YAW_DEG,
    SCALE_RANGE,
    FilletPlacement,
    LineConditions,
    crowding_note,
    line_preset,
    longest_placed_length,
    place_mesh,
    placement_for,
)
from woody_sim.line_geometry import LineGeometry, top_camera_preset
from woody_sim.line_world import MAX_MASS, LineWorld, PhysicsConfig
from woody_sim.loop_phases import PhaseClock
from woody_sim.meshes import MAX_YAW_SD_DEG, FilletMesh, MeshError, checked_mesh_set, load_mesh
from woody_sim.pacing import LeadLimiter
from woody_sim.rendering import RenderProcess, camera_info_fields
from woody_sim.sensor_model import ENCODINGS, sensor_preset, to_message_array
from woody_sim.side_gate import SideFrameGate
from woody_sim.spawn_clearance import SpawnClearance, footprint
from woody_sim.spawn_schedule import SpawnSchedule
from woody_sim.split_world import SplitLineWorld

SENSOR_STREAM = 11
"""Second seed word of the camera error model's random stream (the first is the node's ``seed``)."""
STAMP_STREAM = 13
"""Second seed word of the colour stamps' jitter draws."""
HELD_WARN_S = 1.0
"""A line held this long (wall s) by what it waits for says so on /diagnostics."""
CLOCK_PERIOD = 0.005
"""Sim seconds between /clock messages (200 Hz) besides one per camera frame."""
CHILD_START = "fork"
"""How the render and physics processes start: forked, they begin with this process's modules already imported
(started fresh, each imported pybullet, numba and the renderer again, ~2 s on two busy cores, while the line
waited). They never touch ROS: only numpy, pybullet and the compiled kernels, over a pipe."""


@dataclass
class DrawnFillet:
    """A fillet the line has drawn a placement for, before it is laid on the belt."""

    index: int
    """Its placement draw's index, which becomes its id."""
    mesh: FilletMesh
    placement: FilletPlacement
    placed: FilletMesh
    lane: int
    k: float
    footprint: np.ndarray
    """Its footprint at the spawn point (woody_sim.spawn_clearance.footprint)."""
    waited: bool = False
    """Whether it had to wait for room at the spawn point."""


class LineSim(Node):
    """Publishes /clock, the top RGB-D and side cameras and /line/ground_truth; serves /spawn_fillet."""

    def __init__(self) -> None:
        super().__init__("line_sim")
        p = self._declare_parameters()
        p.__dict__.update(vars(self._declare_line(p.lanes, p.speed_fpm)))
        self.geometry = LineGeometry(lanes=p.lanes, lane_pitch=p.pitch, side_lane=p.side_lane,
                                     **top_camera_preset(p.top_camera))
        self.top_mount = self._declare_top_mount()
        check_overrides(self)  # an unknown parameter is refused before any physics or render process starts
        self._build_line(p)
        self._create_interfaces(p)
        c = self.conditions
        self.summary = (  # logged when the line starts, i.e. once every parameter has been accepted
            f"{p.lanes} lanes at {p.speed_fpm:g} FPM ({self.speed:.3f} m/s), {p.pitch:g} m apart, "
            f"{len(self.meshes)} meshes, k from {self.k_values}, "
            f"M={self.mass:g} kg, physics dt={self.world.config.dt * 1e3:.2f} ms, {self.world.config.n_segments} "
            f"segments, {self.world.config.solver_iterations} solver iterations, top {p.top_rate:g} Hz, "
            f"side {p.side_rate:g} Hz on lane {self.geometry.watched_lane}, top camera model {self.sensor.name}; "
            f"{p.line} line: yaw sd {c.yaw_sd_deg:g} deg (max {c.yaw_max_deg:g}), {c.blunt_fraction:g} blunt end "
            f"first, lateral sd {c.lateral_sd_m:g} m (max {c.lateral_max_m:g}), size x{c.scale_min:g}-"
            f"{c.scale_max:g}, spacing {self._spacing():.3f} m")

    def _declare_parameters(self) -> SimpleNamespace:
        """Declare and check every parameter; the node's own settings become attributes, the rest is returned."""
        lanes = declare(self, "lanes", LANES, "Lanes across the belt.", 1, MAX_LANES)
        speed_fpm = declare(self, "line_speed_fpm", REFERENCE_SPEED_FPM, "Belt speed in feet per minute (100 "
                            "and 130 are the commercial line speeds).", *SPEED_RANGE_FPM)
        self.k_values = [float(k) for k in declare(self, "k_values", list(CLASS_K),
                                                   "Stiffness values (N*m/rad) drawn per spawned fillet.")]
        mesh_spec = declare(self, "meshes", "builtin",
                            "Mesh set: builtin, generated:N[:SEED], a folder; comma-combinable.")
        self.seed = seed = declare(self, "seed", 7, "Seed of the stiffness draw, the fillets' placements "
                                   "(line conditions) and generated meshes.", 0, MAX_SEED)
        self.max_fillets = declare(self, "fillets", 0, "Fillets to spawn in total (0 = no limit).", 0, MAX_FILLETS)
        self.spawn_duration = declare(self, "spawn_duration_s", 0.0, "Stop spawning after this much sim time "
                                      "(0 = no limit).", 0.0, MAX_SPAWN_DURATION_S)
        calibrated = calibrated_defaults(self, "line_sim")  # read once, before declaring; none if given
        self.mass = declare(self, "mass", calibrated["mass"], "Total mass M of a fillet's segment chain (kg); "
                            "a tuning value (config/calibration.yaml, docs/results.md).", 0.1, MAX_MASS)
        damping = declare(self, "damping", calibrated["damping"], "Hinge damping c (N*m*s/rad).", 0.0, 10.0)
        mu_static = declare(self, "friction_static", calibrated["friction_static"], "Coulomb cap of the belt drive "
                            "while a segment holds the belt speed.", 0.0, 10.0)
        mu_dynamic = declare(self, "friction_dynamic", calibrated["friction_dynamic"], "Coulomb cap of the belt drive "
                             "once a segment slips.", 0.0, 10.0)
        workers, recycle = self._declare_workers()
        physics = self._declare_physics()
        top_camera, top_rate = self._declare_top_camera()
        side_rate = declare(self, "side_rate_hz", 60.0, "Side camera frame rate (Hz); 0 disables it.", 0.0,
                            MAX_SIDE_RATE_HZ)
        side_idle = declare(self, "side_idle_rate_hz", 2.0, "Side frame rate while no fillet of the watched lane "
                            "is in its view (frames just after one leaves go at side_rate_hz).", 0.1, 400.0)
        side_lane = declare(self, "side_lane", -1, "Lane the side camera watches (-1 = centre lane).", -1,
                            MAX_LANES - 1)
        self.realtime = declare(self, "realtime", False, "Pace the simulation to the wall clock.")
        self.duration = declare(self, "duration_s", 0.0, "Exit after this much sim time (0 = run until stopped).",
                                0.0, 1e6)
        max_lead = declare(self, "max_lead_s", 0.0, "Hold the simulation while the newest /vision/tracks stamp, or "
                           "with wait_for_recorder the recorder's written clock, lags more than this behind (0 = run "
                           "free); keeps a slower vision graph from losing frames and a slower disk from losing "
                           "messages.", 0.0, 10.0)
        self._declare_start_gate()
        self.sensor_rng = np.random.default_rng([seed, SENSOR_STREAM])
        self.stamp_rng = np.random.default_rng([seed, STAMP_STREAM])
        if not self.k_values or not all(0 <= k < float("inf") for k in self.k_values):
            raise ValueError(f"k_values must be a non-empty list of finite values >= 0, got {self.k_values}")
        if side_lane >= lanes:
            raise ValueError(f"side_lane {side_lane} is not a lane (0..{lanes - 1})")
        return SimpleNamespace(
            lanes=lanes, speed_fpm=speed_fpm, mesh_spec=mesh_spec, seed=seed,
            damping=damping, mu_static=mu_static, mu_dynamic=mu_dynamic, physics=physics, workers=workers,
            recycle=recycle, top_rate=top_rate, side_rate=side_rate, side_idle=side_idle, side_lane=side_lane,
            top_camera=top_camera, max_lead=max_lead)

    def _declare_workers(self) -> tuple[int, int]:
        """The physics worker processes, and after how many fillets each is replaced (woody_sim.split_world)."""
        workers = declare(self, "physics_workers", 1, "Worker processes that share the physics with this one, "
                          "each spawn going to the process with the fewest live fillets (0 = all physics in this "
                          "process; at most the core count).", 0, MAX_PHYSICS_WORKERS)
        recycle = declare(self, "physics_recycle_fillets", 0, "Replace each physics worker process with a fresh one "
                          "after it has taken this many fillets, so that a line running for hours keeps its memory "
                          "flat; the physics then runs in the workers only (0 = never; needs physics_workers >= 1).",
                          0, 1_000_000)
        if recycle and not workers:
            raise ValueError("physics_recycle_fillets needs physics_workers >= 1: only a worker process can be "
                             "replaced")
        return workers, recycle

    def _declare_physics(self) -> dict:
        """The chain's resolution and the physics step: PhysicsConfig fields (docs/physics.md, "What each setting
        costs and what it changes", measures what a coarser one saves and moves)."""
        defaults = PhysicsConfig()
        segments = declare(self, "segments", defaults.n_segments, "Rigid segments N per fillet (the paper's chain: "
                           "40 at 480 Hz; k and c are scaled so that fewer, faster ones bend like it).", 2, 200)
        rate = declare(self, "physics_rate_hz", 1.0 / defaults.dt, "Physics steps per second of sim time (240 lets "
                       "stiff chains whip on the roller).", 240.0, 4800.0)
        iterations = declare(self, "solver_iterations", defaults.solver_iterations, "Contact solver iterations "
                             "per physics step.", 1, 200)
        return {"n_segments": segments, "dt": 1.0 / rate, "solver_iterations": iterations}

    def _declare_top_camera(self) -> tuple[str, float]:
        """The top camera (a preset or a description file) and its frame rate; its error model and colour stamps
        become attributes. A file's frame rate, error model and stamp offsets are the defaults of theirs."""
        top_camera = declare(self, "top_camera", "default", "Top camera: a preset, default (672x376 at 0.75 m) or "
                             "paper (the seed system's 960x696, 86.6 deg, 0.33 m), or a camera description file "
                             "(*.yaml: resolution, intrinsics, distortion, mount, timing; config/cameras/).")
        given = vars(load_camera(top_camera)) if is_camera_file(top_camera) else CAMERA_DEFAULTS
        top_rate = declare(self, "top_rate_hz", given["frame_rate_hz"], "Top-down RGB-D frame rate (Hz).", 1.0,
                           120.0)
        self.sensor = sensor_preset(declare(self, "sensor", given["sensor"], "Top RGB-D camera error model: ideal, "
                                            "stereo or structured_light (docs/sensors.md)."))
        encoding = declare(self, "depth_encoding", given["depth_encoding"] or self.sensor.encoding, "Top depth "
                           "image encoding: 32FC1 (metres) or 16UC1 (steps of depth_unit_m); default the error "
                           "model's.")
        if encoding not in ENCODINGS:
            raise ValueError(f"depth_encoding must be one of {', '.join(ENCODINGS)}, got {encoding!r}")
        self.depth_encoding = encoding
        self.depth_unit_m = declare(self, "depth_unit_m", given["depth_unit_m"], "One step of a 16UC1 depth image "
                                    "(m; REP 118: 0.001).", 1e-5, 0.01)
        self.color_offset_s = declare(self, "color_stamp_offset_s", given["color_stamp_offset_s"], "Colour "
                                      "frames' stamp minus their depth frame's (s), as a driver that does not "
                                      "align them stamps them.", -1.0, 1.0)
        self.color_jitter_s = declare(self, "color_stamp_jitter_s", given["color_stamp_jitter_s"], "Standard "
                                      "deviation of a random part of the colour stamps' offset (s).", 0.0, 0.1)
        return top_camera, top_rate

    def _declare_top_mount(self) -> tuple[np.ndarray, np.ndarray]:
        """The top camera's pose the line puts on tf_static: by default the rendered camera's own; given, what a
        plant's installer measured (``woody camera setup`` writes it), so the vision is set up as on a real line."""
        camera = self.geometry.top_camera()
        own = [float(c) for c in (*camera.position, *Rotation.from_matrix(camera.rotation).as_quat())]
        mount = declare(self, "top_camera_mount", own, "The top camera's pose published on tf_static, [x, y, z, "
                        "qx, qy, qz, qw] in the world frame (m); default the rendered camera's own. The camera "
                        "is rendered where top_camera puts it either way.")
        if len(mount) != 7 or abs(float(np.linalg.norm(mount[3:])) - 1.0) > 1e-3:
            raise ValueError(f"top_camera_mount must be [x, y, z, qx, qy, qz, qw] with a unit quaternion, got {mount}")
        return np.asarray(mount[:3], dtype=float), Rotation.from_quat(mount[3:]).as_matrix()

    def _declare_start_gate(self) -> None:
        """What the line waits for before its first step: the graph that consumes it."""
        self.wait_subscribers = declare(self, "wait_for_subscribers", 0, "Hold the simulation until this many "
                                        "subscribers listen to the top depth image.", 0, 100)
        self.wait_side_subscribers = declare(self, "wait_for_side_subscribers", 0, "... and this many to the side "
                                             "camera image (a grader subscribes once its kernels are warm).", 0, 100)
        self.wait_recorder = declare(self, "wait_for_recorder", "", "... and until the node of this name (a "
                                     "recorder of all topics) subscribes to every topic this node publishes; '' = "
                                     "give late joiners 1 s once the cameras have their subscribers.")

    def _declare_conditions(self) -> tuple[str, LineConditions]:
        """The line preset and the placement parameters, whose defaults are the preset's values: ``line``
        sets all seven, and any given explicitly wins over the preset."""
        name = declare(self, "line", "tidy", "Line conditions preset: tidy (straight, narrow end first, centred, "
                       "one size) or messy (woody_sim.line_conditions.LINE_PRESETS); it sets the defaults of "
                       "yaw_sd_deg .. scale_max, and any of those given explicitly wins.")
        preset = line_preset(name)
        values = {
            "yaw_sd_deg": declare(self, "yaw_sd_deg", preset.yaw_sd_deg, "Per-fillet turn on the belt: sd (deg) of "
                                  "a normal draw truncated at yaw_max_deg (0 = straight).", 0.0, MAX_YAW_SD_DEG),
            "yaw_max_deg": declare(self, "yaw_max_deg", preset.yaw_max_deg, "Largest turn (deg); 0 = 2 x "
                                   f"yaw_sd_deg, at most {MAX_YAW_DEG:g}.", 0.0, MAX_YAW_DEG) or None,
            "blunt_fraction": declare(self, "blunt_fraction", preset.blunt_fraction, "Fraction of fillets sent "
                                      "blunt end first (turned 180 deg about the vertical).", 0.0, 1.0),
            "lateral_sd_m": declare(self, "lateral_sd_m", preset.lateral_sd_m, "Offset of a fillet's centre across "
                                    "its lane: sd (m) of a normal draw truncated at lateral_max_m.", 0.0,
                                    MAX_LATERAL_M),
            "lateral_max_m": declare(self, "lateral_max_m", preset.lateral_max_m, "Largest lateral offset (m), at "
                                     "most half the lane pitch; 0 = 2 x lateral_sd_m.", 0.0, MAX_LATERAL_M) or None,
            "scale_min": declare(self, "scale_min", preset.scale_min, "Smallest size factor s (uniform draw); the "
                                 "chain's mass is mass x s^3.", *SCALE_RANGE),
            "scale_max": declare(self, "scale_max", preset.scale_max, "Largest size factor s.", *SCALE_RANGE),
        }
        return name, LineConditions(**values)

    def _declare_line(self, lanes: int, speed_fpm: float) -> SimpleNamespace:
        """Placement, lane pitch, in-lane spacing and speed change parameters, checked against each other."""
        line, self.conditions = self._declare_conditions()
        pitch = check_lane_pitch(lanes, declare(
            self, "lane_pitch_m", LANE_PITCH_M, "Distance between lane centres across the belt (m); the belt is "
            f"lanes x pitch + {2 * BELT_MARGIN_M:g} m wide, at most {MAX_BELT_WIDTH_M:g} m. The segmenter needs "
            "the same value.", *LANE_PITCH_RANGE_M))
        if self.conditions.lateral_max_m > pitch / 2 + 1e-12:
            raise ValueError(f"lateral_max_m {self.conditions.lateral_max_m:g} m would move fillets out of their "
                             f"lane: at most half the lane pitch, {pitch / 2:g} m")
        spacing = declare(self, "spawn_spacing_m", 0.45, "Belt distance between fillets in a lane (m); down to "
                          f"{MIN_SPAWN_SPACING_M:g} m, where the shortest fillets touch end to end.",
                          MIN_SPAWN_SPACING_M, MAX_SPAWN_SPACING_M)
        top_speed = fpm_to_mps(SPEED_RANGE_FPM[1])
        rate = declare(self, "fillets_per_minute", 0.0, "Spawn rate per lane; overrides spacing when > 0 (at most "
                       f"{MIN_SPAWN_SPACING_M:g} m apart at the line speed).", 0.0, max_fillets_per_minute(top_speed))
        change_fpm = declare(self, "speed_change_fpm", 0.0, "New belt speed (FPM) from speed_change_at_s on; every "
                             "fillet on the belt follows it (0 = no change).", 0.0, SPEED_RANGE_FPM[1])
        change_at = declare(self, "speed_change_at_s", 0.0, "Sim time (s) of the belt speed change.", 0.0,
                            MAX_SPAWN_DURATION_S)
        if 0.0 < change_fpm < SPEED_RANGE_FPM[0]:
            raise ValueError(f"speed_change_fpm must be 0 or within {SPEED_RANGE_FPM[0]:g}..{SPEED_RANGE_FPM[1]:g} "
                             f"FPM, got {change_fpm:g}")
        for fpm in (speed_fpm, change_fpm or speed_fpm):
            _check_rate(rate, fpm)
        return SimpleNamespace(line=line, pitch=pitch, spacing=spacing, rate=rate, change_fpm=change_fpm,
                               change_at=change_at)

    def _build_line(self, p: SimpleNamespace) -> None:
        """The simulated line on ``self.geometry``: physics world, renderer, mesh set, spawn schedule."""
        self.speed = fpm_to_mps(p.speed_fpm)
        config = PhysicsConfig(**p.physics, damping=p.damping, friction_static=p.mu_static,
                               friction_dynamic=p.mu_dynamic)
        self.world = (SplitLineWorld(self.geometry, config, p.workers, start_method=CHILD_START,
                                     recycle_after=p.recycle)
                      if p.workers else LineWorld(self.geometry, config))
        self.top_period = 1.0 / p.top_rate
        self.side_period = 1.0 / p.side_rate if p.side_rate > 0 else None
        # the child processes start (and import) on the other cores while the meshes load here
        self.renderer = RenderProcess(self.geometry, render_top=True, render_side=self.side_period is not None,
                                      start_method=CHILD_START)
        meshes, notes = checked_mesh_set(p.mesh_spec)
        for note in notes:
            self.get_logger().warning(note)
        self.meshes = {m.name: m for m in meshes}
        for mesh in meshes:  # build every chain model now (~0.2 s each), not in the loop at its first spawn
            self.world.model_for(mesh)
        self.spacing_m, self.rate = p.spacing, p.rate
        self.schedule = SpawnSchedule(meshes=meshes, k_values=self.k_values, lanes=p.lanes,
                                      interval_s=self._interval(), seed=p.seed)
        self.spawned = 0
        self.drawn = 0
        """Placements drawn: each fillet's id is its draw's index, so its placement is placement_for(seed, id)."""
        self._waiting: dict[int, deque] = {lane: deque() for lane in range(p.lanes)}
        """Per lane, the scheduled fillets waiting for room at the spawn point, in order."""
        longest = longest_placed_length(meshes, self.conditions)
        self.clearance = SpawnClearance(reach_m=longest)
        self.waited = 0
        """Scheduled fillets that waited for room at the spawn point."""
        self._belt_time = 0.0
        """Sim time up to which the clearance has followed the belt."""
        self._placed: dict[int, tuple] = {}  # fillet id -> (its own placed mesh, its visuals), released on removal
        self.speed_change = (fpm_to_mps(p.change_fpm), p.change_at, p.change_fpm) if p.change_fpm else None
        if self.speed_change:
            self.world.change_speed(self.speed_change[0], p.change_at)
        note = crowding_note(self._spacing(), longest)
        if note:
            self.get_logger().warning(note)
        self.side_gate = SideFrameGate(idle_period_s=1.0 / p.side_idle)

    def _interval(self) -> float:
        """Seconds between spawns in a lane: the rate's, or the spacing at the current belt speed."""
        return 60.0 / self.rate if self.rate > 0 else self.spacing_m / self.speed

    def _spacing(self) -> float:
        """In-lane spacing (m) at the current belt speed."""
        return spacing_at_rate(self.speed, self.rate) if self.rate > 0 else self.spacing_m

    def _create_interfaces(self, p: SimpleNamespace) -> None:
        """Publishers (clock, ground truth, cameras, camera poses), the spawn service and the pacing subscription."""
        latched = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        camera_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.truth_pub = self.create_publisher(FilletSpawn, topics.GROUND_TRUTH, latched)
        self.color_pub = self.create_publisher(Image, topics.TOP_COLOR_IMAGE, camera_qos)
        self.depth_pub = self.create_publisher(Image, topics.TOP_DEPTH_IMAGE, camera_qos)
        self.color_info_pub = self.create_publisher(CameraInfo, "top_camera/color/camera_info", camera_qos)
        self.depth_info_pub = self.create_publisher(CameraInfo, topics.TOP_DEPTH_INFO, camera_qos)
        self.side_pub = self.create_publisher(Image, topics.SIDE_IMAGE, camera_qos)
        self.side_info_pub = self.create_publisher(CameraInfo, "side_camera/camera_info", camera_qos)
        self.top_info = _camera_info(self.geometry.top_camera(), topics.TOP_FRAME)
        self.side_info = _camera_info(self.geometry.side_camera(), topics.SIDE_FRAME)
        self.create_service(SpawnFillet, "spawn_fillet", self.on_spawn_request)
        tf_static = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                               durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.tf_static_pub = self.create_publisher(TFMessage, topics.TF_STATIC, tf_static)
        self._line_publishers = [self.clock_pub, self.truth_pub, self.color_pub, self.depth_pub, self.color_info_pub,
                                 self.depth_info_pub, self.side_pub, self.side_info_pub, self.tf_static_pub]
        self.tf_static_pub.publish(static_transforms(self.geometry, self.top_mount))
        self.pacers: dict[str, LeadLimiter] = {}
        """Consumers the line keeps within max_lead_s of: the segmenter's tracks and, when waited for, the
        recorder's written clock."""
        self.waiting_for = "the line to start"
        """What holds the line now ("" when it runs): /diagnostics and woody run's progress line say it."""
        self._held_since = time.monotonic()
        self._started = (time.monotonic(), 0.0)  # wall and sim time when the line started
        self.diagnostics = DiagnosticsPublisher(self, self.health)
        if p.max_lead > 0:
            self._pace_on("/vision/tracks", p.max_lead, FilletTrackArray, topics.TRACKS,
                          lambda m: m.header.stamp, QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
            if self.wait_recorder:
                self._pace_on("the recorder", p.max_lead, Clock, topics.RECORDED_CLOCK, lambda m: m.clock, 10)

    def health(self) -> Health:
        """A line held longer than `HELD_WARN_S` (a consumer silent, or waiting to start) is a warning that names
        what it waits for; the brief holds of a paced line keeping in step with the vision are not."""
        now = time.monotonic()
        wall = now - self._started[0]
        values = {"sim time (s)": self.world.time, "fillets spawned": self.spawned,
                  "real-time factor": (self.world.time - self._started[1]) / max(wall, 1e-9),
                  "waiting for": self.waiting_for or "nothing"}
        if self.waiting_for and now - self._held_since >= HELD_WARN_S:
            return Health(WARN, f"waiting for {self.waiting_for} ({now - self._held_since:.0f} s)", values)
        return Health(OK, f"running, sim time {self.world.time:.1f} s, {self.spawned} fillets spawned", values)

    def _pace_on(self, name: str, max_lead: float, msg_type, topic: str, stamp_of, qos) -> None:
        pacer = self.pacers[name] = LeadLimiter(max_lead)
        self.create_subscription(msg_type, topic, lambda m: pacer.ack(stamp_to_seconds(stamp_of(m))), qos)

    # ------------------------------------------------------------------ spawning

    def spawn(self, mesh, k: float, lane: int, mass: float, speed: float) -> int:
        """Spawn ``mesh`` now, placed by the line conditions' next draw (see :meth:`_lay`)."""
        return self._lay(self._draw(mesh, lane, k), mass, speed)

    def _draw(self, mesh, lane: int, k: float) -> DrawnFillet:
        """The next placement draw for a fillet of ``mesh`` in ``lane``; its index is the fillet's id."""
        index, self.drawn = self.drawn, self.drawn + 1
        placement = placement_for(self.conditions, self.seed, index)
        placed = place_mesh(mesh, placement)
        shape = footprint(placed.mesh.vertices, self.geometry.spawn_x,
                          self.geometry.lane_y(lane) + placement.lateral_offset_m)
        return DrawnFillet(index, mesh, placement, placed, lane, float(k), shape)

    def _lay(self, fillet: DrawnFillet, mass: float, speed: float) -> int:
        """Lay a drawn fillet on the belt at the spawn point; its chain weighs ``mass`` x scale^3. The ground truth
        carries the placed footprint and the offset position."""
        placement, placed, lane = fillet.placement, fillet.placed, fillet.lane
        mass = mass * placement.scale ** 3
        fillet_id = self.world.spawn(placed, k=fillet.k, lane=lane, mass=mass, speed_mps=speed, fillet_id=fillet.index,
                                     lateral_offset=placement.lateral_offset_m)
        self.clearance.lay(fillet.footprint)
        model = self.world.model(fillet_id)
        self.renderer.add_fillet(fillet_id, lane, model.visuals)
        if placed is not fillet.mesh:
            self._placed[fillet_id] = (placed, model.visuals)
        msg = FilletSpawn(fillet_id=fillet_id, lane=lane, mesh=fillet.mesh.name, stiffness=fillet.k,
                          damping=float(self.world.config.damping), mass=float(mass), line_speed=float(speed),
                          segments=model.n_segments, length=float(placed.length), width=float(placed.width),
                          thickness=float(placed.thickness))
        msg.header = self._header(topics.WORLD_FRAME)
        msg.position.x = float(self.geometry.spawn_x)
        msg.position.y = float(self.geometry.lane_y(lane) + placement.lateral_offset_m)
        self.truth_pub.publish(msg)
        self.spawned += 1
        return fillet_id

    def on_spawn_request(self, request: SpawnFillet.Request, response: SpawnFillet.Response) -> SpawnFillet.Response:
        try:
            mesh = self.meshes.get(request.mesh) or load_mesh(request.mesh)
            fillet_id = self.spawn(mesh, request.stiffness, int(request.lane), request.mass or self.mass,
                                   request.line_speed or self.speed)
        except (MeshError, ValueError) as exc:
            response.success, response.message = False, str(exc)
            self.get_logger().error(f"spawn request refused: {exc}")
            return response
        response.success, response.fillet_id, response.message = True, fillet_id, f"spawned fillet {fillet_id}"
        return response

    def _follow_speed_change(self) -> None:
        """At speed_change_at_s the node's speed (spawns, spacing) follows the belt, which the world changes."""
        if self.speed_change is None or self.world.time + 1e-9 < self.speed_change[1]:
            return
        old = self.speed
        self.speed, at, fpm = self.speed_change
        self.speed_change = None
        self.schedule.interval_s = self._interval()
        self.get_logger().info(f"belt speed {old:.3f} -> {self.speed:.3f} m/s ({fpm:g} FPM) at sim time {at:g} s; "
                               f"in-lane spacing now {self._spacing():.3f} m")

    def _spawn_due(self) -> None:
        """Draw the scheduled fillets, then lay each lane's waiting ones that have room."""
        self.clearance.advance(self.speed * (self.world.time - self._belt_time))
        self._belt_time = self.world.time
        self._follow_speed_change()
        limit_reached = (self.max_fillets and self.drawn >= self.max_fillets) or (
            self.spawn_duration and self.world.time >= self.spawn_duration)
        for mesh, k, lane in ([] if limit_reached else self.schedule.due(self.world.time)):
            if self.max_fillets and self.drawn >= self.max_fillets:
                break
            self._waiting[lane].append(self._draw(mesh, lane, k))
        for queue in self._waiting.values():
            while queue and self.clearance.clear(queue[0].footprint):
                self._lay(queue.popleft(), self.mass, self.speed)
            if queue and not queue[0].waited:
                queue[0].waited = True
                self.waited += 1

    # ------------------------------------------------------------------ publishing

    def _header(self, frame_id: str, stamp: float | None = None) -> Header:
        t = self.world.time if stamp is None else stamp
        return Header(frame_id=frame_id, stamp=seconds_to_stamp(t))

    def _color_stamp(self, stamp: float) -> float:
        """The colour frame's stamp for a depth frame stamped ``stamp`` (never before 0)."""
        if not (self.color_offset_s or self.color_jitter_s):
            return stamp
        return max(0.0, stamp + self.color_offset_s + self.color_jitter_s * float(self.stamp_rng.standard_normal()))

    def _publish_clock(self) -> None:
        msg = Clock()
        msg.clock = self._header("").stamp
        self.clock_pub.publish(msg)

    def _publish_frames(self, frames, stamp: float) -> None:
        if frames.top_rgb is not None and not self.sensor.drop(self.sensor_rng):
            header = self._header(topics.TOP_FRAME, stamp)
            color_header = self._header(topics.TOP_FRAME, self._color_stamp(stamp))
            depth = to_message_array(self.sensor.depth(frames.top_depth, self.sensor_rng), self.depth_encoding,
                                     self.depth_unit_m)
            color = self.sensor.color(frames.top_rgb, self.sensor_rng)
            self.color_pub.publish(serialized_image(color, "rgb8", color_header))
            self.depth_pub.publish(serialized_image(depth, self.depth_encoding, header))
            self.top_info.header = color_header
            self.color_info_pub.publish(self.top_info)
            self.top_info.header = header
            self.depth_info_pub.publish(self.top_info)
        if frames.side_rgb is not None:
            header = self._header(topics.SIDE_FRAME, stamp)
            self.side_pub.publish(serialized_image(frames.side_rgb, "rgb8", header))
            self.side_info.header = header
            self.side_info_pub.publish(self.side_info)

    # ------------------------------------------------------------------ loop

    def spin(self, stop: threading.Event) -> int:
        """Run the line until ``stop`` (SIGINT/SIGTERM) or ``duration_s``; the executor serves the spawn service
        in between."""
        self._stop = stop
        executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        executor.add_node(self)
        self.get_logger().info(self.summary)
        self._wait_for_subscribers(executor)
        frames, next_clock = FrameSchedule(self.top_period, self.side_period), 0.0
        in_flight: deque[float] = deque()  # sim stamps of the frames the renderer is working on, oldest first
        phases = PhaseClock()
        wall_start, sim_start = self._started = time.monotonic(), self.world.time
        self.waiting_for = ""
        while not stop.is_set():
            self._spawn_due()
            phases.lap("spawn")
            now = self.world.step()
            phases.lap("physics")
            self._forget_removed()
            want_top, want_side = frames.due(now)
            if (want_top or want_side) and self._camera_frame(executor, frames, in_flight, now, want_top, want_side,
                                                              phases):
                next_clock = now + CLOCK_PERIOD
            elif now >= next_clock:
                self._publish_clock()
                next_clock = now + CLOCK_PERIOD
            phases.lap("publish")
            if self.realtime:
                ahead = (now - sim_start) - (time.monotonic() - wall_start)
                if ahead > 0.002:
                    time.sleep(ahead)
                phases.lap("pace")
            if self.duration and now >= self.duration:
                break
        while in_flight:
            self._publish_frames(self.renderer.collect(copy=False), in_flight.popleft())
        elapsed = time.monotonic() - wall_start
        self.get_logger().info(f"stopped at sim time {self.world.time:.2f} s after {elapsed:.1f} s wall "
                               f"(rtf {(self.world.time - sim_start) / max(elapsed, 1e-9):.2f}x), "
                               f"{self.spawned} fillets spawned")
        if self.waited:
            waiting = sum(len(queue) for queue in self._waiting.values())
            self.get_logger().info(f"{self.waited} fillets waited for room at the spawn point (no fillet is laid "
                                   f"into another); {waiting} still waiting at the end")
        if isinstance(self.world, SplitLineWorld) and self.world.recycle_after:
            self.get_logger().info(f"physics workers: {self.world.workers_started} started, each replaced after "
                                   f"{self.world.recycle_after} fillets")
        self.get_logger().info(phases.summary())
        executor.remove_node(self)
        return 0

    def _camera_frame(self, executor, frames: FrameSchedule, in_flight: deque, now: float, want_top: bool,
                      want_side: bool, phases: PhaseClock) -> bool:
        """A camera is due: gather the poses, publish the frames the renderer has finished, submit this one
        (False: the side frame was not wanted after all, and nothing went out)."""
        poses = self.world.segment_poses()
        phases.lap("physics_sync")
        self.world.plan(frames.next_time)  # a worker world steps on while this frame goes out
        want_side = want_side and self.side_gate.take(self.renderer.side_view_occupied(poses), now)
        if not (want_top or want_side):
            return False
        if want_top:
            self._hold_for_consumer(executor, now)
            phases.lap("hold_for_vision")
        while in_flight and (self.renderer.ready() or not self.renderer.can_submit):
            frames_done = self.renderer.collect(copy=False)
            phases.lap("render_wait")
            self._publish_frames(frames_done, in_flight.popleft())
        self._publish_clock()
        self.renderer.submit(poses, want_top=want_top, want_side=want_side)
        in_flight.append(now)
        if want_top:  # serve /spawn_fillet at the top camera's rate: a spin costs ~0.5 ms
            phases.lap("publish")
            executor.spin_once(timeout_sec=0.0)
            phases.lap("serve")
        return True

    def _forget_removed(self) -> None:
        """Stop rendering the fillets the world removed; a chain that blew up is worth a warning."""
        for fillet_id in self.world.take_removed():
            self.renderer.remove_fillet(fillet_id)
            placed = self._placed.pop(fillet_id, None)
            if placed is not None:  # a fillet's own mesh: no later spawn uses its model or visuals
                self.world.release(placed[0])
                self.renderer.release(placed[1])
            if fillet_id in self.world.blown_up:
                self.get_logger().warning(f"fillet {fillet_id} removed: its chain blew up numerically "
                                          "(a physics defect: please report it); it will be unscored")

    def _hold_for_consumer(self, executor, now: float) -> None:
        """With max_lead_s: wait (serving callbacks) until every paced consumer has caught up to within the lead."""
        stalls = {name: pacer.stalls for name, pacer in self.pacers.items()}
        self._held_since = time.monotonic()
        while not self._stop.is_set() and any(pacer.must_wait(now) for pacer in self.pacers.values()):
            self.waiting_for = " and ".join(name for name, pacer in self.pacers.items()
                                            if now - pacer.acked > pacer.max_lead_s)
            executor.spin_once(timeout_sec=0.005)
        self.waiting_for = ""
        for name, pacer in self.pacers.items():
            if pacer.stalls > stalls[name] and pacer.stalls == 1:
                self.get_logger().warning(f"{name} silent: running on without it until it answers")

    def _wait_for_subscribers(self, executor) -> None:
        """Hold until the consumers the start-gate parameters name are there (each costs at most a discovery)."""
        wanted = [(p, n) for p, n in ((self.depth_pub, self.wait_subscribers),
                                      (self.side_pub, self.wait_side_subscribers)) if n]
        if not (wanted or self.wait_recorder):
            return
        self.waiting_for = "subscribers: " + ", ".join(
            [f"{n} on {p.topic_name}" for p, n in wanted] + ([f"{self.wait_recorder} on every topic of this node"]
                                                             if self.wait_recorder else []))
        self.get_logger().info(f"waiting for {self.waiting_for}")
        waited = time.monotonic()
        while not self._stop.is_set() and (any(p.get_subscription_count() < n for p, n in wanted)
                                           or not self._recorder_listens()):
            executor.spin_once(timeout_sec=0.02)
        self.get_logger().info(f"subscribers there after {time.monotonic() - waited:.2f} s")
        if self.wait_recorder:
            return
        # Give late joiners (a recorder discovering topics) a moment to subscribe to the rest.
        deadline = time.monotonic() + 1.0
        while not self._stop.is_set() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)

    def _recorder_listens(self) -> bool:
        """The node ``wait_for_recorder`` names subscribes to every topic this node publishes (or none is named)."""
        return not self.wait_recorder or all(
            any(info.node_name == self.wait_recorder for info in self.get_subscriptions_info_by_topic(p.topic_name))
            for p in self._line_publishers)

    def close(self) -> None:
        self.renderer.close()
        self.world.close()


def _check_rate(rate: float, speed_fpm: float) -> None:
    """A spawn rate must keep fillets at least MIN_SPAWN_SPACING_M apart at the belt speed (one line if not)."""
    speed = fpm_to_mps(speed_fpm)
    if rate > 0 and spacing_at_rate(speed, rate) < MIN_SPAWN_SPACING_M - 1e-12:
        raise ValueError(f"fillets_per_minute {rate:g} at {speed_fpm:g} FPM puts fillets "
                         f"{spacing_at_rate(speed, rate):.3f} m apart, closer than {MIN_SPAWN_SPACING_M:g} m: at "
                         f"most {max_fillets_per_minute(speed):.0f} per minute")


def _transform(child: str, position, rotation) -> TransformStamped:
    """``child`` in the world frame: its origin at ``position`` (m), its axes the columns of ``rotation``."""
    transform = TransformStamped()
    transform.header.frame_id, transform.child_frame_id = topics.WORLD_FRAME, child
    t = transform.transform.translation
    t.x, t.y, t.z = (float(c) for c in position)
    q = transform.transform.rotation
    q.x, q.y, q.z, q.w = (float(c) for c in Rotation.from_matrix(np.asarray(rotation, dtype=float)).as_quat())
    return transform


def static_transforms(geometry: LineGeometry, top_mount: tuple[np.ndarray, np.ndarray] | None = None) -> TFMessage:
    """The line's fixed frames for /tf_static: the roller axle, the top camera's optical frame (at ``top_mount``,
    position and rotation, if given) and the side camera's in the world."""
    axle_x, axle_z = geometry.roller_axle
    top, side = geometry.top_camera(), geometry.side_camera()
    return TFMessage(transforms=[_transform(topics.ROLLER_FRAME, (axle_x, 0.0, axle_z), np.eye(3)),
                                 _transform(topics.TOP_FRAME, *(top_mount or (top.position, top.rotation))),
                                 _transform(topics.SIDE_FRAME, side.position, side.rotation)])


def _camera_info(camera, frame_id: str) -> CameraInfo:
    fields = camera_info_fields(camera)
    info = CameraInfo(width=fields["width"], height=fields["height"], distortion_model=fields["distortion_model"])
    info.k, info.p, info.r, info.d = fields["K"], fields["P"], fields["R"], fields["D"]
    info.header.frame_id = frame_id
    return info


def main(args: list[str] | None = None) -> None:
    sys.exit(run_node("line_sim", LineSim, args))


if __name__ == "__main__":
    main()
