"""Histogram counter and equalization, in floating point and in shifts (seed 002 §3.2.2–§3.2.3).

Counter (seed 002 §3.2.2): the FPGA feeds 8 pixels per clock to 8 decoder+counter banks,
each with 256 twenty-bit counters (8 × 256 = 2 048 counters); after the frame an adder sums
the banks. :func:`histogram_counter` reproduces that structure (lane j counts pixels
j, j + 8, j + 16, … of the raster) and checks that no counter can overflow.

Equalization (seed 002 eqs. (2), (3)): with cumulative histogram c(k) = Σ_{i≤k} n_i and N
pixels, t(k) = c(k) · 255 / N. Without multipliers the seed writes ×255 as << 8 and
÷921 600 as >> 20, i.e. t ≈ c >> 12, which is c · 2⁻¹² instead of c · 255 / 921 600: too
small by e(k) = c · (255/921 600 − 2⁻¹²) = 3.26·10⁻⁵ · c (seed eq. (4): 0.000 03 · c). The
error is compensated by adding c >> 15 (2⁻¹⁵ ≈ 0.000 03), so

    t(k) = (c >> 12) + (c >> 15)                                                    (E1)

:func:`seed_shift_terms` derives the two shifts by the seed's rule for any pixel count
(for N = 921 600 it returns 12 and 15), and :func:`shift_error` measures the worst error
against the floating-point mapping over every possible c.
"""

from __future__ import annotations

import math

import numpy as np

from viform._validate import ViformError, check_choice, check_int
from viform.sensors.highspeed import to_gray8  # noqa: F401 - the camera's 8-bit output, equalized here

LEVELS = 256


def _check_gray8(gray) -> np.ndarray:
    gray = np.asarray(gray)
    if gray.dtype != np.uint8:
        bad_range = gray.size and (gray.min() < 0 or gray.max() > 255)
        if not np.issubdtype(gray.dtype, np.integer) or bad_range:
            raise ViformError(f"gray image must hold 8-bit levels 0–255; got dtype {gray.dtype}")
        gray = gray.astype(np.uint8)
    return gray


def histogram_counter(gray8, pixels_per_clock: int = 8, counter_bits: int = 20,
                      return_lanes: bool = False):
    """256-bin histogram by the seed's parallel counter design (seed 002 §3.2.2).

    Parameters
    ----------
    gray8 : array of uint8
        One frame (any shape; raster order is C order).
    pixels_per_clock : int
        Pixels arriving per clock = number of counter banks (8 in the seed).
    counter_bits : int
        Width of each counter and of the summed result (20 in the seed).
    return_lanes : bool
        Also return the per-bank counts, shape (pixels_per_clock, 256).

    Returns
    -------
    hist : ndarray of int64, shape (256,)
    """
    gray = _check_gray8(gray8).ravel()
    lanes_n = check_int("pixels_per_clock", pixels_per_clock, 1)
    bits = check_int("counter_bits", counter_bits, 1, 62)
    if gray.size > (1 << bits) - 1:
        raise ViformError(f"counter_bits = {bits} is too narrow: a frame of {gray.size} pixels can "
                          f"put more than {(1 << bits) - 1} counts in one bin")
    lanes = np.stack([np.bincount(gray[j::lanes_n], minlength=LEVELS) for j in range(lanes_n)])
    hist = lanes.sum(axis=0)  # the adder after the frame
    return (hist, lanes) if return_lanes else hist


def equalization_lut_float(hist) -> np.ndarray:
    """Seed eq. (3) in floating point: t(k) = c(k) · 255 / N (float64, not rounded).

    Parameters
    ----------
    hist : array_like of int (256,)
        Pixel count per gray level.

    Returns
    -------
    ndarray of float64 (256,)
        Output gray level t(k) per input level k.

    Examples
    --------
    Two gray levels holding half the pixels each:

    >>> hist = np.zeros(256, int); hist[[10, 200]] = 50
    >>> lut = equalization_lut_float(hist)
    >>> [round(float(t), 9) for t in lut[[10, 199, 200]]]
    [127.5, 127.5, 255.0]
    """
    hist = np.asarray(hist, dtype=np.int64)
    n = int(hist.sum())
    if n < 1:
        raise ViformError("histogram is empty: no pixels to equalize")
    return np.cumsum(hist) * (255.0 / n)


def seed_shift_terms(n_pixels: int) -> tuple[int, int, int]:
    """The seed's shift form of ×255/N for ``n_pixels`` (seed 002 §3.2.3).

    ×255 ≈ << round(log2 255) = << 8 and ÷N ≈ >> round(log2 N), so the main term is
    c >> s1 with s1 = round(log2 N) − 8. The residual slope 255/N − 2^−s1 is compensated by
    ±(c >> s2), s2 = round(−log2 |slope|). For N = 921 600: (12, 15, +1).

    Returns
    -------
    s1, s2, sign : int
        ``sign`` is +1 or −1 (0 when no compensation is needed).
    """
    n = check_int("n_pixels", n_pixels, 1)
    s1 = round(math.log2(n)) - round(math.log2(255))
    slope = 255.0 / n - 2.0 ** -s1
    if slope == 0:
        return s1, 0, 0
    return s1, round(-math.log2(abs(slope))), 1 if slope > 0 else -1


def _shift(c, s):
    return c >> s if s >= 0 else c << -s


def shift_map(cdf, n_pixels: int, compensate: bool = True) -> np.ndarray:
    """Integer mapping (E1) of cumulative counts ``cdf`` (int64), clipped to 0–255."""
    c = np.asarray(cdf, dtype=np.int64)
    s1, s2, sign = seed_shift_terms(n_pixels)
    # (c << 8) >> (s1 + 8) is c >> s1 exactly for integers; the hardware does the same.
    t = _shift(c << 8, s1 + 8)
    if compensate and sign:
        t = t + sign * _shift(c, s2)
    return np.clip(t, 0, 255)


def equalization_lut_shift(hist, compensate: bool = True) -> np.ndarray:
    """Seed eq. (3) by shifts, (E1): lookup table (uint8) from a 256-bin histogram.

    Parameters
    ----------
    hist : array_like of int (256,)
        Pixel count per gray level.
    compensate : bool
        Add the seed's compensating shift (c >> 15 for 1280 × 720).

    Returns
    -------
    ndarray of uint8 (256,)
        Output gray level per input level.
    """
    hist = np.asarray(hist, dtype=np.int64)
    n = int(hist.sum())
    if n < 1:
        raise ViformError("histogram is empty: no pixels to equalize")
    return shift_map(np.cumsum(hist), n, compensate).astype(np.uint8)


def shift_error(n_pixels: int = 921_600) -> dict:
    """Worst error of the shift form against floating point over every cumulative count 0…N.

    Returns the maximum |t_shift − c·255/N| (against the exact real value) and against the
    float value rounded to a level, before and after compensation, plus the shifts used.
    """
    n = check_int("n_pixels", n_pixels, 1)
    c = np.arange(n + 1, dtype=np.int64)
    exact = c * (255.0 / n)
    out = {"n_pixels": n, "shifts": list(seed_shift_terms(n))}
    for key, comp in (("uncompensated", False), ("compensated", True)):
        t = shift_map(c, n, comp).astype(np.float64)
        out[f"max_abs_error_{key}"] = float(np.max(np.abs(t - exact)))
        out[f"max_abs_error_vs_rounded_{key}"] = float(np.max(np.abs(t - np.rint(exact))))
        out[f"error_at_full_{key}"] = float(exact[-1] - t[-1])
    # Seed eq. (4): the uncompensated error grows linearly, e(k) = slope · c.
    s1 = out["shifts"][0]
    out["error_slope_per_count"] = 255.0 / n - 2.0 ** -s1
    return out


def equalize(gray8, lut) -> np.ndarray:
    """Apply a 256-entry lookup table to an 8-bit image.

    Parameters
    ----------
    gray8 : ndarray of uint8
        The image.
    lut : array_like (256,)
        Output level per input level (rounded and clipped to 0–255).

    Returns
    -------
    ndarray of uint8
        The image mapped through ``lut``.
    """
    lut = np.asarray(lut)
    if lut.shape != (LEVELS,):
        raise ViformError(f"lut must have 256 entries; got shape {lut.shape}")
    return np.rint(lut).clip(0, 255).astype(np.uint8)[_check_gray8(gray8)]


class StreamEqualizer:
    """Histogram equalization of a live stream (seed 002 §3.2.2–§3.2.3).

    ``source="same"`` (default, the seed's way) uses frame k's own histogram: the seed's
    camera can afford it because each frame sits in DDR4 until its histogram is complete
    (§3.2.2: statistics are gathered while the frame is written, the frame is equalized when
    read back; a ping-pong RAM holds the next frame's histogram meanwhile), so a light step
    never maps one frame through another frame's table. ``source="previous"`` maps frame k
    through the histogram of the previous frame it saw (a streaming form without a frame
    buffer; the first frame passes through unchanged; after a step the frame flashes
    black or white).

    ``method="shift"`` uses (E1) (``compensate`` toggles the >> 15 term); ``"float"`` uses
    eq. (3) in floating point, rounded to the nearest level.
    """

    def __init__(self, source: str = "same", method: str = "shift", compensate: bool = True,
                 pixels_per_clock: int = 8, counter_bits: int = 20):
        self.source = check_choice("source", source, ("previous", "same"))
        self.method = check_choice("method", method, ("shift", "float"))
        self.compensate = bool(compensate)
        self.pixels_per_clock = pixels_per_clock
        self.counter_bits = counter_bits
        self._lut = None

    def lut(self, hist) -> np.ndarray:
        if self.method == "float":
            return np.rint(equalization_lut_float(hist)).astype(np.uint8)
        return equalization_lut_shift(hist, self.compensate)

    def __call__(self, gray8) -> np.ndarray:
        gray8 = _check_gray8(gray8)
        hist = histogram_counter(gray8, self.pixels_per_clock, self.counter_bits)
        if self.source == "same":
            return equalize(gray8, self.lut(hist))
        out = gray8.copy() if self._lut is None else equalize(gray8, self._lut)
        self._lut = self.lut(hist)
        return out

    def reset(self) -> None:
        self._lut = None
