"""What the grader draws on the top image (grading/annotations), as plain data both it and `woody report` share.

Each outline goes out with a text label beside it (``foxglove_msgs/ImageAnnotations``: the i-th outline and
the i-th label belong together), which a viewer draws and :func:`parse_text` reads back:

- every frame, each track's contour: ``7 lane 1 pending Φ_t 12.35`` (``Φ_t -`` when the frame was not scored);
- at the verdict, two outlines of the frames they were taken from, drawn over the frame that closed the
  window: ``7 lane 1 woody reference score 3.210 cut 5.100 frame 12.333333333 s`` (the flat reference) and
  ``7 lane 1 woody measured score ... frame ... s`` (the frame nearest the measuring point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

REFERENCE = "reference"
MEASURED = "measured"
FRAME = "frame"


@dataclass(frozen=True)
class Overlay:
    """One outline of one fillet: what a marker carries and what the report reads back from it."""

    track_id: int
    lane: int
    label: str
    kind: str
    """FRAME (every frame), REFERENCE or MEASURED (at the verdict)."""
    stamp: float
    outline: np.ndarray
    """(N, 2) pixel polygon."""
    phi: float = math.nan
    """FRAME: Φ_t of this frame."""
    score: float = math.nan
    """REFERENCE / MEASURED: the score the verdict used."""
    cut: float = math.nan
    """REFERENCE / MEASURED: the reject cut it was compared with."""

    @property
    def text(self) -> str:
        """The label drawn beside the outline (module doc)."""
        head = f"{self.track_id} lane {self.lane} {self.label}"
        if self.kind == FRAME:
            return f"{head} Φ_t {_number(self.phi)}"
        return f"{head} {self.kind} score {_number(self.score)} cut {_number(self.cut)} frame {self.stamp:.9f} s"


def outline(contour: np.ndarray) -> np.ndarray:
    """A contour thinned to the polygon a marker draws (1 px tolerance)."""
    return cv2.approxPolyDP(np.asarray(contour, np.int32).reshape(-1, 1, 2), 1.0, True).reshape(-1, 2)


def verdict_overlays(graded) -> list[Overlay]:
    """The reference outline and the measuring-point outline of a woody_vision.grader_core.GradedFillet."""
    shape, out = graded.shape, []
    for kind, contour, stamp in ((REFERENCE, shape.reference_contour, shape.reference_stamp),
                                 (MEASURED, shape.line_contour, shape.line_stamp)):
        if contour is not None and stamp is not None:
            out.append(Overlay(graded.fillet_id, max(graded.lane, 0), graded.label, kind, stamp, outline(contour),
                               score=graded.score, cut=graded.threshold))
    return out


def parse_text(text: str, stamp: float, points: np.ndarray) -> Overlay | None:
    """The overlay a label describes (None for a label of another format); ``stamp`` is the annotation's, which a
    verdict's outline replaces with its own frame's."""
    words = text.split()
    try:
        track_id, lane, label = int(words[0]), int(words[2]), words[3]
        if words[1] != "lane":
            return None
        if len(words) == 6 and words[4] == "Φ_t":
            return Overlay(track_id, lane, label, FRAME, stamp, points, phi=_parse(words[5]))
        if len(words) == 12 and words[4] in (REFERENCE, MEASURED):
            return Overlay(track_id, lane, label, words[4], float(words[10]), points, score=_parse(words[6]),
                           cut=_parse(words[8]))
    except (IndexError, ValueError):
        return None
    return None


def _number(value: float) -> str:
    return f"{value:.3f}" if math.isfinite(value) else "-"


def _parse(text: str) -> float:
    return math.nan if text == "-" else float(text)
