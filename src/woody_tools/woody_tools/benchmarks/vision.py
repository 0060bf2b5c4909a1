"""Per-frame cost of the top-down vision path, without ROS: what the segmenter and grader nodes do per frame.

:func:`benchmark_vision` renders realistic 672×376 depth sequences with
:mod:`woody_vision.synthetic` (three 0.16 m lanes at 100 FPM, fillets moving
downstream and over the roller edge, some touching tip-to-tail), learns the
background like the segmenter, and then times, frame by frame on one core,
exactly the per-frame work of the two nodes (OpenCV limited to one thread):

    segment_depth → CentroidTracker.update → TrackObservation list → FilletGrader.on_tracks

Each frame is rendered just before its timed step (like a freshly received
message) and the rendering is not timed. Times are the
thread's CPU time (``time.thread_time``), i.e. the single-core cost, which
other processes on the machine cannot inflate by preempting it; the wall-clock
percentiles are reported alongside (``wall_ms_*``). The number of
fillets in view is measured from the segmented blobs, so a "6 fillets" figure
is checked, not assumed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import cv2
import numpy as np

from woody_common.line import LANE_PITCH_M, LANES
from woody_vision.camera_model import LaneLayout
from woody_vision.grader_core import FilletGrader, TrackObservation
from woody_vision.segmentation import BackgroundModel, SegmentationParams, segment_depth
from woody_vision.synthetic import SPEED_100_FPM, TopScene, lane_streams
from woody_vision.tracking import CentroidTracker

FRAME_RATE_HZ = 30.0
"""Top camera rate (line_sim default ``top_rate_hz``)."""
VISIBLE_TRAVEL_M = 0.70
"""Mean lead-to-lead spacing per lane that keeps one fillet per lane segmented on average (~0.6 m of belt in
view plus the fillet's length and fall, less gaps); calibrated against the blob counts, which the result reports."""
BACKGROUND_FRAMES = 5
WARMUP_FRAMES = 10
"""Frames run before timing starts (first-call allocations), not counted in the figures."""


def benchmark_vision(frames: int = 300, fillets: tuple[int, ...] = (3, 6), seed: int = 7) -> dict:
    """Time the segmenter + grader per-frame work on synthetic streams with ~3 and ~6 fillets in view.

    Returns ``frame_ms_p50``/``frame_ms_p95`` for the 6-fillet stream,
    ``frame_ms_p50_3``/``frame_ms_p95_3`` for the 3-fillet one,
    ``fillets_in_view_mean_6``/``_3`` (mean blobs per timed frame) and
    ``verdicts`` (total over all streams; ``verdicts_n``/``scored_n`` per stream); for any other count n in
    ``fillets`` the keys carry the suffix ``_n``.
    """
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    if not fillets:
        raise ValueError("fillets must name at least one fillets-in-view count")
    out: dict = {"frames": frames}
    verdicts = 0
    with _single_core():
        for n in fillets:
            stats = run_stream(n, frames, seed=seed)
            verdicts += stats["verdicts"]
            suffix = "" if n == 6 else f"_{n}"
            out[f"frame_ms_p50{suffix}"] = stats["frame_ms_p50"]
            out[f"frame_ms_p95{suffix}"] = stats["frame_ms_p95"]
            out[f"frame_ms_max{suffix}"] = stats["frame_ms_max"]
            out[f"wall_ms_p50{suffix}"] = stats["wall_ms_p50"]
            out[f"wall_ms_p95{suffix}"] = stats["wall_ms_p95"]
            out[f"fillets_in_view_mean_{n}"] = stats["fillets_in_view_mean"]
            out[f"verdicts_{n}"] = stats["verdicts"]
            out[f"scored_{n}"] = stats["scored"]
    out["verdicts"] = verdicts
    return out


def make_scene(fillets_in_view: int, frames: int, seed: int = 7) -> TopScene:
    """Three lanes with fillets spaced so that about ``fillets_in_view`` are segmented at any time."""
    per_lane_in_view = fillets_in_view / LANES
    pitch = VISIBLE_TRAVEL_M / per_lane_in_view
    travel = SPEED_100_FPM * (frames + WARMUP_FRAMES) / FRAME_RATE_HZ
    # each lane's first fillet starts up to one pitch upstream of 0.25 m past the edge: the view is full at once
    start_lead = 0.25
    per_lane = int(math.ceil((travel + VISIBLE_TRAVEL_M + start_lead + 0.5) / pitch)) + 1
    return TopScene(lane_streams(LANES, per_lane, pitch, lane_pitch_m=LANE_PITCH_M, seed=seed,
                                 start_lead_m=start_lead))


NEAR_VIEW_LEAD_M = (-0.75, 1.5)
"""Leads (m from the edge) outside which a fillet cannot be in the top view (upstream of the image, or gone)."""


def render_near_view(scene: TopScene, t: float) -> tuple[np.ndarray, np.ndarray]:
    """``scene.render(t)`` drawing only the fillets that can be in view (the same pixels, much faster)."""
    near = [f for f in scene.fillets if NEAR_VIEW_LEAD_M[0] < f.lead_m + f.speed_mps * t < NEAR_VIEW_LEAD_M[1]]
    return replace(scene, fillets=near).render(t)


def run_stream(fillets_in_view: int, frames: int, seed: int = 7) -> dict:
    """Time the per-frame vision work on one rendered stream (each frame is rendered just before, untimed)."""
    scene = make_scene(fillets_in_view, frames, seed)
    background = BackgroundModel(BACKGROUND_FRAMES)
    empty = scene.background_depth()
    for _ in range(BACKGROUND_FRAMES):
        background.add(empty)
    params = SegmentationParams()
    tracker = CentroidTracker(lane_layout=LaneLayout(scene.k, scene.camera_height_m, LANES, LANE_PITCH_M))
    grader = FilletGrader(scene.edge_row)
    bg = background.depth
    times: list[float] = []
    wall_times: list[float] = []
    blobs_per_frame: list[int] = []
    verdicts: list = []
    for i in range(frames + WARMUP_FRAMES):
        stamp = i / FRAME_RATE_HZ
        _, depth = render_near_view(scene, stamp)  # like a just-received message: fresh, not timed
        w0, t0 = time.perf_counter(), time.thread_time()
        blobs = segment_depth(depth, bg, params, priors=tracker.predicted_outlines(stamp))
        update = tracker.update(blobs, stamp)
        observations = [TrackObservation(t.track_id, t.lane, t.blob.contour, t.unseen) for t in update.active]
        decided = grader.on_tracks(stamp, observations, [t.track_id for t in update.ended])
        cpu, wall = time.thread_time() - t0, time.perf_counter() - w0
        verdicts += decided
        if i >= WARMUP_FRAMES:
            times.append(cpu * 1e3)
            wall_times.append(wall * 1e3)
            blobs_per_frame.append(len(blobs))
    ms = np.asarray(times)
    return {
        "frame_ms_p50": float(np.percentile(ms, 50)),
        "frame_ms_p95": float(np.percentile(ms, 95)),
        "frame_ms_max": float(ms.max()),
        "wall_ms_p50": float(np.percentile(wall_times, 50)),
        "wall_ms_p95": float(np.percentile(wall_times, 95)),
        "fillets_in_view_mean": float(np.mean(blobs_per_frame)),
        "verdicts": len(verdicts),
        "scored": sum(1 for v in verdicts if v.scored),
    }


@contextmanager
def _single_core() -> Iterator[None]:
    """OpenCV on one thread while timing (numpy and scipy calls here are single-threaded anyway); restored after."""
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(threads)


if __name__ == "__main__":
    import json

    print(json.dumps(benchmark_vision(), indent=2))
