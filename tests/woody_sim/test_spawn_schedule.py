"""woody_sim.spawn_schedule: one fillet per lane every interval, the same mesh across a spawn, seeded k."""

from __future__ import annotations

import pytest

from woody_sim.meshes import FilletMesh
from woody_sim.spawn_schedule import SpawnSchedule


def meshes(n: int) -> list[FilletMesh]:
    return [FilletMesh.__new__(FilletMesh) for _ in range(n)]  # the schedule only hands them on


def test_every_interval_one_fillet_per_lane_with_the_same_mesh():
    pool = meshes(2)
    schedule = SpawnSchedule(pool, [0.0, 100.0], lanes=3, interval_s=0.5, seed=1)
    first = list(schedule.due(0.0))
    assert [lane for _, _, lane in first] == [0, 1, 2]
    assert all(mesh is pool[0] for mesh, _, _ in first)
    assert list(schedule.due(0.49)) == []
    second = list(schedule.due(0.5))
    assert all(mesh is pool[1] for mesh, _, _ in second)  # meshes cycle in order
    assert len(list(schedule.due(1.6))) == 2 * 3  # a late call catches up: the events at 1.0 and 1.5 s
    assert schedule.events == 4 and schedule.next_time == 2.0


def test_k_draws_are_seeded_and_from_the_values():
    def draw(seed):
        schedule = SpawnSchedule(meshes(1), [0.0, 10.0, 100.0], lanes=3, interval_s=1.0, seed=seed)
        return [k for _, k, _ in schedule.due(20.0)]

    assert draw(4) == draw(4)
    assert draw(4) != draw(5)
    assert set(draw(4)) <= {0.0, 10.0, 100.0}


def test_first_at_delays_the_first_spawn():
    schedule = SpawnSchedule(meshes(1), [0.0], lanes=1, interval_s=1.0, first_at=2.0)
    assert list(schedule.due(1.9)) == [] and len(list(schedule.due(2.0))) == 1


@pytest.mark.parametrize("kwargs", [dict(meshes=[]), dict(k_values=[]), dict(interval_s=0.0)])
def test_refuses_an_empty_or_degenerate_plan(kwargs):
    args = {**dict(meshes=meshes(1), k_values=[0.0], lanes=1, interval_s=1.0), **kwargs}
    with pytest.raises(ValueError):
        SpawnSchedule(**args)
