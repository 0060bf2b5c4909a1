"""The line's numbers that the simulator, the vision nodes and the tools all need.

The simulator builds its geometry from them (`woody_sim.line_geometry`), and the
vision nodes take them as parameter defaults, so a vision-only host on a real
line reads them without pybullet. tests/test_line.py checks that the side
camera's pixel values are the ones the simulator's geometry projects.
"""

FPM_TO_MPS = 0.3048 / 60.0
"""Feet per minute to metres per second (100 FPM = 0.508 m/s)."""

SPEED_RANGE_FPM = (1.0, 400.0)
"""Line speeds every entry point accepts (woody run, line_sim, reject_gate), inclusive."""
MAX_SIDE_RATE_HZ = 400.0
"""Fastest side camera line_sim and woody run accept (0 turns it off)."""
MAX_SPAWN_DURATION_S = 1e6
"""Longest spawning time (sim seconds) line_sim and woody run accept."""

LANES = 3
LANE_PITCH_M = 0.16
"""Distance between lane centres across the belt."""

TOP_CAMERA_HEIGHT_M = 0.75
"""Default top camera: nadir, this high above the belt."""
TOP_EDGE_OFFSET_M = 0.20
"""Its optical axis sits this far upstream of the roller edge."""

SIDE_AXLE_PX = (480.0, 348.0)
"""(u, v) of the roller axle in the 960 x 696 side image (the image is centred on the axle)."""
SIDE_ROLLER_RADIUS_PX = 48.0
"""The 20.7 mm end roller at the side camera's 0.431 mm/px (seed-system.md, Cameras)."""


def fpm_to_mps(speed_fpm: float) -> float:
    """Convert the user-facing line speed in feet per minute to m/s."""
    return float(speed_fpm) * FPM_TO_MPS


REFERENCE_SPEED_FPM = 100.0
"""The paper's line speed: the default of every entry point, and where a speed-dependent cut takes its base."""
REFERENCE_SPEED_MPS = REFERENCE_SPEED_FPM * FPM_TO_MPS
