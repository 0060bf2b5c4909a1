"""Validate the production step against a small-step reference, over meshes, masses and k (docs/physics.md).

For each mesh, total mass M and stiffness k, one fillet rides to the roller
edge and falls; the centre-of-mass trajectory and the total bend angle (sum
of hinge angles) are sampled every 5 ms and compared with the reference run:
the same formulation at a step ten times smaller or more (``--ref-dt``). With
the calibrated damper (c = 0.1-0.2 N m s/rad) an explicit spring-damper would
need a step below 1e-7 s on the lightest tip slices (2 I / c), so the reference
is the implicit hinge at a small step, whose error vanishes with the step.

    .venv/bin/python tools/validate_physics.py [--meshes builtin] [--masses 5 20 100] [--ks 0 100 400]

Also reported: the reference against itself at half its step (is it
converged?), and the production run with and without the flat-belt fast path
(is the kinematic ride exact?). MDM is the closest approach of the centre of
mass to the roller axle (the side camera's metric, in 3-D); kink is the
largest zig-zag between neighbouring hinges (mean and max over the run).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from woody_common.line import fpm_to_mps
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, PhysicsConfig, calibrated_config
from woody_sim.meshes import load_mesh_set

SAMPLE = 0.005
"""Seconds between compared samples."""


def trajectory(mesh, k: float, mass: float, config: PhysicsConfig, speed: float,
               duration: float) -> tuple[np.ndarray, float]:
    """(T, 6) rows of [t, com_x, com_y, com_z, bend, kink] on a SAMPLE grid (linear interpolation), and the wall time.

    kink = the largest second difference of the hinge angles along the chain
    (rad), a measure of zig-zag between neighbouring segments.
    """
    world = LineWorld(geometry=LineGeometry(spawn_x=-0.15), config=config)
    fid = world.spawn(mesh, k, 1, mass, speed)
    every = max(1, int(SAMPLE / config.dt / 10))
    rows = []
    start = time.perf_counter()
    step = 0
    while fid in world.fillets and world.time < duration:
        if step % every == 0:
            theta = world.hinge_angles(fid)
            kink = np.abs(theta[1:-1] - 0.5 * (theta[:-2] + theta[2:])).max()
            rows.append((world.time, *world.center_of_mass(fid), float(theta.sum()), kink))
        world.step()
        step += 1
    wall = time.perf_counter() - start
    world.close()
    rows = np.asarray(rows)
    grid = np.arange(0.0, rows[-1, 0], SAMPLE)
    return np.column_stack([grid] + [np.interp(grid, rows[:, 0], rows[:, i]) for i in range(1, 6)]), wall


def compare(ref: np.ndarray, cand: np.ndarray) -> dict:
    n = min(len(ref), len(cand))
    ref, cand = ref[:n], cand[:n]
    com_err = np.linalg.norm(ref[:, 1:4] - cand[:, 1:4], axis=1)
    bend_err = np.degrees(np.abs(ref[:, 4] - cand[:, 4]))
    return {
        "com_max_mm": 1000 * com_err.max(),
        "com_rms_mm": 1000 * np.sqrt((com_err**2).mean()),
        "bend_max_deg": bend_err.max(),
        "bend_rms_deg": np.sqrt((bend_err**2).mean()),
        "mdm_err_mm": 1000 * abs(mdm(ref) - mdm(cand)),
        "kink_mean_deg": np.degrees(cand[:, 5].mean()),
        "kink_max_deg": np.degrees(cand[:, 5].max()),
    }


def mdm(rows: np.ndarray) -> float:
    """Closest approach (m) of the centre of mass to the roller axle at (x, z) = (0, -R)."""
    return float(np.hypot(rows[:, 1], rows[:, 3] + LineGeometry().roller_radius).min())


def row(case: str, label: str, m: dict, wall: float) -> str:
    return (
        f"| {case} | {label} | {m['com_max_mm']:.1f} | {m['com_rms_mm']:.1f} | {m['bend_max_deg']:.1f} | "
        f"{m['bend_rms_deg']:.1f} | {m['mdm_err_mm']:.2f} | "
        f"{m['kink_mean_deg']:.2f} / {m['kink_max_deg']:.1f} | {wall:.1f} |"
    )


def validate(mesh, mass: float, k: float, args: argparse.Namespace) -> None:
    """Print the table rows of one (mesh, M, k): the reference, its convergence, each production rate."""
    speed = fpm_to_mps(args.fpm)
    ref_cfg = calibrated_config(dt=args.ref_dt)
    ref, ref_wall = trajectory(mesh, k, mass, ref_cfg, speed, args.duration)
    label = f"{mesh.name} | {mass:g} | {k:g}"
    print(f"| {label} | reference | MDM {1000 * mdm(ref):.1f} mm, max bend {np.degrees(np.abs(ref[:, 4]).max()):.0f} "
          f"deg | | | | | {np.degrees(ref[:, 5].mean()):.2f} / {np.degrees(ref[:, 5].max()):.1f} | {ref_wall:.0f} |",
          flush=True)
    if args.converge:
        half, wall = trajectory(mesh, k, mass, calibrated_config(dt=args.ref_dt / 2), speed, args.duration)
        print(row(label, "reference at dt/2", compare(ref, half), wall), flush=True)
    for rate in args.rates:
        cand, wall = trajectory(mesh, k, mass, calibrated_config(dt=1.0 / rate), speed, args.duration)
        print(row(label, f"{rate:.0f} Hz", compare(ref, cand), wall), flush=True)
    if args.converge:
        fast, _ = trajectory(mesh, k, mass, calibrated_config(), speed, args.duration)
        full, wall = trajectory(mesh, k, mass, calibrated_config(activation_margin=None), speed, args.duration)
        print(row(label, "no fast path vs fast path", compare(full, fast), wall), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--meshes", default="builtin", help="mesh set; the first --n-meshes are used")
    parser.add_argument("--n-meshes", type=int, default=3)
    parser.add_argument("--masses", type=float, nargs="+", default=[5.0, 20.0, 100.0])
    parser.add_argument("--ks", type=float, nargs="+", default=[0.0, 100.0, 400.0])
    parser.add_argument("--rates", type=float, nargs="+", default=[240.0, 480.0])
    parser.add_argument("--ref-dt", type=float, default=1e-4)
    parser.add_argument("--duration", type=float, default=0.8, help="simulated seconds per run")
    parser.add_argument("--fpm", type=float, default=100.0)
    parser.add_argument("--converge", action="store_true", help="also the reference at dt/2 and the fast-path check")
    args = parser.parse_args()
    meshes = load_mesh_set(args.meshes)[0][: args.n_meshes]
    print(f"{args.fpm:.0f} FPM, reference: the production formulation at dt = {args.ref_dt:g} s")
    print("| mesh | M (kg) | k | run | COM max err (mm) | COM RMS err (mm) | bend max err (deg) | bend RMS err (deg) "
          "| MDM err (mm) | kink mean / max (deg) | wall (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for mesh in meshes:
        for mass in args.masses:
            for k in args.ks:
                validate(mesh, mass, k, args)


if __name__ == "__main__":
    main()
