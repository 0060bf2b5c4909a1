"""Fillet meshes: loading and orientation, the generator, the scan import, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from woody_sim.mesh_stats import describe
from woody_sim.meshes import (
    BUILTIN_DIR,
    BUILTIN_REFERENCE_NAMES,
    LENGTH_RANGE,
    THICKNESS_RANGE,
    WIDTH_RANGE,
    FilletMesh,
    MeshError,
    depth_map_to_mesh,
    generate_fillet,
    load_mesh,
    load_mesh_set,
    rasterize_top,
    scan_height,
    scan_to_depth_map,
    scan_to_fillet,
)


def end_widths(fillet: FilletMesh, fraction: float = 0.2) -> tuple[float, float]:
    """Widest footprint in the -x end band and in the +x end band."""
    lo, hi = fillet.mesh.bounds[:, 0]
    widths = {}
    band = fraction * (hi - lo)
    for side, xs in (("low", np.linspace(lo, lo + band, 12)), ("high", np.linspace(hi - band, hi, 12))):
        spans = [fillet.height_map.footprint_interval(x) for x in xs]
        widths[side] = max((b - a for a, b in (s for s in spans if s)), default=0.0)
    return widths["low"], widths["high"]


@pytest.fixture(scope="module")
def references() -> list[FilletMesh]:
    return [load_mesh(BUILTIN_DIR / f"{name}.obj") for name in BUILTIN_REFERENCE_NAMES]


def test_reference_meshes_are_in_the_canonical_frame(references: list[FilletMesh]) -> None:
    for fillet in references:
        assert fillet.length > fillet.width > fillet.thickness
        assert 0.15 < fillet.length < 0.25 and 0.015 < fillet.thickness < 0.04
        lo, hi = fillet.mesh.bounds
        assert lo[2] == pytest.approx(0.0, abs=1e-9)
        assert (lo[:2] + hi[:2]) == pytest.approx([0.0, 0.0], abs=1e-9)
        wide_end, tip_end = end_widths(fillet)
        assert tip_end < wide_end, f"{fillet.name}: the narrow tip must point to +x"


def test_reference_mesh_bottom_is_flat(references: list[FilletMesh]) -> None:
    for fillet in references:
        verts = fillet.mesh.vertices
        bottom = verts[verts[:, 2] < 0.002]
        assert len(bottom) > 0.2 * len(verts)
        assert np.abs(bottom[:, 2]).max() < 0.002


def test_generated_fillets_are_watertight_real_sized_and_tip_forward() -> None:
    for seed in range(4):
        fillet = generate_fillet(seed)
        assert fillet.mesh.is_watertight and fillet.mesh.is_volume
        assert LENGTH_RANGE[0] <= fillet.length <= LENGTH_RANGE[1]
        assert WIDTH_RANGE[0] <= fillet.width <= WIDTH_RANGE[1]
        assert THICKNESS_RANGE[0] <= fillet.thickness <= THICKNESS_RANGE[1]
        assert fillet.height_map.heights.max() == pytest.approx(fillet.thickness, rel=0.02)
        lo, hi = fillet.mesh.bounds
        assert lo[2] == 0.0 and (lo[:2] + hi[:2]) == pytest.approx([0.0, 0.0], abs=1e-12)
        wide_end, tip_end = end_widths(fillet)
        assert tip_end < wide_end


def test_generated_top_surface_never_folds_over() -> None:
    """Every face is top (normal up), bottom (straight down) or rim wall (horizontal normal): no overhangs."""
    for seed in range(12):
        nz = generate_fillet(seed).mesh.face_normals[:, 2]
        top, bottom, wall = nz > 1e-6, np.isclose(nz, -1.0), np.abs(nz) < 1e-6
        assert (top | bottom | wall).all(), f"seed {seed}: {np.count_nonzero(~(top | bottom | wall))} folded faces"


def test_generated_rims_are_smooth_not_stair_stepped() -> None:
    for seed in range(3):
        assert describe(generate_fillet(seed)).rim_roughness < 1.06


@pytest.mark.parametrize("winding", [(0, 1, 2), (0, 2, 1)])
def test_the_height_map_is_the_upper_envelope_at_every_pixel_centre_for_either_winding(winding) -> None:
    """A square pyramid over a flat base (apex 2 cm over a 4 cm square) seen from above: the height at each pixel
    centre is the pyramid's, the base under it never shows, and outside the footprint is 0."""
    base = [(-0.02, -0.02, 0.0), (0.02, -0.02, 0.0), (0.02, 0.02, 0.0), (-0.02, 0.02, 0.0)]
    vertices = np.array([*base, (0.0, 0.0, 0.02)])
    faces = np.array([(0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4), (0, 2, 1), (0, 3, 2)])[:, list(winding)]
    height_map = rasterize_top(vertices, faces, 0.001)
    rows, cols = np.indices(height_map.heights.shape)
    x, y = height_map.x0 + cols * 0.001, height_map.y0 + rows * 0.001
    pyramid = np.maximum(0.02 - np.maximum(np.abs(x), np.abs(y)), 0.0)
    assert height_map.heights.shape == (43, 43)
    np.testing.assert_allclose(height_map.heights, np.where(np.maximum(np.abs(x), np.abs(y)) <= 0.02 + 1e-12,
                                                             pyramid, 0.0), atol=1e-12)


def test_a_yawed_fillet_is_the_same_fillet_turned_on_the_belt(references: list[FilletMesh]) -> None:
    from woody_sim.meshes import yawed

    fillet = references[0]
    quarter = yawed(fillet, 90.0)
    assert quarter.name == fillet.name and quarter.source.endswith("@yaw+90.0")
    assert quarter.length == pytest.approx(fillet.width, abs=1e-9)
    assert quarter.width == pytest.approx(fillet.length, abs=1e-9)
    assert quarter.mesh.area == pytest.approx(fillet.mesh.area)
    lo, hi = yawed(fillet, -13.0).mesh.bounds
    assert lo[2] == pytest.approx(0.0, abs=1e-12) and lo[0] == pytest.approx(-hi[0]) and lo[1] == pytest.approx(-hi[1])
    with pytest.raises(ValueError, match="yaw"):
        yawed(fillet, math.nan)


def test_a_meshs_yaw_is_seeded_by_its_name_and_scales_with_the_spread() -> None:
    from woody_sim.meshes import mesh_yaw

    assert mesh_yaw("seed0001", 13.0) == mesh_yaw("seed0001", 13.0) != mesh_yaw("seed0002", 13.0)
    assert mesh_yaw("seed0001", 26.0) == 2.0 * mesh_yaw("seed0001", 13.0) and mesh_yaw("seed0001", 0.0) == 0.0
    for bad in (-1.0, 46.0, math.nan):
        with pytest.raises(ValueError, match="yaw spread"):
            mesh_yaw("seed0001", bad)


def test_generator_is_reproducible_per_seed() -> None:
    a, b, c = generate_fillet(7), generate_fillet(7), generate_fillet(8)
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices) and np.array_equal(a.mesh.faces, b.mesh.faces)
    assert a.mesh.vertices.shape != c.mesh.vertices.shape or not np.allclose(a.mesh.vertices, c.mesh.vertices)
    assert a.name != c.name


def test_depth_map_rebuild_closes_pinches_islands_and_holes() -> None:
    depth = np.zeros((12, 14))
    depth[2:9, 2:10] = 0.01
    depth[5, 5] = 0.0  # a hole
    depth[9, 10] = 0.01  # touches the body only at a corner
    depth[1, 12] = 0.02  # a separate island
    mesh = depth_map_to_mesh(depth, 0.002)
    assert mesh.is_watertight and mesh.is_volume
    assert mesh.bounds[0, 2] == 0.0 and mesh.bounds[1, 2] == pytest.approx(0.01)


def test_scan_import_round_trip(references: list[FilletMesh]) -> None:
    original = references[1]
    points = trimesh.sample.sample_surface(original.mesh, 60000, seed=3)[0]
    rotation = trimesh.transformations.random_rotation_matrix(np.random.default_rng(4).random(3))[:3, :3]
    scanned = points @ rotation.T + np.array([0.3, -1.2, 0.7])
    fillet = scan_to_fillet(scanned)
    assert fillet.mesh.is_watertight and fillet.mesh.is_volume
    assert fillet.length == pytest.approx(original.length, rel=0.04)
    assert fillet.width == pytest.approx(original.width, rel=0.05)
    assert fillet.thickness == pytest.approx(original.thickness, rel=0.06)
    wide_end, tip_end = end_widths(fillet)
    assert tip_end < wide_end


def test_scan_depth_is_normalised_by_the_data_set_maximum(references: list[FilletMesh]) -> None:
    clouds = [trimesh.sample.sample_surface(f.mesh, 20000, seed=1)[0] for f in references]
    data_set_max = max(scan_height(cloud) for cloud in clouds)
    maps = [scan_to_depth_map(cloud, data_set_max) for cloud in clouds]
    peaks = [m.depth.max() for m in maps]
    assert max(peaks) == pytest.approx(1.0, abs=0.02)
    assert all(0.5 < peak <= 1.0 for peak in peaks)
    assert all(m.depth.shape == (128, 128) for m in maps)


def write(path, text: str) -> str:
    path.write_text(text)
    return str(path)


def open_sphere(path) -> str:
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    keep = sphere.triangles_center[:, 2] < 0.03  # cut a big cap off
    trimesh.Trimesh(sphere.vertices, sphere.faces[keep]).export(path)
    return str(path)


@pytest.mark.parametrize(
    ("make", "reason"),
    [
        (lambda tmp: write(tmp / "empty.obj", ""), "empty file"),
        (lambda tmp: write(tmp / "garbage.obj", "this is not\na mesh at all\n"), "no triangles"),
        (lambda tmp: open_sphere(tmp / "open.stl"), "open mesh"),
        (lambda tmp: str(tmp / "missing.ply"), "file not found"),
        (lambda tmp: write(tmp / "notes.txt", "v 0 0 0\n"), "unsupported format"),
    ],
)
def test_bad_files_raise_one_line_mesh_error_naming_the_file(tmp_path, make, reason: str) -> None:
    path = make(tmp_path)
    with pytest.raises(MeshError) as info:
        load_mesh(path)
    message = str(info.value)
    assert path in message and reason in message and "\n" not in message


def test_degenerate_mesh_is_rejected(tmp_path) -> None:
    path = tmp_path / "flat.stl"
    trimesh.creation.box(extents=[0.2, 0.1, 0.001]).export(path)
    with pytest.raises(MeshError, match="degenerate"):
        load_mesh(path)


def test_mesh_set_folder_skips_a_bad_file_and_reports_it(tmp_path) -> None:
    for seed in (1, 2):
        generate_fillet(seed).mesh.export(tmp_path / f"good{seed}.ply")
    write(tmp_path / "broken.obj", "garbage\n")
    fillets, errors = load_mesh_set(str(tmp_path))
    assert sorted(f.name for f in fillets) == ["good1", "good2"]
    assert len(errors) == 1 and "broken.obj" in errors[0]


def test_mesh_set_specs() -> None:
    builtin, errors = load_mesh_set("builtin")
    assert len(builtin) == 6 and not errors
    assert [f.name for f in builtin[:3]] == list(BUILTIN_REFERENCE_NAMES)
    combined, _ = load_mesh_set("builtin, generated:2:7")
    assert len(combined) == 8 and combined[-1].name == "generated-70001"
    assert len(load_mesh_set("generated:3")[0]) == 3
    for bad in ("generated:x", "generated:0", "", "no/such/folder"):
        with pytest.raises(ValueError):
            load_mesh_set(bad)


# ---------------------------------------------------------------- files as users bring them

def reference_saved_as(tmp_path, suffix: str, scale: float = 1.0, nan_vertex: int | None = None):
    raw = trimesh.load(BUILTIN_DIR / "seed0001.obj", force="mesh", process=False)
    vertices = raw.vertices * scale
    if nan_vertex is not None:
        vertices[nan_vertex] = np.nan
    path = tmp_path / f"seed0001{suffix}"
    trimesh.Trimesh(vertices, raw.faces, process=False).export(path)
    return path


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".obj"])
def test_the_projects_meshes_resaved_load_as_the_same_fillet(tmp_path, references, suffix) -> None:
    fillet = load_mesh(reference_saved_as(tmp_path, suffix))
    assert fillet.mesh.is_watertight
    assert np.allclose(fillet.mesh.extents, references[1].mesh.extents, atol=1e-6)


@pytest.mark.parametrize("scale,unit", [(1000.0, "mm"), (100.0, "cm")])
def test_a_mesh_in_mm_or_cm_is_converted_with_a_warning(tmp_path, references, scale, unit) -> None:
    from woody_sim.meshes import MeshWarning

    path = reference_saved_as(tmp_path, ".stl", scale=scale)
    with pytest.warns(MeshWarning, match=rf"seed0001\.stl: .* taken as {unit} and converted to metres"):
        fillet = load_mesh(path)
    assert np.allclose(fillet.mesh.extents, references[1].mesh.extents, rtol=1e-6)


@pytest.mark.parametrize(
    ("make", "reason"),
    [
        (lambda tmp: str(reference_saved_as(tmp, ".obj", nan_vertex=7)), "1 vertices with NaN or infinite coordinates"),
        (lambda tmp: str(reference_saved_as(tmp, ".stl", scale=1e6)), "units long, not a fillet"),
        (lambda tmp: (tmp / "noise.stl").write_bytes(np.random.default_rng(1).bytes(3000)) and str(tmp / "noise.stl"),
         "not a valid STL"),
    ],
)
def test_bad_user_meshes_name_the_real_problem(tmp_path, make, reason: str) -> None:
    path = make(tmp_path)
    with pytest.raises(MeshError) as info:
        load_mesh(path)
    message = str(info.value)
    assert message.startswith(path) and reason in message and "\n" not in message
