"""Our renderer (top and side view) against pybullet's TinyRenderer on the same meshes, poses and cameras."""

from __future__ import annotations

import time

import numpy as np

from woody_sim.fillet_model import DEFAULT_SEGMENTS
from woody_sim.line_geometry import LineGeometry
from woody_sim.rendering import LineRenderer, draped_poses, fillet_color, flat_poses, load_reference_visuals
from woody_tools.benchmarks.tiny_renderer import TinyRendererScene


def _bench_poses(g: LineGeometry, offsets: list[tuple[np.ndarray, int]], phase: float) -> dict[int, np.ndarray]:
    """Bench scene at ``phase`` in [0, 1]: fillets spread over the lanes, along the belt and over the roller."""
    poses = {}
    for i, (off, lane) in enumerate(offsets):
        x = -0.45 + 0.5 * ((phase + i / len(offsets)) % 1.0)
        y = g.lane_y(lane)
        poses[i] = flat_poses(off, x, y) if x < -0.1 else draped_poses(off, x, y, g.roller_radius)
    return poses


def benchmark_rendering(
    n_fillets: int = 3, frames: int = 100, geometry: LineGeometry | None = None, n_segments: int = DEFAULT_SEGMENTS,
    baseline_every: int = 6,
) -> dict:
    """Time LineRenderer on the reference meshes (the watched lane always has a fillet in the side view)
    and, on every ``baseline_every``-th frame, pybullet's TinyRenderer on the same scene and cameras.

    Returns ms per frame {top_p50, top_p95, side_p50, side_p95, tiny_top_p50, tiny_side_p50}, the
    speed-ups over TinyRenderer (p50 ratios) and counts.
    """
    g = geometry or LineGeometry()
    r = LineRenderer(g)
    tiny = TinyRendererScene()
    tri = 0
    offsets = []
    for i in range(n_fillets):
        vis, off = load_reference_visuals(i % 3, n_segments)
        tri += sum(len(v.faces) for v in vis)
        lane = (g.watched_lane + i) % g.lanes
        r.add_fillet(i, lane, vis)
        tiny.add_fillet(i, vis, fillet_color(i))
        offsets.append((off, lane))
    times: dict[str, list[float]] = {"top": [], "side": [], "tiny_top": [], "tiny_side": []}
    try:
        for k in range(frames):
            poses = _bench_poses(g, offsets, k / max(frames - 1, 1))
            t0 = time.perf_counter()
            r.render_top(poses)
            t1 = time.perf_counter()
            r.render_side({i: p for i, p in poses.items() if offsets[i][1] == g.watched_lane})
            times["top"].append(t1 - t0)
            times["side"].append(time.perf_counter() - t1)
            if k % baseline_every == 0:
                times["tiny_top"].append(tiny.render(g.top_camera(), poses))
                times["tiny_side"].append(tiny.render(g.side_camera(), poses))
    finally:
        tiny.close()
    ms = {name: np.array(t) * 1e3 for name, t in times.items()}
    out: dict = {"n_fillets": n_fillets, "frames": frames, "triangles": tri}
    for name in ("top", "side"):
        out[f"{name}_ms_p50"] = float(np.percentile(ms[name], 50))
        out[f"{name}_ms_p95"] = float(np.percentile(ms[name], 95))
        out[f"tiny_{name}_ms_p50"] = float(np.percentile(ms[f"tiny_{name}"], 50))
        out[f"{name}_speedup_vs_tiny"] = out[f"tiny_{name}_ms_p50"] / out[f"{name}_ms_p50"]
    return out
