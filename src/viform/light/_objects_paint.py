"""Compiled painting of :class:`~viform.light.multi_object.MultiObjectScene`'s objects per light sample.

:meth:`MultiObjectScene._paint <viform.light.multi_object.MultiObjectScene._paint>` draws seven small
rectangles with a dozen NumPy calls each: at 400×250 and 40 kHz that per-call cost, not the few thousand
pixels drawn, was most of the light's cost (≈ 0.35 ms a light sample). Here the 1-D quantities of every
(instant, object) pair of a chunk of light samples are computed in one batch of NumPy calls — the same
operations on the same operands as ``_paint``, elementwise — and one compiled call draws, converts to charge
and restores the canvas: the light is the scene's ``illuminance_lux`` to the bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from viform.light.sampled import PaintedSampler
from viform.light.truth import interval_overlap


def _paint_plan(scene, times_s: np.ndarray) -> dict:
    """What :meth:`MultiObjectScene._paint` draws at each of ``times_s``, as flat arrays for
    :func:`_composite_rates` / :func:`_composite_lux`: per drawn (instant, object) pair, in the order
    ``_paint`` draws them, its box and lux, and per row and column of the box the coverage and the
    texture's sine. Every value is computed by the same NumPy (or ``math``) operations on the same
    operands as in ``_paint`` — elementwise, so batched over instants and objects they are the same
    numbers — and the compiled composite repeats ``_paint``'s arithmetic (no fused multiply-add): the
    light is ``illuminance_lux``'s to the bit."""
    times = np.asarray(times_s, dtype=np.float64)
    n = times.size
    H, W = scene.shape
    p = scene.texture_period_px
    sx, sy = scene.scale_xy
    dt = times - scene.t_ref_s
    xs0, ys0, xs1, ys1 = (np.empty((len(scene._paint_order), n)) for _ in range(4))
    for o, spec in enumerate(scene._paint_order):
        w, h = scene.size_px(spec)
        if spec.radius_px:  # math.cos / math.sin, as centre_px (NumPy's may differ in the last bit)
            centres = np.array([scene.centre_px(spec, float(t)) for t in times.tolist()]).reshape(n, 2)
            cx, cy = centres[:, 0], centres[:, 1]
        else:
            cx = (spec.centre_px[0] + spec.velocity_px_per_s[0] * scene.speed * dt) * sx
            cy = (spec.centre_px[1] + spec.velocity_px_per_s[1] * scene.speed * dt) * sy
        xs0[o], ys0[o], xs1[o], ys1[o] = cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2
    # pairs instant-major, objects in paint order (far to near)
    x0, y0, x1, y1 = (v.T.ravel() for v in (xs0, ys0, xs1, ys1))
    lux = np.tile([scene.object_lux(spec) for spec in scene._paint_order], n)
    sample = np.repeat(np.arange(n, dtype=np.int64), len(scene._paint_order))
    c0 = np.maximum(0, np.floor(x0)).astype(np.int64)
    c1 = np.minimum(W, np.ceil(x1)).astype(np.int64)
    r0 = np.maximum(0, np.floor(y0)).astype(np.int64)
    r1 = np.minimum(H, np.ceil(y1)).astype(np.int64)
    keep = (c1 > c0) & (r1 > r0)
    x0, y0, x1, y1, lux, sample, c0, c1, r0, r1 = (v[keep] for v in (x0, y0, x1, y1, lux, sample, c0, c1, r0, r1))
    ncol, nrow = c1 - c0, r1 - r0
    coff = np.concatenate(([0], np.cumsum(ncol))).astype(np.int64)
    roff = np.concatenate(([0], np.cumsum(nrow))).astype(np.int64)
    cols = (np.arange(coff[-1], dtype=np.int64) - np.repeat(coff[:-1] - c0, ncol)).astype(np.float64)
    rows = (np.arange(roff[-1], dtype=np.int64) - np.repeat(roff[:-1] - r0, nrow)).astype(np.float64)
    cx0, cx1 = np.repeat(x0, ncol), np.repeat(x1, ncol)
    ry0, ry1 = np.repeat(y0, nrow), np.repeat(y1, nrow)
    return {
        "sample": sample, "r0": r0, "r1": r1, "c0": c0, "c1": c1, "lux": lux, "roff": roff, "coff": coff,
        "alpha_rows": interval_overlap(rows, rows + 1, ry0, ry1),
        "alpha_cols": interval_overlap(cols, cols + 1, cx0, cx1),
        "sin_rows": np.sin(2 * np.pi * (rows + 0.5 - ry0) / p), "sin_cols": np.sin(2 * np.pi * (cols + 0.5 - cx0) / p),
    }


@njit(cache=True)
def _composite(canvas, width, k, r0, r1, c0, c1, lux, roff, coff, alpha_rows, sin_rows, alpha_cols, sin_cols):
    """Draw pair k of a :func:`_paint_plan` over ``canvas`` (flat): ``_paint``'s
    ``patch += outer(αr, αc)·(lux·(1 + 0.5·outer(sin v, sin u)) − patch)``, element by element."""
    for i in range(r1[k] - r0[k]):
        ar = alpha_rows[roff[k] + i]
        sr = sin_rows[roff[k] + i]
        base = (r0[k] + i) * width + c0[k]
        for j in range(c1[k] - c0[k]):
            alpha = ar * alpha_cols[coff[k] + j]
            light = lux[k] * (1.0 + 0.5 * (sr * sin_cols[coff[k] + j]))
            patch = canvas[base + j]
            canvas[base + j] = patch + alpha * (light - patch)


@njit(cache=True)
def _restore(canvas, background, width, k, r0, r1, c0, c1):
    for r in range(r0[k], r1[k]):
        for c in range(c0[k], c1[k]):
            canvas[r * width + c] = background[r * width + c]


@njit(cache=True)
def _composite_rates(canvas, background, width, sample, r0, r1, c0, c1, lux, roff, coff, alpha_rows, sin_rows,
                     alpha_cols, sin_cols, starts, stops, a, b, out):
    """Per instant i: draw its pairs, ``out[i]`` = rint(a·lux + b) of the flat ranges' pixels laid end to
    end (as :func:`~viform.light.sampled._gather_rates`), restore the drawn boxes from ``background``."""
    k0 = 0
    for i in range(out.shape[0]):
        k1 = k0
        while k1 < sample.size and sample[k1] == i:
            _composite(canvas, width, k1, r0, r1, c0, c1, lux, roff, coff, alpha_rows, sin_rows, alpha_cols,
                       sin_cols)
            k1 += 1
        o = 0
        for s in range(starts.size):
            for p in range(starts[s], stops[s]):
                out[i, o] = np.int64(np.rint(canvas[p] * a[o] + b[o]))
                o += 1
        for k in range(k0, k1):
            _restore(canvas, background, width, k, r0, r1, c0, c1)
        k0 = k1


@njit(cache=True)
def _composite_lux(canvas, background, width, sample, r0, r1, c0, c1, lux, roff, coff, alpha_rows, sin_rows,
                   alpha_cols, sin_cols, starts, stops, out):
    """As :func:`_composite_rates`, ``out[i]`` the light itself (lux)."""
    k0 = 0
    for i in range(out.shape[0]):
        k1 = k0
        while k1 < sample.size and sample[k1] == i:
            _composite(canvas, width, k1, r0, r1, c0, c1, lux, roff, coff, alpha_rows, sin_rows, alpha_cols,
                       sin_cols)
            k1 += 1
        o = 0
        for s in range(starts.size):
            for p in range(starts[s], stops[s]):
                out[i, o] = canvas[p]
                o += 1
        for k in range(k0, k1):
            _restore(canvas, background, width, k, r0, r1, c0, c1)
        k0 = k1


class ObjectsSampler(PaintedSampler):
    """:class:`~viform.light.sampled.PaintedSampler` of a :class:`MultiObjectScene` whose painting runs in
    compiled code (:func:`_paint_plan`): the same light to the bit, without NumPy's per-call cost for each
    object at each light sample."""

    def __init__(self, background, paint, rects, lux_max, scene):
        super().__init__(background, paint, rects, lux_max)
        self._scene = scene

    def render(self, times_s, starts, stops, a, b, out) -> None:
        plan = _paint_plan(self._scene, np.asarray(times_s, dtype=np.float64).ravel())
        args = (self._canvas.reshape(-1), self.background.reshape(-1), self.width, plan["sample"], plan["r0"],
                plan["r1"], plan["c0"], plan["c1"], plan["lux"], plan["roff"], plan["coff"], plan["alpha_rows"],
                plan["sin_rows"], plan["alpha_cols"], plan["sin_cols"],
                np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(stops, dtype=np.int64))
        try:
            if out.dtype == np.int64:
                _composite_rates(*args, np.ascontiguousarray(a, dtype=np.float64),
                                 np.ascontiguousarray(b, dtype=np.float64), out)
            else:
                _composite_lux(*args, out)
        except BaseException:
            self._canvas[...] = self.background  # never leave a drawn object on the canvas
            raise
