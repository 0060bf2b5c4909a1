"""The camera error model: noise that grows with distance, quantisation, holes, edges, drops; seeded."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from woody_sim.sensor_model import PRESETS, SensorModel, sensor_preset, to_message_array
from woody_vision.segmentation import REAL_CAMERA_FILTERS, BackgroundModel, SegmentationParams, segment_depth

STEREO = sensor_preset("stereo")
STRUCTURED = sensor_preset("structured_light")
QUIET = dict(edge_invalid_px=0, hole_fraction=0.0)


def flat(z: float, shape=(200, 300)) -> np.ndarray:
    return np.full(shape, z, np.float32)


def test_ideal_changes_nothing_and_every_preset_is_reproducible_from_its_seed():
    exact = flat(0.75)
    exact[50:80, 60:90] = 0.72
    assert np.array_equal(PRESETS["ideal"].depth(exact, np.random.default_rng(1)), exact)
    for model in PRESETS.values():
        a = model.depth(exact, np.random.default_rng(5))
        b = model.depth(exact, np.random.default_rng(5))
        assert np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("model", [STEREO, STRUCTURED], ids=lambda m: m.name)
def test_depth_noise_has_the_modelled_sigma_and_grows_with_distance(model):
    model = replace(model, disparity_step_px=0.0, depth_step_m=0.0, **QUIET)
    for z in (0.75, 1.5):
        noisy = model.depth(flat(z, (400, 600)), np.random.default_rng(2))
        assert np.std(noisy - z) == pytest.approx(model.sigma(z), rel=0.1)
    assert model.sigma(1.5) > 2.0 * model.sigma(0.75)


def test_stereo_sigma_follows_the_triangulation_law():
    assert STEREO.sigma(0.75) == pytest.approx(0.75 ** 2 * 0.15 / (STEREO.focal_px * 0.12))
    assert 0.001 < STEREO.sigma(0.75) < 0.003  # ~2 mm over the belt


def test_structured_light_depth_is_quantised_in_disparity_and_millimetres():
    model = replace(STRUCTURED, disparity_noise_px=0.0, noise_floor_m=0.0, **QUIET)
    ramp = np.tile(np.linspace(0.70, 0.80, 300, dtype=np.float32), (10, 1))
    out = model.depth(ramp, np.random.default_rng(0))
    assert np.allclose(out * 1000.0, np.round(out * 1000.0), atol=1e-3)
    steps = np.diff(np.unique(out))
    expected = 0.75 ** 2 * 0.125 / (580.0 * 0.075)  # 1.6 mm at 0.75 m
    assert np.median(steps) == pytest.approx(expected, abs=0.0011)


def test_depth_edges_lose_a_band_of_pixels_and_holes_cover_their_fraction():
    exact = flat(0.75)
    exact[:, 150:] = 0.72  # a 30 mm step
    band = replace(STEREO, disparity_noise_px=0.0, hole_fraction=0.0).depth(exact, np.random.default_rng(0))
    invalid_cols = np.unique(np.nonzero(np.isnan(band))[1])
    assert set(invalid_cols) == {148, 149, 150, 151}
    holes = replace(STEREO, disparity_noise_px=0.0, edge_invalid_px=0, hole_fraction=0.05).depth(
        flat(0.75, (400, 600)), np.random.default_rng(0))
    assert np.isnan(holes).mean() == pytest.approx(0.05, abs=0.01)


def test_drops_and_colour_noise_at_their_rates():
    rng = np.random.default_rng(3)
    assert sum(STEREO.drop(rng) for _ in range(5000)) / 5000 == pytest.approx(0.01, abs=0.005)
    assert not any(PRESETS["ideal"].drop(rng) for _ in range(100))
    grey = np.full((100, 100, 3), 128, np.uint8)
    assert np.std(STRUCTURED.color(grey, rng).astype(float)) == pytest.approx(3.0, rel=0.1)
    assert PRESETS["ideal"].color(grey, rng) is grey


@pytest.mark.parametrize("model", [STEREO, STRUCTURED], ids=lambda m: m.name)
def test_a_noisy_empty_belt_is_never_a_fillet_with_the_real_camera_filters(model):
    params = SegmentationParams(**REAL_CAMERA_FILTERS)
    rng = np.random.default_rng(4)
    exact = flat(0.75, (376, 672))
    exact[300:] = 1.35  # the floor beyond the roller edge
    background = BackgroundModel(5)
    for _ in range(5):
        background.add(model.depth(exact, rng))
    for _ in range(20):
        assert segment_depth(model.depth(exact, rng), background.depth, params) == []


def test_published_encodings_and_bad_models():
    depth = np.array([[0.7504, np.nan]], np.float32)
    assert to_message_array(depth, "16UC1").tolist() == [[750, 0]]
    assert to_message_array(depth, "16UC1", unit_m=0.0001).tolist() == [[7504, 0]]
    assert to_message_array(depth, "32FC1").dtype == np.float32
    with pytest.raises(ValueError, match="choose one of ideal, stereo, structured_light"):
        sensor_preset("lidar")
    for bad in (dict(hole_fraction=1.0), dict(encoding="mono8"), dict(baseline_m=0.0), dict(color_noise=-1.0)):
        with pytest.raises(ValueError):
            SensorModel(**bad)
