"""An articulated fast motion: a person waving a hand (seed 000 §6, the chip experiment).

Seed 000 §6 films "a person waving a hand" with the SpikeTwo chip at 20 kHz and shows the
first 800 ticks (40 ms). :class:`WavingHandScene` draws such a scene in lux: a lit wall, a
torso and a head, and an arm whose forearm swings about the elbow (the upper arm sways
less), so different parts move at different speeds — the hand fastest. Shapes are capsules
(segments with a radius) with a one-pixel anti-aliased edge, evaluated at any instant.
"""

from __future__ import annotations

import math

import numpy as np

from viform._validate import check_int, check_non_negative, check_positive
from viform.light.scenes import Scene
from viform.light.truth import FlowTruth, ObjectTruth, flow_from_layers

#: Object ids of the arm's parts in the truth (the body and head are still background).
UPPER_ARM_ID, FOREARM_ID, HAND_ID = 1, 2, 3
_PART_NAMES = {UPPER_ARM_ID: "upper arm", FOREARM_ID: "forearm", HAND_ID: "hand"}


def _capsule(yy, xx, p0, p1, radius):
    """Coverage (0..1) of the capsule p0–p1 of ``radius`` px, anti-aliased over one pixel."""
    (y0, x0), (y1, x1) = p0, p1
    dy, dx = y1 - y0, x1 - x0
    n2 = dy * dy + dx * dx
    t = np.clip(((yy - y0) * dy + (xx - x0) * dx) / n2, 0.0, 1.0) if n2 > 0 else 0.0
    d = np.hypot(yy - (y0 + t * dy), xx - (x0 + t * dx))
    return np.clip(radius - d + 0.5, 0.0, 1.0)


class WavingHandScene(Scene):
    """A person waving a hand in front of a wall (lux on the sensor).

    Parameters
    ----------
    height, width : int
    wall_lux, shirt_lux, skin_lux : float
        Illuminance of the wall, the clothes and the skin (hand, face).
    wave_hz : float
        Waving frequency (a fast wave: 4 Hz).
    forearm_amplitude_rad, upper_arm_amplitude_rad : float
        Swing of the forearm about the elbow and of the upper arm about the shoulder.
    phase_rad : float
        Phase at t = 0 (π/2 − small: the hand passes the vertical, at its fastest, early on).
    """

    name = "waving-hand"

    def __init__(self, height: int = 240, width: int = 240, wall_lux: float = 100.0, shirt_lux: float = 30.0,
                 skin_lux: float = 230.0, wave_hz: float = 4.0, forearm_amplitude_rad: float = 0.7,
                 upper_arm_amplitude_rad: float = 0.15, phase_rad: float = -0.3):
        super().__init__(check_int("height", height, 16), check_int("width", width, 16))
        self.wall_lux = check_non_negative("wall_lux", wall_lux)
        self.shirt_lux = check_non_negative("shirt_lux", shirt_lux)
        self.skin_lux = check_non_negative("skin_lux", skin_lux)
        self.wave_hz = check_positive("wave_hz", wave_hz)
        self.forearm_amplitude_rad = float(forearm_amplitude_rad)
        self.upper_arm_amplitude_rad = float(upper_arm_amplitude_rad)
        self.phase_rad = float(phase_rad)
        h, w = self.height, self.width
        self._yy, self._xx = np.mgrid[0:h, 0:w].astype(np.float64)
        # wall: a soft left-to-right gradient and a faint vertical panel pattern (texture)
        self._wall = wall_lux * (0.85 + 0.3 * self._xx / w) * (1 + 0.08 * np.cos(2 * np.pi * self._xx / (w / 3)))
        s = min(h, w)
        self.s = s
        self.shoulder = (0.60 * h, 0.60 * w)
        self.upper_len, self.fore_len = 0.19 * s, 0.2 * s
        body = np.maximum(_capsule(self._yy, self._xx, (0.70 * h, 0.45 * w), (1.2 * h, 0.45 * w), 0.17 * s),
                          _capsule(self._yy, self._xx, self.shoulder, (0.55 * h, 0.30 * w), 0.06 * s))
        head = _capsule(self._yy, self._xx, (0.42 * h, 0.45 * w), (0.46 * h, 0.45 * w), 0.09 * s)
        self._static = self._wall * (1 - np.maximum(body, head)) + shirt_lux * body * (1 - head) + skin_lux * head

    def joints(self, t_s: float):
        """(shoulder, elbow, wrist) positions (row, col) at ``t_s``."""
        ph = 2 * math.pi * self.wave_hz * t_s + self.phase_rad
        up = math.radians(-30) + self.upper_arm_amplitude_rad * math.sin(ph)      # from vertical, to the right
        fore = up + self.forearm_amplitude_rad * math.sin(ph + 0.4)
        sy, sx = self.shoulder
        ey, ex = sy - self.upper_len * math.cos(up), sx - self.upper_len * math.sin(up)
        wy, wx = ey - self.fore_len * math.cos(fore), ex - self.fore_len * math.sin(fore)
        return (sy, sx), (ey, ex), (wy, wx)

    def _angles(self, t_s: float):
        """Upper-arm and forearm angles (rad, from vertical) and their rates (rad/s) at ``t_s``."""
        rate = 2 * math.pi * self.wave_hz
        ph = rate * t_s + self.phase_rad
        up = math.radians(-30) + self.upper_arm_amplitude_rad * math.sin(ph)
        fore = up + self.forearm_amplitude_rad * math.sin(ph + 0.4)
        up_rate = self.upper_arm_amplitude_rad * math.cos(ph) * rate
        fore_rate = up_rate + self.forearm_amplitude_rad * math.cos(ph + 0.4) * rate
        return up, fore, up_rate, fore_rate

    def _parts(self, t_s: float) -> dict:
        """Each arm part as (start, end, radius) capsules in (row, col), at ``t_s``."""
        s = self.s
        sh, el, wr = self.joints(float(t_s))
        tip = (wr[0] + 0.35 * (wr[0] - el[0]), wr[1] + 0.35 * (wr[1] - el[1]))
        return {UPPER_ARM_ID: (sh, el, 0.045 * s), FOREARM_ID: (el, wr, 0.04 * s), HAND_ID: (wr, tip, 0.055 * s)}

    def _coverage(self, t_s: float) -> dict:
        return {k: _capsule(self._yy, self._xx, p0, p1, r) for k, (p0, p1, r) in self._parts(t_s).items()}

    def _labels_and_mixed(self, t_s: float):
        """Visible part per pixel (the hand over the sleeve, as drawn) and the pixels whose motion is
        undefined: anti-aliased edges (partial coverage) and the elbow, where both arm segments overlap."""
        cover = self._coverage(t_s)
        full = {k: c >= 1.0 for k, c in cover.items()}
        labels = np.zeros(self.shape, np.int32)
        labels[cover[UPPER_ARM_ID] >= 0.5] = UPPER_ARM_ID
        labels[cover[FOREARM_ID] >= 0.5] = FOREARM_ID
        labels[cover[HAND_ID] >= 0.5] = HAND_ID
        partial = np.zeros(self.shape, bool)
        hand_full = full[HAND_ID]
        for k, c in cover.items():
            edge = (c > 0) & (c < 1)
            partial |= edge if k == HAND_ID else edge & ~hand_full  # a full hand hides the sleeve's edge
        elbow = full[UPPER_ARM_ID] & full[FOREARM_ID] & ~hand_full
        return labels, partial | elbow

    def _frames(self, t_s: float) -> dict:
        """Each part's rigid frame: origin (x, y), unit axis (x, y), and their rates, at ``t_s``."""
        up, fore, up_rate, fore_rate = self._angles(t_s)
        (sy, sx), (ey, ex), (wy, wx) = self.joints(t_s)
        # elbow = shoulder − L_up·(sin up, cos up) in (x, y): the axis points from shoulder to elbow
        axis_up = (-math.sin(up), -math.cos(up))
        axis_up_rate = (-math.cos(up) * up_rate, math.sin(up) * up_rate)
        axis_fore = (-math.sin(fore), -math.cos(fore))
        axis_fore_rate = (-math.cos(fore) * fore_rate, math.sin(fore) * fore_rate)
        elbow_rate = (self.upper_len * axis_up_rate[0], self.upper_len * axis_up_rate[1])
        wrist_rate = (elbow_rate[0] + self.fore_len * axis_fore_rate[0],
                      elbow_rate[1] + self.fore_len * axis_fore_rate[1])
        return {UPPER_ARM_ID: ((sx, sy), axis_up, (0.0, 0.0), axis_up_rate),
                FOREARM_ID: ((ex, ey), axis_fore, elbow_rate, axis_fore_rate),
                HAND_ID: ((wx, wy), axis_fore, wrist_rate, axis_fore_rate)}

    # ------------------------------------------------------------------ vision truth
    def truth_kinds(self) -> tuple[str, ...]:
        return ("motion", "objects")

    def object_labels(self, t_s: float) -> np.ndarray:
        """Visible arm part per pixel: upper arm 1, forearm 2, hand 3; body, head and wall 0."""
        return self._labels_and_mixed(t_s)[0]

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        """Velocity (px/s) of the rigid part each pixel shows; NaN at anti-aliased edges and the elbow."""
        labels, mixed = self._labels_and_mixed(t_s)
        motion = np.zeros((2, *self.shape))
        for part, ((ox, oy), (ax, ay), (vx, vy), (arx, ary)) in self._frames(t_s).items():
            where = labels == part
            # a point at (a, b) in the part's frame: p = o + a·e + b·n, n = (−e_y, e_x); dp/dt = ȯ + a·ė + b·ṅ
            dx, dy = self._xx[where] - ox, self._yy[where] - oy
            a, b = dx * ax + dy * ay, -dx * ay + dy * ax
            motion[0][where] = vx + a * arx - b * ary
            motion[1][where] = vy + a * ary + b * arx
        motion[:, mixed] = np.nan
        return motion

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        """Forward flow t0 → t1 of every part's points; the hand hides the sleeve where it passes over it."""
        labels0, mixed0 = self._labels_and_mixed(t0_s)
        labels1, _ = self._labels_and_mixed(t1_s)
        f0, f1 = self._frames(t0_s), self._frames(t1_s)

        def mover(part):
            (ox, oy), (ax, ay) = f0[part][:2]
            (qx, qy), (bx, by) = f1[part][:2]

            def move(x, y):
                dx, dy = x - ox, y - oy
                a, b = dx * ax + dy * ay, -dx * ay + dy * ax
                return qx + a * bx - b * by, qy + a * by + b * bx

            return move

        order = {HAND_ID: 0, FOREARM_ID: 1, UPPER_ARM_ID: 1}
        return flow_from_layers(labels0, labels1, mixed0, {p: mover(p) for p in _PART_NAMES}, order, t0_s, t1_s)

    def objects(self, t_s: float) -> list[ObjectTruth]:
        """Upper arm, forearm and hand: capsule boxes, visible share on the pixel grid, centroid velocity."""
        labels, _ = self._labels_and_mixed(t_s)
        cover = self._coverage(t_s)
        out = []
        for part, (p0, p1, r) in self._parts(t_s).items():
            ys, xs = (p0[0], p1[0]), (p0[1], p1[1])
            area = int((cover[part] >= 0.5).sum())
            visible = float((labels == part).sum()) / area if area else 0.0
            # centroid of a capsule is its segment's midpoint; a rigid part's velocity is affine in position
            (ox, oy), (ax, ay), (vx, vy), (arx, ary) = self._frames(t_s)[part]
            mx, my = (xs[0] + xs[1]) / 2, (ys[0] + ys[1]) / 2
            a, b = (mx - ox) * ax + (my - oy) * ay, -(mx - ox) * ay + (my - oy) * ax
            velocity = (vx + a * arx - b * ary, vy + a * ary + b * arx)
            out.append(ObjectTruth(part, _PART_NAMES[part], min(xs) - r + 0.5, min(ys) - r + 0.5,
                                   abs(xs[1] - xs[0]) + 2 * r, abs(ys[1] - ys[0]) + 2 * r, min(1.0, visible),
                                   velocity))
        return out

    def hand_speed_px_per_s(self, t_s: float, dt_s: float = 1e-5) -> float:
        """Speed of the hand (wrist) on the sensor, px/s (central difference)."""
        a, b = self.joints(t_s - dt_s)[2], self.joints(t_s + dt_s)[2]
        return math.hypot(b[0] - a[0], b[1] - a[1]) / (2 * dt_s)

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        img = self._static.copy()
        self._paint(float(t_s), img)
        return img

    def _arm_box(self, t_s: float):
        """Joints, hand tip and the box (row0, row1, col0, col1) the arm is drawn in at ``t_s``."""
        sh, el, wr = self.joints(t_s)
        hy, hx = wr[0] + 0.35 * (wr[0] - el[0]), wr[1] + 0.35 * (wr[1] - el[1])
        pts = np.array([sh, el, wr, (hy, hx)])
        pad = 0.06 * self.s + 2
        r0, c0 = (max(0, int(v)) for v in pts.min(axis=0) - pad)
        r1, c1 = int(min(self.height, pts[:, 0].max() + pad + 1)), int(min(self.width, pts[:, 1].max() + pad + 1))
        return sh, el, wr, (hy, hx), (r0, r1, c0, c1)

    def illuminance_lux_row_times(self, times_s) -> np.ndarray:
        """Row r of :meth:`illuminance_lux` at ``times_s[r]``: the arm drawn in each row alone, at its instant."""
        if not self._own_light(WavingHandScene):
            return super().illuminance_lux_row_times(times_s)
        img = self._static.copy()
        for r, t in enumerate(self._row_times(times_s).tolist()):
            self._paint(t, img, r)
        return img

    def _paint(self, t_s: float, img: np.ndarray, row: int | None = None) -> list:
        """Draw the arm at ``t_s`` over ``img`` (which holds the still body and wall), or only its part in
        ``row``; return the box written (see :class:`~viform.light.sampled.PaintedSampler`)."""
        s = self.s
        # only the arm's bounding box changes with time: evaluate the capsules there
        sh, el, wr, tip, (r0, r1, c0, c1) = self._arm_box(t_s)
        if row is not None:
            r0, r1 = max(r0, row), min(r1, row + 1)
        if r1 <= r0 or c1 <= c0:
            return []
        yy, xx = self._yy[r0:r1, c0:c1], self._xx[r0:r1, c0:c1]
        sleeve = np.maximum(_capsule(yy, xx, sh, el, 0.045 * s), _capsule(yy, xx, el, wr, 0.04 * s))
        hand = _capsule(yy, xx, wr, tip, 0.055 * s)
        sub = img[r0:r1, c0:c1]
        sub = sub * (1 - sleeve) + self.shirt_lux * sleeve
        img[r0:r1, c0:c1] = sub * (1 - hand) + self.skin_lux * hand
        return [(r0, r1, c0, c1)]

    def _paint_rects(self, times_s: np.ndarray) -> np.ndarray:
        """The arm's box at each of ``times_s`` (one pixel of margin)."""
        boxes = np.array([self._arm_box(t)[4] for t in np.asarray(times_s, dtype=np.float64).tolist()])
        return (boxes + np.array([-1, 1, -1, 1])).reshape(-1, 4)

    def max_speed_px_per_s(self) -> float:
        """A bound on the speed of any point of the arm, px/s: the upper arm's peak rate times its length
        plus the forearm's peak rate times the farthest reach past the elbow (hand tip and radius)."""
        rate = 2 * math.pi * self.wave_hz
        up = abs(self.upper_arm_amplitude_rad) * rate
        fore = up + abs(self.forearm_amplitude_rad) * rate
        return up * self.upper_len + fore * (1.35 * self.fore_len + 0.055 * self.s + 1.0)

    def compiled_light(self):
        """The still body and wall once, and per light sample only the arm's box drawn by :meth:`_paint`
        (kind "sampled", :class:`~viform.light.sampled.PaintedSampler`): the light of
        :meth:`illuminance_lux`, bit for bit."""
        if not self._own_light(WavingHandScene):
            return None
        if getattr(self, "_compiled", None) is None:
            from viform.light.compiled import CompiledLight
            from viform.light.sampled import PaintedSampler

            # the arm blends wall, shirt and skin with weights in [0, 1]: below the largest of them
            peak = max(float(self._static.max()), self.shirt_lux, self.skin_lux)
            sampler = PaintedSampler(self._static, self._paint, self._paint_rects, peak)
            self._compiled = CompiledLight("sampled", self.height, self.width, sampler=sampler)
        return self._compiled

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """The longest hold (ticks) that misplaces the arm's fastest point by at most
        :data:`~viform.light.sampled.LIGHT_ERROR_PX` (:func:`~viform.light.sampled.auto_light_sample_ticks`)."""
        from viform.light.sampled import auto_light_sample_ticks

        return auto_light_sample_ticks(self.max_speed_px_per_s(), clock_hz)

    def describe(self) -> dict:
        return {**super().describe(), "wall_lux": self.wall_lux, "shirt_lux": self.shirt_lux,
                "skin_lux": self.skin_lux, "wave_hz": self.wave_hz,
                "forearm_amplitude_rad": self.forearm_amplitude_rad}
