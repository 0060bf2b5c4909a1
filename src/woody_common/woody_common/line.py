"""The line's numbers that the simulator, the vision nodes and the tools all need.

The simulator builds its geometry from them (`woody_sim.line_geometry`), and the
vision nodes take them as parameter defaults, so a vision-only host on a real
line reads them without pybullet. tests/woody_common/test_line.py checks that the side
camera's pixel values are the ones the simulator's geometry projects.
"""

import os

FPM_TO_MPS = 0.3048 / 60.0
"""Feet per minute to metres per second (100 FPM = 0.508 m/s); convert with :func:`fpm_to_mps` and
:func:`mps_to_fpm`."""

SPEED_RANGE_FPM = (1.0, 400.0)
"""Line speeds every entry point accepts (woody run, line_sim, reject_gate, LineWorld in m/s), inclusive."""
PAPER_SPEEDS_FPM = (100.0, 130.0)
"""The paper's two commercial line speeds (its tables, the sweep's and calibration's default speeds)."""
NORMAL_K = 0.0
SEVERE_K = 100.0
"""Hinge stiffness (N m/rad) of the paper's two classes, normal and severe woody breast: the reject decision is
fitted and scored on them, and a line mixes them by default."""
CLASS_K = (NORMAL_K, SEVERE_K)
MAX_LANES = 6
"""Most lanes any entry point accepts (lanes 1..MAX_LANES; a side lane -1 = centre, or 0..MAX_LANES - 1)."""
PAPER_SEGMENTS = 40
"""Slices of the paper's chain; its k and c are per hinge of it (woody_sim.line_world.PhysicsConfig.hinge_scale)."""
PAPER_PHYSICS_RATE_HZ = 480.0
"""Physics steps per second of sim time the paper's chain was validated at (docs/physics.md)."""
MAX_PHYSICS_WORKERS = 64
"""The most physics worker processes a line starts (woody_sim.split_world); :func:`physics_worker_limit` also caps
them at the core count."""
MAX_SIDE_RATE_HZ = 400.0
"""Fastest side camera line_sim and woody run accept (0 turns it off)."""
MAX_SPAWN_DURATION_S = 1e6
"""Longest spawning time (sim seconds) line_sim and woody run accept."""
MAX_FILLETS = 100_000
"""Most fillets one line_sim or woody run spawns."""
MAX_SEED = 2**31 - 1
"""Largest seed line_sim and woody run accept (seeds are 0..MAX_SEED)."""

LANES = 3
LANE_PITCH_M = 0.16
"""Distance between lane centres across the belt (the default of line_sim's and the segmenter's lane_pitch_m)."""
MIN_LANE_PITCH_M = 0.08
"""Closest lanes line_sim accepts: the narrowest fillets (0.094 m wide) at the smallest size (x0.85) touch
their neighbours side by side there; wider fillets overlap them (fillets do not collide)."""
BELT_MARGIN_M = 0.08
"""Belt width beyond the outer lane centres' pitch, each side."""
MAX_BELT_WIDTH_M = 1.2
"""Widest belt (lanes x pitch + both margins) accepted: a wide processing-line belt, within the default top
camera's 1.37 m view across the belt."""
LANE_PITCH_RANGE_M = (MIN_LANE_PITCH_M, MAX_BELT_WIDTH_M - 2.0 * BELT_MARGIN_M)
"""The lane_pitch_m line_sim and the segmenter accept: closest lanes to one lane on the widest belt."""

MIN_SPAWN_SPACING_M = 0.15
"""Closest in-lane spacing (belt distance between consecutive fillets' spawns) line_sim accepts: the shortest
meshes (0.17 m) at the smallest messy size (x0.85) touch end to end there; the builtin meshes (0.18-0.19 m)
touch at their length and the longest generated one at the largest size (0.208 m x 1.15) at 0.24 m. Closer
spacing overlaps every fillet (fillets do not collide), so it is refused."""
MAX_SPAWN_SPACING_M = 10.0

TOP_CAMERA_HEIGHT_M = 0.75
"""Default top camera: nadir, this high above the belt."""
TOP_EDGE_OFFSET_M = 0.20
"""Its optical axis sits this far upstream of the roller edge."""
STRAIGHT_DOWN_AXES = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0))
"""A top camera looking straight down with image rows downstream: its optical axes (the matrix's columns) in the
belt frame (REP 103 world: x downstream, y to lane 0, z up). Optical x = world +y, y = world +x, z = world -z."""
MOUNT_EULER = "YXZ"
"""How a mount's angles turn a straight-down camera (SciPy's intrinsic Euler order, angles (-tilt, roll, yaw)):
about the vertical first, then leaned, so tilt (towards downstream) and roll (towards lane 0) are the optical
axis's lean in the belt frame."""
DEPTH_UNIT_M = 0.001
"""What one step of a 16UC1 depth image is (REP 118: millimetres); a camera whose driver counts otherwise says so
(line_sim's and the segmenter's ``depth_unit_m``)."""
MAX_CAMERA_TILT_DEG = 20.0
"""The most a top camera may lean from straight down: further, the parallax of a fillet's height grows past a few
pixels and the far side of the belt falls off the sharp part of the image (the twin refuses to render it, the
vision to take it)."""

SIDE_AXLE_PX = (480.0, 348.0)
"""(u, v) of the roller axle in the 960 x 696 side image (the image is centred on the axle)."""
ROLLER_RADIUS_M = 0.0207
"""The seed system's end roller (the simulator's roller, woody_sim.line_geometry.LineGeometry)."""
SIDE_ROLLER_RADIUS_PX = 48.0
"""ROLLER_RADIUS_M at the side camera's 0.431 mm/px (the paper's system)."""


def fpm_to_mps(speed_fpm: float) -> float:
    """Convert the user-facing line speed in feet per minute to m/s."""
    return float(speed_fpm) * FPM_TO_MPS


def mps_to_fpm(speed_mps: float) -> float:
    """Convert a belt speed in m/s (ground truth, the simulator) to feet per minute."""
    return float(speed_mps) / FPM_TO_MPS


def watched_lane(lanes: int, side_lane: int = -1) -> int:
    """The lane the side camera watches: ``side_lane``, or the centre lane when it is -1 (the paper's camera)."""
    return (lanes - 1) // 2 if side_lane < 0 else side_lane


def belt_width_m(lanes: int, lane_pitch_m: float) -> float:
    """Width of a belt carrying ``lanes`` lanes ``lane_pitch_m`` apart."""
    return lanes * float(lane_pitch_m) + 2.0 * BELT_MARGIN_M


def check_lane_pitch(lanes: int, lane_pitch_m: float) -> float:
    """The lane pitch if ``lanes`` lanes that far apart fit the widest belt, else one ValueError line."""
    pitch = float(lane_pitch_m)
    if not MIN_LANE_PITCH_M <= pitch:
        raise ValueError(f"lane pitch must be at least {MIN_LANE_PITCH_M:g} m, got {lane_pitch_m!r}")
    if belt_width_m(lanes, pitch) > MAX_BELT_WIDTH_M + 1e-9:
        widest = (MAX_BELT_WIDTH_M - 2.0 * BELT_MARGIN_M) / lanes
        raise ValueError(f"{lanes} lanes {pitch:g} m apart need a {belt_width_m(lanes, pitch):.3f} m belt, wider "
                         f"than {MAX_BELT_WIDTH_M:g} m: use a lane pitch of at most {widest:.3f} m")
    return pitch


def spacing_at_rate(speed_mps: float, fillets_per_minute: float) -> float:
    """In-lane spacing (m) of fillets spawned ``fillets_per_minute`` per lane on a belt at ``speed_mps``."""
    return 60.0 * float(speed_mps) / float(fillets_per_minute)


def max_fillets_per_minute(speed_mps: float) -> float:
    """Highest spawn rate per lane that keeps MIN_SPAWN_SPACING_M at this belt speed."""
    return 60.0 * float(speed_mps) / MIN_SPAWN_SPACING_M


REFERENCE_SPEED_FPM = 100.0
"""The paper's line speed: the default of every entry point, and where a speed-dependent cut takes its base."""
REFERENCE_SPEED_MPS = fpm_to_mps(REFERENCE_SPEED_FPM)
MAX_SPEED_MPS = fpm_to_mps(SPEED_RANGE_FPM[1])
"""The fastest belt in m/s (the simulator refuses a faster one as a unit mistake)."""

MAX_FILLET_WIDTH_M = 0.13
"""The widest a single fillet lies across the flow when straight (generated widths reach 0.11 m, sizes x1.15):
a blob wider than this may be two fillets side by side (the segmenter checks it by height)."""
MAX_FILLET_AREA_M2 = 0.025
"""The most belt a single fillet covers seen from above (the meshes' footprints reach 168 cm², 222 cm² at the messy
line's largest size, x1.15): a blob wider than MAX_FILLET_WIDTH_M that covers more than this is surely fillets side
by side, and the segmenter splits it however little their heights part them."""
MAX_FILLET_LENGTH_M = 0.30
"""The longest a single fillet lies along the flow (on the messy line the built-in and generated meshes span 0.27 m
at most, large and turned): a blob longer than this is two fillets touching end to end (the segmenter splits it by
height)."""


def physics_worker_limit() -> int:
    """The most physics worker processes this machine runs: one per core (more only add switching), at most
    MAX_PHYSICS_WORKERS."""
    return min(os.cpu_count() or 1, MAX_PHYSICS_WORKERS)
