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
        Image-plane velocity (vx, vy) of the object's centroid, px/s (for an object in pure
        translation, that of its box centre too).
    lux, background_lux : float or None
        Mean illuminance of the object's surface and of the background it covers, lux (None
        where the scene does not say): what a sensor can see of it (its contrast).
    """

    object_id: int
    class_name: str
    x_px: float
    y_px: float
    width_px: float
    height_px: float
    visible_fraction: float
    velocity_px_per_s: tuple[float, float]
    lux: float | None = None
    background_lux: float | None = None

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


def static_motion(shape) -> np.ndarray:
    """Velocity field of a scene that does not move: zeros, shape (2, H, W), px/s."""
    return np.zeros((2, *shape))


def flow_from_layers(labels_t0: np.ndarray, labels_t1: np.ndarray, undefined_t0: np.ndarray | None,
                     transforms: dict, depth_order: dict, t0_s: float, t1_s: float) -> FlowTruth:
    """Forward flow of a scene made of rigid layers (background and objects), with occlusions.

    Parameters
    ----------
    labels_t0, labels_t1 : ndarray of int, shape (H, W)
        The layer visible at every pixel centre at t0 and t1 (0 = background).
    undefined_t0 : ndarray of bool or None
        Pixels whose motion is undefined at t0 (e.g. an anti-aliased edge mixing two layers).
    transforms : dict
        Layer id → function ``(x, y) -> (x1, y1)`` mapping a point's position at t0 (px, arrays)
        to its position at t1. Layers absent from the dict do not move.
    depth_order : dict
        Layer id → rank, smaller = nearer the camera; layers absent from it rank behind every
        object (the background).
    t0_s, t1_s : float
        The two instants (s).

    Notes
    -----
    A point is occluded at t1 when the layer visible at the pixel nearest its destination is
    a different layer nearer the camera; a point landing on a farther layer's pixel (an edge
    that moved by a fraction of a pixel) is still visible. Points whose destination lies
    outside the field (centres beyond [-0.5, W - 0.5) × [-0.5, H - 0.5)) are invalid.
    """
    height, width = labels_t0.shape
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    x1, y1 = x.copy(), y.copy()
    for layer, move in transforms.items():
        where = labels_t0 == layer
        if where.any():
            x1[where], y1[where] = move(x[where], y[where])
    flow = np.stack([x1 - x, y1 - y])
    inside = (x1 >= -0.5) & (x1 < width - 0.5) & (y1 >= -0.5) & (y1 < height - 0.5)
    col = np.clip(np.floor(x1 + 0.5), 0, width - 1).astype(np.intp)
    row = np.clip(np.floor(y1 + 0.5), 0, height - 1).astype(np.intp)
    there = labels_t1[row, col]
    behind = max(depth_order.values(), default=0) + 1
    top = int(max(labels_t0.max(initial=0), labels_t1.max(initial=0)))
    rank = np.full(top + 1, behind, dtype=np.int64)  # layer id -> depth rank lookup
    for layer, order in depth_order.items():
        if 0 <= layer <= top:
            rank[layer] = order
    occluded = (there != labels_t0) & (rank[there] < rank[labels_t0])
    valid = inside & ~occluded
    if undefined_t0 is not None:
        valid &= ~undefined_t0
        flow[:, undefined_t0] = np.nan
    return FlowTruth(flow_px=flow, valid=valid, t0_s=float(t0_s), t1_s=float(t1_s))


def rotate_about(cx: float, cy: float, angle_rad: float):
    """A transform ``(x, y) -> (x1, y1)``: rotation by ``angle_rad`` about (cx, cy) (x right, y down)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)

    def move(x, y):
        dx, dy = x - cx, y - cy
        return cx + c * dx - s * dy, cy + s * dx + c * dy

    return move


def translate_by(dx: float, dy: float):
    """A transform ``(x, y) -> (x + dx, y + dy)``."""
    return lambda x, y: (x + dx, y + dy)


def interval_overlap(lo, hi, edges_lo, edges_hi):
    """Length of [lo, hi) ∩ [edges_lo, edges_hi), elementwise (0 where they do not meet): with
    ``lo`` = column ``c``, ``hi`` = ``c + 1``, the share of that pixel column an object spanning
    [edges_lo, edges_hi) covers."""
    return np.clip(np.minimum(hi, edges_hi) - np.maximum(lo, edges_lo), 0.0, None)


def disc_fraction_inside(cx: float, cy: float, radius: float, x_lo: float, x_hi: float,
                         y_lo: float, y_hi: float) -> float:
    """Share of the disc's area inside the rectangle [x_lo, x_hi] × [y_lo, y_hi] (exact for one cut per axis side).

    Each side that cuts the disc removes a circular segment; segments of opposite sides are
    subtracted independently, which is exact unless two cuts overlap inside the disc (a
    rectangle smaller than the disc), where it is a lower bound clipped at 0.
    """
    def segment(d):  # area of the part of a unit-radius disc beyond a chord at distance d from the centre
        d = min(max(d, -1.0), 1.0)
        return np.arccos(d) - d * np.sqrt(1 - d * d)

    r = float(radius)
    lost = sum(segment(d / r) for d in (cx - x_lo, x_hi - cx, cy - y_lo, y_hi - cy))
    return float(max(0.0, 1.0 - lost / np.pi))
