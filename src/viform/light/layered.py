"""Described scenes: layers of light with shapes, motions and depths, rendered with exact truth.

:class:`DescribedScene` renders a validated description (:mod:`viform.light.description`).

Geometry. Every layer has its own plane with coordinates (u, v) in px; its pose at time t
(position of its origin, rotation, scale) maps them to the world, the camera's pose maps the
world to the canvas (pan, roll and zoom about the canvas centre, plus shake), and a fixed
scale maps the described canvas to the requested size (x by width / described width, y
likewise). The composite is one affine map A(t) per layer: canvas point p = A(t)·(u, v, 1).
Pixel (row r, column c) covers [c, c + 1) × [r, r + 1) (:mod:`viform.light.truth`); sources are
sampled at pixel centres (c + 0.5, r + 0.5), at the instant asked (the simulator asks at the
middle of each tick or light sample).

Light. A pixel's light is the background, then every layer from far to near: "over" layers
cover what is behind by their coverage α of the pixel (L ← L + α·(m·s − L)), "add" layers add
α·m·s (glows). s is the source at the pixel centre, m the modulation. Coverage is the exact
area of the pixel inside the layer's outline: polygons (rectangles included) by integrating
each edge's trapezoid over the pixel (Green's theorem; exact for any simple polygon);
ellipses as the 256-gon of equal area (edges within 8·10⁻⁵ of the radius); alpha and mask
images as their area-sampled values. Images are piecewise-constant texels integrated over a
box the size of the pixel's footprint in texels (at least one texel: bilinear interpolation
when magnified, the exact area mean when minified by translation and scale; a rotated
footprint is taken as its bounding box).

Truth. The visible layer at a pixel is the nearest "over" layer whose outline holds the pixel
centre (:meth:`DescribedScene.layer_labels`); flow moves each pixel's point with its layer's
map, A(t1)·A(t0)⁻¹, and is invalid where the point is hidden or leaves the field at t1, or at
mixed edges (the visible layer covering the pixel partly, or a nearer layer covering it
partly); depth is the visible layer's plane; objects' boxes bound their projected outline and
their visible fraction is their coverage not hidden by nearer layers, over their projected area.
"""

from __future__ import annotations

import math
from functools import cached_property
from pathlib import Path

import numpy as np

from viform._validate import ViformError, one_line
from viform.light.affine import invert_many
from viform.light.scenes import PATTERNS, Scene
from viform.light.truth import FlowTruth, ObjectTruth, flow_from_layers

ELLIPSE_SIDES = 256
#: Light samples per period of a layer's modulation at least, when the simulator chooses the hold.
MODULATION_SAMPLES_PER_PERIOD = 32


# ------------------------------------------------------------------------- affine maps

def pose_matrix(x, y, angle, sx, sy) -> np.ndarray:
    """2×3 map of a pose: p = (x, y) + R(angle)·diag(sx, sy)·q."""
    return pose_matrices(*(np.array([v], dtype=np.float64) for v in (x, y, angle, sx, sy)))[0]


def pose_matrices(x, y, angle, sx, sy) -> np.ndarray:
    """(n, 2, 3) maps of poses given as arrays (n,)."""
    c, s = np.cos(angle), np.sin(angle)
    out = np.empty((np.size(x), 2, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = c * sx, -s * sy, x
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = s * sx, c * sy, y
    return out


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ∘ b for 2×3 affine maps, or stacks of them (..., 2, 3), broadcast."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a00, a01, a02 = a[..., 0, 0], a[..., 0, 1], a[..., 0, 2]
    a10, a11, a12 = a[..., 1, 0], a[..., 1, 1], a[..., 1, 2]
    b00, b01, b02 = b[..., 0, 0], b[..., 0, 1], b[..., 0, 2]
    b10, b11, b12 = b[..., 1, 0], b[..., 1, 1], b[..., 1, 2]
    out[..., 0, 0] = a00 * b00 + a01 * b10
    out[..., 0, 1] = a00 * b01 + a01 * b11
    out[..., 0, 2] = a00 * b02 + a01 * b12 + a02
    out[..., 1, 0] = a10 * b00 + a11 * b10
    out[..., 1, 1] = a10 * b01 + a11 * b11
    out[..., 1, 2] = a10 * b02 + a11 * b12 + a12
    return out


def invert(a: np.ndarray) -> np.ndarray:
    return invert_many(a)


def apply(a: np.ndarray, x, y):
    return a[0, 0] * x + a[0, 1] * y + a[0, 2], a[1, 0] * x + a[1, 1] * y + a[1, 2]


# ------------------------------------------------------------------------- motion

class Motion:
    """A pose over time: (x, y, angle, sx, sy) at t (s), from a description's pose and motion."""

    def __init__(self, node: dict, time_factor: float = 1.0, t_ref_s: float = 0.0,
                 default_position=(0.0, 0.0)):
        pos = node.get("position_px", default_position)
        self.t_ref_s = float(t_ref_s)
        scale = node.get("scale", 1.0)
        sx, sy = (scale, scale) if not isinstance(scale, list) else scale
        self.base = (float(pos[0]), float(pos[1]), float(node.get("angle_rad", 0.0)), float(sx), float(sy))
        self.k = float(time_factor)
        self.motion = node.get("motion")
        self.static = self.motion is None
        self._spline = None
        if self.motion and "keyframes" in self.motion:
            keys = self.motion["keyframes"]["keys"]
            self.key_t = np.array([k["t_s"] for k in keys], dtype=np.float64)
            rows = []
            prev = list(self.base)
            for k in keys:
                p = k.get("position_px", prev[:2])
                sc = k.get("scale", None)
                sxy = prev[3:] if sc is None else ([sc, sc] if not isinstance(sc, list) else sc)
                row = [float(p[0]), float(p[1]), float(k.get("angle_rad", prev[2])), float(sxy[0]), float(sxy[1])]
                rows.append(row)
                prev = row
            self.key_v = np.array(rows)
            if self.motion["keyframes"].get("interpolation", "linear") == "spline" and len(keys) >= 2:
                from scipy.interpolate import CubicSpline

                self._spline = CubicSpline(self.key_t, self.key_v, axis=0, bc_type="natural")

    def pose(self, t: float) -> tuple:
        return tuple(float(v[0]) for v in self.poses(np.array([t], dtype=np.float64)))

    def poses(self, times) -> tuple:
        """(x, y, angle, sx, sy) at ``times`` (s), each an array (n,)."""
        times = np.asarray(times, dtype=np.float64).ravel()
        n = times.size
        x, y, a, sx, sy = self.base
        if self.static:
            return tuple(np.full(n, v) for v in self.base)
        tau = self.k * (times - self.t_ref_s)  # time since the reference instant, scaled by the speed
        m = self.motion
        if "velocity" in m:
            v = m["velocity"]
            vx, vy = v.get("px_per_s", (0.0, 0.0))
            ds = v.get("scale_per_s", 0.0) * tau
            return (x + vx * tau, y + vy * tau, a + v.get("rad_per_s", 0.0) * tau, sx + ds * sx, sy + ds * sy)
        if "circle" in m:
            c = m["circle"]
            phi = c.get("phase_rad", 0.0) + c["rad_per_s"] * tau
            return (c["centre_px"][0] + c["radius_px"] * np.cos(phi), c["centre_px"][1] + c["radius_px"] * np.sin(phi),
                    np.full(n, a), np.full(n, sx), np.full(n, sy))
        t = self.t_ref_s + tau
        kt, kv = self.key_t, self.key_v
        if self._spline is not None:
            inner = self._spline(np.clip(t, kt[0], kt[-1]))
            rows = np.where((t <= kt[0])[:, None], kv[0], np.where((t >= kt[-1])[:, None], kv[-1], inner))
        else:
            j = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, max(0, kt.size - 2))
            if kt.size == 1:
                rows = np.repeat(kv[:1], n, axis=0)
            else:
                w = ((t - kt[j]) / (kt[j + 1] - kt[j]))[:, None]
                rows = kv[j] + w * (kv[j + 1] - kv[j])
                rows = np.where((t <= kt[0])[:, None], kv[0], np.where((t >= kt[-1])[:, None], kv[-1], rows))
        return tuple(rows[:, k] for k in range(5))

    def matrix(self, t: float) -> np.ndarray:
        return pose_matrix(*self.pose(t))

    def matrices(self, times) -> np.ndarray:
        return pose_matrices(*self.poses(times))


def modulation_factor(node: dict | None, t: float) -> float:
    """The modulation m(t) of a layer (1 without one)."""
    return float(modulation_factors(node, np.array([t], dtype=np.float64))[0])


def modulation_factors(node: dict | None, times) -> np.ndarray:
    """The modulation m(t) of a layer at ``times`` (s), an array (1 without one)."""
    t = np.asarray(times, dtype=np.float64).ravel()
    if not node:
        return np.ones(t.size)
    if "pwm" in node:
        p = node["pwm"]
        phase = ((t - p.get("phase_s", 0.0)) * p["frequency_hz"]) % 1.0
        return np.where(phase < p["duty"], 1.0, p.get("low", 0.0))
    if "sine" in node:
        p = node["sine"]
        return 1.0 + p["depth"] * np.sin(2 * math.pi * p["frequency_hz"] * t + p.get("phase_rad", 0.0))
    if "square" in node:
        p = node["square"]
        return 1.0 + p["depth"] * np.where(np.sin(2 * math.pi * p["frequency_hz"] * t) >= 0, 1.0, -1.0)
    p = node["step"]
    return np.where(t >= p["t_s"], p["factor"], 1.0)


def modulation_peak(node: dict | None) -> float:
    if not node:
        return 1.0
    kind, p = next(iter(node.items()))
    if kind == "pwm":
        return max(1.0, p.get("low", 0.0))
    if kind in ("sine", "square"):
        return 1.0 + p["depth"]
    return max(1.0, p["factor"])


# ------------------------------------------------------------------------- images

def _srgb_to_linear(v):
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def read_image(path: str, what: str):
    """(grey float64 (H, W), alpha in [0, 1] or None, integer: bool) of an image file."""
    p = Path(path)
    try:
        if str(path).startswith("skimage:"):
            import skimage.data

            arr = getattr(skimage.data, str(path)[len("skimage:"):])()
        elif p.suffix.lower() == ".npy":
            arr = np.load(p, allow_pickle=False)
        else:
            import imageio.v3 as iio

            arr = iio.imread(p)
    except Exception as exc:
        raise ViformError(f"{what}: image {str(p)!r} could not be read: {one_line(exc)}") from None
    arr = np.asarray(arr)
    if arr.ndim == 3 and arr.shape[-1] in (2, 4):
        alpha_raw, arr = arr[..., -1], arr[..., :-1]
    else:
        alpha_raw = None
    integer = np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool
    full = float(np.iinfo(arr.dtype).max) if np.issubdtype(arr.dtype, np.integer) else 1.0
    values = arr.astype(np.float64) / (full if integer else 1.0)
    if values.ndim == 3:
        values = values[..., :3] @ np.array([0.2126, 0.7152, 0.0722]) if values.shape[-1] >= 3 else values[..., 0]
    if values.ndim != 2 or values.size == 0:
        raise ViformError(f"{what}: image {str(p)!r} must be 2-D grey or colour; got shape {arr.shape}")
    if not np.all(np.isfinite(values)) or values.min() < 0:
        raise ViformError(f"{what}: image {str(p)!r} holds negative or non-finite values")
    alpha = None
    if alpha_raw is not None:
        afull = float(np.iinfo(alpha_raw.dtype).max) if np.issubdtype(alpha_raw.dtype, np.integer) else 1.0
        alpha = np.clip(alpha_raw.astype(np.float64) / afull, 0.0, 1.0)
    return values, alpha, integer


class Texels:
    """An image as piecewise-constant texels on [0, W) × [0, H), sampled by area (see the module notes)."""

    def __init__(self, values: np.ndarray):
        self.values = np.ascontiguousarray(values, dtype=np.float64)
        h, w = self.values.shape
        sat = np.zeros((h + 1, w + 1))
        sat[1:, 1:] = self.values.cumsum(0).cumsum(1)
        self.sat = sat

    @property
    def shape(self):
        return self.values.shape

    def _integral(self, x, y):
        """∫∫ over [0, x] × [0, y] (x, y clipped to the image): bilinear in the summed-area table."""
        h, w = self.values.shape
        x = np.clip(x, 0.0, w)
        y = np.clip(y, 0.0, h)
        i = np.minimum(np.floor(x).astype(np.intp), w - 1)
        j = np.minimum(np.floor(y).astype(np.intp), h - 1)
        fx, fy = x - i, y - j
        s = self.sat
        return ((1 - fy) * ((1 - fx) * s[j, i] + fx * s[j, i + 1])
                + fy * ((1 - fx) * s[j + 1, i] + fx * s[j + 1, i + 1]))

    def sample(self, u, v, hx, hy) -> np.ndarray:
        """Mean over the box [u ± hx] × [v ± hy] (texel units; the box is clamped into the image,
        so the edge texels extend outward). Boxes at most two texels wide (magnified or mildly
        minified images) sum their ≤ 3 × 3 texels directly; wider ones difference the summed-area
        table."""
        h, w = self.values.shape
        hx = np.broadcast_to(hx, np.shape(u))
        hy = np.broadcast_to(hy, np.shape(v))
        x0 = np.clip(u - hx, 0.0, w - 2 * hx)
        y0 = np.clip(v - hy, 0.0, h - 2 * hy)
        x0 = np.maximum(x0, 0.0)
        y0 = np.maximum(y0, 0.0)
        x1 = np.minimum(x0 + 2 * hx, w)
        y1 = np.minimum(y0 + 2 * hy, h)
        area = (x1 - x0) * (y1 - y0)
        small = (hx <= 1.0) & (hy <= 1.0)
        out = np.empty(np.shape(u))
        if small.any():
            sx0, sx1, sy0, sy1 = x0[small], x1[small], y0[small], y1[small]
            i0 = np.minimum(np.floor(sx0).astype(np.intp), w - 1)
            j0 = np.minimum(np.floor(sy0).astype(np.intp), h - 1)
            total = np.zeros(sx0.shape)
            for kj in range(3):
                j = j0 + kj
                wy = np.maximum(np.minimum(sy1, j + 1.0) - np.maximum(sy0, j * 1.0), 0.0)
                jj = np.minimum(j, h - 1)
                row = np.zeros(sx0.shape)
                for ki in range(3):
                    i = i0 + ki
                    wx = np.maximum(np.minimum(sx1, i + 1.0) - np.maximum(sx0, i * 1.0), 0.0)
                    row += wx * self.values[jj, np.minimum(i, w - 1)]
                total += wy * row
            out[small] = total / area[small]
        if not small.all():
            big = ~small
            bx0, bx1, by0, by1 = x0[big], x1[big], y0[big], y1[big]
            total = self._integral(bx1, by1) - self._integral(bx0, by1) - self._integral(bx1, by0) + \
                self._integral(bx0, by0)
            out[big] = total / area[big]
        return out


# ------------------------------------------------------------------------- coverage

def _clamp_integral(a, b, width):
    """∫ clamp(s, 0, width) ds from a to b, elementwise (a, b arrays; width > 0)."""
    def big(s):
        s = np.asarray(s)
        return np.where(s <= 0, 0.0, np.where(s < width, 0.5 * s * s, 0.5 * width * width + width * (s - width)))

    return big(b) - big(a)


def polygon_coverage(px, py, x0: int, y0: int, nx: int, ny: int) -> np.ndarray:
    """Exact area of each pixel [c, c+1) × [r, r+1), c in x0 … x0+nx−1, r in y0 … y0+ny−1, inside the
    simple polygon (px, py) (any orientation): per edge, the trapezoid between it and the pixel
    column's left side, integrated in closed form (Green's theorem)."""
    cov = np.zeros((ny, nx))
    cols = x0 + np.arange(nx, dtype=np.float64)
    rows = y0 + np.arange(ny, dtype=np.float64)
    n = len(px)
    for k in range(n):
        xa, ya, xb, yb = px[k], py[k], px[(k + 1) % n], py[(k + 1) % n]
        if ya == yb:
            continue
        sign = 1.0 if yb > ya else -1.0
        if ya > yb:
            xa, ya, xb, yb = xb, yb, xa, ya
        r0 = max(int(math.floor(ya)) - y0, 0)
        r1 = min(int(math.ceil(yb)) - y0, ny)
        if r1 <= r0:
            continue
        lo = np.maximum(rows[r0:r1], ya)[:, None]
        hi = np.minimum(rows[r0:r1] + 1, yb)[:, None]
        slope = (xb - xa) / (yb - ya)
        xlo = xa + slope * (lo - ya) - cols[None, :]  # edge's x minus the pixel's left side, at lo and hi
        xhi = xa + slope * (hi - ya) - cols[None, :]
        dy = hi - lo
        ds = xhi - xlo
        small = np.abs(ds) < 1e-9
        mean = np.where(small, np.clip(0.5 * (xlo + xhi), 0.0, 1.0),
                        _clamp_integral(xlo, xhi, 1.0) / np.where(small, 1.0, ds))
        # along a line y, inside(x) = Σ_e sign_e·1(x < x_e(y)) (the winding number), so the pixel's covered
        # length is Σ_e sign_e·clamp(x_e(y) − c, 0, 1); integrated over the row's part of the edge's span
        cov[r0:r1] += sign * mean * dy
    return np.abs(cov)


def polygon_contains(px, py, x, y) -> np.ndarray:
    """Non-zero winding rule: which points (x, y) lie inside the polygon."""
    inside = np.zeros(np.shape(x), dtype=np.int32)
    n = len(px)
    for k in range(n):
        xa, ya, xb, yb = px[k], py[k], px[(k + 1) % n], py[(k + 1) % n]
        if ya == yb:
            continue
        up = (ya <= y) & (yb > y)
        down = (yb <= y) & (ya > y)
        cross = (xb - xa) * (y - ya) - (x - xa) * (yb - ya)
        inside += np.where(up & (cross > 0), 1, 0) - np.where(down & (cross < 0), 1, 0)
    return inside != 0


def ellipse_polygon(w: float, h: float, cx: float = 0.0, cy: float = 0.0, sides: int = ELLIPSE_SIDES):
    """The ``sides``-gon of the ellipse's area (vertices at radius scaled by √(θ / sin θ), θ = 2π/sides)."""
    theta = 2 * math.pi / sides
    k = math.sqrt(theta / math.sin(theta))
    a = np.arange(sides) * theta
    return cx + 0.5 * w * k * np.cos(a), cy + 0.5 * h * k * np.sin(a)


def polygon_area(px, py) -> float:
    return 0.5 * abs(float(np.dot(px, np.roll(py, -1)) - np.dot(py, np.roll(px, -1))))


def polygon_centroid(px, py) -> tuple[float, float]:
    cross = px * np.roll(py, -1) - np.roll(px, -1) * py
    a = 0.5 * cross.sum()
    return (float(((px + np.roll(px, -1)) * cross).sum() / (6 * a)),
            float(((py + np.roll(py, -1)) * cross).sum() / (6 * a)))


def _ccw(px, py):
    """The polygon with counter-clockwise vertices (in x right, y down: positive shoelace area)."""
    signed = float(np.dot(px, np.roll(py, -1)) - np.dot(py, np.roll(px, -1)))
    return (px, py) if signed >= 0 else (px[::-1], py[::-1])


def is_convex(px, py) -> bool:
    x, y = _ccw(np.asarray(px), np.asarray(py))
    dx, dy = np.roll(x, -1) - x, np.roll(y, -1) - y
    cross = dx * np.roll(dy, -1) - dy * np.roll(dx, -1)
    return bool(np.all(cross >= -1e-12 * (np.abs(dx).max() + np.abs(dy).max()) ** 2))


def clip_convex(subject, clip):
    """Sutherland–Hodgman: the part of polygon ``subject`` (x, y arrays) inside the convex ``clip``.

    Per edge (a → b) of the clip, counter-clockwise, each vertex q of the polygon so far, with p the one
    before it, on the side s(v) = (b − a) × (v − a): where s(p) and s(q) differ in sign (s ≥ 0 is inside),
    the crossing p + w·(q − p), w = s(p) / (s(p) − s(q)); then q where s(q) ≥ 0. Compiled
    (:func:`viform.light._polygon.clip_convex_ccw`).
    """
    from viform.light._polygon import clip_convex_ccw

    cx, cy = _ccw(np.asarray(clip[0]), np.asarray(clip[1]))
    return clip_convex_ccw(np.ascontiguousarray(subject[0], dtype=np.float64),
                           np.ascontiguousarray(subject[1], dtype=np.float64),
                           np.ascontiguousarray(cx, dtype=np.float64), np.ascontiguousarray(cy, dtype=np.float64))


def _area_or_zero(poly) -> float:
    return polygon_area(*poly) if len(poly[0]) >= 3 else 0.0


def visible_area_exact(subject, occluders, field) -> float:
    """Area of convex ``subject`` inside convex ``field`` and outside every convex occluder
    (inclusion–exclusion over the occluders that touch it)."""
    from itertools import combinations

    base = clip_convex(subject, field)
    total = _area_or_zero(base)
    if total == 0.0:
        return 0.0
    touching = [o for o in occluders if _area_or_zero(clip_convex(base, o)) > 0]
    hidden = 0.0
    for k in range(1, len(touching) + 1):
        for group in combinations(touching, k):
            part = base
            for o in group:
                part = clip_convex(part, o)
                if len(part[0]) < 3:
                    break
            hidden += (-1) ** (k + 1) * _area_or_zero(part)
    return max(0.0, total - hidden)


# ------------------------------------------------------------------------- layers

class Layer:
    """One layer of a described scene: its source, outline, motion, modulation and depth."""

    def __init__(self, node: dict, index: int, where: str, brightness: float, time_factor: float,
                 t_ref_s: float = 0.0, background: bool = False):
        self.node, self.index, self.where = node, index, where
        self.background = background
        self.blend = node.get("blend", "over")
        self.motion = Motion(node, time_factor, t_ref_s)
        self.modulation = node.get("modulation")
        self.object = node.get("object")
        depth = node.get("depth_m")
        self.depth_m = None if depth is None else (depth if isinstance(depth, dict) else {"depth_m": depth})
        self.brightness = brightness
        self._source(node["source"])
        self._shape(node.get("shape"))

    # source ----------------------------------------------------------------
    def _source(self, src):
        self.kind, p = next(iter(src.items()))
        self.params = p
        b = self.brightness
        self.texels = None
        if self.kind == "solid":
            self.lux_low = self.lux_high = p["lux"] * b
        elif self.kind == "gaussian":
            self.lux_low, self.lux_high = 0.0, p["lux"] * b
        elif self.kind == "pattern":
            lux = p["lux"]
            if p["name"] == "sines":
                if isinstance(lux, list):
                    raise ViformError(f"{self.where}.source.pattern.lux = {lux!r} is not allowed: the sines "
                                      "pattern takes one mean level")
                depth = p.get("depth", 0.5)
                self.lux_low, self.lux_high = lux * b * (1 - depth), lux * b * (1 + depth)
            else:
                if not isinstance(lux, list):
                    raise ViformError(f"{self.where}.source.pattern.lux = {lux!r} is not allowed: give "
                                      "[low, high] lux")
                self.lux_low, self.lux_high = lux[0] * b, lux[1] * b
        else:
            values, alpha, integer = read_image(p["path"], f"{self.where}.source.image.path")
            self.alpha_image = alpha
            if integer:
                if "lux" not in p:
                    raise ViformError(f"{self.where}.source.image.lux is required: give the lux of value 0 and "
                                      f"of full scale of the 8/16-bit image {Path(p['path']).name!r}")
                if p.get("transfer", "srgb") == "srgb":
                    values = _srgb_to_linear(values)
                lo, hi = p["lux"]
                if p.get("map", "linear") == "log":
                    if not lo > 0:
                        raise ViformError(f"{self.where}.source.image.lux = {p['lux']!r} is not allowed: a log map "
                                          "needs a low level > 0 lux")
                    lux = lo * (hi / lo) ** values
                else:
                    lux = lo + (hi - lo) * values
            else:
                lux = values * p.get("gain", 1.0)
            lux = lux * b
            self.texels = Texels(lux)
            self.lux_low, self.lux_high = float(lux.min()), float(lux.max())
            ih, iw = lux.shape
            size = p.get("size_px", [iw, ih])
            centre = p.get("centre_px", [0.0, 0.0])
            # image plane: texel (i, j) ↔ layer point; texel coordinate = (u − left)·iw / width
            self.image_box = (centre[0] - size[0] / 2, centre[1] - size[1] / 2, float(size[0]), float(size[1]))

    def _shape(self, shape):
        self.polygon = None
        self.mask = None
        if shape is None:
            if self.kind == "image" and not self.background:
                x, y, w, h = self.image_box
                self.polygon = (np.array([x, x + w, x + w, x]), np.array([y, y, y + h, y + h]))
            return
        kind, p = next(iter(shape.items()))
        self.shape_kind = kind
        if kind == "rectangle":
            cx, cy = p.get("centre_px", (0.0, 0.0))
            w, h = p["width_px"], p["height_px"]
            self.polygon = (np.array([cx - w / 2, cx + w / 2, cx + w / 2, cx - w / 2]),
                            np.array([cy - h / 2, cy - h / 2, cy + h / 2, cy + h / 2]))
        elif kind == "ellipse":
            cx, cy = p.get("centre_px", (0.0, 0.0))
            self.polygon = ellipse_polygon(p["width_px"], p["height_px"], cx, cy)
        elif kind == "polygon":
            pts = np.asarray(p["points_px"], dtype=np.float64)
            if polygon_area(pts[:, 0], pts[:, 1]) <= 0:
                raise ViformError(f"{self.where}.shape.polygon.points_px is not allowed: the polygon has no area")
            self.polygon = (pts[:, 0].copy(), pts[:, 1].copy())
        elif kind == "alpha":
            if self.alpha_image is None:
                raise ViformError(f"{self.where}.shape.alpha is not allowed: image "
                                  f"{Path(self.params['path']).name!r} has no alpha channel")
            self.mask = Texels(self.alpha_image)
        else:
            values, _, integer = read_image(p["path"], f"{self.where}.shape.mask.path")
            if values.shape != self.texels.shape:
                raise ViformError(f"{self.where}.shape.mask.path: the mask is {values.shape[1]}×{values.shape[0]} "
                                  f"px, the source image {self.texels.shape[1]}×{self.texels.shape[0]} "
                                  "(width × height): they must match")
            self.mask = Texels(np.clip(values, 0.0, 1.0))
        if self.mask is not None:
            x, y, w, h = self.image_box
            self.polygon = (np.array([x, x + w, x + w, x]), np.array([y, y, y + h, y + h]))

    @property
    def full_field(self) -> bool:
        return self.polygon is None

    def peak_lux(self) -> float:
        return self.lux_high * modulation_peak(self.modulation)

    # evaluation -------------------------------------------------------------
    def light(self, u, v, jac) -> np.ndarray:
        """Source lux at layer points (u, v); ``jac``: |∂(u, v)/∂(x, y)| rows (for the image footprint)."""
        p = self.params
        if self.kind == "solid":
            return np.full(np.shape(u), self.lux_high)
        if self.kind == "gaussian":
            return self.lux_high * np.exp(-(u * u + v * v) / (2 * p["sigma_px"] ** 2))
        if self.kind == "pattern":
            name = p["name"]
            period = p.get("period_px", 48.0 if name != "sines" else 6.0)
            if name == "sines":
                x0, y0 = self.sines_origin()
                depth = p.get("depth", 0.5)
                mean = self.lux_high / (1 + depth)
                return mean * (1.0 + depth * np.sin(2 * np.pi * (v - y0) / period)
                               * np.sin(2 * np.pi * (u - x0) / period))
            sx, sy = p.get("scale", (1.0, 1.0))
            if name == "noise":
                value = value_noise(u / sx, v / sy, period, p.get("seed", 0))
            else:
                value = PATTERNS[name](u / sx, v / sy, period)
            return self.lux_low + (self.lux_high - self.lux_low) * value
        return self._sample(self.texels, u, v, jac)

    def sines_origin(self) -> tuple[float, float]:
        """Where the sines pattern starts: the top-left corner of the layer's outline (0, 0 without one)."""
        if self.polygon is None:
            return 0.0, 0.0
        return float(self.polygon[0].min()), float(self.polygon[1].min())

    def _sample(self, texels, u, v, jac):
        x, y, w, h = self.image_box
        ih, iw = texels.shape
        kx, ky = iw / w, ih / h
        hx = 0.5 * np.maximum(kx * jac[0], 1.0)
        hy = 0.5 * np.maximum(ky * jac[1], 1.0)
        return texels.sample((u - x) * kx, (v - y) * ky, hx, hy)

    def depth_at(self, u, v) -> np.ndarray:
        d = self.depth_m
        slope = d.get("slope_m_per_px", (0.0, 0.0))
        return d["depth_m"] + slope[0] * u + slope[1] * v


def value_noise(x, y, period_px: float, seed: int) -> np.ndarray:
    """Smooth value noise in [0, 1]: random lattice values every ``period_px``, blended with smoothstep
    (two octaves, the second at half the period and half the weight)."""
    out = 0.0
    weight = 0.0
    for octave, amp in ((1.0, 2 / 3), (0.5, 1 / 3)):
        p = period_px * octave
        gx, gy = np.asarray(x) / p, np.asarray(y) / p
        ix, iy = np.floor(gx), np.floor(gy)
        fx, fy = gx - ix, gy - iy
        fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)

        def lattice(i, j, octave=octave):
            h = (i.astype(np.int64) * 73856093) ^ (j.astype(np.int64) * 19349663) ^ (seed * 83492791 + int(octave * 7))
            h = (h * 2654435761) & 0xFFFFFFFF
            return (h % 65536) / 65535.0

        v00, v10 = lattice(ix, iy), lattice(ix + 1, iy)
        v01, v11 = lattice(ix, iy + 1), lattice(ix + 1, iy + 1)
        out = out + amp * ((1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11))
        weight += amp
    return out / weight


# ------------------------------------------------------------------------- the scene

class DescribedScene(Scene):
    """A scene rendered from a description (see the module notes).

    Parameters
    ----------
    description : dict
        A validated description (:func:`~viform.light.description.load_description`).
    height, width : int, optional
        Size to render at; every position and size scales from the described canvas.
    source : str, optional
        Where the description came from (a file path or a built-in name), for metadata.
    settings : dict, optional
        The settings it was resolved with (recorded so the scene can be remade).
    """

    name = "described"

    def __init__(self, description: dict, height: int | None = None, width: int | None = None,
                 source: str | None = None, settings: dict | None = None):
        canvas = description["canvas"]
        w0, h0 = canvas["width_px"], canvas["height_px"]
        height = h0 if height is None else height
        width = w0 if width is None else width
        super().__init__(height, width, canvas.get("duration_s"))
        self.description = description
        self.name = description["name"]
        self.source_spec = source
        self.settings = dict(settings or {})
        self.scale_xy = (width / w0, height / h0)
        self.canvas_px = (w0, h0)
        brightness = float(self.settings.get("brightness", 1.0))
        speed = float(self.settings.get("speed", 1.0))
        if not (math.isfinite(brightness) and brightness > 0):
            raise ViformError(f"setting brightness={brightness!r} is not allowed: it must be a finite factor > 0")
        if not (math.isfinite(speed) and speed >= 0):
            raise ViformError(f"setting speed={speed!r} is not allowed: it must be a finite factor ≥ 0")
        self.speed = speed
        t_ref = float(canvas.get("time_reference_s", 0.0))
        self._build(brightness, speed, t_ref)
        if "peak_lux" in self.settings:
            peak = float(self.settings["peak_lux"])
            if not (math.isfinite(peak) and peak > 0):
                raise ViformError(f"setting peak_lux={peak!r} is not allowed: it must be a finite lux > 0")
            if "brightness" in self.settings:
                raise ViformError("settings brightness and peak_lux both set the brightness: give one")
            brightness = peak / self.peak_lux()
            self._build(brightness, speed, t_ref)
        self.brightness = brightness
        # paint order, far to near: by depth (larger first), then list order
        if any(layer.depth_m is not None for layer in self.layers):
            self.order = sorted(self.layers, key=lambda l: (-l.depth_m["depth_m"], l.index))
        else:
            self.order = list(self.layers)
        self.rank = {layer.index: r for r, layer in enumerate(reversed(self.order))}  # 0 = nearest
        camera = description.get("camera", {})
        self.camera = Motion(camera, speed, t_ref) if "motion" in camera else None
        self.shake = camera.get("shake")
        cx, cy = w0 / 2.0, h0 / 2.0
        self._canvas_scale = np.array([[self.scale_xy[0], 0.0, 0.0], [0.0, self.scale_xy[1], 0.0]])
        self._centre = (cx, cy)
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
        self._xc, self._yc = xx + 0.5, yy + 0.5

    def _build(self, brightness: float, speed: float, t_ref: float) -> None:
        d = self.description
        self.background = Layer(d["background"], 0, "background", brightness, speed, t_ref, background=True)
        self.layers = [Layer(node, i + 1, f"layers[{i}]", brightness, speed, t_ref)
                       for i, node in enumerate(d.get("layers", []))]

    # ----------------------------------------------------------------- description
    def peak_lux(self) -> float:
        """An upper bound of the light: the sum of every source's peak (lux)."""
        over = max([self.background.peak_lux()] + [l.peak_lux() for l in self.layers if l.blend == "over"])
        return over + sum(l.peak_lux() for l in self.layers if l.blend == "add")

    def describe(self) -> dict:
        d = super().describe()
        d["described"] = {"source": self.source_spec, "settings": self.settings, "height": self.height,
                          "width": self.width, "description": self.description}
        return d

    # ----------------------------------------------------------------- maps
    def _camera(self, t: float) -> np.ndarray:
        return self._cameras(np.array([t], dtype=np.float64))[0]

    def _cameras(self, times) -> np.ndarray:
        """The camera's map (view → canvas) at ``times`` (s), (n, 2, 3)."""
        times = np.asarray(times, dtype=np.float64).ravel()
        n = times.size
        cx, cy = self._centre
        cam = np.zeros((n, 2, 3))
        cam[:, 0, 0] = cam[:, 1, 1] = 1.0
        if self.camera is not None:
            px, py, a, sx, sy = self.camera.poses(times)
            about = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy]])
            cam = compose(pose_matrices(cx + px, cy + py, a, sx, sy), about)
        if self.shake:
            s = self.shake
            rng = np.random.default_rng(s.get("seed", 0))
            phases = rng.uniform(0, 2 * np.pi, (2, 3))
            ratios = np.array([1.0, 1.618, 2.718])
            tt = (self.speed * times)[:, None]
            amp = s["amplitude_px"] / math.sqrt(3 / 2)
            k = (2 * np.pi * s["frequency_hz"] * ratios)[None, :]
            dx = amp * np.sum(np.sin(k * tt + phases[0]) / np.sqrt(3), axis=1)
            dy = amp * np.sum(np.sin(k * tt + phases[1]) / np.sqrt(3), axis=1)
            cam[:, 0, 2] = cam[:, 0, 2] + dx
            cam[:, 1, 2] = cam[:, 1, 2] + dy
        return cam

    def layer_map(self, layer: Layer, t: float) -> np.ndarray:
        """2×3 map from the layer's plane to the canvas (px of the rendered size) at ``t_s``."""
        return self.layer_maps(layer, np.array([t], dtype=np.float64))[0]

    def layer_maps(self, layer: Layer, times) -> np.ndarray:
        """The layer's maps at ``times`` (s), (n, 2, 3): what the reference and the compiled light both use."""
        times = np.asarray(times, dtype=np.float64).ravel()
        return compose(self._canvas_scale, compose(self._cameras(times), layer.motion.matrices(times)))

    def modulation_factors(self, layer: Layer, times) -> np.ndarray:
        """The layer's modulation at ``times`` (s)."""
        return modulation_factors(layer.modulation, times)

    def _moves(self, layer: Layer) -> bool:
        return not layer.motion.static or self.camera is not None or bool(self.shake)

    # ----------------------------------------------------------------- light
    def _bbox(self, layer: Layer, a: np.ndarray):
        """Pixel range (c0, c1, r0, r1) the layer's outline can touch under map ``a``."""
        if layer.full_field:
            return 0, self.width, 0, self.height
        x, y = apply(a, *layer.polygon)
        c0 = max(0, int(math.floor(x.min())))
        c1 = min(self.width, int(math.ceil(x.max())) + 1)
        r0 = max(0, int(math.floor(y.min())))
        r1 = min(self.height, int(math.ceil(y.max())) + 1)
        return c0, c1, r0, r1

    def _coverage(self, layer: Layer, a: np.ndarray, box, u=None, v=None, jac=None) -> np.ndarray:
        c0, c1, r0, r1 = box
        if layer.full_field:
            return np.ones((r1 - r0, c1 - c0))
        x, y = apply(a, *layer.polygon)
        cov = np.clip(polygon_coverage(x, y, c0, r0, c1 - c0, r1 - r0), 0.0, 1.0)
        if layer.mask is not None:
            cov = cov * np.clip(layer._sample(layer.mask, u, v, jac), 0.0, 1.0)
        return cov

    def _local(self, a: np.ndarray, box):
        c0, c1, r0, r1 = box
        inv = invert(a)
        xc, yc = self._xc[r0:r1, c0:c1], self._yc[r0:r1, c0:c1]
        u, v = apply(inv, xc, yc)
        jac = (abs(inv[0, 0]) + abs(inv[0, 1]), abs(inv[1, 0]) + abs(inv[1, 1]))
        return u, v, jac

    def reference_lux(self, t_s: float) -> np.ndarray:
        """The light at ``t_s`` (lux, (H, W)) by the plain NumPy renderer."""
        t = float(t_s)
        bg = self.background
        a = self.layer_map(bg, t)
        box = (0, self.width, 0, self.height)
        u, v, jac = self._local(a, box)
        lux = bg.light(u, v, jac) * modulation_factor(bg.modulation, t)
        for layer in self.order:
            a = self.layer_map(layer, t)
            box = self._bbox(layer, a)
            c0, c1, r0, r1 = box
            if c1 <= c0 or r1 <= r0:
                continue
            u, v, jac = self._local(a, box)
            cov = self._coverage(layer, a, box, u, v, jac)
            if not cov.any():
                continue
            src = layer.light(u, v, jac) * modulation_factor(layer.modulation, t)
            patch = lux[r0:r1, c0:c1]
            if layer.blend == "add":
                patch += cov * src
            else:
                patch += cov * (src - patch)
        return lux

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        """The light at ``t_s`` (lux, (H, W)): the compiled renderer's (:meth:`sampler`), which agrees
        with :meth:`reference_lux` to rounding."""
        return self.sampler().frames(np.array([float(t_s)]))[0]

    def illuminance_lux_many(self, times_s) -> np.ndarray:
        return self.sampler().frames(np.asarray(times_s, dtype=np.float64).ravel())

    def illuminance_lux_row_times(self, times_s) -> np.ndarray:
        """Row r of :meth:`illuminance_lux` at ``times_s[r]``, every row rendered once at its own instant (a
        rolling shutter's rows: :meth:`~viform.light.scenes.Scene.rolling_mean_illuminance_lux`)."""
        if type(self).illuminance_lux is not DescribedScene.illuminance_lux or self._light_patched():
            return super().illuminance_lux_row_times(times_s)
        return self.sampler().row_frames(self._row_times(times_s))

    def sampler(self):
        """The :class:`~viform.light.layered_render.LayeredSampler` that renders this scene (made once)."""
        if getattr(self, "_sampler", None) is None:
            from viform.light.layered_render import LayeredSampler

            self._sampler = LayeredSampler(self)
        return self._sampler

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """The longest hold of the light (ticks) that misplaces the fastest outline vertex or field corner
        by at most :data:`~viform.light.sampled.LIGHT_ERROR_PX` px at any tick (v·S/2 ≤ bound, v in px per
        tick), and that keeps at least :data:`MODULATION_SAMPLES_PER_PERIOD` samples per period of every
        modulation (a step: any); 1 where the light is evaluated per tick in the kernel."""
        from viform.light.sampled import MAX_AUTO_SAMPLE_TICKS, auto_light_sample_ticks

        light = self.compiled_light()
        if light is None or light.kind != "sampled":
            return 1
        span = duration_s if duration_s is not None else (self.duration_s or 0.05)
        speed = self.max_speed_px_per_s(0.0, span)
        ticks = auto_light_sample_ticks(speed, clock_hz)
        for layer in self._all_layers():
            mod = layer.modulation
            if mod:
                kind, p = next(iter(mod.items()))
                if kind != "step":
                    per_period = clock_hz / (p["frequency_hz"] * MODULATION_SAMPLES_PER_PERIOD)
                    ticks = min(ticks, max(1, int(math.floor(per_period))))
        return int(max(1, min(ticks, MAX_AUTO_SAMPLE_TICKS)))

    def compiled_light(self):
        """The simulator's light: the per-tick compiled kinds where the description is one of their forms
        (a full-field pattern — texture, edge, bars — translating or rotating, or a solid level, times a
        modulation, with no layers, no camera motion and the canvas at its own size: the built-in scenes'
        bits), else the sampled kind rendered by :meth:`sampler`; None when a subclass changed the light."""
        if type(self).illuminance_lux is not DescribedScene.illuminance_lux:
            return None
        if getattr(self, "_compiled", None) is None:
            light = self._per_tick_light()
            if light is None:
                from viform.light.compiled import CompiledLight

                light = CompiledLight("sampled", self.height, self.width, sampler=self.sampler())
            self._compiled = light
        return self._compiled

    def _per_tick_light(self):
        if self.layers or self.camera is not None or self.shake or self.scale_xy != (1.0, 1.0):
            return None
        from viform.light.compiled import CompiledLight

        bg = self.background
        mod = bg.modulation
        modulation = ("none",)
        if mod:
            kind, p = next(iter(mod.items()))
            if kind == "pwm":
                return None
            modulation = (("step", p["t_s"], p["factor"]) if kind == "step"
                          else (kind, p["frequency_hz"], p["depth"]))
            if kind == "sine" and p.get("phase_rad", 0.0) != 0.0:
                return None
        if bg.kind == "solid":
            if bg.motion.static is False and not self._static_solid():
                return None
            frame = np.full(self.shape, bg.lux_high)[None]
            if modulation[0] == "none":
                return CompiledLight("frames", self.height, self.width, frames=frame,
                                     frame_index=lambda times: np.zeros(np.shape(times), np.int64))
            if modulation[0] == "step":
                step = modulation[1]
                frames = np.concatenate([frame, frame * modulation[2]])
                return CompiledLight("frames", self.height, self.width, frames=frames,
                                     frame_index=lambda times: (np.asarray(times) >= step).astype(np.int64))
            return CompiledLight("frames-modulated", self.height, self.width, frames=frame, modulation=modulation)
        if bg.kind != "pattern" or bg.params["name"] not in ("texture", "edge", "bars") or "scale" in bg.params:
            return None
        x, y, angle, sx, sy = bg.motion.base
        if angle != 0.0 or (sx, sy) != (1.0, 1.0) or bg.motion.t_ref_s != 0.0:
            return None
        m = bg.motion.motion or {}
        v = m.get("velocity")
        if m and v is None:
            return None
        v = v or {}
        vx, vy = v.get("px_per_s", (0.0, 0.0))
        w = v.get("rad_per_s", 0.0)
        if v.get("scale_per_s", 0.0) != 0.0 or (w != 0.0 and (vx, vy) != (0.0, 0.0)):
            return None
        k = bg.motion.k
        # the kernel counts pixel centres at integers: the origin moves half a pixel
        motion = (("rotate", x - 0.5, y - 0.5, w * k) if w != 0.0 else ("translate", x - 0.5, y - 0.5, vx * k, vy * k))
        return CompiledLight("pattern", self.height, self.width, pattern=bg.params["name"], min_lux=bg.lux_low,
                             max_lux=bg.lux_high, period_px=bg.params.get("period_px", 48.0), motion=motion,
                             modulation=modulation)

    def _static_solid(self) -> bool:
        return True  # a solid level looks the same wherever it moves

    # ----------------------------------------------------------------- truth
    def truth_kinds(self) -> tuple[str, ...]:
        kinds = ["motion", "objects"]
        if self.background.depth_m is not None and all(l.depth_m is not None for l in self.layers):
            kinds.insert(1, "depth")
        return tuple(kinds)

    def _labels_and_mixed(self, t: float):
        """Visible layer index per pixel (0 = background) and the mixed-edge pixels, at ``t``."""
        labels = np.zeros(self.shape, np.int32)
        mixed = np.zeros(self.shape, bool)
        for layer in self.order:  # far to near: nearer layers overwrite
            if layer.blend == "add":
                continue
            a = self.layer_map(layer, t)
            box = self._bbox(layer, a)
            c0, c1, r0, r1 = box
            if c1 <= c0 or r1 <= r0:
                continue
            if layer.full_field:
                labels[:] = layer.index
                mixed[:] = False
                continue
            u, v, jac = self._local(a, box)
            cov = self._coverage(layer, a, box, u, v, jac)
            x, y = apply(a, *layer.polygon)
            inside = polygon_contains(x, y, self._xc[r0:r1, c0:c1], self._yc[r0:r1, c0:c1])
            if layer.mask is not None:
                inside &= layer._sample(layer.mask, u, v, jac) >= 0.5
            lab = labels[r0:r1, c0:c1]
            mix = mixed[r0:r1, c0:c1]
            partial = (cov > 1e-12) & (cov < 1 - 1e-9)
            mix[inside] = partial[inside]  # the visible layer covers this pixel partly
            mix[~inside & partial] = True  # a nearer layer's edge crosses a pixel it does not own
            lab[inside] = layer.index
        return labels, mixed

    def layer_labels(self, t_s: float) -> np.ndarray:
        """Visible layer per pixel at ``t_s`` (0 = background, i = layers[i − 1])."""
        return self._labels_and_mixed(float(t_s))[0]

    def _layer_ids(self) -> np.ndarray:
        ids = np.zeros(len(self.layers) + 1, np.int32)
        for layer in self.layers:
            if layer.object:
                ids[layer.index] = layer.object["id"]
        return ids

    def object_labels(self, t_s: float) -> np.ndarray:
        return self._layer_ids()[self.layer_labels(t_s)]

    def _all_layers(self):
        return [self.background] + self.layers

    def motion_px_per_s(self, t_s: float, dt_s: float = 1e-7) -> np.ndarray:
        """Velocity (px/s) of the point each pixel shows: its layer's map differentiated in time
        (central difference over ±``dt_s``); NaN at mixed edges."""
        t = float(t_s)
        labels, mixed = self._labels_and_mixed(t)
        motion = np.zeros((2, *self.shape))
        for layer in self._all_layers():
            where = labels == layer.index
            if not where.any() or not self._moves(layer):
                continue
            a0, a1 = self.layer_map(layer, t - dt_s), self.layer_map(layer, t + dt_s)
            a = self.layer_map(layer, t)
            x, y = self._xc[where], self._yc[where]
            u, v = apply(invert(a), x, y)
            x1, y1 = apply(a1, u, v)
            x0, y0 = apply(a0, u, v)
            motion[0][where] = (x1 - x0) / (2 * dt_s)
            motion[1][where] = (y1 - y0) / (2 * dt_s)
        motion[:, mixed] = np.nan
        return motion

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        if not (math.isfinite(t0_s) and math.isfinite(t1_s)):
            raise ViformError(f"optical flow instants t0_s = {t0_s!r}, t1_s = {t1_s!r} must be finite")
        labels0, mixed0 = self._labels_and_mixed(float(t0_s))
        labels1, _ = self._labels_and_mixed(float(t1_s))
        moves = {}
        for layer in self._all_layers():
            if not self._moves(layer):
                continue
            m = compose(self.layer_map(layer, t1_s), invert(self.layer_map(layer, t0_s)))

            def move(x, y, m=m):  # flow_from_layers counts pixel centres at integers
                x1, y1 = apply(m, x + 0.5, y + 0.5)
                return x1 - 0.5, y1 - 0.5

            moves[layer.index] = move
        order = {layer.index: self.rank[layer.index] for layer in self.layers}
        return flow_from_layers(labels0, labels1, mixed0, moves, order, t0_s, t1_s)

    def depth_m(self, t_s: float) -> np.ndarray:
        if "depth" not in self.truth_kinds():
            self._no_truth("depth")
        t = float(t_s)
        labels = self.layer_labels(t)
        depth = np.empty(self.shape)
        for layer in self._all_layers():
            where = labels == layer.index
            if where.any():
                u, v = apply(invert(self.layer_map(layer, t)), self._xc[where], self._yc[where])
                depth[where] = layer.depth_at(u, v)
        return depth

    @cached_property
    def _outline_area_local(self) -> dict:
        out = {}
        for layer in self.layers:
            if layer.polygon is None:
                continue
            area = polygon_area(*layer.polygon)
            if layer.mask is not None:
                x, y, w, h = layer.image_box
                area = float(layer.mask.values.mean()) * w * h
            out[layer.index] = area
        return out

    @cached_property
    def _outline_centroid_local(self) -> dict:
        return {layer.index: polygon_centroid(*layer.polygon) for layer in self.layers if layer.polygon is not None}

    def objects(self, t_s: float) -> list[ObjectTruth]:
        """Every layer with an object: the tight box of its projected outline, its velocity (its outline's
        centroid, differentiated in time) and its visible fraction — exact for convex outlines hidden by
        convex "over" layers (polygon clipping), else counted on the pixel grid from the coverages."""
        t = float(t_s)
        out = []
        maps = {layer.index: self.layer_map(layer, t) for layer in self.layers}
        field = (np.array([0.0, self.width, self.width, 0.0]), np.array([0.0, 0.0, self.height, self.height]))
        grid = None
        outlines, convex = {}, {}  # each layer's projected outline, and whether it is convex: once per instant

        def outline(o):
            if o.index not in outlines:
                outlines[o.index] = apply(maps[o.index], *o.polygon)
            return outlines[o.index]

        def is_convex_here(o):
            if o.index not in convex:
                convex[o.index] = o.mask is None and is_convex(*outline(o))
            return convex[o.index]

        for layer in self.layers:
            if not layer.object or layer.polygon is None:
                continue
            a = maps[layer.index]
            x, y = outline(layer)
            if x.max() <= 0 or y.max() <= 0 or x.min() >= self.width or y.min() >= self.height:
                continue
            area = self._outline_area_local[layer.index] * abs(np.linalg.det(a[:, :2]))
            nearer = [o for o in self.layers if o.blend == "over" and o.index != layer.index
                      and self.rank[o.index] < self.rank[layer.index]]
            if nearer and any(o.full_field for o in nearer):
                visible_area = 0.0
            elif is_convex_here(layer) and all(is_convex_here(o) for o in nearer):
                visible_area = visible_area_exact((x, y), [outline(o) for o in nearer], field)
            else:
                if grid is None:
                    grid = self._visible_on_grid(t)
                visible_area = grid.get(layer.index, 0.0)
            visible = min(1.0, max(0.0, visible_area / area)) if area > 0 else 0.0
            cx, cy = self._outline_centroid_local[layer.index]
            h = 1e-7
            x1, y1 = apply(self.layer_map(layer, t + h), cx, cy)
            x0, y0 = apply(self.layer_map(layer, t - h), cx, cy)
            velocity = ((x1 - x0) / (2 * h), (y1 - y0) / (2 * h))
            name = layer.object.get("class", layer.node.get("name", "object"))
            out.append(ObjectTruth(int(layer.object["id"]), name, float(x.min()), float(y.min()),
                                   float(x.max() - x.min()), float(y.max() - y.min()), visible, velocity))
        return out

    def _visible_on_grid(self, t: float) -> dict:
        """Visible area (px²) of every outlined layer: its coverage times what nearer layers leave."""
        nearer_cov = np.zeros(self.shape)
        visible = {}
        for layer in reversed(self.order):  # near to far
            if layer.polygon is None:
                continue
            a = self.layer_map(layer, t)
            box = self._bbox(layer, a)
            c0, c1, r0, r1 = box
            if c1 <= c0 or r1 <= r0:
                visible[layer.index] = 0.0
                continue
            u, v, jac = self._local(a, box)
            cov = self._coverage(layer, a, box, u, v, jac)
            hidden = nearer_cov[r0:r1, c0:c1]
            visible[layer.index] = float((cov * (1 - hidden)).sum())
            if layer.blend == "over":
                hidden += cov * (1 - hidden)
        return visible

    def max_speed_px_per_s(self, t0_s: float = 0.0, t1_s: float | None = None, samples: int = 64) -> float:
        """The fastest image speed of any outline vertex or field corner over [t0, t1] (px/s), sampled."""
        t1_s = t0_s + (self.duration_s or 0.05) if t1_s is None else t1_s
        best = 0.0
        for layer in self._all_layers():
            if not self._moves(layer):
                continue
            if layer.polygon is not None:
                px, py = layer.polygon
            else:
                inv = invert(self.layer_map(layer, t0_s))
                px, py = apply(inv, np.array([0.0, self.width, self.width, 0.0]),
                               np.array([0.0, 0.0, self.height, self.height]))
            for t in np.linspace(t0_s, t1_s, samples):
                h = 1e-7
                x1, y1 = apply(self.layer_map(layer, t + h), px, py)
                x0, y0 = apply(self.layer_map(layer, t - h), px, py)
                best = max(best, float(np.hypot(x1 - x0, y1 - y0).max() / (2 * h)))
        return best
