"""What the grader draws on the top image (grading/markers), as plain data both it and `woody report` share.

ImageMarker has no text, so each marker's ``ns`` carries its label, ``/``-separated:

- every frame, each track's contour: ``lane1/pending/id 7/Φ_t 0.0123`` (``Φ_t -`` when the frame was not scored);
- at the verdict, two outlines stamped with their own frames: ``lane1/woody/id 7/reference/score 0.0456 cut
  0.0600`` (the flat reference) and ``lane1/woody/id 7/measured/score ...`` (the frame nearest the measuring point).

The first two fields (lane, verdict) are what a Foxglove user filters on; :func:`parse_ns` reads them all back.
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
    def ns(self) -> str:
        head = f"lane{self.lane}/{self.label}/id {self.track_id}"
        if self.kind == FRAME:
            return f"{head}/Φ_t {_number(self.phi)}"
        return f"{head}/{self.kind}/score {_number(self.score)} cut {_number(self.cut)}"


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


def parse_ns(ns: str, stamp: float, points: np.ndarray) -> Overlay | None:
    """The overlay a marker's ``ns`` describes (None for a marker of another format)."""
    parts = ns.split("/")
    try:
        lane, label, track_id = int(parts[0].removeprefix("lane")), parts[1], int(parts[2].removeprefix("id "))
        if len(parts) == 4 and parts[3].startswith("Φ_t "):
            return Overlay(track_id, lane, label, FRAME, stamp, points, phi=_parse(parts[3].split()[1]))
        if len(parts) == 5 and parts[3] in (REFERENCE, MEASURED):
            words = parts[4].split()
            return Overlay(track_id, lane, label, parts[3], stamp, points, score=_parse(words[1]),
                           cut=_parse(words[3]))
    except (IndexError, ValueError):
        return None
    return None


def _number(value: float) -> str:
    return f"{value:.4f}" if math.isfinite(value) else "-"


def _parse(text: str) -> float:
    return math.nan if text == "-" else float(text)
