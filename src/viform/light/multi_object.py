"""A built-in scene made for detection and tracking, with exact object truth (``multi-object``).

Seed 000 (abstract, §7) promises detection and tracking on the spike stream far faster than a
frame camera; scoring that needs a scene whose every object is known at every instant. Seven
textured rectangular objects move over a static textured (or plain) background, each with its
own size, brightness and speed, chosen to span what a tracker meets (at the default 400×250
size, sensor-plane lux):

====  ============  =========  ======  ==========================  ==================================
 id   class         size px    lux     speed px/s                  role
====  ============  =========  ======  ==========================  ==================================
 1    truck         44 × 40    300     2,000 →                     occluder (nearest)
 2    ball          16 × 16    40      1,000 ←                     fully hidden by the truck ≈ 9 ms
 3    bullet        10 × 6     1,000   10,000 →                    enters at ≈ 4.5 ms, leaves ≈ 45.5 ms
 4    car           50 × 24    100     4,000 ←                     leaves at ≈ 44 ms; crosses the walker
 5    pedestrian    12 × 30    20      100 ↑                       slowest; partly hidden by the car
 6    drone         20 × 12    1       400 on a circle (R = 40)    dimmest (≈ 1 lux)
 7    bird          12 × 8     1.5     3,606 ↙                     dim and fast
====  ============  =========  ======  ==========================  ==================================

The background is 5 lux (3–7 lux textured). Paths are written about a reference instant
``t_ref_s`` (25 ms): the truck passes in front of the ball exactly then, whatever ``speed``
factor is chosen. Positions and speeds scale with the image size (x with width/400, y with
height/250), so the choreography is the same at any resolution.

Light model (the analytic truth): each object is an axis-aligned rectangle whose edges are
anti-aliased by their exact area coverage of each pixel; inside it the light is
``lux · (1 + 0.5·sin(2π u/p)·sin(2π v/p))`` (u, v: object coordinates, p = 6 px at the default
size, sampled at the pixel centre) so the whole object changes as it moves, not only its edges.
Objects composite front to back with their coverage as opacity ("over").

Truth (conventions in :mod:`viform.light.truth`): boxes are the rectangles themselves; a pixel
belongs to the nearest object whose rectangle holds its centre (:meth:`object_labels`); the
visible fraction is the rectangle's area inside the field and not under a nearer rectangle
(exact, by inclusion–exclusion of rectangle intersections); velocities are analytic (the drone
moves on a circle, the others on straight lines); optical flow is each object's displacement,
0 on the static background, invalid where the point is hidden or outside the field at t1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from viform._validate import ViformError, check_choice, check_int, check_positive
from viform.light.scenes import Scene, texture
from viform.light.truth import FlowTruth, ObjectTruth, interval_overlap

#: Reference size the object table is written for (width, height), px.
REFERENCE_SIZE_PX = (400, 250)


@dataclass(frozen=True)
class ObjectSpec:
    """One object of the scene at the reference size (400×250 px), before the speed factor.

    ``depth_rank`` orders occlusion (smaller = nearer). Straight paths have ``radius_px = 0``:
    centre = ``centre_px + velocity_px_per_s·(t − t_ref)``. Circular paths: centre =
    ``centre_px + radius_px·(cos φ, sin φ)`` with φ = ``phase_rad + angular_rad_per_s·(t − t_ref)``.
    """

    object_id: int
    class_name: str
    size_px: tuple[float, float]
    lux: float
    centre_px: tuple[float, float]
    velocity_px_per_s: tuple[float, float] = (0.0, 0.0)
    depth_rank: int = 0
    radius_px: float = 0.0
    angular_rad_per_s: float = 0.0
    phase_rad: float = 0.0


OBJECTS = (
    ObjectSpec(1, "truck", (44, 40), 300.0, (200, 125), (2000, 0), depth_rank=1),
    ObjectSpec(2, "ball", (16, 16), 40.0, (200, 125), (-1000, 0), depth_rank=3),
    ObjectSpec(3, "bullet", (10, 6), 1000.0, (200, 45), (10_000, 0), depth_rank=2),
    ObjectSpec(4, "car", (50, 24), 100.0, (50, 205), (-4000, 0), depth_rank=0),
    ObjectSpec(5, "pedestrian", (12, 30), 20.0, (100, 200), (0, -100), depth_rank=4),
    ObjectSpec(6, "drone", (20, 12), 1.0, (320, 120), depth_rank=5, radius_px=40.0, angular_rad_per_s=10.0,
               phase_rad=0.5 * math.pi),
    ObjectSpec(7, "bird", (12, 8), 1.5, (300, 60), (-3000, 2000), depth_rank=6),
)


def _rect_intersection(a, b):
    """Intersection of two (x0, y0, x1, y1) rectangles, or None."""
    r = (max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3]))
    return r if r[2] > r[0] and r[3] > r[1] else None


def _union_area(rects) -> float:
    """Area of a union of rectangles by inclusion–exclusion (exact; a handful of rectangles)."""
    total = 0.0
    for k in range(1, len(rects) + 1):
        for group in combinations(rects, k):
            r = group[0]
            for other in group[1:]:
                r = _rect_intersection(r, other)
                if r is None:
                    break
            if r is not None:
                total += (-1) ** (k + 1) * (r[2] - r[0]) * (r[3] - r[1])
    return total


class MultiObjectScene(Scene):
    """Seven objects for detection and tracking, with exact truth (see the module notes).

    Parameters
    ----------
    height, width : int
        Resolution (≥ 24 × 32); positions, sizes and speeds scale with it.
    brightness : float
        Factor on the objects' illuminance (not the background's): 0.01 … 100 sweeps contrast.
    speed : float
        Factor on every speed (paths keep their crossing at ``t_ref_s``).
    background : {"texture", "plain"}
        Static textured background (3–7 lux) or a plain one (5 lux).
    background_lux : float
        Mean background illuminance, lux.
    t_ref_s : float
        The instant the paths are written about (the truck covers the ball then), s.
    duration_s : float
        Nominal clip length, s (50 ms: every event of the table happens inside it).
    """

    name = "multi-object"

    def __init__(self, height: int = 250, width: int = 400, brightness: float = 1.0, speed: float = 1.0,
                 background: str = "texture", background_lux: float = 5.0, t_ref_s: float = 0.025,
                 duration_s: float | None = 0.05):
        height = check_int("height", height, 24)
        width = check_int("width", width, 32)
        super().__init__(height, width, duration_s)
        self.brightness = check_positive("brightness", brightness)
        self.speed = check_positive("speed", speed)
        self.background = check_choice("background", background, ("texture", "plain"))
        self.background_lux = check_positive("background_lux", background_lux)
        if not math.isfinite(t_ref_s):
            raise ViformError(f"t_ref_s = {t_ref_s!r} must be a finite time in seconds")
        self.t_ref_s = float(t_ref_s)
        self.scale_xy = (width / REFERENCE_SIZE_PX[0], height / REFERENCE_SIZE_PX[1])
        self.texture_period_px = 6.0 * min(self.scale_xy)
        self.specs = OBJECTS
        sx, sy = self.scale_xy
        y, x = np.mgrid[0:height, 0:width].astype(np.float64)
        if self.background == "texture":
            self._background = self.background_lux * (0.6 + 0.8 * texture(x / sx, y / sy, 48.0))
        else:
            self._background = np.full((height, width), self.background_lux)
        self._cols = np.arange(width, dtype=np.float64)
        self._rows = np.arange(height, dtype=np.float64)
        # far to near: later objects are painted over earlier ones
        self._paint_order = sorted(self.specs, key=lambda s: -s.depth_rank)

    # ------------------------------------------------------------------ kinematics
    def centre_px(self, spec: ObjectSpec, t_s: float) -> tuple[float, float]:
        """Centre (x, y) of an object at ``t_s``, px."""
        sx, sy = self.scale_xy
        dt = t_s - self.t_ref_s
        if spec.radius_px:
            phi = spec.phase_rad + spec.angular_rad_per_s * self.speed * dt
            return ((spec.centre_px[0] + spec.radius_px * math.cos(phi)) * sx,
                    (spec.centre_px[1] + spec.radius_px * math.sin(phi)) * sy)
        return ((spec.centre_px[0] + spec.velocity_px_per_s[0] * self.speed * dt) * sx,
                (spec.centre_px[1] + spec.velocity_px_per_s[1] * self.speed * dt) * sy)

    def velocity_px_per_s(self, spec: ObjectSpec, t_s: float) -> tuple[float, float]:
        """Velocity (vx, vy) of an object's centre at ``t_s``, px/s (the analytic derivative)."""
        sx, sy = self.scale_xy
        if spec.radius_px:
            w = spec.angular_rad_per_s * self.speed
            phi = spec.phase_rad + w * (t_s - self.t_ref_s)
            return (-spec.radius_px * w * math.sin(phi) * sx, spec.radius_px * w * math.cos(phi) * sy)
        return (spec.velocity_px_per_s[0] * self.speed * sx, spec.velocity_px_per_s[1] * self.speed * sy)

    def size_px(self, spec: ObjectSpec) -> tuple[float, float]:
        """(width, height) of an object at this resolution, px."""
        return (spec.size_px[0] * self.scale_xy[0], spec.size_px[1] * self.scale_xy[1])

    def rect_px(self, spec: ObjectSpec, t_s: float) -> tuple[float, float, float, float]:
        """The object's rectangle (x0, y0, x1, y1) at ``t_s``, px (0-based, right/bottom open)."""
        cx, cy = self.centre_px(spec, t_s)
        w, h = self.size_px(spec)
        return (cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)

    def object_lux(self, spec: ObjectSpec) -> float:
        """Mean illuminance of an object (its texture averages to 1), lux."""
        return spec.lux * self.brightness

    # ------------------------------------------------------------------ light
    def illuminance_lux(self, t_s: float) -> np.ndarray:
        lux = self._background.copy()
        self._paint(float(t_s), lux)
        return lux

    def _paint(self, t_s: float, lux: np.ndarray) -> list:
        """Draw the objects at ``t_s`` over ``lux`` (which holds the background), far to near; return the
        boxes (row0, row1, col0, col1) written (see :class:`~viform.light.sampled.PaintedSampler`)."""
        H, W = self.shape
        p = self.texture_period_px
        boxes = []
        for spec in self._paint_order:
            x0, y0, x1, y1 = self.rect_px(spec, t_s)
            c0, c1 = max(0, int(math.floor(x0))), min(W, int(math.ceil(x1)))
            r0, r1 = max(0, int(math.floor(y0))), min(H, int(math.ceil(y1)))
            if c1 <= c0 or r1 <= r0:
                continue
            boxes.append((r0, r1, c0, c1))
            cols, rows = self._cols[c0:c1], self._rows[r0:r1]
            alpha = np.outer(interval_overlap(rows, rows + 1, y0, y1), interval_overlap(cols, cols + 1, x0, x1))
            u = 2 * np.pi * (cols + 0.5 - x0) / p
            v = 2 * np.pi * (rows + 0.5 - y0) / p
            light = self.object_lux(spec) * (1.0 + 0.5 * np.outer(np.sin(v), np.sin(u)))
            patch = lux[r0:r1, c0:c1]
            patch += alpha * (light - patch)
        return boxes

    def _paint_rects(self, times_s: np.ndarray) -> np.ndarray:
        """Boxes holding every pixel :meth:`_paint` writes at any of ``times_s`` (each object's rectangle
        per instant, one pixel of margin)."""
        t = np.asarray(times_s, dtype=np.float64)
        sx, sy = self.scale_xy
        dt = t - self.t_ref_s
        out = []
        for spec in self.specs:
            if spec.radius_px:
                phi = spec.phase_rad + spec.angular_rad_per_s * self.speed * dt
                cx = (spec.centre_px[0] + spec.radius_px * np.cos(phi)) * sx
                cy = (spec.centre_px[1] + spec.radius_px * np.sin(phi)) * sy
            else:
                cx = (spec.centre_px[0] + spec.velocity_px_per_s[0] * self.speed * dt) * sx
                cy = (spec.centre_px[1] + spec.velocity_px_per_s[1] * self.speed * dt) * sy
            w, h = self.size_px(spec)
            out.append(np.stack([np.floor(cy - h / 2) - 1, np.ceil(cy + h / 2) + 1,
                                 np.floor(cx - w / 2) - 1, np.ceil(cx + w / 2) + 1], axis=1))
        return np.clip(np.concatenate(out), -1, max(self.height, self.width) + 1).astype(np.int64)

    def max_speed_px_per_s(self) -> float:
        """The fastest object's speed, px/s."""
        def speed(spec):
            if spec.radius_px:  # on a circle: the larger of the two axis scales bounds it
                return spec.radius_px * abs(spec.angular_rad_per_s) * self.speed * max(self.scale_xy)
            return math.hypot(*self.velocity_px_per_s(spec, self.t_ref_s))

        return max(speed(spec) for spec in self.specs)

    def compiled_light(self):
        """The background once, and per light sample only the objects' rectangles drawn by :meth:`_paint`
        (kind "sampled", :class:`~viform.light.sampled.PaintedSampler`): the light of
        :meth:`illuminance_lux`, bit for bit."""
        if not self._own_light(MultiObjectScene):
            return None
        if getattr(self, "_compiled", None) is None:
            from viform.light._objects_paint import ObjectsSampler  # numba: imported only when light is compiled
            from viform.light.compiled import CompiledLight

            # an object's texture peaks at 1.5 times its level; "over" compositing stays below the largest
            peak = max([float(self._background.max())] + [1.5 * self.object_lux(s) for s in self.specs])
            sampler = ObjectsSampler(self._background, self._paint, self._paint_rects, peak, self)
            self._compiled = CompiledLight("sampled", self.height, self.width, sampler=sampler)
        return self._compiled

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """The longest hold (ticks) that misplaces the fastest object by at most
        :data:`~viform.light.sampled.LIGHT_ERROR_PX` (:func:`~viform.light.sampled.auto_light_sample_ticks`)."""
        from viform.light.sampled import auto_light_sample_ticks

        return auto_light_sample_ticks(self.max_speed_px_per_s(), clock_hz)

    # ------------------------------------------------------------------ truth
    def truth_kinds(self) -> tuple[str, ...]:
        return ("motion", "objects")

    def object_labels(self, t_s: float) -> np.ndarray:
        labels = np.zeros(self.shape, np.int32)
        H, W = self.shape
        for spec in self._paint_order:  # nearer objects overwrite farther ones
            x0, y0, x1, y1 = self.rect_px(spec, t_s)
            # pixels whose centre c + 0.5 lies in [x0, x1)
            c0, c1 = max(0, math.ceil(x0 - 0.5)), min(W, math.ceil(x1 - 0.5))
            r0, r1 = max(0, math.ceil(y0 - 0.5)), min(H, math.ceil(y1 - 0.5))
            if c1 > c0 and r1 > r0:
                labels[r0:r1, c0:c1] = spec.object_id
        return labels

    def _visible_fraction(self, spec: ObjectSpec, t_s: float) -> float:
        rect = self.rect_px(spec, t_s)
        area = (rect[2] - rect[0]) * (rect[3] - rect[1])
        inside = _rect_intersection(rect, (0.0, 0.0, float(self.width), float(self.height)))
        if inside is None:
            return 0.0
        hiding = [r for other in self.specs if other.depth_rank < spec.depth_rank
                  for r in [_rect_intersection(inside, self.rect_px(other, t_s))] if r is not None]
        visible = (inside[2] - inside[0]) * (inside[3] - inside[1]) - _union_area(hiding)
        return float(min(1.0, max(0.0, visible / area)))

    def objects(self, t_s: float) -> list[ObjectTruth]:
        out = []
        for spec in self.specs:
            x0, y0, x1, y1 = self.rect_px(spec, t_s)
            if x1 <= 0 or y1 <= 0 or x0 >= self.width or y0 >= self.height:
                continue  # entirely outside the field
            r0, r1 = max(0, int(math.floor(y0))), min(self.height, int(math.ceil(y1)))
            c0, c1 = max(0, int(math.floor(x0))), min(self.width, int(math.ceil(x1)))
            out.append(ObjectTruth(spec.object_id, spec.class_name, x0, y0, x1 - x0, y1 - y0,
                                   self._visible_fraction(spec, t_s), self.velocity_px_per_s(spec, t_s),
                                   lux=self.object_lux(spec),
                                   background_lux=float(self._background[r0:r1, c0:c1].mean())))
        return out

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        labels = self.object_labels(t_s)
        motion = np.zeros((2,) + self.shape)  # the background is static: 0 px/s
        for spec in self.specs:
            mask = labels == spec.object_id
            if mask.any():
                vx, vy = self.velocity_px_per_s(spec, t_s)
                motion[0][mask], motion[1][mask] = vx, vy
        return motion

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        if not (math.isfinite(t0_s) and math.isfinite(t1_s)):
            raise ViformError(f"optical flow instants t0_s = {t0_s!r}, t1_s = {t1_s!r} must be finite")
        labels0 = self.object_labels(t0_s)
        flow = np.zeros((2,) + self.shape)
        valid = self.object_labels(t1_s) == 0  # static background: seen again unless covered at t1
        rows, cols = np.nonzero(labels0)
        for spec in self.specs:
            sel = labels0[rows, cols] == spec.object_id
            if not sel.any():
                continue
            (ax, ay), (bx, by) = self.centre_px(spec, t0_s), self.centre_px(spec, t1_s)
            dx, dy = bx - ax, by - ay
            r, c = rows[sel], cols[sel]
            flow[0, r, c], flow[1, r, c] = dx, dy
            # where the point lands at t1: inside the field and on top of every nearer rectangle
            xs, ys = c + 0.5 + dx, r + 0.5 + dy
            ok = (xs >= 0) & (xs < self.width) & (ys >= 0) & (ys < self.height)
            for other in self.specs:
                if other.depth_rank < spec.depth_rank:
                    ox0, oy0, ox1, oy1 = self.rect_px(other, t1_s)
                    ok &= ~((xs >= ox0) & (xs < ox1) & (ys >= oy0) & (ys < oy1))
            valid[r, c] = ok
        return FlowTruth(flow, valid, float(t0_s), float(t1_s))

    def describe(self) -> dict:
        return {**super().describe(), "brightness": self.brightness, "speed": self.speed,
                "background": self.background, "background_lux": self.background_lux, "t_ref_s": self.t_ref_s}

