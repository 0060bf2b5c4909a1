"""pybullet's own CPU renderer (TinyRenderer) on the bench scene: the same-run yardstick for ours.

Machines differ about 2x, so a render time alone says little; the ratio to
``getCameraImage`` on the same meshes, poses and camera, timed in the same
run, does. The scene is posed as in :func:`woody_tools.benchmarks.rendering.benchmark_rendering`:
every chain segment is one visual-only body, re-posed every frame.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np
import pybullet

from woody_sim.line_geometry import PinholeCamera


def view_matrix(camera: PinholeCamera) -> list[float]:
    """OpenGL view matrix (column-major) of a camera whose optical frame is x right, y down, z forward."""
    rot = np.asarray(camera.rotation, dtype=np.float64) * [1.0, -1.0, -1.0]  # optical -> OpenGL eye axes
    world_to_eye = np.eye(4)
    world_to_eye[:3, :3] = rot.T
    world_to_eye[:3, 3] = -rot.T @ np.asarray(camera.position, dtype=np.float64)
    return world_to_eye.T.reshape(-1).tolist()


def projection_matrix(camera: PinholeCamera) -> list[float]:
    """OpenGL projection with the camera's vertical field of view, aspect ratio and clip planes."""
    fov = math.degrees(2.0 * math.atan(0.5 * camera.height / camera.fy))
    return list(pybullet.computeProjectionMatrixFOV(fov, camera.width / camera.height, camera.near, camera.far))


class TinyRendererScene:
    """Segment meshes as visual-only pybullet bodies in a DIRECT client of their own."""

    def __init__(self) -> None:
        self._client = pybullet.connect(pybullet.DIRECT)
        self._bodies: dict[int, list[int]] = {}

    def add_fillet(self, fillet_id: int, visuals: Sequence, rgb: Sequence[int]) -> None:
        colour = [c / 255.0 for c in rgb] + [1.0]
        bodies = []
        for vis in visuals:
            shape = pybullet.createVisualShape(
                pybullet.GEOM_MESH, vertices=np.asarray(vis.vertices, np.float64).tolist(),
                indices=np.asarray(vis.faces, np.int64).reshape(-1).tolist(), rgbaColor=colour,
                physicsClientId=self._client)
            bodies.append(pybullet.createMultiBody(0.0, -1, shape, physicsClientId=self._client))
        self._bodies[fillet_id] = bodies

    def render(self, camera: PinholeCamera, poses: dict[int, np.ndarray]) -> float:
        """Pose the fillets, take one RGB-D image; returns the seconds getCameraImage took."""
        for fid, pose in poses.items():
            for body, p in zip(self._bodies[fid], pose):
                pybullet.resetBasePositionAndOrientation(body, p[:3].tolist(), p[3:7].tolist(),
                                                         physicsClientId=self._client)
        t0 = time.perf_counter()
        pybullet.getCameraImage(camera.width, camera.height, view_matrix(camera), projection_matrix(camera),
                                renderer=pybullet.ER_TINY_RENDERER, physicsClientId=self._client)
        return time.perf_counter() - t0

    def close(self) -> None:
        if self._client >= 0:
            pybullet.disconnect(physicsClientId=self._client)
            self._client = -1
