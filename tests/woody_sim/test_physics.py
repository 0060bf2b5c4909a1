"""The chain model and the pybullet line: masses, drive, stiffness contrast, removal, validation, stability."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from woody_common.calibration import resolved_calibration
from woody_sim.fillet_model import SegmentVisual, build_fillet_model, slab_volumes
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import (
    PAPER_PHYSICS,
    LineWorld,
    PhysicsConfig,
    calibrated_config,
    hinge_state,
    segment_inertias,
)
from woody_sim.meshes import BUILTIN_DIR, FilletMesh, load_mesh

MASS = resolved_calibration().total_mass_kg
SPEED = 0.508  # 100 FPM
NEAR_EDGE = LineGeometry(spawn_x=-0.15)
"""Spawn close to the roller so the tests spend their time where the physics happens."""


@pytest.fixture(scope="module")
def fillet() -> FilletMesh:
    """A reference mesh, so these tests do not change whenever the generator does."""
    return load_mesh(BUILTIN_DIR / "seed0000.obj")


def run_to_the_floor(world: LineWorld, fid: int, limit: float = 3.0) -> np.ndarray:
    """Step until the fillet is removed; rows of [t, com_x, com_y, com_z, max |v|, max |hinge rate|]."""
    rows = []
    while fid in world.fillets and world.time < limit:
        world.step()
        if fid in world.fillets:
            state = world._fillets[fid].state
            assert np.isfinite(state).all()
            rate = hinge_state(state)[1]
            rows.append((world.time, *world.center_of_mass(fid), np.abs(state[:, 7:10]).max(), np.abs(rate).max()))
    return np.asarray(rows)


def test_masses_follow_the_slab_volumes(fillet: FilletMesh) -> None:
    model = build_fillet_model(fillet, n_segments=40, total_mass=20.0)
    assert model.n_segments == 40 and len(model.visuals) == 40
    assert model.masses.sum() == pytest.approx(20.0, rel=1e-12)
    volumes = slab_volumes(fillet.height_map, model.edges)
    assert volumes.sum() == pytest.approx(fillet.height_map.heights.sum() * fillet.height_map.pixel**2, rel=1e-9)
    assert model.masses / volumes == pytest.approx(np.full(40, 20.0 / volumes.sum()), rel=1e-9)
    box = 8.0 * model.box_half_extents.prod(axis=1)
    assert np.all(volumes <= box * 1.001), "a slab holds no more than its bounding box"
    assert model.masses[20] > 5 * model.masses[-1]  # the tip is light, the body heavy
    assert model.with_mass(5.0).masses == pytest.approx(model.masses / 4.0)


def test_segment_visuals_are_small_closed_pieces_in_the_segment_frames(fillet: FilletMesh) -> None:
    model = build_fillet_model(fillet)
    for visual, _centre, half in zip(model.visuals, model.box_centers, model.box_half_extents):
        assert isinstance(visual, SegmentVisual)
        assert visual.vertices.dtype == np.float32 and visual.faces.dtype == np.int32
        assert 100 <= len(visual.faces) <= 300
        assert np.all(np.abs(visual.vertices) <= half + 1e-6)  # inside the collision box, about its centre
    pieces = np.vstack([v.vertices + c for v, c in zip(model.visuals, model.box_centers)])
    assert pieces.min(axis=0) == pytest.approx(fillet.mesh.bounds[0], abs=1.5e-3)
    assert pieces.max(axis=0) == pytest.approx(fillet.mesh.bounds[1], abs=1.5e-3)


def test_segment_poses_and_hinge_angles_match_pybullet(fillet: FilletMesh) -> None:
    with LineWorld(geometry=NEAR_EDGE) as world:
        fid = world.spawn(fillet, 0.0, 2, MASS, SPEED)
        while not world.is_dynamic(fid) or world.center_of_mass(fid)[0] < 0.02:
            world.step()
        poses = world.segment_poses()[fid]
        n = PhysicsConfig().n_segments
        assert poses.shape == (n, 7)
        assert np.linalg.norm(poses[:, 3:], axis=1) == pytest.approx(np.ones(n))
        body = world._fillets[fid].body
        joints = p.getJointStates(body, list(range(n - 1)), physicsClientId=world._fillets[fid].physics.client)
        assert world.hinge_angles(fid) == pytest.approx([j[0] for j in joints], abs=1e-9)
        assert world.hinge_angles(fid).sum() > 0.3  # the tip hangs down over the roller
        base = p.getBasePositionAndOrientation(body, physicsClientId=world._fillets[fid].physics.client)
        assert poses[0, :3] == pytest.approx(base[0]) and poses[0, 3:] == pytest.approx(base[1])


def test_drive_holds_flat_belt_segments_at_line_speed(fillet: FilletMesh) -> None:
    config = PhysicsConfig(activation_margin=None)  # full physics on the belt, no fast path
    with LineWorld(config=config) as world:
        fid = world.spawn(fillet, 100.0, 0, MASS, SPEED)
        start = world.center_of_mass(fid)
        worst = 0.0
        for _ in range(int(0.4 / config.dt)):
            world.step()
            worst = max(worst, np.abs(world.segment_velocities(fid)[:, 0] - SPEED).max())
        assert worst < 0.01 * SPEED
        travelled = world.center_of_mass(fid) - start
        assert travelled[0] == pytest.approx(SPEED * world.time, rel=0.01)
        assert abs(travelled[1]) < 1e-3 and abs(travelled[2]) < 1e-3


def test_stiff_fillet_projects_further_than_a_compliant_one(fillet: FilletMesh) -> None:
    """The side view's premise: k = 100 holds its shape past the edge, k = 0 drapes."""
    results = {}
    for k in (0.0, 100.0):
        with LineWorld(geometry=NEAR_EDGE) as world:
            fid = world.spawn(fillet, k, 1, MASS, SPEED)
            rows = run_to_the_floor(world, fid)
        crossing = rows[np.argmax(rows[:, 1] > 0.0), 0]
        later = rows[np.argmin(np.abs(rows[:, 0] - crossing - 0.2))]
        soon = rows[np.argmin(np.abs(rows[:, 0] - crossing - 0.1))]
        axle_distance = np.hypot(rows[:, 1], rows[:, 3] + world.geometry.roller_radius).min()
        results[k] = (later[1], soon[3], axle_distance)
    assert results[100.0][0] - results[0.0][0] > 0.02  # 20 mm further downstream 0.2 s after crossing
    assert results[100.0][1] - results[0.0][1] > 0.008  # and higher 0.1 s after crossing
    assert results[100.0][2] - results[0.0][2] > 0.005  # the centre of mass never gets as close to the axle


@pytest.mark.parametrize("k", [0.0, 400.0])
def test_chain_is_stable_over_the_roller_and_fallen_fillets_are_removed(fillet: FilletMesh, k: float) -> None:
    with LineWorld(geometry=NEAR_EDGE) as world:
        fid = world.spawn(fillet, k, 1, MASS, SPEED)
        rows = run_to_the_floor(world, fid)
        assert fid not in world.fillets and world.take_removed() == [fid]
        assert world.take_removed() == [] and world.segment_poses() == {}
    assert rows[-1, 3] < world.geometry.remove_z + 0.05  # removed because it fell, not because it blew up
    assert rows[:, 4].max() < 4.0  # no segment faster than a 0.4 m free fall allows
    assert rows[:, 5].max() < 40.0  # no hinge whipping


@pytest.mark.parametrize("settings", [{"slice_shape": "capsule"}, {"island_sleeping": True}])
def test_the_settings_tables_other_contacts_and_sleeping_still_carry_a_chain_over_the_roller(
        fillet: FilletMesh, settings: dict) -> None:
    with LineWorld(geometry=NEAR_EDGE, config=PhysicsConfig(**settings)) as world:
        fid = world.spawn(fillet, 0.0, 1, MASS, SPEED)
        rows = run_to_the_floor(world, fid)
        assert fid not in world.fillets and world.take_removed() == [fid]
    assert rows[-1, 3] < world.geometry.remove_z + 0.05 and rows[:, 4].max() < 4.0


def test_ids_are_unique_and_metadata_is_kept(fillet: FilletMesh) -> None:
    with LineWorld() as world:
        a = world.spawn(fillet, 0.0, 0, 20.0, SPEED)
        b = world.spawn(fillet, 100.0, 2, 30.0, 0.66, fillet_id=7)
        c = world.spawn(fillet, 10.0, 1, 20.0, SPEED)
        assert len({a, b, c}) == 3 and b == 7 and c > 7
        info = world.fillets[b]
        assert (info.lane, info.mesh_name, info.k, info.mass, info.speed_mps) == (2, fillet.name, 100.0, 30.0, 0.66)
        assert world.model(b).total_mass == pytest.approx(30.0)
        world.remove(a)
        assert world.take_removed() == [a] and a not in world.segment_poses()


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"k": -1.0}, "stiffness k"),
        ({"k": math.nan}, "stiffness k"),
        ({"mass": 0.0}, "mass"),
        ({"mass": math.inf}, "mass"),
        ({"speed_mps": 0.0}, "speed"),
        ({"speed_mps": 30.0}, "speed"),
        ({"lane": 3}, "lane"),
        ({"lane": -1}, "lane"),
        ({"lane": 1.5}, "lane"),
        ({"fillet_id": -2}, "fillet_id"),
    ],
)
def test_bad_spawn_parameters_raise_value_error(fillet: FilletMesh, kwargs: dict, reason: str) -> None:
    args = {"mesh": fillet, "k": 10.0, "lane": 0, "mass": 20.0, "speed_mps": SPEED} | kwargs
    with LineWorld() as world:
        with pytest.raises(ValueError, match=reason):
            world.spawn(**args)
        fid = world.spawn(fillet, 10.0, 0, 20.0, SPEED)
        with pytest.raises(ValueError, match="already on the line"):
            world.spawn(fillet, 10.0, 1, 20.0, SPEED, fillet_id=fid)


def test_a_fillet_spawned_late_with_its_spawn_time_moves_as_if_spawned_then(fillet: FilletMesh) -> None:
    """A worker world hears of its spawns a few steps late (split_world): placed where the belt has carried it,
    the fillet is bit for bit the one spawned on time, over the roller too."""
    runs = []
    for late in (0, 7):
        with LineWorld(NEAR_EDGE) as world:
            for _ in range(3 + late):
                world.step()
            fid = world.spawn(fillet, 20.0, 1, MASS, SPEED, spawn_time=3 * world.config.dt)
            assert world.fillets[fid].spawn_time == 3 * world.config.dt
            while world.steps < 200:
                world.step()
            runs.append(world.segment_poses()[fid])
    assert runs[0][-1, 0] > 0.05 and runs[0][-1, 2] < 0.0  # the tip hangs over the edge
    assert np.array_equal(runs[0], runs[1])


@pytest.mark.parametrize("spawn_time", [-0.01, 1.0, math.nan])
def test_a_spawn_time_outside_the_past_is_refused(fillet: FilletMesh, spawn_time: float) -> None:
    with LineWorld() as world:
        world.step()
        with pytest.raises(ValueError, match="spawn_time"):
            world.spawn(fillet, 10.0, 0, MASS, SPEED, spawn_time=spawn_time)
    with LineWorld(config=PhysicsConfig(activation_margin=None)) as world:
        world.step()
        with pytest.raises(ValueError, match="spawn_time"):
            world.spawn(fillet, 10.0, 0, MASS, SPEED, spawn_time=0.0)


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [({"n_segments": 1}, "N"), ({"dt": 0.5}, "dt"), ({"damping": -0.1}, "damping"),
     ({"inertia_floor": -0.1}, "inertia_floor"), ({"inertia_floor": 1.5}, "inertia_floor"),
     ({"slice_shape": "sphere"}, "slice_shape")],
)
def test_bad_config_raises_value_error(kwargs: dict, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        PhysicsConfig(**kwargs)


@pytest.mark.slow
def test_soak_of_a_few_hundred_passages_has_no_blow_up():
    """A fixed 240-passage sample of every `woody soak` condition family, strictly: a regression guard.

    Fresh worlds are bit-reproducible, so the sample is deterministic. Besides no blow-up (12 m/s), no
    segment may come near one: free fall past the roller stays under ~4 m/s.
    """
    from woody_sim.meshes import load_mesh_set
    from woody_sim.soak import soak

    meshes, _ = load_mesh_set("builtin")
    result = soak(meshes, 240, seed=11, config=calibrated_config())
    assert result.passages >= 240
    assert result.blowups == 0, f"blew up: {result.failures}"
    assert result.worst_speed_mps < 6.0


def test_soak_waves_send_each_lane_a_fillet_per_wave_in_time_order():
    from woody_sim.soak import SPAWN_GAP_S, WAVE_GAP_S, SoakCondition

    staggered = SoakCondition(mesh=0, k=0.0, mass=20.0, speed_fpm=100.0, lanes=3, staggered=True, waves=2)
    assert staggered.spawn_times() == [(0.0, 0), (SPAWN_GAP_S, 1), (2 * SPAWN_GAP_S, 2), (WAVE_GAP_S, 0),
                                       (WAVE_GAP_S + SPAWN_GAP_S, 1), (WAVE_GAP_S + 2 * SPAWN_GAP_S, 2)]
    side_by_side = SoakCondition(mesh=0, k=0.0, mass=20.0, speed_fpm=100.0, lanes=2, staggered=False)
    assert side_by_side.spawn_times() == [(0.0, 0), (0.0, 1)]


def test_inertia_floor_raises_only_the_thin_slices_hinge_axis(fillet: FilletMesh) -> None:
    model = build_fillet_model(fillet, total_mass=20.0)
    bare, floored = segment_inertias(model, 0.0), segment_inertias(model, 0.1)
    assert floored[:, [0, 2]] == pytest.approx(bare[:, [0, 2]])
    assert np.all(floored[:, 1] >= bare[:, 1]) and floored[:, 1].min() == pytest.approx(0.1 * bare[:, 1].mean())
    raised = floored[:, 1] > bare[:, 1]
    assert raised[0] and raised[-1] and not raised[20]  # the tapering ends, not the body
    half = model.box_half_extents[5]
    assert bare[5, 1] == pytest.approx(model.masses[5] * 4.0 * (half[0] ** 2 + half[2] ** 2) / 12.0)


def test_without_the_inertia_floor_heavy_stiff_chains_blow_up_on_the_roller():
    """The soak's failure (docs/physics.md, "Blow-ups"), kept reproducible so the soak test can fail.

    Heavy, stiff chains of the paper's thin slices pivot on the roller on their thin tail slices; without the
    floor they whip and a chain is thrown faster than 12 m/s; with it the same batches fall as they should, and
    so do the default chain's. Two batches of the failing family, because which single passage blows up changes
    with round-off (docs/physics.md).
    """
    from woody_sim.meshes import load_mesh_set
    from woody_sim.soak import SoakCondition, run_batch

    meshes, _ = load_mesh_set("builtin")
    conditions = [SoakCondition(mesh=1, k=400.0, mass=300.0, speed_fpm=100.0, lanes=6, staggered=True),
                  SoakCondition(mesh=3, k=400.0, mass=100.0, speed_fpm=100.0, lanes=6, staggered=False)]
    bare = [run_batch(c, meshes[c.mesh], calibrated_config(inertia_floor=0.0, **PAPER_PHYSICS)) for c in conditions]
    assert sum(blown for _, blown, _, _ in bare) >= 1
    for condition in conditions:
        for config in (calibrated_config(**PAPER_PHYSICS), calibrated_config()):
            passages, blown, worst, _ = run_batch(condition, meshes[condition.mesh], config)
            assert (passages, blown) == (6, 0) and worst < 6.0


def run_digest(config: PhysicsConfig | None = None) -> str:
    """SHA-256 of every segment pose while three fillets cross the roller side by side, are taken off the line
    and three others follow (chains built where removed ones were, as in a running line)."""
    import hashlib

    from woody_sim.meshes import load_mesh_set

    meshes, _ = load_mesh_set("builtin")
    states = []
    with LineWorld(LineGeometry(lanes=3, spawn_x=-0.15), config or calibrated_config()) as world:
        for wave in range(2):
            for lane, k in enumerate((0.0, 100.0, 400.0)):
                world.spawn(meshes[lane + 3 * wave], k, lane, MASS, SPEED)
            for _ in range(200):
                world.step()
                states += list(world.segment_poses().values())
            for fid in list(world.fillets):
                world.remove(fid)
    return hashlib.sha256(np.concatenate([s.ravel() for s in states]).tobytes()).hexdigest()


@pytest.mark.slow
def test_identical_inputs_give_bit_identical_runs_in_and_across_processes():
    """pybullet is deterministic for identical inputs (same spawns, removals and steps): the tests rely on it.

    The subprocesses get other hash seeds, hence another memory layout, which once changed a running
    line's results through pybullet's stale mass matrices (docs/physics.md).
    """
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = dict(os.environ, PYTHONPATH=str(Path(__file__).parent))
    script = "import test_physics; print(test_physics.run_digest())"
    others = {subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                             env=env).stdout.split()[-1] for _ in range(2)}
    assert {run_digest(), run_digest()} | others == {run_digest()}


def test_the_friction_cone_is_left_out_because_the_frictionless_belt_makes_it_change_nothing(monkeypatch):
    """LineWorld turns pybullet's implicit friction cone off to save solver work; with the belt and roller
    frictionless that must leave every pose bit-identical (it would not if they had friction)."""
    settings = []
    setter = p.setPhysicsEngineParameter
    monkeypatch.setattr(p, "setPhysicsEngineParameter", lambda **kw: settings.append(kw) or setter(**kw))
    without_cone = run_digest()
    assert settings and all(kw["enableConeFriction"] == 0 for kw in settings)
    rough = calibrated_config(belt_friction=0.5)
    rough_without_cone = run_digest(rough)
    monkeypatch.setattr(p, "setPhysicsEngineParameter", lambda **kw: setter(**{**kw, "enableConeFriction": 1}))
    assert run_digest() == without_cone
    assert run_digest(rough) != rough_without_cone  # the setting does act where there is friction


STEPS_PAST_EDGE = round(0.625 / PhysicsConfig().dt)
"""Steps of the default physics over which a chain spawned at -0.15 m tips over the roller."""


def chain_poses_after(history: int) -> np.ndarray:
    """Poses of one k = 100 chain over STEPS_PAST_EDGE steps, in a world that first built and removed ``history``
    other chains."""
    from woody_sim.meshes import load_mesh_set

    meshes, _ = load_mesh_set("builtin")
    with LineWorld(LineGeometry(lanes=3, spawn_x=-0.15), calibrated_config()) as world:
        for i in range(history):
            earlier = world.spawn(meshes[i % 3], 400.0, 1, 5.0 * (i + 1), SPEED)
            while not world.is_dynamic(earlier):
                world.step()
            world.step()
            world.remove(earlier)
        fid = world.spawn(meshes[2], 100.0, 1, MASS, SPEED)
        poses = []
        for _ in range(STEPS_PAST_EDGE):
            world.step()
            if fid in world.fillets:
                poses.append(world.segment_poses()[fid])
    return np.array(poses)


def test_a_chain_moves_the_same_in_a_world_that_has_run_other_chains():
    """A running line builds chains where earlier ones were removed; nothing of those may leak into the new one.

    pybullet's ``calculateMassMatrix`` did leak: it keeps the inverse-dynamics model it built for a body and a
    later chain can inherit it, so the hinge law integrated it with another fillet's mass matrix (up to 100 %
    off) and it blew up in a running line (docs/physics.md). Contact order may differ, so round-off may too:
    the two agree to round-off while the chain bends over the roller, and once it slides off, a contact
    event can amplify that round-off to millimetres (how much depends on the build of pybullet), never to the
    metres a wrong mass matrix gives.
    """
    fresh, aged = chain_poses_after(0), chain_poses_after(6)
    assert len(aged) == len(fresh) == STEPS_PAST_EDGE
    step_error = np.abs(fresh - aged).reshape(STEPS_PAST_EDGE, -1).max(axis=1)
    assert step_error[:STEPS_PAST_EDGE * 140 // 300].max() < 1e-9
    assert step_error.max() < 0.01


def test_chain_fate_tells_blow_ups_finished_chains_and_live_ones_apart():
    from woody_sim.line_world import BLOWN_UP, BLOWUP_SPEED, FINISHED, KEEP, PAST_ROLLER_X, chain_fate

    masses = np.array([1.0, 3.0])
    state = np.zeros((2, 13))
    state[:, 6] = 1.0
    assert chain_fate(state, masses, -0.2) == KEEP
    for row, col, value in ((1, 3, np.nan), (0, 12, np.inf), (1, 9, -1.01 * BLOWUP_SPEED)):
        bad = state.copy()
        bad[row, col] = value
        assert chain_fate(bad, masses, -0.2) == BLOWN_UP, (row, col, value)
    fallen = state.copy()
    fallen[:, 2] = -0.3
    assert chain_fate(fallen, masses, -0.2) == FINISHED  # every segment below remove_z
    half_fallen = state.copy()
    half_fallen[0, 2] = -0.3
    assert chain_fate(half_fallen, masses, -0.2) == KEEP
    past = state.copy()
    past[:, 0] = [PAST_ROLLER_X - 0.3, PAST_ROLLER_X + 0.2]  # centre of mass 0.075 m past the limit
    assert chain_fate(past, masses, -0.2) == FINISHED
    past[1, 0] = PAST_ROLLER_X + 0.05  # centre of mass short of it
    assert chain_fate(past, masses, -0.2) == KEEP


def test_chains_are_built_in_fresh_pybullet_worlds_and_an_emptied_world_is_closed(monkeypatch) -> None:
    """pybullet keeps every shape and some memory of every body a world ever built, so a world builds at most
    CHAINS_PER_PHYSICS chains. With one per world, every chain is alone in its pybullet world and moves bit for
    bit as in a line that only ever held it, however the chains overlap in time."""
    from woody_sim import line_world
    from woody_sim.meshes import load_mesh_set

    meshes, _ = load_mesh_set("builtin")
    geometry = LineGeometry(lanes=3, spawn_x=-0.15)
    step = PhysicsConfig().dt
    at = ((0.0, meshes[0], 0.0, 0), (0.083, meshes[1], 100.0, 1), (0.167, meshes[2], 0.0, 2),
          (0.625, meshes[0], 100.0, 0))
    spawns = [(round(t / step), mesh, k, lane) for t, mesh, k, lane in at]
    sample_step = round(0.667 / step)

    def poses_of(chosen: list, chains_per_world: int) -> tuple[dict[int, np.ndarray], int]:
        monkeypatch.setattr(line_world, "CHAINS_PER_PHYSICS", chains_per_world)
        with LineWorld(geometry, calibrated_config()) as world:
            ids, most = {}, 0
            while world.steps < sample_step:
                for step, mesh, k, lane in chosen:
                    if world.steps == step:
                        ids[step] = world.spawn(mesh, k, lane, MASS, SPEED)
                world.step()
                most = max(most, len(world._physics))
            poses = {step: world.segment_poses()[fid] for step, fid in ids.items() if fid in world.fillets}
            while world.fillets:
                world.step()
            assert len(world._physics) == 1  # the emptied worlds were closed
        return poses, most

    together, worlds = poses_of(spawns, 1)
    assert worlds >= 3 and len(together) >= 2
    for spawn in spawns:
        if spawn[0] in together:
            alone, _ = poses_of([spawn], 1000)
            assert np.array_equal(together[spawn[0]], alone[spawn[0]])
