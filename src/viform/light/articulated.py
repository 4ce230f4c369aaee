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

    def hand_speed_px_per_s(self, t_s: float, dt_s: float = 1e-5) -> float:
        """Speed of the hand (wrist) on the sensor, px/s (central difference)."""
        a, b = self.joints(t_s - dt_s)[2], self.joints(t_s + dt_s)[2]
        return math.hypot(b[0] - a[0], b[1] - a[1]) / (2 * dt_s)

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        s = self.s
        sh, el, wr = self.joints(float(t_s))
        hy, hx = wr[0] + 0.35 * (wr[0] - el[0]), wr[1] + 0.35 * (wr[1] - el[1])
        # only the arm's bounding box changes with time: evaluate the capsules there
        pts = np.array([sh, el, wr, (hy, hx)])
        pad = 0.06 * s + 2
        r0, c0 = (max(0, int(v)) for v in pts.min(axis=0) - pad)
        r1, c1 = int(min(self.height, pts[:, 0].max() + pad + 1)), int(min(self.width, pts[:, 1].max() + pad + 1))
        img = self._static.copy()
        if r1 <= r0 or c1 <= c0:
            return img
        yy, xx = self._yy[r0:r1, c0:c1], self._xx[r0:r1, c0:c1]
        sleeve = np.maximum(_capsule(yy, xx, sh, el, 0.045 * s), _capsule(yy, xx, el, wr, 0.04 * s))
        hand = _capsule(yy, xx, wr, (hy, hx), 0.055 * s)
        sub = img[r0:r1, c0:c1]
        sub = sub * (1 - sleeve) + self.shirt_lux * sleeve
        img[r0:r1, c0:c1] = sub * (1 - hand) + self.skin_lux * hand
        return img

    def describe(self) -> dict:
        return {**super().describe(), "wall_lux": self.wall_lux, "shirt_lux": self.shirt_lux,
                "skin_lux": self.skin_lux, "wave_hz": self.wave_hz,
                "forearm_amplitude_rad": self.forearm_amplitude_rad}
