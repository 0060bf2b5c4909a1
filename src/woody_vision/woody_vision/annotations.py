"""The grader's overlays (woody_vision.overlays) as one ``foxglove_msgs/ImageAnnotations`` per top frame, and back.

Each outline is a closed ``PointsAnnotation`` coloured by the fillet's state, with its label as the
``TextAnnotation`` of the same index, just above the outline. Every annotation carries the stamp of the
frame it is drawn on (Foxglove's image panel shows it with that image); a verdict's outlines say in their
label which frame they were taken from.
"""

from __future__ import annotations

import numpy as np
from foxglove_msgs.msg import Color, ImageAnnotations, Point2, PointsAnnotation, TextAnnotation

from woody_common.stamps import seconds_to_stamp, stamp_to_seconds
from woody_vision.overlays import REFERENCE, Overlay, parse_text

COLOURS = {"pending": (1.0, 0.85, 0.0), "normal": (0.0, 0.8, 0.0), "woody": (1.0, 0.0, 0.0),
           "unscored": (0.6, 0.6, 0.6), REFERENCE: (0.0, 0.8, 1.0)}
"""Outline colours: yellow until graded, then green normal, red woody, grey unscored; a verdict's reference
outline cyan (its measuring-point outline has the verdict's colour)."""
FONT_PX = 11.0
LINE_PX = 2.0
LABEL_BACKGROUND = Color(r=0.0, g=0.0, b=0.0, a=0.55)


def _colour(overlay: Overlay) -> Color:
    r, g, b = COLOURS[REFERENCE if overlay.kind == REFERENCE else overlay.label]
    return Color(r=r, g=g, b=b, a=1.0)


def image_annotations(overlays: list[Overlay], stamp: float) -> ImageAnnotations:
    """One frame's annotations: each overlay's outline and, at the same index, its label."""
    msg = ImageAnnotations()
    when = seconds_to_stamp(stamp)
    for overlay in overlays:
        colour = _colour(overlay)
        msg.points.append(PointsAnnotation(
            timestamp=when, type=PointsAnnotation.LINE_LOOP, outline_color=colour, thickness=LINE_PX,
            points=[Point2(x=float(u), y=float(v)) for u, v in overlay.outline]))
        u, v = overlay.outline.min(axis=0) if len(overlay.outline) else (0.0, 0.0)
        msg.texts.append(TextAnnotation(timestamp=when, position=Point2(x=float(u), y=float(max(v - 3.0, 0.0))),
                                        text=overlay.text, font_size=FONT_PX, text_color=colour,
                                        background_color=LABEL_BACKGROUND))
    return msg


def overlays_of(msg: ImageAnnotations) -> list[Overlay]:
    """The overlays a recorded annotations message holds (labels of another format are skipped)."""
    out = []
    for points, text in zip(msg.points, msg.texts):
        outline = np.array([(p.x, p.y) for p in points.points], np.float64).reshape(-1, 2)
        overlay = parse_text(text.text, stamp_to_seconds(points.timestamp), outline)
        if overlay is not None:
            out.append(overlay)
    return out
