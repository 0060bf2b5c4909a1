"""woody_vision.overlays: the grader's outlines lie on their fillet in the colour frame, and their labels read back.

A synthetic top scene (woody_vision.synthetic) runs through segmentation, tracking and the grader core; every
outline an overlay would draw (each frame's contour, the verdict's reference and measuring-point outlines) is
filled and must cover fillet pixels of the colour image at its stamp, not belt or floor.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from woody_common.line import TOP_CAMERA_HEIGHT_M
from woody_vision.annotations import image_annotations, overlays_of
from woody_vision.camera_model import LaneLayout
from woody_vision.grader_core import FilletGrader, TrackObservation
from woody_vision.grading import GradingRules
from woody_vision.overlays import FRAME, MEASURED, REFERENCE, Overlay, outline, parse_text, verdict_overlays
from woody_vision.segmentation import segment_depth
from woody_vision.synthetic import DEFAULT_TOP_K, TopFillet, TopScene
from woody_vision.tracking import CentroidTracker

FPS = 30.0


def run_scene(scene: TopScene, frames: int) -> tuple[list[Overlay], list, dict[float, np.ndarray]]:
    """(every frame's overlay, the verdicts, colour image by stamp) of the scene through the grader core."""
    background = scene.background_depth()
    tracker = CentroidTracker(lane_layout=LaneLayout(DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 3, 0.16))
    grader = FilletGrader(scene.edge_row, GradingRules(0.05), pixels_per_metre=scene.k[4] / TOP_CAMERA_HEIGHT_M)
    overlays, verdicts, images = [], [], {}
    for i in range(frames):
        t = i / FPS
        rgb, depth = scene.render(t)
        images[t] = rgb
        update = tracker.update(segment_depth(depth, background), t)
        tracks = [TrackObservation(tr.track_id, tr.lane, tr.blob.contour, tr.unseen) for tr in update.active]
        verdicts += grader.on_tracks(t, tracks, [tr.track_id for tr in update.ended])
        overlays += [Overlay(tr.track_id, tr.lane, "pending", FRAME, t, outline(tr.contour),
                             phi=grader.frame_phi(tr.track_id, t)) for tr in tracks if not tr.unseen]
    return overlays, verdicts, images


def fillet_share(overlay: Overlay, rgb: np.ndarray, belt: np.ndarray) -> float:
    """Share of the outline's filled interior that is fillet in the colour image (not belt or floor)."""
    inside = np.zeros(rgb.shape[:2], np.uint8)
    cv2.fillPoly(inside, [np.round(overlay.outline).astype(np.int32).reshape(-1, 1, 2)], 1)
    fillet = np.any(rgb != belt, axis=2)
    return float(fillet[inside.astype(bool)].mean())


def test_every_overlay_outline_lies_on_its_fillet_in_the_colour_frame():
    scene = TopScene([TopFillet(lead_m=-0.12, across_m=0.0, curvature_per_m=8.0),
                      TopFillet(lead_m=-0.20, across_m=0.16, curvature_per_m=1.0)])
    overlays, verdicts, images = run_scene(scene, 45)
    belt = scene.background_rgb()
    assert len(verdicts) == 2 and all(v.scored for v in verdicts), [v.shape.reason for v in verdicts]
    outlines = [o for v in verdicts for o in verdict_overlays(v)]
    assert sorted(o.kind for o in outlines) == [MEASURED, MEASURED, REFERENCE, REFERENCE]
    for overlay in overlays + outlines:
        share = fillet_share(overlay, images[overlay.stamp], belt)
        assert share >= 0.9, (overlay.kind, overlay.track_id, overlay.stamp, share)
    # the label of a frame carries Φ_t once the window is open, and the verdict's the score and cut
    assert any(math.isfinite(o.phi) for o in overlays) and any(math.isnan(o.phi) for o in overlays)
    assert all(o.score == v.score and o.cut == v.threshold for v in verdicts for o in verdict_overlays(v))


def test_a_label_reads_back_from_its_text():
    points = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 1.0]])
    frame = Overlay(7, 1, "pending", FRAME, 1.5, points, phi=12.3456)
    assert frame.text == "7 lane 1 pending Φ_t 12.346"
    back = parse_text(frame.text, 1.5, points)
    assert (back.track_id, back.lane, back.label, back.kind, back.stamp) == (7, 1, "pending", FRAME, 1.5)
    assert back.phi == 12.346
    reference = Overlay(7, 1, "woody", REFERENCE, 1.0 / 3.0, points, score=3.21, cut=math.nan)
    assert reference.text == "7 lane 1 woody reference score 3.210 cut - frame 0.333333333 s"
    back = parse_text(reference.text, 2.0, points)  # drawn on a later frame, read back with its own frame's stamp
    assert back.kind == REFERENCE and back.score == 3.21 and math.isnan(back.cut) and back.stamp == 0.333333333
    assert parse_text("lane1/woody/id 7", 1.0, points) is None  # a label of another format is skipped


def test_one_frames_annotations_hold_each_outline_with_its_label_and_read_back():
    points = np.array([[10.0, 20.0], [30.0, 20.0], [20.0, 40.0]])
    overlays = [Overlay(7, 1, "pending", FRAME, 1.5, points, phi=12.3),
                Overlay(8, 2, "woody", REFERENCE, 1.2, points + 5, score=3.2, cut=5.1),
                Overlay(8, 2, "woody", MEASURED, 1.4, points + 9, score=3.2, cut=5.1)]
    msg = image_annotations(overlays, 1.5)
    assert len(msg.points) == len(msg.texts) == 3 and not msg.circles
    assert all(p.type == p.LINE_LOOP and len(p.points) == 3 and p.timestamp.sec == 1 for p in msg.points)
    assert [t.text for t in msg.texts] == [o.text for o in overlays]
    assert msg.points[0].outline_color.g > 0.8 and msg.points[1].outline_color.b == 1.0  # pending, reference
    assert msg.texts[0].position.y < points[:, 1].min()  # the label sits above its outline
    back = overlays_of(msg)
    assert [(o.track_id, o.kind, o.stamp) for o in back] == [(7, FRAME, 1.5), (8, REFERENCE, 1.2), (8, MEASURED, 1.4)]
    assert np.allclose(back[2].outline, points + 9)
