"""The compiled rasteriser: exact planar depth, no cracks, nearest surface wins, buffers cleared per frame."""

from __future__ import annotations

import numpy as np
import pytest

from woody_sim.raster import ZBuffer

W, H = 64, 48
FX = FY = 50.0
CX, CY = 31.5, 23.5
LIGHT = np.array([0.0, 0.0, -1.0])


def zbuffer() -> ZBuffer:
    return ZBuffer(W, H, (FX, FY, CX, CY), 0.01, LIGHT, 0.35, 0.65)


def quad(z_left: float, z_right: float, half: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """One link with a square of two triangles spanning x in [-half, half], z from z_left to z_right."""
    verts = np.array([[[-half, -half, z_left], [half, -half, z_right], [half, half, z_right], [-half, half, z_left]]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int64)
    return verts, faces


def draw(zb: ZBuffer, verts: np.ndarray, faces: np.ndarray, slot: int = 0, shift: float = 0.0) -> None:
    zb.draw(verts, faces, np.eye(3)[None], np.array([[0.0, 0.0, shift]]), slot)


def frame(zb: ZBuffer, colors=((200.0, 100.0, 50.0),)) -> tuple[np.ndarray, np.ndarray]:
    rgb = np.zeros((H, W, 3), np.uint8)
    depth = np.full((H, W), 10.0, np.float32)
    zb.compose(np.array(colors), rgb, depth)
    return rgb, depth


def test_tilted_plane_depth_is_exact_and_has_no_cracks():
    zb = zbuffer()
    verts, faces = quad(1.0, 1.5)
    draw(zb, verts, faces)
    rgb, depth = frame(zb)
    covered = depth < 10.0
    rows, cols = np.nonzero(covered)
    # every pixel centre inside the projected square is covered: the shared diagonal leaves no crack
    corners = verts[0]
    cu, cv = FX * corners[:, 0] / corners[:, 2] + CX, FY * corners[:, 1] / corners[:, 2] + CY
    vv, uu = np.mgrid[0:H, 0:W]
    inside = np.ones((H, W), bool)
    for i in range(4):
        j = (i + 1) % 4
        inside &= (cu[j] - cu[i]) * (vv - cv[i]) - (cv[j] - cv[i]) * (uu - cu[i]) > 1e-6
    assert inside.sum() > 200 and np.array_equal(covered & inside, inside)
    # the plane through the square: z = 1.25 + 1.25 x, with x = (u - cx) z / fx
    u = cols.astype(np.float64)
    expected = 1.25 / (1.0 - 1.25 * (u - CX) / FX)
    assert np.allclose(depth[covered], expected, rtol=2e-7, atol=0.0)
    # shaded flat colour: one face normal, the same Lambert factor on both triangles
    assert len({tuple(c) for c in rgb[covered]}) == 1


def test_nearest_surface_wins_and_background_in_front_is_kept():
    zb = zbuffer()
    verts, faces = quad(1.0, 1.0)
    draw(zb, verts * [2.0, 2.0, 1.0], faces, slot=0, shift=1.0)  # far square at z = 2, columns 22..41
    draw(zb, verts * [0.5, 0.5, 1.0], faces, slot=1, shift=0.0)  # nearer square at z = 1, columns 27..36
    rgb = np.zeros((H, W, 3), np.uint8)
    depth = np.full((H, W), 10.0, np.float32)
    depth[:, :24] = 0.5  # a background object in front of both at the left
    zb.compose(np.array([(0.0, 0.0, 250.0), (250.0, 0.0, 0.0)]), rgb, depth)
    assert depth[H // 2, W // 2] == pytest.approx(1.0) and tuple(rgb[H // 2, W // 2]) == (250, 0, 0)
    assert depth[H // 2, 39] == pytest.approx(2.0) and tuple(rgb[H // 2, 39]) == (0, 0, 250)
    assert np.all(depth[:, :24] == 0.5) and not rgb[:, :24].any()


def test_compose_clears_the_buffer_and_the_near_plane_is_respected():
    zb = zbuffer()
    verts, faces = quad(1.0, 1.0)
    draw(zb, verts, faces)
    first, _ = frame(zb)
    assert first.any()
    second, depth = frame(zb)  # nothing drawn since: background only
    assert not second.any() and np.all(depth == 10.0)
    draw(zb, verts, faces, shift=-0.995)  # at z = 0.005, in front of the near plane 0.01
    third, _ = frame(zb)
    assert not third.any()
