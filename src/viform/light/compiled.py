"""Light a scene can hand to compiled code: a description the spike kernel evaluates itself.

Evaluating a scene tick by tick in NumPy costs far more than simulating the pixels (a
400×250 texture is ≈ 3 ms a tick, the sensor ≈ 0.1 ms). A :class:`~viform.light.scenes.Scene`
that can say what its light *is* returns a :class:`CompiledLight` from ``compiled_light()``;
the simulator then works from it:

* ``"frames"`` — light constant per pixel between change instants: a still image (one
  frame, one charge rate per pixel for the whole stream), a step, an image sequence with
  hold. The event-driven kernel jumps from crossing to crossing inside each constant
  stretch.
* ``"video-linear"`` — frames interpolated linearly in time: the kernel computes each
  tick's light per pixel, (1 − w)·F_k + w·F_{k+1}, from the float64 frames.
* ``"pattern"`` — a synthetic pattern P(u, v) (texture, edge, bars) seen through a
  time-dependent affine map (translation or rotation), times a modulation m(t) (none, a
  step, sine or square flicker). Each tick needs the map's six coefficients and, for the
  texture's two gratings, sin/cos tables along x and along y (angle addition:
  sin(a + b) = sin a·cos b + cos a·sin b), so no transcendental is evaluated per pixel.

* ``"sampled"`` — light that renders itself per light sample, only where it can change
  (:mod:`viform.light.sampled`: a described scene's layers, or a built-in scene's moving parts
  painted over its background by its own code): the simulator runs the pixels it leaves static as one run of
  constant light per stretch of ticks, the others one run per light sample.

Per-tick quantities are computed by compiled scalar code from the absolute tick time, so a
tick's light is the same number whatever block it falls in (the simulator's same-seed,
same-bits property). The light agrees with the scene's NumPy ``illuminance_lux`` to rounding
(≈ 1e-15 relative), except exactly on a pattern's discontinuities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

#: Light kinds the tick kernel evaluates (``"frames"`` goes to the event-driven kernel).
KIND_FRAME_MODULATED = 0  # frames[0]·m(t)
KIND_VIDEO_LINEAR = 1
KIND_PATTERN = 2
#: Patterns (the functions of the same names in :mod:`viform.light.scenes`).
PATTERN_CODES = {"texture": 0, "edge": 1, "bars": 2}
#: Modulations m(t).
MODULATION_CODES = {"none": 0, "step": 1, "sine": 2, "square": 3}
#: Per-tick scalars: affine map (6), modulation, video frame index and weight.
N_SCALARS = 9


@dataclass
class CompiledLight:
    """What a scene's light is, for the compiled simulator (see the module notes).

    Attributes
    ----------
    kind : {"frames", "frames-modulated", "video-linear", "pattern", "sampled"}
    frames : ndarray, (F, H, W)
        Lux frames: "frames" (float64), "frames-modulated" (one frame times m(t)),
        "video-linear"; the kernels read them as float64.
    frame_index : callable
        "frames": times (s, array) → index of the frame in effect (int array), elementwise
        (so a tick's frame does not depend on the block it is computed in).
    frame_rate_hz : float
        "video-linear": frame k is the light at k / frame_rate_hz; past the last, it is held.
    pattern, min_lux, max_lux, period_px : pattern parameters.
    motion : tuple
        ("translate", x0, y0, vx, vy): u = x − x0 − vx·t, v = y − y0 − vy·t;
        ("rotate", cx, cy, ω): (u, v) = R(−ω t)·(x − cx, y − cy).
    modulation : tuple
        ("none",), ("step", t_step_s, factor), ("sine"|"square", frequency_hz, depth).
    """

    kind: str
    height: int
    width: int
    frames: np.ndarray | None = None
    frame_index: object = None
    frame_rate_hz: float = 1.0
    pattern: str = "texture"
    min_lux: float = 0.0
    max_lux: float = 1.0
    period_px: float = 48.0
    motion: tuple = ("translate", 0.0, 0.0, 0.0, 0.0)
    modulation: tuple = ("none",)
    sampler: object = None  # "sampled": a :class:`~viform.light.sampled.LightSampler`

    @property
    def lux_max(self) -> float:
        """An upper bound of the light, lux (for the fixed-point range check)."""
        if self.kind == "sampled":
            return float(self.sampler.lux_max)
        peak = float(self.frames.max()) if self.frames is not None else self.max_lux
        kind = self.modulation[0]
        if kind == "step":
            peak *= max(1.0, self.modulation[2])
        elif kind in ("sine", "square"):
            peak *= 1.0 + self.modulation[2]
        return peak

    def kernel_kind(self) -> int:
        if self.kind == "frames-modulated":
            return KIND_FRAME_MODULATED
        if self.kind == "video-linear":
            return KIND_VIDEO_LINEAR
        return KIND_PATTERN

    def flat_frames(self) -> np.ndarray:
        """Frames as (F, H·W) float64 (one compiled specialization of the kernel for every kind)."""
        if self.frames is None:
            return np.zeros((1, 1))
        return np.ascontiguousarray(self.frames.reshape(self.frames.shape[0], -1), dtype=np.float64)

    def parameters(self) -> np.ndarray:
        """The float parameters the compiled per-tick code reads (see :func:`tick_scalars`)."""
        motion = self.motion
        rotate = motion[0] == "rotate"
        m = self.modulation
        values = [
            float(PATTERN_CODES[self.pattern]), self.min_lux, self.max_lux, self.period_px,
            1.0 if rotate else 0.0, motion[1], motion[2],
            motion[3], motion[4] if not rotate else 0.0,
            float(MODULATION_CODES[m[0]]), m[1] if len(m) > 1 else 0.0, m[2] if len(m) > 2 else 0.0,
            self.frame_rate_hz, float(self.frames.shape[0] if self.frames is not None else 1),
        ]
        return np.array(values, dtype=np.float64)


@njit(cache=True, inline="always")
def _modulation(t, code, a, b):
    if code == 1:
        return b if t >= a else 1.0
    if code == 2:
        return 1.0 + b * math.sin(2.0 * math.pi * a * t)
    if code == 3:
        return 1.0 + b * (1.0 if math.sin(2.0 * math.pi * a * t) >= 0.0 else -1.0)
    return 1.0


def tick_scalars(times, params, kind, scalars, xtab, ytab):
    """Fill the per-tick scalars (and tables) at ``times`` (s) (:func:`_tick_scalars`, compiled)."""
    _tick_scalars(times, params, kind, scalars, xtab, ytab)


@njit(cache=True, parallel=True)
def _tick_scalars(times, params, kind, scalars, xtab, ytab):
    """Fill the per-tick scalars (and, for the texture, grating tables) at ``times`` (s).

    ``scalars[i]``: A11, A12, B1, A21, A22, B2 (u = A11·x + A12·y + B1, v likewise), m(t),
    video frame index k, weight w. ``xtab[i, g]``/``ytab[i, g]``: sin and cos of the x and
    y parts of the phase of the texture's grating g (g = 0: sin/cos of grating 1, 2: of 2).
    """
    pattern = np.int64(params[0])
    period = params[3]
    rotate = params[4] != 0.0
    mod_code = np.int64(params[9])
    rate_hz = params[12]
    last = params[13] - 1.0
    k1 = 2.0 * math.pi / (0.7 * period)
    k2 = 2.0 * math.pi / (1.9 * period)
    width = xtab.shape[2]
    height = ytab.shape[2]
    for i in prange(times.size):
        t = times[i]
        if rotate:
            cx, cy, omega = params[5], params[6], params[7]
            a = -omega * t
            ca, sa = math.cos(a), math.sin(a)
            a11, a12, b1 = ca, -sa, -ca * cx + sa * cy
            a21, a22, b2 = sa, ca, -sa * cx - ca * cy
        else:
            a11, a12, b1 = 1.0, 0.0, -params[5] - params[7] * t
            a21, a22, b2 = 0.0, 1.0, -params[6] - params[8] * t
        scalars[i, 0] = a11
        scalars[i, 1] = a12
        scalars[i, 2] = b1
        scalars[i, 3] = a21
        scalars[i, 4] = a22
        scalars[i, 5] = b2
        scalars[i, 6] = _modulation(t, mod_code, params[10], params[11])
        if kind == KIND_VIDEO_LINEAR:
            position = max(0.0, t * rate_hz)
            k = min(math.floor(position), last)
            scalars[i, 7] = k
            scalars[i, 8] = 0.0 if k >= last else position - k
        if kind == KIND_PATTERN and pattern == 0:
            # grating phases k·(α·u + β·v) = k·(αx·x + αy·y + αc), split into x and y parts
            for g in range(2):
                if g == 0:
                    al, be, kk = 0.8, 0.6, k1
                else:
                    al, be, kk = -0.5, 0.87, k2
                ax = kk * (al * a11 + be * a21)
                ay = kk * (al * a12 + be * a22)
                ac = kk * (al * b1 + be * b2)
                for x in range(width):
                    xtab[i, 2 * g, x] = math.sin(ax * x)
                    xtab[i, 2 * g + 1, x] = math.cos(ax * x)
                for y in range(height):
                    ytab[i, 2 * g, y] = math.sin(ay * y + ac)
                    ytab[i, 2 * g + 1, y] = math.cos(ay * y + ac)


@njit(cache=True, inline="always")
def pixel_lux(kind, p, x, y, i, scalars, xtab, ytab, frames, params):
    """Light (lux) of pixel p at column x, row y for the tick whose scalars are row i."""
    m = scalars[i, 6]
    if kind == KIND_FRAME_MODULATED:
        return frames[0, p] * m
    if kind == KIND_VIDEO_LINEAR:
        k = np.int64(scalars[i, 7])
        w = scalars[i, 8]
        f0 = np.float64(frames[k, p])
        return f0 + w * (np.float64(frames[k + 1 if w != 0.0 else k, p]) - f0)
    yf = np.float64(y)
    u = scalars[i, 0] * np.float64(x) + (scalars[i, 1] * yf + scalars[i, 2])
    pattern = np.int64(params[0])
    period = params[3]
    if pattern == 1:
        value = 1.0 if u >= 0.0 else 0.0
    elif pattern == 2:
        f = np.floor(u / (period / 2.0))
        value = f - 2.0 * np.floor(0.5 * f)
    else:
        v = scalars[i, 3] * np.float64(x) + (scalars[i, 4] * yf + scalars[i, 5])
        f = np.floor(u / period) + np.floor(v / period)
        checker = f - 2.0 * np.floor(0.5 * f)
        s1 = xtab[i, 0, x] * ytab[i, 1, y] + xtab[i, 1, x] * ytab[i, 0, y]
        c2 = xtab[i, 3, x] * ytab[i, 3, y] - xtab[i, 2, x] * ytab[i, 2, y]
        value = 0.55 * checker + 0.25 * (0.5 + 0.5 * s1) + 0.20 * (0.5 + 0.5 * c2)
    return (params[1] + (params[2] - params[1]) * value) * m


@njit(cache=True)
def row_lux(kind, k, y, xs, scalars, xtab, ytab, frames, params, out):
    """``out[x]`` = :func:`pixel_lux` of row ``y`` for tick row ``k`` — the same arithmetic,
    written as straight loops per kind so the compiler vectorizes them (``xs``: the column
    coordinates as float64, 0 … width − 1, since AVX2 has no packed int64 → float conversion)."""
    width = xs.size
    m = scalars[k, 6]
    base = y * width
    if kind == KIND_FRAME_MODULATED:
        for x in range(width):
            out[x] = frames[0, base + x] * m
        return
    if kind == KIND_VIDEO_LINEAR:
        f = np.int64(scalars[k, 7])
        w = scalars[k, 8]
        g = f + 1 if w != 0.0 else f
        for x in range(width):
            f0 = np.float64(frames[f, base + x])
            out[x] = f0 + w * (np.float64(frames[g, base + x]) - f0)
        return
    pattern = np.int64(params[0])
    period = params[3]
    lo = params[1]
    span = params[2] - params[1]
    yf = np.float64(y)
    a11, b1 = scalars[k, 0], scalars[k, 1] * yf + scalars[k, 2]
    a21, b2 = scalars[k, 3], scalars[k, 4] * yf + scalars[k, 5]
    if pattern == 1:
        for x in range(width):
            u = a11 * xs[x] + b1
            value = 1.0 if u >= 0.0 else 0.0
            out[x] = (lo + span * value) * m
    elif pattern == 2:
        half = period / 2.0
        for x in range(width):
            u = a11 * xs[x] + b1
            f = np.floor(u / half)
            value = f - 2.0 * np.floor(0.5 * f)  # parity in floating point: vectorizes (AVX2)
            out[x] = (lo + span * value) * m
    else:
        sy1, cy1, sy2, cy2 = ytab[k, 0, y], ytab[k, 1, y], ytab[k, 2, y], ytab[k, 3, y]
        sx1, cx1, sx2, cx2 = xtab[k, 0], xtab[k, 1], xtab[k, 2], xtab[k, 3]
        for x in range(width):
            u = a11 * xs[x] + b1
            v = a21 * xs[x] + b2
            f = np.floor(u / period) + np.floor(v / period)
            checker = f - 2.0 * np.floor(0.5 * f)
            s1 = sx1[x] * cy1 + cx1[x] * sy1
            c2 = cx2[x] * cy2 - sx2[x] * sy2
            value = 0.55 * checker + 0.25 * (0.5 + 0.5 * s1) + 0.20 * (0.5 + 0.5 * c2)
            out[x] = (lo + span * value) * m


def tick_buffers(light: CompiledLight, n_ticks: int):
    """Per-tick scalar and table buffers for ``n_ticks`` ticks."""
    tables = light.kind == "pattern" and light.pattern == "texture"
    scalars = np.zeros((n_ticks, N_SCALARS))
    xtab = np.zeros((n_ticks if tables else 1, 4, light.width if tables else 1))
    ytab = np.zeros((n_ticks if tables else 1, 4, light.height if tables else 1))
    return scalars, xtab, ytab


def tick_bytes(light: CompiledLight) -> int:
    """Bytes of per-tick buffers for one tick."""
    tables = light.kind == "pattern" and light.pattern == "texture"
    return 8 * N_SCALARS + (32 * (light.width + light.height) if tables else 0)


@njit(cache=True, parallel=True)
def _evaluate(kind, times, scalars, xtab, ytab, frames, params, height, width, out):
    for i in prange(times.size):
        for y in range(height):
            for x in range(width):
                out[i, y, x] = pixel_lux(kind, y * width + x, x, y, i, scalars, xtab, ytab, frames, params)


def evaluate(light: CompiledLight, times_s) -> np.ndarray:
    """The compiled light at instants ``times_s`` (N, H, W), lux — what the kernel sees (for tests)."""
    times = np.ascontiguousarray(times_s, dtype=np.float64).ravel()
    if light.kind == "frames":
        return light.frames[light.frame_index(times)].astype(np.float64)
    kind = light.kernel_kind()
    params = light.parameters()
    scalars, xtab, ytab = tick_buffers(light, times.size)
    tick_scalars(times, params, kind, scalars, xtab, ytab)
    out = np.empty((times.size, light.height, light.width))
    _evaluate(kind, times, scalars, xtab, ytab, light.flat_frames(), params, light.height, light.width, out)
    return out
