"""Ground truth a scene knows about itself: motion, depth and objects at any instant.

viform's built-in scenes are analytic, so besides the light (:mod:`viform.light.scenes`) they
can say exactly what a vision task is scored against (seed 000, abstract and §7: optical flow,
depth, detection and tracking on the spike stream). Image and video files know none of it:
asking them raises :class:`TruthUnavailable` with a message that says so, never zeros.

Conventions (shared by every scene, writer and consumer):

* image coordinates: ``x`` is the column (px, positive to the right), ``y`` the row (px,
  positive downwards); pixel (row r, column c) covers ``[c, c+1) × [r, r+1)`` and its centre is
  at ``(c + 0.5, r + 0.5)``;
* velocity fields are ``(2, H, W)`` arrays in px/s, component 0 = x (u), component 1 = y (v),
  NaN where undefined;
* optical flow between t0 and t1 is *forward* flow (the convention of optical-flow benchmarks
  such as Middlebury, KITTI and the spike-camera flow sets): for the surface point seen at pixel
  p at t0, its image position at t1 minus p, in px; ``valid`` is False where that point is
  occluded or leaves the field at t1, or where the motion is undefined;
* boxes are ``(x, y, w, h)`` in px, 0-based, top-left corner at ``(x, y)``, the tight box of the
  object's projected region (visible or not); the MOTChallenge writer adds 1 to x and y, as that
  format counts from 1;
* ``visible_fraction`` is the share of the object's projected area not hidden by a nearer object
  or the field's border, in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError

TRUTH_KINDS = ("motion", "depth", "objects")


class TruthUnavailable(ViformError):
    """The scene cannot give this truth (a file-based scene, or a scene without range)."""


@dataclass(frozen=True)
class ObjectTruth:
    """One labelled object at one instant.

    Attributes
    ----------
    object_id : int
        Stable id (≥ 1) for the object's whole life in the scene.
    class_name : str
        What it is (``"vehicle"``, ``"blade"``, ``"disc"``, …).
    x_px, y_px, width_px, height_px : float
        Tight bounding box of the projected object, px, 0-based, top-left corner.
    visible_fraction : float
        Share of the projected area that is visible (not occluded, inside the field), [0, 1].
    velocity_px_per_s : tuple[float, float]
        Image-plane velocity of the box centre, (vx, vy) in px/s.
    """

    object_id: int
    class_name: str
    x_px: float
    y_px: float
    width_px: float
    height_px: float
    visible_fraction: float
    velocity_px_per_s: tuple[float, float]

    @property
    def box_xywh(self) -> tuple[float, float, float, float]:
        return (self.x_px, self.y_px, self.width_px, self.height_px)


@dataclass(frozen=True)
class FlowTruth:
    """Forward optical flow between two instants.

    Attributes
    ----------
    flow_px : ndarray, shape (2, H, W), float64
        Displacement (dx, dy) in px of the surface point seen at each pixel at ``t0_s``.
    valid : ndarray, shape (H, W), bool
        False where the point is occluded or outside the field at ``t1_s``, or motion is undefined.
    t0_s, t1_s : float
        The two instants (s).
    """

    flow_px: np.ndarray
    valid: np.ndarray
    t0_s: float
    t1_s: float
