"""Shape descriptors: known answers on simple shapes, and the generated set against the reference meshes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from woody_sim.mesh_stats import describe, outside_range, summarize
from woody_sim.meshes import (
    BUILTIN_DIR,
    BUILTIN_REFERENCE_NAMES,
    FilletMesh,
    depth_map_to_mesh,
    generate_fillet,
    load_mesh,
)

GENERATED_SEEDS = range(24)


def elliptic_slab(a: float, b: float, height: float) -> FilletMesh:
    """A flat slab whose footprint is an ellipse with semi-axes a (x) and b (y)."""
    mesh = trimesh.creation.cylinder(radius=1.0, height=height, sections=256)
    mesh.apply_scale([a, b, 1.0])
    return FilletMesh(name="ellipse", mesh=mesh)


def test_rectangle_has_its_known_descriptors() -> None:
    d = describe(FilletMesh(name="box", mesh=trimesh.creation.box(extents=[0.2, 0.1, 0.02])))
    assert d.aspect_ratio == pytest.approx(2.0, rel=0.01)
    assert d.solidity == pytest.approx(1.0, abs=0.002)
    assert d.rim_roughness == pytest.approx(1.0, abs=0.002)
    assert [d.width_10, d.width_25, d.width_50, d.width_75, d.width_90] == pytest.approx([1.0] * 5, abs=0.01)
    assert d.thickness_m == pytest.approx(0.02)
    assert d.fullness == pytest.approx(1.0, abs=0.01)
    assert d.area_m2 == pytest.approx(0.02, rel=0.01)


@pytest.mark.slow  # 10 s: rasterises and meshes an ellipse at full resolution
def test_ellipse_has_its_known_descriptors() -> None:
    d = describe(elliptic_slab(0.1, 0.05, 0.03))
    assert d.aspect_ratio == pytest.approx(2.0, rel=0.01)
    assert d.solidity == pytest.approx(1.0, abs=0.002)
    assert d.rim_roughness == pytest.approx(1.0, abs=0.003)
    expected = [math.sqrt(1.0 - (2.0 * p - 1.0) ** 2) for p in (0.10, 0.25, 0.50, 0.75, 0.90)]
    assert [d.width_10, d.width_25, d.width_50, d.width_75, d.width_90] == pytest.approx(expected, abs=0.01)
    assert d.area_m2 == pytest.approx(math.pi * 0.1 * 0.05, rel=0.01)
    dome = describe(FilletMesh(name="dome", mesh=trimesh.creation.icosphere(subdivisions=5, radius=0.05)))
    assert dome.fullness == pytest.approx(5.0 / 6.0, abs=0.01)  # a ball's top over its disc: mean r + 2r/3 of 2r


def test_stair_stepped_rim_is_rough_and_a_notch_lowers_solidity() -> None:
    n = 16  # a staircase diamond of 10 mm cells: rim 4 x 16 cells; hull 4 flat 2-cell ends + 4 diagonals of 7 steps
    i, j = np.mgrid[:n, :n]
    diamond = np.where(np.abs(i - (n - 1) / 2) + np.abs(j - (n - 1) / 2) <= n / 2, 0.02, 0.0)
    stairs = describe(FilletMesh(name="stairs", mesh=depth_map_to_mesh(diamond, 0.01)))
    assert stairs.rim_roughness == pytest.approx(64.0 / (8.0 + 28.0 * math.sqrt(2.0)), rel=0.04)  # step corners round
    notched = np.full((50, 100), 0.02)
    notched[:25, 40:60] = 0.0  # a 20 x 25 notch out of a 100 x 50 rectangle: solidity 0.9
    d = describe(FilletMesh(name="notch", mesh=depth_map_to_mesh(notched, 0.002)))
    assert d.solidity == pytest.approx(0.9, abs=0.01)


def test_summary_and_range_check() -> None:
    boxes = [FilletMesh(name=f"box{w}", mesh=trimesh.creation.box(extents=[0.2, w, 0.02])) for w in (0.1, 0.08)]
    sets = [describe(box) for box in boxes]
    summary = summarize(sets)
    assert summary["aspect_ratio"]["min"] == pytest.approx(2.0, rel=0.01)
    assert summary["aspect_ratio"]["max"] == pytest.approx(2.5, rel=0.01)
    assert summary["aspect_ratio"]["mean"] == pytest.approx(2.25, rel=0.01)
    assert summary["aspect_ratio"]["sd"] == pytest.approx(0.5 / math.sqrt(2.0), rel=0.02)
    assert outside_range(summary, summary) == []
    narrower = {**summary, "aspect_ratio": {**summary["aspect_ratio"], "max": 2.2}}
    assert outside_range(summary, narrower) == ["aspect_ratio"]
    with pytest.raises(ValueError):
        summarize([])


@pytest.fixture(scope="module")
def reference_summary() -> dict:
    return summarize([describe(load_mesh(BUILTIN_DIR / f"{name}.obj")) for name in BUILTIN_REFERENCE_NAMES])


@pytest.mark.slow  # 12 s: generates and measures a mesh set
def test_generated_set_means_fall_inside_the_reference_range(reference_summary: dict) -> None:
    generated = summarize([describe(generate_fillet(seed)) for seed in GENERATED_SEEDS])
    outside = outside_range(generated, reference_summary)
    report = {k: (generated[k]["mean"], reference_summary[k]["min"], reference_summary[k]["max"]) for k in outside}
    assert outside == [], f"generated mean, reference min, max: {report}"
