"""Physics alone: wall ms per step and simulated seconds per wall second with N fillets on the line."""

from __future__ import annotations

import math
import time

from woody_common.calibration import resolved_calibration
from woody_common.line import REFERENCE_SPEED_FPM, fpm_to_mps
from woody_sim.line_world import LineWorld, PhysicsConfig, calibrated_config
from woody_sim.meshes import generate_fillet


def benchmark_physics(
    n_fillets: int, seconds: float, config: PhysicsConfig | None = None, aligned: bool = False
) -> dict:
    """Time the physics alone: ``n_fillets`` on the line at 100 FPM, one per lane, respawned as they fall.

    By default the fillets enter staggered along the belt, the way a running
    line spreads out the roller crossings (the expensive part); ``aligned``
    spawns them side by side so all cross the roller together (worst case).
    Returns wall ms per step, CPU seconds per simulated second, simulated
    seconds per wall second, and the wall ms of the steps in which every
    fillet is a live chain at the roller (the peak load).
    """
    if n_fillets < 1 or seconds <= 0.0:
        raise ValueError("benchmark needs n_fillets >= 1 and seconds > 0")
    calibration = resolved_calibration()
    world = LineWorld(config=config or calibrated_config(calibration))
    mass = calibration.total_mass_kg
    try:
        speed = fpm_to_mps(REFERENCE_SPEED_FPM)
        meshes = [generate_fillet(seed) for seed in range(3)]
        stiffness = (0.0, 100.0, 400.0)
        lanes = world.geometry.lanes
        travel = -world.geometry.spawn_x / speed
        pending = {slot: 0.0 if aligned else slot * travel / n_fillets for slot in range(n_fillets)}
        slots: dict[int, int] = {}
        steps = max(1, int(round(seconds / world.config.dt)))
        busy_time, busy_steps = 0.0, 0
        wall0, cpu0 = time.perf_counter(), time.process_time()
        for _ in range(steps):
            for slot, when in list(pending.items()):
                if world.time >= when:
                    fid = world.spawn(meshes[slot % 3], stiffness[slot % 3], slot % lanes, mass, speed)
                    slots[fid] = slot
                    del pending[slot]
            busy = len(world.fillets) == n_fillets and all(world.is_dynamic(fid) for fid in world.fillets)
            tick = time.perf_counter()
            world.step()
            if busy:
                busy_time += time.perf_counter() - tick
                busy_steps += 1
            for fid in world.take_removed():
                pending[slots.pop(fid)] = world.time
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        sim = steps * world.config.dt
        return {
            "n_fillets": n_fillets,
            "aligned": aligned,
            "sim_seconds": sim,
            "steps": steps,
            "ms_per_step": 1000.0 * wall / steps,
            "cpu_s_per_sim_s": cpu / sim,
            "sim_s_per_wall_s": sim / wall,
            "ms_per_step_all_crossing": 1000.0 * busy_time / busy_steps if busy_steps else math.nan,
        }
    finally:
        world.close()
