"""Demonstrations: mapping a recorded path onto a new start and goal.

A goal-shift DMP (:mod:`wholebody.planning.dmp`) generalises a demonstration by shifting its
goal, but its forcing term keeps the demonstration's shape in absolute world axes: learned
on a 1.6 m reach along +x, it adds that reach's along-x profile to a 24 cm move along y.
When a motion differs from the demonstration in length or direction, the demonstration can
instead be carried onto the motion's chord first and a DMP fitted to it
(:func:`align_to_chord`): its progress along the chord and its lateral and vertical
deviations from it are kept, scaled by the ratio of chord lengths.
"""

from __future__ import annotations

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_array, as_vector

__all__ = ["align_to_chord", "chord_frame"]

UP = np.array([0.0, 0.0, 1.0])


def chord_frame(start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """3x3 frame of a chord: columns unit chord, lateral (``up x chord``), and the vertical
    direction orthogonal to the chord (world x if the chord is vertical)."""
    d = np.asarray(goal, float) - np.asarray(start, float)
    length = float(np.linalg.norm(d))
    if length < 1e-9:
        raise DimensionError("chord_frame: start and goal coincide")
    e1 = d / length
    up = UP if abs(e1 @ UP) < 0.99 else np.array([1.0, 0.0, 0.0])
    e3 = up - (up @ e1) * e1
    e3 /= np.linalg.norm(e3)
    return np.column_stack([e1, np.cross(e3, e1), e3])


def align_to_chord(positions: np.ndarray, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Map a demonstrated path (N, 3) onto the chord from ``start`` to ``goal`` (m): the
    similarity (rotation and uniform scale) that takes the demonstration's chord frame to
    the new one. The first point goes to ``start`` and the last to ``goal`` exactly."""
    p = as_array(positions, (None, 3), "align_to_chord: positions")
    s, g = as_vector(start, 3, "align_to_chord: start"), as_vector(goal, 3, "align_to_chord: goal")
    if len(p) < 2:
        raise DimensionError("align_to_chord: need at least two positions")
    demo = chord_frame(p[0], p[-1])
    new = chord_frame(s, g)
    scale = np.linalg.norm(g - s) / np.linalg.norm(p[-1] - p[0])
    out = s + scale * ((p - p[0]) @ demo) @ new.T
    out[-1] = g
    return out
