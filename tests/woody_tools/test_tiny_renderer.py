"""The TinyRenderer yardstick sees the scene our renderer sees: same camera, same fillet, same pixels."""

from __future__ import annotations

import numpy as np
import pybullet

from woody_sim.line_geometry import LineGeometry
from woody_sim.rendering import LineRenderer, draped_poses, fillet_color, load_reference_visuals
from woody_tools.benchmarks.tiny_renderer import TinyRendererScene, projection_matrix, view_matrix


def test_opengl_matrices_project_like_the_pinhole_camera():
    camera = LineGeometry().top_camera()
    points = np.array([[-0.3, 0.1, 0.0], [0.05, -0.2, -0.05], [-0.1, 0.0, 0.02]])
    view = np.array(view_matrix(camera)).reshape(4, 4).T
    proj = np.array(projection_matrix(camera)).reshape(4, 4).T
    clip = proj @ view @ np.c_[points, np.ones(len(points))].T
    ndc = clip[:2] / clip[3]
    u = (ndc[0] + 1.0) / 2.0 * camera.width - 0.5
    v = (1.0 - ndc[1]) / 2.0 * camera.height - 0.5
    expected = camera.project(points)
    assert np.allclose(np.c_[u, v], expected, atol=0.6)  # GL's principal point is the image centre


def test_tiny_renderer_covers_the_pixels_our_renderer_covers():
    g = LineGeometry()
    visuals, offsets = load_reference_visuals(0, 40)
    poses = {0: draped_poses(offsets, -0.1, g.lane_y(1), g.roller_radius)}
    ours = LineRenderer(g, render_side=False)
    ours.add_fillet(0, 1, visuals)
    covered = ours.render_top({})[1] - ours.render_top(poses)[1] > 0.002
    tiny = TinyRendererScene()
    try:
        tiny.add_fillet(0, visuals, fillet_color(0))
        assert tiny.render(g.top_camera(), poses) > 0.0
        cam = g.top_camera()
        *_, seg = pybullet.getCameraImage(cam.width, cam.height, view_matrix(cam), projection_matrix(cam),
                                          renderer=pybullet.ER_TINY_RENDERER, physicsClientId=tiny._client)
    finally:
        tiny.close()
    theirs = np.asarray(seg).reshape(cam.height, cam.width) >= 0
    assert covered.sum() > 2000
    assert (covered & theirs).sum() > 0.9 * max(covered.sum(), theirs.sum())
