"""woody_vision.tracking: stable ids and lanes over many frames, track ends, prediction across missed frames.

Frames come from woody_vision.synthetic (a nadir pinhole camera over the belt end).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from woody_common.line import TOP_CAMERA_HEIGHT_M
from woody_vision.camera_model import LaneLayout, lane_center_u
from woody_vision.segmentation import (
    DEFAULT_HEIGHT_THRESHOLD_M,
    Blob,
    segment_depth,
)
from woody_vision.synthetic import (
    DEFAULT_TOP_K,
    TopFillet,
    TopScene,
)
from woody_vision.tracking import CentroidTracker, TrackUpdate

FPS = 30.0
LAYOUT3 = LaneLayout(DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 3, 0.16)
L = 0.19
"""Length (m) of the drawn fillets, as in test_segmentation."""


def fillet_masks(fillets, t: float) -> list[np.ndarray]:
    """Each fillet rendered alone: its own pixel mask (the ground truth for matching blobs)."""
    out = []
    for fillet in fillets:
        scene = TopScene([fillet])
        out.append((scene.background_depth() - scene.render(t)[1]) > DEFAULT_HEIGHT_THRESHOLD_M)
    return out


def owner(blob: Blob, masks: list[np.ndarray]) -> int:
    """Index of the fillet whose own pixels cover most of the blob (-1 if none covers half of it)."""
    filled = np.zeros(masks[0].shape, np.uint8)
    cv2.fillPoly(filled, [blob.contour.reshape(-1, 1, 2)], 1)
    overlaps = [int(np.count_nonzero(filled.astype(bool) & m)) for m in masks]
    best = int(np.argmax(overlaps))
    return best if overlaps[best] >= 0.5 * blob.area_px else -1


def square_blob(u: float, v: float, half: int = 15) -> Blob:
    contour = np.array([[u - half, v - half], [u + half, v - half], [u + half, v + half], [u - half, v + half]],
                       np.int32)
    return Blob(contour=contour, centroid=(float(u), float(v)), area_px=(2 * half) ** 2,
                bbox=(int(u - half), int(v - half), 2 * half, 2 * half), mean_height_m=0.02)


def test_ids_stable_and_lanes_right_over_50_frames_of_several_fillets():
    """9 fillets in 3 lanes (one touching pair) pass the view: one id per fillet for its whole passage."""
    across = {0: 0.16, 1: 0.0, 2: -0.16}
    leads = {0: [-0.05, -0.33, -0.62], 1: [-0.15, -0.15 - L + 0.005, -0.64], 2: [0.02, -0.30, -0.60]}
    fillets, lanes = [], []
    for lane, lane_leads in leads.items():
        for k, lead in enumerate(lane_leads):
            fillets.append(TopFillet(lead_m=lead, across_m=across[lane], curvature_per_m=3.0 + 5.0 * k))
            lanes.append(lane)
    scene = TopScene(fillets)
    background = scene.background_depth()
    tracker = CentroidTracker(lane_layout=LAYOUT3)
    ids_of_fillet: dict[int, set[int]] = {}
    fillets_of_id: dict[int, set[int]] = {}
    seen_frames: dict[int, int] = {}
    visible_frames: dict[int, int] = {}
    ended: list[int] = []
    for i in range(50):
        t = i / FPS
        blobs = segment_depth(scene.render(t)[1], background)
        update = tracker.update(blobs, t)
        ended += [track.track_id for track in update.ended]
        masks = fillet_masks(fillets, t)
        for k, m in enumerate(masks):
            if np.count_nonzero(m) >= 1500:
                visible_frames[k] = visible_frames.get(k, 0) + 1
        by_blob = {id(track.blob): track for track in update.active if track.unseen == 0}
        assert len(by_blob) == len(blobs), "every blob of this frame belongs to a track seen now"
        for blob in blobs:
            track = by_blob[id(blob)]
            k = owner(blob, masks)
            assert k >= 0, f"frame {i}: blob at {blob.centroid} is not mostly one fillet"
            ids_of_fillet.setdefault(k, set()).add(track.track_id)
            fillets_of_id.setdefault(track.track_id, set()).add(k)
            seen_frames[k] = seen_frames.get(k, 0) + 1
            assert track.lane == lanes[k], f"fillet {k} in lane {lanes[k]} tracked in lane {track.lane}"
    assert set(ids_of_fillet) == set(range(len(fillets))), "every fillet was segmented at some point"
    assert all(len(ids) == 1 for ids in ids_of_fillet.values()), ids_of_fillet
    assert all(len(ks) == 1 for ks in fillets_of_id.values()), fillets_of_id
    for k, frames in visible_frames.items():
        assert seen_frames.get(k, 0) >= 0.9 * frames, f"fillet {k} segmented in too few of its frames"
    # the three leaders fell past the edge long enough ago that their tracks ended, once each
    leaders = [next(iter(ids_of_fillet[k])) for k in (0, 3, 6)]
    assert sorted(set(ended) & set(leaders)) == sorted(leaders) and len(ended) == len(set(ended))


def test_track_ends_after_max_unseen_frames_exactly_once():
    tracker = CentroidTracker(max_unseen=5)
    for i, v in enumerate((100, 110, 120)):
        update = tracker.update([square_blob(300, v)], i / FPS)
    (track,) = update.active
    for missed in range(1, 5):
        update = tracker.update([], (2 + missed) / FPS)
        assert [t.unseen for t in update.active] == [missed] and not update.ended
        assert update.active[0].blob.centroid == (300.0, 120.0)  # stale blob kept
    update = tracker.update([], 7 / FPS)
    assert update.active == [] and [t.track_id for t in update.ended] == [track.track_id]
    assert update.ended[0].unseen == 5
    assert tracker.update([], 8 / FPS) == TrackUpdate(active=[], ended=[])


def test_new_blobs_open_new_tracks_and_ids_are_never_reused():
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=2)
    first = tracker.update([square_blob(100, 100)], 0.0).active[0].track_id
    update = tracker.update([square_blob(100, 108), square_blob(400, 100)], 1 / FPS)  # beyond the gate: new track
    assert [t.track_id for t in update.active] == [first, first + 1]
    assert update.active[0].age == 2 and update.active[1].age == 1
    tracker.update([], 2 / FPS)
    update = tracker.update([], 3 / FPS)
    assert sorted(t.track_id for t in update.ended) == [first, first + 1]
    reopened = tracker.update([square_blob(100, 116)], 4 / FPS).active
    assert [t.track_id for t in reopened] == [first + 2]
    tracker.reset()
    assert tracker.update([square_blob(100, 116)], 5 / FPS).active[0].track_id == first + 3


def test_prediction_bridges_frames_the_segmenter_saw_empty():
    tracker = CentroidTracker(max_distance_px=20.0)
    for i, v in enumerate((100, 110, 120)):
        (track,) = tracker.update([square_blob(200, v)], i / FPS).active
    tracker.update([], 3 / FPS)
    tracker.update([], 4 / FPS)
    (again,) = tracker.update([square_blob(200, 150)], 5 / FPS).active  # 30 px from the last sighting, 0 predicted
    assert again.track_id == track.track_id and again.unseen == 0
    assert again.velocity == pytest.approx((10.0 * FPS, 10.0 * FPS))  # (trailing, leading) edge


def test_prediction_bridges_frames_that_never_arrived():
    """A burst of frames lost before the segmenter (camera, network) is timed by the stamps, not by updates."""
    tracker = CentroidTracker(max_distance_px=20.0)
    for i, v in enumerate((100, 110, 120)):
        (track,) = tracker.update([square_blob(200, v)], i / FPS).active
    (again,) = tracker.update([square_blob(200, 200)], 10 / FPS).active  # 8 frames lost: 80 px on
    assert again.track_id == track.track_id and again.age == 4


def test_a_burst_of_lost_frames_right_after_entering_the_view_keeps_the_id():
    """Entering from the image border the centroid moves at half speed, so the velocity is short; the gate widens
    with the predicted motion and the fillet keeps its track across 12 lost frames."""
    tracker = CentroidTracker(max_distance_px=40.0)
    for i, v in enumerate((20, 24, 28)):  # growing out of the border: 4 px a frame, the belt moves 8
        (track,) = tracker.update([square_blob(300, v)], i / FPS).active
    (again,) = tracker.update([square_blob(300, 28 + 13 * 8)], 15 / FPS).active  # predicted 80 px short
    assert again.track_id == track.track_id
    far = CentroidTracker(max_distance_px=40.0)  # the widening is bounded: a blob much farther is another fillet
    for i, v in enumerate((20, 24, 28)):
        far.update([square_blob(300, v)], i / FPS)
    assert far.update([square_blob(300, 28 + 13 * 20)], 15 / FPS).active[-1].track_id != track.track_id


def test_stale_track_ghost_does_not_steal_a_live_tracks_blob():
    """A fillet falling off the edge moves backwards in the image; its extrapolated ghost must not take over."""
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=15)
    for i in range(3):
        update = tracker.update([square_blob(300, 300 - 2 * i), square_blob(300, 200 + 6 * i)], i / FPS)
    ghost, live = (t.track_id for t in sorted(update.active, key=lambda t: -t.blob.centroid[1]))
    for i in range(3, 13):
        v = 200 + 6 * i + (3 if i == 12 else 0)  # at frame 12 the ghost's prediction (276) is nearer than live's
        update = tracker.update([square_blob(300, v)], i / FPS)
        matched = [t.track_id for t in update.active if t.unseen == 0]
        assert matched == [live], f"frame {i}"
    assert ghost in [t.track_id for t in update.active]


def test_a_ghost_stalled_at_the_edge_moves_on_with_the_belt_and_leaves_the_next_fillet_its_own_track():
    """A fillet tipping over the roller stalls its visible centroid, then vanishes; the next fillet of its lane
    arrives at that place 14 frames later and must open a track of its own, not continue the stalled one."""
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=15)
    for i in range(4):  # the tipping fillet stalls at v 280 while its neighbour lane's rides at 12 px a frame
        update = tracker.update([square_blob(300, 280), square_blob(500, 20 + 12 * i)], i / FPS)
    stalled = next(t.track_id for t in update.active if t.blob.centroid[0] == 300)
    for i in range(4, 18):
        update = tracker.update([square_blob(500, 20 + 12 * i)] + ([square_blob(300, 282)] if i == 17 else []),
                                i / FPS)
    follower = next(t for t in update.active if t.blob.centroid[0] == 300 and t.unseen == 0)
    assert follower.track_id != stalled


def test_lane_from_the_mean_column():
    tracker = CentroidTracker(lane_layout=LAYOUT3)
    blobs = [square_blob(LAYOUT3.lane_center_u(lane) + offset, 100) for lane, offset in ((0, 25), (1, -25), (2, 10))]
    update = tracker.update(blobs, 0.0)
    assert {round(t.blob.centroid[0]): t.lane for t in update.active} == {
        round(b.centroid[0]): lane for b, lane in zip(blobs, (0, 1, 2))}
    assert LAYOUT3.lane_center_u(0) > LAYOUT3.lane_center_u(1) > LAYOUT3.lane_center_u(2)  # lane 0 on the right
    assert LAYOUT3.lane_of_u(10_000) == 0 and LAYOUT3.lane_of_u(-10_000) == 2  # clamped
    no_layout = CentroidTracker().update([square_blob(100, 100)], 0.0).active[0]
    assert no_layout.lane == -1
    assert lane_center_u(1, DEFAULT_TOP_K, TOP_CAMERA_HEIGHT_M, 3, 0.16) == pytest.approx(DEFAULT_TOP_K[2])


def test_tracker_validates_its_options():
    with pytest.raises(ValueError):
        CentroidTracker(max_distance_px=0.0)
    with pytest.raises(ValueError):
        CentroidTracker(max_unseen=0)


def test_a_fillet_whose_blob_merged_for_a_while_takes_it_back_from_a_fresher_ghost():
    """Crowded lanes: a fillet's blob merges with its neighbour's for five frames (its track goes unseen), while
    the tail of the fillet ahead hangs at the edge and vanishes a frame before the merge ends. The blob coming
    back is the long-unseen track's (its prediction hits it), not the fresher ghost's 24 px away."""
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=15)
    for i in range(3):
        update = tracker.update([square_blob(320, 270), square_blob(340, 200 + 8 * i)], i / FPS)
    ahead, fillet = (t.track_id for t in sorted(update.active, key=lambda t: -t.blob.centroid[1]))
    for i in range(3, 7):  # the fillet's blob is part of a neighbour's (not among this lane's blobs)
        tracker.update([square_blob(320, 270)] if i < 6 else [], i / FPS)
    update = tracker.update([square_blob(340, 200 + 8 * 7)], 7 / FPS)
    assert [t.track_id for t in update.active if t.unseen == 0] == [fillet]
    assert ahead in [t.track_id for t in update.active]


def test_a_blob_merged_with_the_next_lanes_for_a_frame_does_not_hand_the_track_across():
    """Two lanes 60 px apart: one frame, the left fillet's blob merges with the right one's (one wide blob in
    between, the left track takes it). Next frame both are apart again: each track keeps its own fillet, because
    a fillet rides the belt along the rows and the merged blob's sideways jump is no motion."""
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=15)
    for i in range(4):
        update = tracker.update([square_blob(360, 200 + 10 * i), square_blob(420, 210 + 10 * i)], i / FPS)
    left, right = (t.track_id for t in sorted(update.active, key=lambda t: t.blob.centroid[0]))
    tracker.update([square_blob(388, 250, half=30)], 4 / FPS)  # the merged blob, nearer the left prediction
    update = tracker.update([square_blob(360, 250), square_blob(420, 260)], 5 / FPS)
    columns = {t.track_id: t.blob.centroid[0] for t in update.active if t.unseen == 0}
    assert columns == {left: 360.0, right: 420.0}


def test_a_fillet_merged_with_the_one_hanging_ahead_for_a_frame_keeps_its_track_from_the_piece_beside_it():
    """A fillet reaches the edge while the one ahead of it still hangs there: for one frame their blobs merge (the
    centroid jumps 26 px ahead, and with it the next prediction) and a piece split off opens a track beside it.
    Next frame the fillet's blob is nearer the piece's track than the fillet's own jumped prediction, and still
    stays with the fillet's track: a track opened a frame ago does not outbid an established one."""
    tracker = CentroidTracker(max_distance_px=40.0, max_unseen=15)
    for i in range(6):
        update = tracker.update([square_blob(385, 173 + 11 * i)], i / FPS)
    (fillet,) = (t.track_id for t in update.active)
    tracker.update([square_blob(386, 254, half=30), square_blob(368, 263, half=8)], 6 / FPS)
    update = tracker.update([square_blob(384, 250)], 7 / FPS)
    assert [t.track_id for t in update.active if t.unseen == 0] == [fillet]


def test_predicted_outlines_are_the_seen_established_tracks_moved_by_their_motion():
    tracker = CentroidTracker()
    for i in range(3):
        tracker.update([square_blob(100.0, 50.0 + 10.0 * i), square_blob(300.0, 20.0)], i / FPS)
    tracker.update([square_blob(100.0, 80.0)], 3 / FPS)  # the second fillet goes unseen
    (outline,) = tracker.predicted_outlines(5 / FPS)  # two frames on, at 10 px per frame
    assert np.array_equal(outline, square_blob(100.0, 100.0).contour)
    assert CentroidTracker().predicted_outlines(0.0) == []


def blob_rows(u: float, trailing: float, leading: float, half: int = 25) -> Blob:
    """A box blob spanning rows ``trailing`` .. ``leading`` around column ``u``."""
    contour = np.array([[u - half, trailing], [u + half, trailing], [u + half, leading], [u - half, leading]],
                       np.int32)
    rows = int(leading - trailing) + 1
    return Blob(contour=contour, centroid=(float(u), (trailing + leading) / 2.0), area_px=2 * half * rows,
                bbox=(int(u - half), int(trailing), 2 * half, rows), mean_height_m=0.02)


def test_a_fillet_tipping_over_the_roller_is_followed_by_its_trailing_edge_riding_the_belt():
    """Past the edge the visible outline shortens from the front (its centroid stalls, then jumps back when the
    hanging part vanishes) while the trailing edge keeps the belt's 10 px a frame: one track throughout, and a
    lane-mate arriving behind keeps its own."""
    tracker = CentroidTracker(max_distance_px=20.0)
    for i in range(6):  # flat, 100 rows long
        (track,) = tracker.update([blob_rows(300, 100 + 10 * i, 200 + 10 * i)], i / FPS).active
    for i, lead in enumerate((255, 258, 260, 262, 215, 216), start=6):  # tipping: the front falls away
        trailing = 100 + 10 * i
        update = tracker.update([blob_rows(300, trailing, lead), blob_rows(300, trailing - 120, trailing - 20)],
                                i / FPS)
        owners = {t.blob.bbox[1]: t.track_id for t in update.active if t.unseen == 0}
        assert owners[trailing] == track.track_id, f"frame {i}"


def test_a_track_that_left_the_image_border_never_takes_a_blob_at_the_border():
    """A fillet whose blob is missing for a frame (merged with a neighbour's) lies 36 px ahead of the next fillet of
    its lane entering the view: within the gate, but a fillet that has left the border never reaches it again. Its
    track waits and takes its own blob back; the entering fillet opens its own."""
    tracker = CentroidTracker(max_distance_px=40.0)
    for i in range(17):  # entering, then whole in view at 8 px a frame: trailing edge at row 28
        (fillet,) = tracker.update([blob_rows(300, max(0, 8 * i - 100), 8 * i + 20)], i / FPS).active
    update = tracker.update([blob_rows(300, 0, 14)], 17 / FPS)
    assert next(t for t in update.active if t.track_id == fillet.track_id).unseen == 1
    update = tracker.update([blob_rows(300, 44, 164), blob_rows(300, 0, 22)], 18 / FPS)
    owners = {t.blob.bbox[1]: t.track_id for t in update.active if t.unseen == 0}
    assert owners[44] == fillet.track_id and owners[0] != fillet.track_id
