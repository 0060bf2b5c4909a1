"""The compiled immersion flood gives, pixel for pixel, what whole-image 3×3 max-dilation waves give."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from woody_vision.flood import flood


def reference_flood(distance, markers, component, levels):
    """The definition: per level, admit pixels with distance >= level, grow all regions by 3×3 max-dilation
    restricted to the admitted pixels until no admitted pixel touches a region."""
    labels = markers.astype(np.int32).copy()
    for level in levels:
        pending = (component > 0) & (labels == 0) & (distance >= np.float32(level))
        while True:
            grown = cv2.dilate(labels.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int32)
            reached = pending & (grown > 0)
            if not reached.any():
                break
            labels[reached] = grown[reached]
            pending &= ~reached
    return labels


def touching_blobs(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    component = np.zeros((120, 160), np.uint8)
    for _ in range(rng.integers(2, 4)):
        centre = (int(rng.integers(40, 120)), int(rng.integers(35, 85)))
        axes = (int(rng.integers(15, 35)), int(rng.integers(10, 25)))
        cv2.ellipse(component, centre, axes, float(rng.uniform(0, 180)), 0, 360, 255, -1)
    component[0, :] = component[-1, :] = component[:, 0] = component[:, -1] = 0
    distance = cv2.distanceTransform(component, cv2.DIST_L2, 5)
    cores = (distance > 0.6 * distance.max()).astype(np.uint8)
    _, markers = cv2.connectedComponents(cores, connectivity=8, ltype=cv2.CV_32S)
    return distance, markers, component


@pytest.mark.parametrize("seed", range(8))
def test_flood_matches_the_dilation_definition(seed):
    distance, markers, component = touching_blobs(seed)
    levels = np.linspace(float(distance.max()), 0.0, 7)[1:]
    got = flood(distance, markers, component, levels)
    assert np.array_equal(got, reference_flood(distance, markers, component, levels))
    assert np.all(got[component == 0] == markers[component == 0])  # nothing outside the component
    assert (got[component > 0] > 0).mean() > 0.95  # the regions fill the component


@pytest.mark.parametrize("seed", range(8, 40))
def test_flood_matches_the_dilation_definition_on_more_shapes(seed):
    """Also where the ellipses do not all touch, so some pixels stay unreached: the flood admits each level's
    pixels once, and a pixel left pending carries over to the next level as the definition's rescan has it."""
    distance, markers, component = touching_blobs(seed)
    levels = np.linspace(float(distance.max()), 0.0, 7)[1:]
    assert np.array_equal(flood(distance, markers, component, levels),
                          reference_flood(distance, markers, component, levels))


def test_a_pixel_reached_by_two_regions_at_once_takes_the_higher_label():
    component = np.full((3, 5), 255, np.uint8)
    markers = np.zeros((3, 5), np.int32)
    markers[:, 0], markers[:, 4] = 1, 2
    got = flood(np.ones((3, 5), np.float32), markers, component, np.array([0.0]))
    assert got[:, 1].tolist() == [1, 1, 1] and got[:, 3].tolist() == [2, 2, 2]
    assert got[:, 2].tolist() == [2, 2, 2]
