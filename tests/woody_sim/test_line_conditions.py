"""The messy line's placements (woody_sim.line_conditions): seeded, bounded, and the meshes they lay."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from woody_common.line import MIN_SPAWN_SPACING_M, check_lane_pitch, max_fillets_per_minute, spacing_at_rate
from woody_sim.line_conditions import (
    LINE_PRESETS,
    FilletPlacement,
    LineConditions,
    crowding_note,
    draw_placement,
    line_preset,
    longest_placed_length,
    mean_placed_length,
    place_mesh,
    placement_for,
)
from woody_sim.meshes import generate_fillet

MESSY = LINE_PRESETS["messy"]


def placements(conditions: LineConditions, n: int = 400, seed: int = 7) -> list[FilletPlacement]:
    return [placement_for(conditions, seed, i) for i in range(n)]


def test_placements_are_seeded_by_seed_and_index_alone():
    forward = placements(MESSY, 50)
    assert [placement_for(MESSY, 7, i) for i in reversed(range(50))][::-1] == forward
    assert placements(MESSY, 50, seed=8) != forward
    assert len({p.yaw_deg for p in forward}) == 50
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    assert [draw_placement(MESSY, rng_a) for _ in range(5)] == [draw_placement(MESSY, rng_b) for _ in range(5)]


def test_one_knob_never_shifts_another_draw():
    """Each placement takes the same four draws whatever is switched on, so yaws stay put when sizes vary."""
    only_yaw = placements(LineConditions(yaw_sd_deg=15.0, yaw_max_deg=35.0), 30)
    assert [p.yaw_deg for p in only_yaw] == [p.yaw_deg for p in placements(MESSY, 30)]


def test_draws_respect_their_bounds_and_spread():
    drawn = placements(MESSY)
    yaws = np.array([p.yaw_deg for p in drawn])
    lateral = np.array([p.lateral_offset_m for p in drawn])
    scales = np.array([p.scale for p in drawn])
    assert np.abs(yaws).max() <= 35.0 and 12.0 < yaws.std() < 16.0 and abs(yaws.mean()) < 2.5
    assert np.abs(lateral).max() <= 0.025 and 0.008 < lateral.std() < 0.011
    assert scales.min() >= 0.85 and scales.max() <= 1.15 and scales.max() - scales.min() > 0.25
    assert 0.4 < np.mean([p.blunt_first for p in drawn]) < 0.6


def test_the_tidy_line_keeps_every_mesh_as_it_is():
    mesh = generate_fillet(1)
    assert all(p == FilletPlacement() and p.keeps_mesh for p in placements(LINE_PRESETS["tidy"], 20))
    assert place_mesh(mesh, FilletPlacement()) is mesh


def test_the_bounds_default_to_two_sd():
    turned = LineConditions(yaw_sd_deg=10.0, lateral_sd_m=0.01)
    assert (turned.yaw_max_deg, turned.lateral_max_m) == (20.0, 0.02)
    assert LineConditions(yaw_sd_deg=40.0).yaw_max_deg == 45.0


def test_presets_are_valid_and_an_unknown_one_is_one_line():
    assert line_preset("messy") is MESSY and line_preset("tidy") == LineConditions()
    assert all(dataclasses.replace(c) == c for c in LINE_PRESETS.values())
    with pytest.raises(ValueError, match="unknown line preset 'muddy'; known: tidy, messy"):
        line_preset("muddy")


@pytest.mark.parametrize(("field", "value", "message"), [
    ("yaw_sd_deg", -1.0, "yaw_sd_deg must be within 0..45 deg, got -1.0"),
    ("yaw_sd_deg", float("nan"), "yaw_sd_deg must be within"),
    ("yaw_max_deg", 60.0, "yaw_max_deg must be within 0..45 deg, got 60.0"),
    ("blunt_fraction", 1.5, "blunt_fraction must be within 0..1, got 1.5"),
    ("lateral_sd_m", 0.2, "lateral_sd_m must be within 0..0.05 m, got 0.2"),
    ("lateral_max_m", -0.01, "lateral_max_m must be within 0..0.05 m"),
    ("scale_min", 0.1, "scale_min must be within 0.5..1.5, got 0.1"),
    ("scale_min", 1.2, "scale_max must be >= scale_min 1.2, got 1.15"),
])
def test_a_bad_value_is_one_line(field, value, message):
    with pytest.raises(ValueError, match=re.escape(message)) as raised:
        dataclasses.replace(MESSY, **{field: value})
    assert "\n" not in str(raised.value)


def test_place_mesh_scales_volume_by_s_cubed_and_turns_the_narrow_end_back():
    mesh = generate_fillet(2)
    big = place_mesh(mesh, FilletPlacement(scale=1.1))
    assert big.mesh.volume == pytest.approx(mesh.mesh.volume * 1.1 ** 3, rel=1e-9)
    assert (big.length, big.width) == pytest.approx((1.1 * mesh.length, 1.1 * mesh.width))
    blunt = place_mesh(mesh, FilletPlacement(blunt_first=True))
    assert blunt.length == pytest.approx(mesh.length) and blunt.name == mesh.name

    def leading_share(fillet):  # share of the surface in the downstream (+x) quarter: small for the narrow tip
        centres, area = fillet.mesh.triangles_center, fillet.mesh.area_faces
        return area[centres[:, 0] > fillet.mesh.bounds[1, 0] - 0.25 * fillet.length].sum() / area.sum()

    assert leading_share(mesh) < leading_share(blunt)
    turned = place_mesh(mesh, FilletPlacement(yaw_deg=20.0, scale=0.9))
    assert turned.length != pytest.approx(0.9 * mesh.length) and np.allclose(turned.mesh.bounds[0, 2], 0.0)
    lo, hi = turned.mesh.bounds
    assert np.allclose((lo + hi)[:2], 0.0, atol=1e-9)  # re-centred on the footprint


def test_longest_placed_length_bounds_every_placed_fillet():
    meshes = [generate_fillet(s) for s in (0, 3)]
    longest = longest_placed_length(meshes, MESSY)
    for i, placement in enumerate(placements(MESSY, 40)):
        assert place_mesh(meshes[i % 2], placement).length <= longest + 1e-9
    assert longest_placed_length(meshes, LineConditions()) == pytest.approx(max(m.length for m in meshes))


def test_mean_placed_length_lies_between_the_mean_mesh_and_the_longest_placed_fillet():
    meshes = [generate_fillet(s) for s in (0, 3)]
    tidy = mean_placed_length(meshes, LineConditions())
    assert tidy == pytest.approx(np.mean([m.length for m in meshes]))
    assert tidy < mean_placed_length(meshes, MESSY) < longest_placed_length(meshes, MESSY)  # turns lengthen the box


def test_lane_pitch_and_spawn_rate_limits_are_one_line():
    assert check_lane_pitch(6, 0.16) == 0.16
    with pytest.raises(ValueError, match=r"6 lanes 0.2 m apart need a 1.360 m belt, wider than 1.2 m: use a lane "
                                         r"pitch of at most 0.173 m"):
        check_lane_pitch(6, 0.2)
    with pytest.raises(ValueError, match="lane pitch must be at least 0.08 m"):
        check_lane_pitch(3, 0.05)
    speed = 0.508
    assert spacing_at_rate(speed, max_fillets_per_minute(speed)) == pytest.approx(MIN_SPAWN_SPACING_M)


def test_the_crowding_note_is_said_only_below_the_longest_placed_fillet():
    assert crowding_note(0.27, 0.26) == "" and crowding_note(0.26, 0.26) == ""
    assert crowding_note(0.2, 0.26) == ("in-lane spacing 0.200 m is below the longest placed fillet (0.260 m): a "
                                        "fillet waits at the spawn point until it has room, so a lane may carry "
                                        "fewer fillets than its spacing says")
