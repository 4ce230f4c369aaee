"""Built-in scenes that pose the high-speed / high-dynamic-range dilemma, with analytic truth.

Seed 000 §1–§2 calls it the "dilemma" of timed-exposure cameras: a long exposure reaches
dim light but blurs motion and saturates bright light, a short one freezes motion but
loses the shadows. Seeds 001 (segmented exposure) and 003 (conditional overflow) widen
the range of one exposure, seed 002 shortens the frame, seed 000's spike camera lets every
pixel choose its own integration time. :class:`DilemmaScene` puts all of it in one view:

* more than six decades of sensor-plane illuminance (a lamp, a sunlit window, a shadowed
  interior and a deep-shadow corner);
* fast motion: a three-blade propeller (tip speed ≥ 2 000 px/s) and a vehicle crossing at
  2 500 px/s whose leading edge is a sharp vertical step (it gives the motion-blur metric);
* a 90 Hz PWM LED (the flicker of LED lamps and signs that short exposures catch or miss);
* a small, dim, fast object (a Gaussian blob moving at 3 000 px/s over the dark interior).

The light at any instant is a closed form (:meth:`DilemmaScene.illuminance_lux`), so every
sensor is compared with the exact truth. Every component is defined relative to the
image size, so the scene exists at any resolution; speeds are in pixels per second at the
chosen size.

:class:`NightRoadFogScene` is a night road in fog for the range-gated camera (seed 004): a
passive view in lux (oncoming headlights with their fog halo, airlight, signs and a car
attenuated by the fog) and, for the gated camera, the same scene as an
:class:`~viform.light.active.ActiveScene` (range, reflectance, retroreflective sheeting).
"""

from __future__ import annotations

import math

import numpy as np

from viform._validate import ViformError, check_int, check_non_negative, check_positive, check_range
from viform.light.scenes import Scene
from viform.light.truth import (
    FlowTruth,
    ObjectTruth,
    disc_fraction_inside,
    flow_from_layers,
    rotate_about,
    translate_by,
)

# Object ids of the dilemma scene's truth (stable for every instant and size).
VEHICLE_ID, BLADE_IDS, SMALL_OBJECT_ID, LED_ID = 1, (2, 3, 4), 5, 6
_BLADE_HALF_WIDTH_RAD = math.radians(14.0)
_BLADE_INNER_FRACTION = 0.12


def pwm_on_time_s(t_s: float, frequency_hz: float, duty: float) -> float:
    """Time the PWM output has been on in [0, t_s]: whole periods plus the part of the last one.

    The LED is on during the first ``duty`` fraction of each period 1/f.
    """
    period = 1.0 / frequency_hz
    whole = math.floor(t_s / period)
    return whole * duty * period + min(t_s - whole * period, duty * period)


def _lux(value: float) -> str:
    """Illuminance for labels: thousands separated, 3 significant figures below 1 000."""
    return f"{value:,.0f}" if value >= 1000 else f"{value:.3g}"


class DilemmaScene(Scene):
    """The dilemma scene (see the module notes); all illuminances on the sensor plane, lux.

    Parameters
    ----------
    height, width : int
        Resolution (≥ 32 × 48).
    brightness : float
        Factor on every illuminance (1 = the documented levels below).
    speed : float
        Factor on every speed (1 = propeller tip 2 000 px/s at the default size scale, vehicle
        2 500 px/s, small object 3 000 px/s).
    shadow_lux, interior_lux, window_lux, lamp_lux : float
        Deep-shadow corner (0.02), interior (0.5–4 textured), sunlit window (1 000–3 000)
        and lamp (50 000) levels: 6.4 decades. Sensor-plane values of a lens at about f/2:
        a lit room of ~50 cd/m² gives ~10 lux, a sunlit sky ~1 000 lux, a bare lamp 10⁴–10⁶.
    led_on_lux, led_off_lux, led_frequency_hz, led_duty : float
        The PWM LED (50 lux on, 0.1 off, 90 Hz, 25 % duty).
    """

    name = "dilemma"

    def __init__(self, height: int = 96, width: int = 160, brightness: float = 1.0, speed: float = 1.0,
                 shadow_lux: float = 0.02, interior_lux: float = 0.5, window_lux: float = 1000.0,
                 lamp_lux: float = 50_000.0, led_on_lux: float = 50.0, led_off_lux: float = 0.1,
                 led_frequency_hz: float = 90.0, led_duty: float = 0.25, duration_s: float | None = None):
        height = check_int("height", height, 32)
        width = check_int("width", width, 48)
        super().__init__(height, width, duration_s)
        self.brightness = check_positive("brightness", brightness)
        self.speed = check_non_negative("speed", speed)
        self.shadow_lux = check_positive("shadow_lux", shadow_lux) * self.brightness
        self.interior_lux = check_positive("interior_lux", interior_lux) * self.brightness
        self.window_lux = check_positive("window_lux", window_lux) * self.brightness
        self.lamp_lux = check_positive("lamp_lux", lamp_lux) * self.brightness
        self.led_on_lux = check_positive("led_on_lux", led_on_lux) * self.brightness
        self.led_off_lux = check_non_negative("led_off_lux", led_off_lux) * self.brightness
        self.led_frequency_hz = check_positive("led_frequency_hz", led_frequency_hz)
        self.led_duty = check_range("led_duty", led_duty, 0.0, 1.0, low_open=True, high_open=True)
        h, w = height, width
        y, x = np.mgrid[0:h, 0:w].astype(np.float64)
        self._x, self._y = x, y
        # Static background: textured interior, darker towards the deep-shadow corner (lower left).
        shade = np.clip((x / w) * 0.6 + (1 - y / h) * 0.6, 0.0, 1.0)
        wall = self.interior_lux * (1.0 + 7.0 * shade) * (0.85 + 0.15 * np.sin(x / 3.0) * np.sin(y / 5.0))
        corner = (x < 0.22 * w) & (y > 0.62 * h)
        wall[corner] = self.shadow_lux
        # Sunlit window (upper left), with a sky gradient and window bars.
        self.window = (x >= 0.04 * w) & (x < 0.36 * w) & (y >= 0.06 * h) & (y < 0.46 * h)
        sky = self.window_lux * (1.0 + 2.0 * (1 - (y - 0.06 * h) / (0.4 * h)))
        bars = (np.abs(x - 0.20 * w) < max(0.5, 0.012 * w)) | (np.abs(y - 0.26 * h) < max(0.5, 0.012 * h))
        wall = np.where(self.window & ~bars, sky, wall)
        wall = np.where(self.window & bars, 5.0 * self.brightness, wall)
        # Lamp (upper right): a small disc.
        lamp_r = max(1.5, 0.035 * h)
        self.lamp = (x - 0.88 * w) ** 2 + (y - 0.14 * h) ** 2 <= lamp_r ** 2
        wall[self.lamp] = self.lamp_lux
        # Road band (bottom) where the vehicle passes.
        self.road_rows = (int(round(0.74 * h)), int(round(0.95 * h)))
        r0, r1 = self.road_rows
        self.road_lux = 1.5 * self.brightness
        wall[r0:r1] = self.road_lux
        self._background = wall
        # Propeller: three blades about (cx, cy), radius R; tip speed 2000 px/s at speed = 1.
        self.prop_centre = (0.58 * w, 0.40 * h)
        self.prop_radius_px = 0.26 * h
        self.prop_tip_speed_px_per_s = 2000.0 * self.speed
        self.prop_omega_rad_per_s = self.prop_tip_speed_px_per_s / self.prop_radius_px
        dx, dy = x - self.prop_centre[0], y - self.prop_centre[1]
        self._prop_r = np.hypot(dx, dy)
        self._prop_theta = np.arctan2(dy, dx)
        self._prop_disc = (self._prop_r <= self.prop_radius_px) & (self._prop_r >= 0.12 * self.prop_radius_px)
        self.prop_lux = 20.0 * self.brightness
        self._disc_index = np.flatnonzero(self._prop_disc)
        self._disc_theta = self._prop_theta.ravel()[self._disc_index]
        # Vehicle: a bright box on the road moving right at 2500 px/s, entering from the left edge.
        self.vehicle_speed_px_per_s = 2500.0 * self.speed
        self.vehicle_length_px = 0.9 * w
        self.vehicle_front0_px = 0.30 * w
        self.vehicle_rows = (r0 + max(1, (r1 - r0) // 5), r1 - max(1, (r1 - r0) // 5))
        self.vehicle_lux = 15.0 * self.brightness
        # PWM LED (right, middle).
        led = max(1.0, 0.04 * h)
        self.led = (np.abs(x - 0.93 * w) <= led) & (np.abs(y - 0.55 * h) <= led)
        # Small dim fast object: crossing the dim interior horizontally at 3000 px/s (wraps around).
        self.object_speed_px_per_s = 3000.0 * self.speed
        self.object_row_px = 0.66 * h
        self.object_x0_px = 0.05 * w
        self.object_sigma_px = max(0.7, 0.012 * h)
        self.object_lux = 3.0 * self.brightness
        self._cache: dict = {}
        self._cache_limit = max(16, int(256e6 // (8 * h * w)))  # frames kept for window means
        self._disc_box = self._mask_box(self._prop_disc)
        self._led_box = self._mask_box(self.led)

    # ------------------------------------------------------------------ truth
    def vehicle_front_px(self, t_s: float) -> float:
        """x of the vehicle's leading (right) edge at ``t_s`` (px, wraps around the width)."""
        span = self.width + self.vehicle_length_px
        return (self.vehicle_front0_px + self.vehicle_speed_px_per_s * t_s) % span

    def led_is_on(self, t_s: float) -> bool:
        phase = (t_s * self.led_frequency_hz) % 1.0
        return phase < self.led_duty

    def _moving(self, t_s: float, lux: np.ndarray, r0: int = 0) -> np.ndarray:
        """Draw the moving parts at ``t_s`` over ``lux``, which holds rows ``r0`` … ``r0`` + len(lux) − 1
        of the frame (all of it by default): each pixel the same value whatever rows are drawn."""
        r1 = r0 + lux.shape[0]
        # Vehicle (opaque box; its front edge is the sharp step the blur metric uses).
        front = self.vehicle_front_px(t_s)
        v0, v1 = self.vehicle_rows
        cols = (self._x[0] <= front) & (self._x[0] > front - self.vehicle_length_px)
        a, b = max(v0, r0), min(v1, r1)
        if a < b:
            lux[a - r0:b - r0, cols] = self.vehicle_lux
        # Propeller blades: |angle to nearest blade| < 14° (the disc's pixels in these rows).
        lo, hi = np.searchsorted(self._disc_index, [r0 * self.width, r1 * self.width])
        phase = self._disc_theta[lo:hi] - self.prop_omega_rad_per_s * t_s
        blade = self._disc_index[lo:hi][np.cos(3.0 * phase) > math.cos(3.0 * math.radians(14.0))]
        lux.ravel()[blade - r0 * self.width] = self.prop_lux
        # Small dim object: an additive Gaussian blob (evaluated within 5 σ, where it is > 4e-6).
        ox = (self.object_x0_px + self.object_speed_px_per_s * t_s) % self.width
        reach = 5 * self.object_sigma_px
        c0, c1 = max(0, int(ox - reach)), min(self.width, int(ox + reach) + 2)
        y0, y1 = max(0, int(self.object_row_px - reach)), min(self.height, int(self.object_row_px + reach) + 2)
        a, b = max(y0, r0), min(y1, r1)
        if a < b:
            lux[a - r0:b - r0, c0:c1] += self.object_lux * np.exp(
                -((self._x[a:b, c0:c1] - ox) ** 2 + (self._y[a:b, c0:c1] - self.object_row_px) ** 2)
                / (2 * self.object_sigma_px ** 2))
        return lux

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        lux = self._background.copy()
        self._paint(float(t_s), lux)
        return lux

    def _paint(self, t_s: float, lux: np.ndarray) -> list:
        """Draw the moving parts and the LED at ``t_s`` over ``lux`` (which holds the background); return the
        boxes (row0, row1, col0, col1) written (see :class:`~viform.light.sampled.PaintedSampler`)."""
        self._moving(t_s, lux)
        lux[self.led] = self.led_on_lux if self.led_is_on(t_s) else self.led_off_lux
        front = self.vehicle_front_px(t_s)
        v0, v1 = self.vehicle_rows
        cols = np.flatnonzero((self._x[0] <= front) & (self._x[0] > front - self.vehicle_length_px))
        boxes = [self._disc_box, self._led_box, self._blob_box(t_s)]
        if cols.size:
            boxes.append((v0, v1, int(cols[0]), int(cols[-1]) + 1))
        return boxes

    def _blob_box(self, t_s: float) -> tuple[int, int, int, int]:
        """The box :meth:`_moving` evaluates the small object's Gaussian in at ``t_s``."""
        ox = (self.object_x0_px + self.object_speed_px_per_s * t_s) % self.width
        reach = 5 * self.object_sigma_px
        return (max(0, int(self.object_row_px - reach)), min(self.height, int(self.object_row_px + reach) + 2),
                max(0, int(ox - reach)), min(self.width, int(ox + reach) + 2))

    def _paint_rects(self, times_s: np.ndarray) -> np.ndarray:
        """Boxes holding every pixel :meth:`_paint` writes at any of ``times_s`` (one pixel of margin
        on the moving boxes' columns)."""
        t = np.asarray(times_s, dtype=np.float64)
        front = np.floor((self.vehicle_front0_px + self.vehicle_speed_px_per_s * t)
                         % (self.width + self.vehicle_length_px))
        v0, v1 = self.vehicle_rows
        vehicle = np.stack([np.full(t.shape, v0), np.full(t.shape, v1),
                            front - np.ceil(self.vehicle_length_px) - 1, front + 2], axis=1)
        ox = (self.object_x0_px + self.object_speed_px_per_s * t) % self.width
        reach = 5 * self.object_sigma_px
        y0, y1, _, _ = self._blob_box(0.0)
        blob = np.stack([np.full(t.shape, y0), np.full(t.shape, y1), np.floor(ox - reach) - 1,
                         np.floor(ox + reach) + 3], axis=1)
        fixed = np.array([self._disc_box, self._led_box], dtype=np.float64)
        return np.concatenate([vehicle, blob, fixed]).astype(np.int64)

    @staticmethod
    def _mask_box(mask: np.ndarray) -> tuple[int, int, int, int]:
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        if rows.size == 0:
            return (0, 0, 0, 0)
        return (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)

    def moving_mask(self, t_s: float) -> np.ndarray:
        """Pixels covered at ``t_s`` by the fast-moving parts (propeller blades, vehicle)."""
        mask = np.zeros(self.shape, bool)
        front = self.vehicle_front_px(t_s)
        v0, v1 = self.vehicle_rows
        mask[v0:v1, (self._x[0] <= front) & (self._x[0] > front - self.vehicle_length_px)] = True
        phase = self._disc_theta - self.prop_omega_rad_per_s * t_s
        mask.ravel()[self._disc_index[np.cos(3.0 * phase) > math.cos(3.0 * math.radians(14.0))]] = True
        return mask

    def max_speed_px_per_s(self) -> float:
        return max(self.prop_tip_speed_px_per_s, self.vehicle_speed_px_per_s, self.object_speed_px_per_s)

    def mean_illuminance_lux(self, t0_s: float, t1_s: float, samples: int | None = None) -> np.ndarray:
        """Mean light over [t0_s, t1_s]: moving parts by the midpoint rule with samples every ≤ 0.5 px
        of motion (so blur is resolved), the PWM LED exactly (its on-time in the window)."""
        return self._window_mean(t0_s, t1_s, 0, self.height)

    def rolling_mean_illuminance_lux(self, t0_s: float, exposure_s: float, row_offset_s: float) -> np.ndarray:
        """As :meth:`Scene.rolling_mean_illuminance_lux <viform.light.scenes.Scene.rolling_mean_illuminance_lux>`,
        drawing each row's window in that row only: the same values as row r of :meth:`mean_illuminance_lux`."""
        if type(self).mean_illuminance_lux is not DilemmaScene.mean_illuminance_lux \
                or not self._own_light(DilemmaScene):
            return super().rolling_mean_illuminance_lux(t0_s, exposure_s, row_offset_s)
        out = np.empty(self.shape)
        for r in range(self.height):
            start = t0_s + r * row_offset_s
            out[r] = self._window_mean(start, start + exposure_s, r, r + 1)[0]
        return out

    def _window_mean(self, t0_s: float, t1_s: float, r0: int, r1: int) -> np.ndarray:
        """Rows ``r0`` … ``r1`` − 1 of :meth:`mean_illuminance_lux`."""
        if not t1_s >= t0_s:
            raise ViformError(f"window end t1_s={t1_s!r} must be ≥ start t0_s={t0_s!r}")
        if t1_s == t0_s:
            return self.illuminance_lux(t0_s)[r0:r1]
        speed = self.max_speed_px_per_s()
        step = 0.5 / speed if speed > 0 else (t1_s - t0_s)
        acc = np.zeros((r1 - r0, self.width))
        if (t1_s - t0_s) < 8 * step:
            n = 8
            for k in range(n):
                acc += self._moving(t0_s + (k + 0.5) * (t1_s - t0_s) / n, self._background[r0:r1].copy(), r0)
            acc /= n
        else:
            # Samples on one global time grid (every 0.5 px of the fastest motion), cached, so
            # overlapping windows (rolling rows, segments) share the work.
            k0, k1 = math.ceil(t0_s / step - 0.5), math.floor(t1_s / step - 0.5)
            for k in range(k0, k1 + 1):
                acc += self._grid_frame(k, step)[r0:r1]
            acc /= k1 - k0 + 1
        on = (pwm_on_time_s(t1_s, self.led_frequency_hz, self.led_duty)
              - pwm_on_time_s(t0_s, self.led_frequency_hz, self.led_duty)) / (t1_s - t0_s)
        acc[self.led[r0:r1]] = self.led_off_lux + (self.led_on_lux - self.led_off_lux) * on
        return acc

    def _grid_frame(self, k: int, step: float) -> np.ndarray:
        key = (k, step)
        frame = self._cache.get(key)
        if frame is None:
            if len(self._cache) >= self._cache_limit:
                self._cache.pop(next(iter(self._cache)))  # oldest first
            frame = self._cache[key] = self._moving((k + 0.5) * step, self._background.copy())
        return frame

    # ------------------------------------------------------------------ vision truth
    # Conventions: viform.light.truth. Scene coordinates put pixel centres at integers; the
    # truth's boxes count from pixel edges, hence the + 0.5 where a box is made.

    def truth_kinds(self) -> tuple[str, ...]:
        return ("motion", "objects")

    def small_object_centre_px(self, t_s: float) -> tuple[float, float]:
        """(x, y) of the small object's centre at ``t_s``, scene coordinates (pixel centres at integers)."""
        return (self.object_x0_px + self.object_speed_px_per_s * t_s) % self.width, self.object_row_px

    def small_object_radius_px(self) -> float:
        """Radius taken as the small object's extent: 2 σ, where its light falls to 13.5 % of the peak."""
        return 2.0 * self.object_sigma_px

    def _blade_index(self, t_s: float) -> np.ndarray:
        """Blade (0, 1, 2) covering each disc pixel at ``t_s``, or -1 between blades."""
        phase = self._disc_theta - self.prop_omega_rad_per_s * t_s
        k = np.round(phase / (2 * math.pi / 3))
        off = phase - k * (2 * math.pi / 3)
        on = np.cos(3.0 * phase) > math.cos(3.0 * _BLADE_HALF_WIDTH_RAD)  # the rendering's own test
        return np.where(on & (np.abs(off) < math.pi / 3), np.mod(k, 3), -1).astype(np.int64)

    def object_labels(self, t_s: float) -> np.ndarray:
        """Visible object id per pixel: LED 6, blades 2–4, vehicle 1, small object 5 (drawn over the rest)."""
        t_s = float(t_s)
        labels = np.zeros(self.shape, np.int32)
        labels[self.led] = LED_ID
        blade = self._blade_index(t_s)
        on = blade >= 0
        labels.ravel()[self._disc_index[on]] = np.asarray(BLADE_IDS)[blade[on]]
        front = self.vehicle_front_px(t_s)
        v0, v1 = self.vehicle_rows
        labels[v0:v1, (self._x[0] <= front) & (self._x[0] > front - self.vehicle_length_px)] = VEHICLE_ID
        ox, oy = self.small_object_centre_px(t_s)
        labels[(self._x - ox) ** 2 + (self._y - oy) ** 2 <= self.small_object_radius_px() ** 2] = SMALL_OBJECT_ID
        return labels

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        """Velocity per pixel (px/s): blades ω × r about the hub, vehicle and small object their speeds, the rest 0."""
        labels = self.object_labels(t_s)
        motion = np.zeros((2, *self.shape))
        w = self.prop_omega_rad_per_s
        cx, cy = self.prop_centre
        blades = np.isin(labels, BLADE_IDS)
        motion[0][blades] = -w * (self._y[blades] - cy)
        motion[1][blades] = w * (self._x[blades] - cx)
        motion[0][labels == VEHICLE_ID] = self.vehicle_speed_px_per_s
        motion[0][labels == SMALL_OBJECT_ID] = self.object_speed_px_per_s
        return motion

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        """Forward flow t0 → t1; points that leave the field (the vehicle and the small object wrap
        around) or are covered by a moving part at t1 are invalid."""
        dt = t1_s - t0_s
        spin = rotate_about(*self.prop_centre, self.prop_omega_rad_per_s * dt)
        moves = {VEHICLE_ID: translate_by(self.vehicle_speed_px_per_s * dt, 0.0),
                 SMALL_OBJECT_ID: translate_by(self.object_speed_px_per_s * dt, 0.0),
                 **{blade: spin for blade in BLADE_IDS}}
        order = {SMALL_OBJECT_ID: 0, VEHICLE_ID: 1, LED_ID: 1, **{blade: 1 for blade in BLADE_IDS}}
        return flow_from_layers(self.object_labels(t0_s), self.object_labels(t1_s), None, moves, order, t0_s, t1_s)

    def _blade_box(self, k: int, t_s: float) -> tuple[float, float, float, float]:
        """Tight box (scene coordinates x0, y0, x1, y1) of blade k, an annular sector."""
        cx, cy = self.prop_centre
        r0, r1 = _BLADE_INNER_FRACTION * self.prop_radius_px, self.prop_radius_px
        centre = self.prop_omega_rad_per_s * t_s + 2 * math.pi * k / 3
        lo, hi = centre - _BLADE_HALF_WIDTH_RAD, centre + _BLADE_HALF_WIDTH_RAD
        angles = [lo, hi] + [q * math.pi / 2 for q in range(math.ceil(lo / (math.pi / 2)),
                                                          math.floor(hi / (math.pi / 2)) + 1)]
        xs = [cx + r1 * math.cos(a) for a in angles] + [cx + r0 * math.cos(a) for a in (lo, hi)]
        ys = [cy + r1 * math.sin(a) for a in angles] + [cy + r0 * math.sin(a) for a in (lo, hi)]
        return min(xs), min(ys), max(xs), max(ys)

    def objects(self, t_s: float) -> list[ObjectTruth]:
        """Vehicle, three propeller blades, the small object and the LED, with boxes and velocities."""
        t_s = float(t_s)
        h, w = self.height, self.width
        out = []
        front = self.vehicle_front_px(t_s)
        v0, v1 = self.vehicle_rows
        x0 = front - self.vehicle_length_px + 0.5
        inside = max(0.0, min(front + 0.5, w) - max(x0, 0.0)) / self.vehicle_length_px
        out.append(ObjectTruth(VEHICLE_ID, "vehicle", x0, float(v0), self.vehicle_length_px, float(v1 - v0),
                               inside, (self.vehicle_speed_px_per_s, 0.0)))
        cx, cy = self.prop_centre
        r0, r1 = _BLADE_INNER_FRACTION * self.prop_radius_px, self.prop_radius_px
        a = _BLADE_HALF_WIDTH_RAD
        centroid_r = 2 / 3 * (r1 ** 3 - r0 ** 3) / (r1 ** 2 - r0 ** 2) * math.sin(a) / a  # annular sector
        for k, blade in enumerate(BLADE_IDS):
            bx0, by0, bx1, by1 = self._blade_box(k, t_s)
            angle = self.prop_omega_rad_per_s * t_s + 2 * math.pi * k / 3
            gx, gy = centroid_r * math.cos(angle), centroid_r * math.sin(angle)
            om = self.prop_omega_rad_per_s
            out.append(ObjectTruth(blade, "propeller blade", bx0 + 0.5, by0 + 0.5, bx1 - bx0, by1 - by0, 1.0,
                                   (-om * gy, om * gx)))
        ox, oy = self.small_object_centre_px(t_s)
        r = self.small_object_radius_px()
        out.append(ObjectTruth(SMALL_OBJECT_ID, "small object", ox - r + 0.5, oy - r + 0.5, 2 * r, 2 * r,
                               disc_fraction_inside(ox, oy, r, -0.5, w - 0.5, -0.5, h - 0.5),
                               (self.object_speed_px_per_s, 0.0)))
        led = max(1.0, 0.04 * h)
        out.append(ObjectTruth(LED_ID, "led", 0.93 * w - led + 0.5, 0.55 * h - led + 0.5, 2 * led, 2 * led, 1.0,
                               (0.0, 0.0)))
        return out

    # ------------------------------------------------------------------ what the scene demands
    def demand(self) -> dict:
        """What a camera needs to see this scene: its dynamic range and time resolution."""
        lo = min(self.shadow_lux, self.led_off_lux or self.shadow_lux)
        hi = self.lamp_lux
        return {
            "min_lux": lo, "max_lux": hi,
            "dynamic_range_db": 20 * math.log10(hi / lo),
            "max_speed_px_per_s": self.max_speed_px_per_s(),
            # an edge moving at the top speed crosses one pixel in this time
            "time_resolution_s": 1.0 / self.max_speed_px_per_s() if self.max_speed_px_per_s() > 0 else math.inf,
            "flicker_hz": self.led_frequency_hz,
        }

    def landmarks(self, t_s: float = 0.0) -> dict:
        """Where each part of the scene is at ``t_s`` (x, y in pixels), with its light, for figures."""
        ys, xs = np.nonzero(self.window)
        ly, lx = np.nonzero(self.lamp)
        ey, ex = np.nonzero(self.led)
        v0, v1 = self.vehicle_rows
        front = self.vehicle_front_px(t_s)
        ox = (self.object_x0_px + self.object_speed_px_per_s * t_s) % self.width
        return {
            f"sunlit window {_lux(self.window_lux)}–{_lux(3 * self.window_lux)} lux": (xs.mean(), ys.max() + 1),
            f"lamp {_lux(self.lamp_lux)} lux": (lx.mean(), ly.max() + 1),
            # labels of the parts above the object's row stand above them (with an arrow), so that
            # none covers the small object as it crosses beneath
            f"propeller {self.prop_lux:.3g} lux, tip {self.prop_tip_speed_px_per_s:.0f} px/s":
                (self.prop_centre[0], self.prop_centre[1] - 0.5 * self.prop_radius_px, self.prop_centre[0],
                 0.05 * self.height),
            f"LED {self.led_frequency_hz:g} Hz PWM": (ex.min(), ey.mean(), 0.70 * self.width, 0.40 * self.height),
            f"vehicle {self.vehicle_speed_px_per_s:.0f} px/s": (min(front, self.width - 1) - 0.1 * self.width,
                                                               (v0 + v1) / 2),
            # the object is a faint blob a couple of pixels wide: its label stands apart, with an arrow
            f"small dim object, {_lux(self.object_lux)} lux, {self.object_speed_px_per_s:.0f} px/s":
                (ox, self.object_row_px, min(ox, 0.62 * self.width) + 0.04 * self.width, 0.56 * self.height),
            f"deep shadow {self.shadow_lux:.3g} lux": (0.02 * self.width, 0.68 * self.height),
            # the road crosses the deep-shadow corner: its lower part is the second dark strip
            f"deep shadow {self.shadow_lux:.3g} lux (below the road)":
                (0.2 * self.width, 0.5 * (self.road_rows[1] + self.height) - 0.5, 0.26 * self.width,
                 0.5 * (self.road_rows[1] + self.height) - 0.5),
        }

    def compiled_light(self):
        """The scene's light for the compiled simulator: the background once, and per light sample only the
        moving parts and the LED, drawn by :meth:`_paint` (kind "sampled",
        :class:`~viform.light.sampled.PaintedSampler`): the light of :meth:`illuminance_lux`, bit for bit."""
        if not self._own_light(DilemmaScene):
            return None
        if getattr(self, "_compiled", None) is None:
            from viform.light.compiled import CompiledLight
            from viform.light.sampled import PaintedSampler

            peak = max(float(self._background.max()), self.vehicle_lux, self.prop_lux) + self.object_lux
            sampler = PaintedSampler(self._background, self._paint, self._paint_rects,
                                     max(peak, self.led_on_lux, self.led_off_lux))
            self._compiled = CompiledLight("sampled", self.height, self.width, sampler=sampler)
        return self._compiled

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """The longest hold (ticks) that misplaces the fastest part by at most
        :data:`~viform.light.sampled.LIGHT_ERROR_PX` and keeps 32 samples per LED period
        (:func:`~viform.light.sampled.auto_light_sample_ticks`)."""
        from viform.light.sampled import auto_light_sample_ticks

        ticks = auto_light_sample_ticks(self.max_speed_px_per_s(), clock_hz)
        return max(1, min(ticks, int(clock_hz / (self.led_frequency_hz * 32))))

    def regions(self) -> dict:
        """Masks and geometry the comparison metrics use."""
        return {"led": self.led, "lamp": self.lamp, "window": self.window,
                "edge_rows": self.vehicle_rows, "edge_dark_lux": self.road_lux,
                "edge_bright_lux": self.vehicle_lux}

    def describe(self) -> dict:
        d = super().describe()
        d.update(brightness=self.brightness, speed=self.speed, shadow_lux=self.shadow_lux,
                 interior_lux=self.interior_lux, window_lux=self.window_lux, lamp_lux=self.lamp_lux,
                 led_on_lux=self.led_on_lux, led_off_lux=self.led_off_lux,
                 led_frequency_hz=self.led_frequency_hz, led_duty=self.led_duty,
                 propeller_tip_speed_px_per_s=self.prop_tip_speed_px_per_s,
                 vehicle_speed_px_per_s=self.vehicle_speed_px_per_s,
                 object_speed_px_per_s=self.object_speed_px_per_s, demand=self.demand())
        return d



class NightRoadFogScene(Scene):
    """A night road in fog: passive light in lux, and the same scene with range for the gated camera.

    A flat road seen from 1.2 m (vertical field of view 20°), fog of visibility
    ``visibility_m`` (extinction σ = 3.912/V, Koschmieder), retroreflective signs at 60, 90
    and 120 m on the right, an unlit car at 80 m in the lane, and an oncoming car's
    headlights at 150 m on the left. Passive light (sensor plane, lux): objects lit by the
    own low beams fall as 1/R² and are attenuated twice by the fog, T(R)², plus the fog's
    own airlight A·(1 − T(R)); the oncoming headlights (once attenuated) carry a forward-
    scattering halo of strength ∝ 1 − T. The light is static: no motion.

    :attr:`active` is the :class:`~viform.light.active.ActiveScene` (range, reflectance at
    905 nm, sheeting R_A, the same fog) that the gated camera of seed 004 images; the
    oncoming headlights are outside its 905 nm filter band and are not part of it.
    """

    name = "night-road-fog"

    def __init__(self, height: int = 96, width: int = 160, visibility_m: float = 150.0,
                 brightness: float = 1.0, speed: float = 0.0, duration_s: float | None = None):
        from viform.light.active import ActiveScene, Medium

        height = check_int("height", height, 32)
        width = check_int("width", width, 48)
        super().__init__(height, width, duration_s)
        self.visibility_m = check_positive("visibility_m", visibility_m, allow_inf=True)
        self.brightness = check_positive("brightness", brightness)
        medium = Medium.from_visibility(self.visibility_m, name=f"fog, visibility {self.visibility_m:g} m")
        h, w = height, width
        ifov = math.radians(20.0) / h
        horizon = 0.42 * h
        y, x = np.mgrid[0:h, 0:w].astype(np.float64)
        below = y - horizon + 0.5
        road_range = np.where(below > 0, 1.2 / np.maximum(below, 1e-9) / ifov, np.inf)
        range_m = np.minimum(road_range, 400.0)
        range_m[below <= 0] = np.inf
        reflectance = np.where(below > 0, 0.15, 0.0)
        retro = np.zeros((h, w))
        self.targets: dict[str, np.ndarray] = {}

        self._target_boxes: dict[str, tuple[float, float, float, float]] = {}

        def box(label, range_, centre_x_m, bottom_m, width_m, height_m, refl, ra):
            cx = w / 2 + centre_x_m / range_ / ifov
            yb = horizon + (1.2 - bottom_m) / range_ / ifov
            hw, hh = max(1.0, width_m / range_ / ifov / 2), max(1.0, height_m / range_ / ifov)
            mask = (np.abs(x - cx) <= hw) & (y <= yb) & (y > yb - hh)
            range_m[mask] = range_
            reflectance[mask] = refl
            retro[mask] = ra
            self.targets[label] = mask
            self._target_boxes[label] = (cx - hw + 0.5, yb - hh + 0.5, 2 * hw, hh)  # truth box, pixel edges

        for r in (120.0, 90.0, 60.0):
            box(f"sign {r:g} m", r, 6.0, 1.5, 0.9, 0.9, 0.6, 50.0)  # on the right shoulder
        box("car 80 m", 80.0, 0.3, 0.3, 1.8, 1.2, 0.3, 0.0)
        self.active = ActiveScene(range_m=range_m, reflectance=reflectance, retro_coefficient_per_sr=retro,
                                  medium=medium, ambient_lux=1e-3, name="night road in fog")
        t = medium.transmission(np.where(np.isfinite(range_m), range_m, 1e4))
        beams = 30.0 ** 2 / np.maximum(range_m, 5.0) ** 2  # own low beams, 1/R²
        lit = (0.02 * reflectance + 0.05 * retro) * beams * 100.0
        airlight = 0.03
        lux = lit * t ** 2 + airlight * (1 - t) + 1e-3
        # oncoming headlights at 150 m, left lane, 1.4 m apart, 0.7 m high
        t150 = float(medium.transmission(150.0))
        for side in (-0.7, 0.7):
            cx = w / 2 + (-3.5 + side) / 150.0 / ifov
            cy = horizon + 0.5 / 150.0 / ifov
            d2 = (x - cx) ** 2 + (y - cy) ** 2
            lux += 3000.0 * t150 * np.exp(-d2 / (2 * 0.6 ** 2))
            lux += 40.0 * (1 - t150) * np.exp(-np.sqrt(d2) / max(2.0, 0.05 * w))
        self.targets["oncoming headlights"] = np.zeros((h, w), bool)
        self._headlights_px = (w / 2 + (-3.5) / 150.0 / ifov, horizon + 0.5 / 150.0 / ifov)
        self._lux = lux * self.brightness

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        return self._lux

    def mean_illuminance_lux(self, t0_s, t1_s, samples=None):
        return self._lux

    def compiled_light(self):
        """The static light as one frame: the simulator jumps from spike to spike (no per-tick light)."""
        if not self._own_light(NightRoadFogScene):
            return None
        from viform.light.compiled import CompiledLight

        return CompiledLight("frames", self.height, self.width, frames=self._lux[None],
                             frame_index=lambda times: np.zeros(np.shape(times), np.int64))

    def demand(self) -> dict:
        lo, hi = float(self._lux.min()), float(self._lux.max())
        return {"min_lux": lo, "max_lux": hi, "dynamic_range_db": 20 * math.log10(hi / lo),
                "max_speed_px_per_s": 0.0, "time_resolution_s": math.inf, "flicker_hz": None,
                "visibility_m": self.visibility_m}

    def landmarks(self, t_s: float = 0.0) -> dict:
        """Where the targets are (x, y in pixels), for figures."""
        # the targets are a few pixels apart: their labels sit in a column, with an arrow to each
        marks = {}
        k = 0
        for name, mask in self.targets.items():
            if mask.any():
                ys, xs = np.nonzero(mask)
                marks[name] = (xs.mean(), ys.mean(), 0.80 * self.width, (0.10 + 0.12 * k) * self.height)
                k += 1
        x, y = self._headlights_px
        marks["oncoming headlights 150 m"] = (x, y, 0.12 * self.width, 0.25 * self.height)
        marks[f"fog, visibility {self.visibility_m:g} m"] = (0.02 * self.width, 0.05 * self.height)
        return marks

    def regions(self) -> dict:
        return {"targets": {k: v for k, v in self.targets.items() if v.any()}}

    # ------------------------------------------------------------------ vision truth (a still scene)
    def truth_kinds(self) -> tuple[str, ...]:
        return ("motion", "depth", "objects")

    def depth_m(self, t_s: float) -> np.ndarray:
        """Range (m) along each pixel's line of sight to the surface it sees; inf for the sky (no surface)."""
        return self.active.range_m.astype(np.float64, copy=True)

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        return np.zeros((2, *self.shape))

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        return FlowTruth(np.zeros((2, *self.shape)), np.ones(self.shape, bool), float(t0_s), float(t1_s))

    def _labelled_targets(self):
        return [(label, mask) for label, mask in self.targets.items() if label in self._target_boxes]

    def object_labels(self, t_s: float) -> np.ndarray:
        """Visible target per pixel: signs and the car, ids 1… in the order they were placed (far first)."""
        labels = np.zeros(self.shape, np.int32)
        for k, (_, mask) in enumerate(self._labelled_targets(), start=1):
            labels[mask] = k  # a nearer target, placed later, covers a farther one
        return labels

    def objects(self, t_s: float) -> list[ObjectTruth]:
        """The road signs and the unlit car: still boxes, visible fraction counted on the pixel grid."""
        labels = self.object_labels(t_s)
        out = []
        for k, (label, mask) in enumerate(self._labelled_targets(), start=1):
            area = int(mask.sum())
            visible = float((labels == k).sum()) / area if area else 0.0
            out.append(ObjectTruth(k, label.split(" ")[0], *self._target_boxes[label], visible, (0.0, 0.0)))
        return out

    def describe(self) -> dict:
        d = super().describe()
        d.update(visibility_m=self.visibility_m, brightness=self.brightness, demand=self.demand(),
                 active=self.active.describe())
        return d


#: Scenes registered in :data:`viform.light.catalog.BUILTIN_SCENES`.
BUILTIN = {
    "dilemma": lambda height, width, **kw: DilemmaScene(height, width, **kw),
    "night-road-fog": lambda height, width, **kw: NightRoadFogScene(height, width, **kw),
}
