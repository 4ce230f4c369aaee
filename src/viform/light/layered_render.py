"""Described scenes rendered in compiled code: the :class:`~viform.light.layered.DescribedScene` light
per light sample, only where it can change.

The renderer follows :meth:`DescribedScene.reference_lux` operation for operation (the same maps
A(t) and their inverses, computed once per sample on the host by the scene's own vectorized code;
the same source expressions, area sampling of images and compositing), so the two agree to rounding.
Coverage is the same exact pixel area (Green's theorem per polygon edge) computed row by row:
for a row, an edge's trapezoid is integrated only over the columns its x-range crosses, and the
columns left of it (covered over the edge's whole height in the row) are filled by a running sum,
so a polygon costs O(perimeter + area) instead of O(edges × area).

Work. A work item is one light sample and a group of row spans (a few items per thread). Within an
item, a layer with no rotation or shear (its inverse map is diagonal) and no mask reads the column
half of its arithmetic from a per-column table filled once: an image magnified or mildly minified
(the direct 3 × 3 texel sum) its texel indices and weights along x, a sines pattern its factor along
x. The expressions are those of the per-pixel path, so the light is the same to the bit.

Static part. Layers that neither move nor flicker (and no camera motion) form the static light;
the layers below the first dynamic one are composited once (``base``). A sample renders, in each
dirty span, the base and every layer from the first dynamic one upward.
"""

from __future__ import annotations

import math

import numpy as np
from numba import get_num_threads, njit, prange

from viform.light.affine import invert_many
from viform.light.sampled import LightSampler, lux_to_rates, ranges_to_spans

SOLID, GAUSSIAN, PATTERN, IMAGE = 0, 1, 2, 3
PATTERN_CODES = {"texture": 0, "edge": 1, "bars": 2, "noise": 3, "sines": 4}
# integer program, per layer
I_KIND, I_PATTERN, I_BLEND, I_POLY0, I_POLYN, I_VAL, I_H, I_W, I_SAT, I_MVAL, I_MSAT, I_SEED, I_FULL = range(13)
N_INT = 13
# float program, per layer
F_LOW, F_HIGH, F_PERIOD, F_SX, F_SY, F_SIGMA2, F_DEPTH, F_X0, F_Y0, F_IX, F_IY, F_KX, F_KY, F_MEAN = range(14)
N_FLOAT = 14
# per sample and layer: forward map (6), inverse (6), jac (2), modulation
S_INV, S_JAC, S_M = 6, 12, 14
N_SAMPLE = 15


# ----------------------------------------------------------------------------- sources

@njit(cache=True, inline="always")
def _texture(x, y, period):
    checker = (math.floor(x / period) + math.floor(y / period)) % 2.0
    g1 = 0.5 + 0.5 * math.sin(2 * math.pi * (0.8 * x + 0.6 * y) / (0.7 * period))
    g2 = 0.5 + 0.5 * math.cos(2 * math.pi * (-0.5 * x + 0.87 * y) / (1.9 * period))
    return 0.55 * checker + 0.25 * g1 + 0.20 * g2


@njit(cache=True, inline="always")
def _lattice(i, j, seed, octave7):
    h = (np.int64(i) * np.int64(73856093)) ^ (np.int64(j) * np.int64(19349663)) ^ (seed * np.int64(83492791)
                                                                                   + octave7)
    h = (h * np.int64(2654435761)) & np.int64(0xFFFFFFFF)
    return (h % np.int64(65536)) / 65535.0


@njit(cache=True, inline="always")
def _noise(x, y, period, seed):
    out = 0.0
    weight = 0.0
    for o in range(2):
        octave = 1.0 if o == 0 else 0.5
        amp = 2 / 3 if o == 0 else 1 / 3
        p = period * octave
        gx, gy = x / p, y / p
        ix, iy = math.floor(gx), math.floor(gy)
        fx, fy = gx - ix, gy - iy
        fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
        o7 = np.int64(octave * 7)
        v00 = _lattice(ix, iy, seed, o7)
        v10 = _lattice(ix + 1, iy, seed, o7)
        v01 = _lattice(ix, iy + 1, seed, o7)
        v11 = _lattice(ix + 1, iy + 1, seed, o7)
        out = out + amp * ((1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11))
        weight += amp
    return out / weight


@njit(cache=True, inline="always")
def _sat_integral(store, sat, h, w, x, y):
    x = min(max(x, 0.0), np.float64(w))
    y = min(max(y, 0.0), np.float64(h))
    i = min(np.int64(math.floor(x)), w - 1)
    j = min(np.int64(math.floor(y)), h - 1)
    fx, fy = x - i, y - j
    w1 = w + 1
    s00 = store[sat + j * w1 + i]
    s01 = store[sat + j * w1 + i + 1]
    s10 = store[sat + (j + 1) * w1 + i]
    s11 = store[sat + (j + 1) * w1 + i + 1]
    return (1 - fy) * ((1 - fx) * s00 + fx * s01) + fy * ((1 - fx) * s10 + fx * s11)


@njit(cache=True, inline="always")
def _texel_mean(store, val, sat, h, w, u, v, hx, hy):
    """Mean of piecewise-constant texels over [u ± hx] × [v ± hy] (texel units), clamped into the image:
    :meth:`viform.light.layered.Texels.sample`, operation for operation."""
    x0 = min(max(u - hx, 0.0), w - 2 * hx)
    y0 = min(max(v - hy, 0.0), h - 2 * hy)
    x0 = max(x0, 0.0)
    y0 = max(y0, 0.0)
    x1 = min(x0 + 2 * hx, np.float64(w))
    y1 = min(y0 + 2 * hy, np.float64(h))
    area = (x1 - x0) * (y1 - y0)
    if hx <= 1.0 and hy <= 1.0:
        i0 = min(np.int64(math.floor(x0)), w - 1)
        j0 = min(np.int64(math.floor(y0)), h - 1)
        total = 0.0
        for kj in range(3):
            j = j0 + kj
            wy = max(min(y1, np.float64(j + 1)) - max(y0, np.float64(j)), 0.0)
            jj = min(j, h - 1)
            row = 0.0
            for ki in range(3):
                i = i0 + ki
                wx = max(min(x1, np.float64(i + 1)) - max(x0, np.float64(i)), 0.0)
                row += wx * store[val + jj * w + min(i, w - 1)]
            total += wy * row
        return total / area
    total = (_sat_integral(store, sat, h, w, x1, y1) - _sat_integral(store, sat, h, w, x0, y1)
             - _sat_integral(store, sat, h, w, x1, y0) + _sat_integral(store, sat, h, w, x0, y0))
    return total / area


@njit(cache=True, inline="always")
def _source(kind, pattern, fp, seed, store, val, sat, h, w, u, v, j0, j1):
    """Source lux of a layer at its point (u, v) (:meth:`viform.light.layered.Layer.light`)."""
    if kind == SOLID:
        return fp[F_HIGH]
    if kind == GAUSSIAN:
        return fp[F_HIGH] * math.exp(-(u * u + v * v) / fp[F_SIGMA2])
    if kind == PATTERN:
        period = fp[F_PERIOD]
        if pattern == 4:
            return fp[F_MEAN] * (1.0 + fp[F_DEPTH] * math.sin(2 * math.pi * (v - fp[F_Y0]) / period)
                                 * math.sin(2 * math.pi * (u - fp[F_X0]) / period))
        x = u / fp[F_SX]
        y = v / fp[F_SY]
        if pattern == 0:
            value = _texture(x, y, period)
        elif pattern == 1:
            value = 1.0 if x >= 0 else 0.0
        elif pattern == 2:
            value = math.floor(x / (period / 2)) % 2.0
        else:
            value = _noise(x, y, period, seed)
        return fp[F_LOW] + (fp[F_HIGH] - fp[F_LOW]) * value
    kx, ky = fp[F_KX], fp[F_KY]
    hx = 0.5 * max(kx * j0, 1.0)
    hy = 0.5 * max(ky * j1, 1.0)
    return _texel_mean(store, val, sat, h, w, (u - fp[F_IX]) * kx, (v - fp[F_IY]) * ky, hx, hy)


@njit(cache=True, inline="always")
def _big(s):
    if s <= 0:
        return 0.0
    if s < 1.0:
        return 0.5 * s * s
    return 0.5 + (s - 1.0)


# ----------------------------------------------------------------------------- coverage

@njit(cache=True)
def _row_coverage(px, py, o, n, y, xs, xe, cov, full):
    """Exact area of pixels (row y, columns xs … xe − 1) inside the polygon px[o:o+n], py[o:o+n]:
    :func:`viform.light.layered.polygon_coverage` for one row."""
    width = xe - xs
    for c in range(width + 1):
        full[c] = 0.0
    for c in range(width):
        cov[c] = 0.0
    yf = np.float64(y)
    for k in range(n):
        xa, ya = px[o + k], py[o + k]
        k1 = k + 1 if k + 1 < n else 0
        xb, yb = px[o + k1], py[o + k1]
        if ya == yb:
            continue
        sign = 1.0 if yb > ya else -1.0
        if ya > yb:
            xa, ya, xb, yb = xb, yb, xa, ya
        lo = max(yf, ya)
        hi = min(yf + 1.0, yb)
        if not hi > lo:
            continue
        slope = (xb - xa) / (yb - ya)
        xlo = xa + slope * (lo - ya)
        xhi = xa + slope * (hi - ya)
        dy = hi - lo
        lo_x = min(max(min(xlo, xhi), xs - 1.0), xe + 1.0)
        hi_x = min(max(max(xlo, xhi), xs - 1.0), xe + 1.0)
        cf = np.int64(math.floor(lo_x))
        ce = np.int64(math.ceil(hi_x))
        f_end = min(xe, cf)
        if f_end > xs:  # columns left of the edge: the edge's whole height in the row
            full[0] += sign * dy
            full[f_end - xs] -= sign * dy
        for c in range(max(xs, cf), min(xe, ce)):
            cc = np.float64(c)
            a = xlo - cc
            b = xhi - cc
            ds = b - a
            if abs(ds) < 1e-9:
                mean = min(max(0.5 * (a + b), 0.0), 1.0)
            else:
                mean = (_big(b) - _big(a)) / ds
            cov[c - xs] += sign * mean * dy
    run = 0.0
    for c in range(width):
        run += full[c]
        cov[c] = min(max(abs(cov[c] + run), 0.0), 1.0)


# ----------------------------------------------------------------------------- per sample

@njit(cache=True)
def _prepare(samp, ints, px, py, qx, qy, bbox, height, width):
    """Per sample and layer: the outline in canvas px (``qx``, ``qy``) and the pixel box it can touch
    (col0, col1, row0, row1), as :meth:`DescribedScene._bbox`."""
    n, n_layers = samp.shape[0], samp.shape[1]
    for i in range(n):
        for l in range(n_layers):
            o, m = ints[l, I_POLY0], ints[l, I_POLYN]
            if ints[l, I_FULL]:
                bbox[i, l, 0], bbox[i, l, 1], bbox[i, l, 2], bbox[i, l, 3] = 0, width, 0, height
                continue
            a = samp[i, l]
            xmin, xmax, ymin, ymax = np.inf, -np.inf, np.inf, -np.inf
            for k in range(m):
                x = a[0] * px[o + k] + a[1] * py[o + k] + a[2]
                y = a[3] * px[o + k] + a[4] * py[o + k] + a[5]
                qx[i, o + k] = x
                qy[i, o + k] = y
                xmin, xmax = min(xmin, x), max(xmax, x)
                ymin, ymax = min(ymin, y), max(ymax, y)
            big = 4.0 * (width + height) + 8.0
            xmin, xmax = min(max(xmin, -big), big), min(max(xmax, -big), big)
            ymin, ymax = min(max(ymin, -big), big), min(max(ymax, -big), big)
            bbox[i, l, 0] = max(0, np.int64(math.floor(xmin)))
            bbox[i, l, 1] = min(width, np.int64(math.ceil(xmax)) + 1)
            bbox[i, l, 2] = max(0, np.int64(math.floor(ymin)))
            bbox[i, l, 3] = min(height, np.int64(math.ceil(ymax)) + 1)


@njit(cache=True, inline="always")
def _axis_weights(p0, p1, n, idx, wts):
    """Texels 0 … n − 1 a box [p0, p1] (texel units, p1 − p0 ≤ 2) overlaps: three indices and weights
    (:meth:`viform.light.layered.Texels.sample`'s direct sum along one axis)."""
    i0 = min(np.int64(math.floor(p0)), n - 1)
    for k in range(3):
        i = i0 + k
        wts[k] = max(min(p1, np.float64(i + 1)) - max(p0, np.float64(i)), 0.0)
        idx[k] = min(i, n - 1)


@njit(cache=True, inline="always")
def _box(u, hw, n):
    """The clamped box [p0, p1] of half-width ``hw`` about ``u`` in [0, n] (Texels.sample)."""
    p0 = min(max(u - hw, 0.0), n - 2 * hw)
    p0 = max(p0, 0.0)
    p1 = min(p0 + 2 * hw, np.float64(n))
    return p0, p1


@njit(cache=True)
def _render_job(i, g0, g1, samp, bbox, ints, fp, qx, qy, store, base, first, active, width, rows, c0s, c1s, offs,
                a, b, lux_out, rates_out, want_rates):
    """Spans g0 … g1 − 1 at sample i (see :func:`_render_parallel`)."""
    n_layers = samp.shape[1]
    lux = np.empty(width)
    cov = np.empty(width)
    full = np.empty(width + 1)
    # per layer: axis-aligned image or sines layers read per-column tables (the column part of their
    # arithmetic, which does not depend on the row), filled over the layer's box once for the job
    table = np.zeros(n_layers, np.bool_)
    xidx = np.empty((n_layers, width, 3), np.int64)
    xw = np.empty((n_layers, width, 4))
    yidx = np.empty(3, np.int64)
    yw = np.empty(3)
    for l in range(first, n_layers):
        sl = samp[i, l]
        if not active[l] or sl[S_INV + 1] != 0.0 or sl[S_INV + 3] != 0.0 or ints[l, I_MVAL] >= 0:
            continue
        kind = ints[l, I_KIND]
        f = fp[l]
        if kind == IMAGE:
            hx = 0.5 * max(f[F_KX] * sl[S_JAC], 1.0)
            hy = 0.5 * max(f[F_KY] * sl[S_JAC + 1], 1.0)
            if hx > 1.0 or hy > 1.0:
                continue
            w = ints[l, I_W]
            for c in range(bbox[i, l, 0], bbox[i, l, 1]):
                u = sl[S_INV] * (c + 0.5) + sl[S_INV + 1] * 0.0 + sl[S_INV + 2]
                p0, p1 = _box((u - f[F_IX]) * f[F_KX], hx, w)
                _axis_weights(p0, p1, w, xidx[l, c], xw[l, c])
                xw[l, c, 3] = p1 - p0
            table[l] = True
        elif kind == PATTERN and ints[l, I_PATTERN] == 4:
            for c in range(bbox[i, l, 0], bbox[i, l, 1]):
                u = sl[S_INV] * (c + 0.5) + sl[S_INV + 1] * 0.0 + sl[S_INV + 2]
                xw[l, c, 0] = math.sin(2 * math.pi * (u - f[F_X0]) / f[F_PERIOD])
            table[l] = True
    for s in range(g0, g1):
        y = rows[s]
        cs, ce = c0s[s], c1s[s]
        nx = ce - cs
        pbase = y * width
        for c in range(nx):
            lux[c] = base[pbase + cs + c]
        yc = y + 0.5
        for l in range(first, n_layers):
            if not active[l] or y < bbox[i, l, 2] or y >= bbox[i, l, 3]:
                continue
            xs = max(cs, bbox[i, l, 0])
            xe = min(ce, bbox[i, l, 1])
            if xe <= xs:
                continue
            sl = samp[i, l]
            mod = sl[S_M]
            kind, pattern, blend = ints[l, I_KIND], ints[l, I_PATTERN], ints[l, I_BLEND]
            val, h, w, sat = ints[l, I_VAL], ints[l, I_H], ints[l, I_W], ints[l, I_SAT]
            mval, msat, seed = ints[l, I_MVAL], ints[l, I_MSAT], ints[l, I_SEED]
            f = fp[l]
            i00, i01, i02 = sl[S_INV], sl[S_INV + 1], sl[S_INV + 2]
            i10, i11, i12 = sl[S_INV + 3], sl[S_INV + 4], sl[S_INV + 5]
            j0, j1 = sl[S_JAC], sl[S_JAC + 1]
            if ints[l, I_FULL]:
                for c in range(xe - xs):
                    cov[c] = 1.0
            else:
                _row_coverage(qx[i], qy[i], ints[l, I_POLY0], ints[l, I_POLYN], y, xs, xe, cov, full)
            over = xs - cs
            if table[l] and kind == IMAGE:
                v = i10 * 0.0 + i11 * yc + i12
                hy = 0.5 * max(f[F_KY] * j1, 1.0)
                q0, q1 = _box((v - f[F_IY]) * f[F_KY], hy, h)
                _axis_weights(q0, q1, h, yidx, yw)
                dy = q1 - q0
                for c in range(xe - xs):
                    alpha = cov[c]
                    if alpha == 0.0 and l > 0:
                        continue
                    col = xs + c
                    total = 0.0
                    for kj in range(3):
                        wy = yw[kj]
                        if wy == 0.0:
                            continue
                        r0 = val + yidx[kj] * w
                        row = 0.0
                        for ki in range(3):
                            wx = xw[l, col, ki]
                            if wx != 0.0:
                                row += wx * store[r0 + xidx[l, col, ki]]
                        total += wy * row
                    src = total / (xw[l, col, 3] * dy) * mod
                    k = over + c
                    if l == 0:
                        lux[k] = src
                    elif blend == 1:
                        lux[k] += alpha * src
                    else:
                        lux[k] += alpha * (src - lux[k])
                continue
            if table[l]:  # sines, axis-aligned
                v = i10 * 0.0 + i11 * yc + i12
                sv = f[F_DEPTH] * math.sin(2 * math.pi * (v - f[F_Y0]) / f[F_PERIOD])
                for c in range(xe - xs):
                    alpha = cov[c]
                    if alpha == 0.0 and l > 0:
                        continue
                    src = f[F_MEAN] * (1.0 + sv * xw[l, xs + c, 0]) * mod
                    k = over + c
                    if l == 0:
                        lux[k] = src
                    elif blend == 1:
                        lux[k] += alpha * src
                    else:
                        lux[k] += alpha * (src - lux[k])
                continue
            for c in range(xe - xs):
                alpha = cov[c]
                if alpha == 0.0 and l > 0:
                    continue
                xc = (xs + c) + 0.5
                u = i00 * xc + i01 * yc + i02
                v = i10 * xc + i11 * yc + i12
                if mval >= 0:
                    kx, ky = f[F_KX], f[F_KY]
                    hx = 0.5 * max(kx * j0, 1.0)
                    hy = 0.5 * max(ky * j1, 1.0)
                    mk = _texel_mean(store, mval, msat, h, w, (u - f[F_IX]) * kx, (v - f[F_IY]) * ky, hx, hy)
                    alpha = alpha * min(max(mk, 0.0), 1.0)
                src = _source(kind, pattern, f, seed, store, val, sat, h, w, u, v, j0, j1) * mod
                k = over + c
                if l == 0:
                    lux[k] = src
                elif blend == 1:
                    lux[k] += alpha * src
                else:
                    lux[k] += alpha * (src - lux[k])
        o = offs[s]
        if want_rates:
            for c in range(nx):
                rates_out[i, o + c] = np.int64(np.rint(lux[c] * a[o + c] + b[o + c]))
        else:
            for c in range(nx):
                lux_out[i, o + c] = lux[c]


@njit(cache=True, parallel=True)
def _render_parallel(samp, bbox, ints, fp, qx, qy, store, base, first, active, width, rows, c0s, c1s, offs, a, b,
                     lux_out, rates_out, want_rates, groups):
    """The light of each span (row, col0 … col1 − 1, laid out from offset) at each sample: the base,
    then layers ``first`` … from far to near (see the module notes). Work items: a sample and a group
    of spans (spans ``groups[g]`` … ``groups[g + 1] − 1``)."""
    n_groups = groups.size - 1
    for job in prange(samp.shape[0] * n_groups):
        i = job // n_groups
        g = job - i * n_groups
        _render_job(i, groups[g], groups[g + 1], samp, bbox, ints, fp, qx, qy, store, base, first, active, width,
                    rows, c0s, c1s, offs, a, b, lux_out, rates_out, want_rates)


@njit(cache=True)
def _render_serial(samp, bbox, ints, fp, qx, qy, store, base, first, active, width, rows, c0s, c1s, offs, a, b,
                   lux_out, rates_out, want_rates, groups):
    """:func:`_render_parallel` on one thread (small renders: waking the other threads costs more)."""
    for i in range(samp.shape[0]):
        _render_job(i, 0, rows.size, samp, bbox, ints, fp, qx, qy, store, base, first, active, width, rows, c0s,
                    c1s, offs, a, b, lux_out, rates_out, want_rates)


@njit(cache=True, parallel=True)
def _render_rows(samp, bbox, ints, fp, qx, qy, store, base, first, active, width, rows, c0s, c1s, offs, a, b,
                 lux_out, rates_out, per):
    """Row ``rows[i]`` (span i) at sample i only, into ``lux_out[i]``: each row of the field at its own instant
    (the spans' offsets are 0). Work items: ``per`` rows."""
    n = rows.size
    for job in prange((n + per - 1) // per):
        for i in range(job * per, min(n, job * per + per)):
            _render_job(i, i, i + 1, samp, bbox, ints, fp, qx, qy, store, base, first, active, width, rows, c0s,
                        c1s, offs, a, b, lux_out, rates_out, False)


#: Pixel-samples below which a render runs on one thread (waking the others costs more).
PARALLEL_WORK = 1 << 15


def _render(*args):
    samp, rows, c0s, c1s = args[0], args[11], args[12], args[13]
    work = samp.shape[0] * int((c1s - c0s).sum()) if rows.size else 0
    if work < PARALLEL_WORK:
        _render_serial(*args, np.zeros(2, np.int64))
        return
    # a few work items per thread: per sample when there are many samples, else groups of spans
    per_sample = max(1, -(-4 * get_num_threads() // samp.shape[0]))
    groups = np.unique(np.linspace(0, rows.size, min(rows.size, per_sample) + 1).round().astype(np.int64))
    _render_parallel(*args, groups)


# ----------------------------------------------------------------------------- the sampler

class LayeredSampler(LightSampler):
    """A :class:`~viform.light.layered.DescribedScene`'s light for the simulator (see the module notes)."""

    def __init__(self, scene):
        self.scene = scene
        self.height, self.width = scene.height, scene.width
        self.layers = [scene.background] + list(scene.order)
        moving_view = scene.camera is not None or bool(scene.shake)
        self.dynamic = np.array([moving_view or not layer.motion.static or bool(layer.modulation)
                                 for layer in self.layers])
        n_layers = len(self.layers)
        ints = np.zeros((n_layers, N_INT), np.int64)
        fp = np.zeros((n_layers, N_FLOAT))
        store, px, py = [np.zeros(1)], [], []
        size = 1
        n_vertices = 0

        def put(array):
            nonlocal size
            store.append(np.ascontiguousarray(array, dtype=np.float64).ravel())
            size += store[-1].size
            return size - store[-1].size

        for l, layer in enumerate(self.layers):
            ints[l, I_MVAL] = ints[l, I_MSAT] = -1
            ints[l, I_BLEND] = 1 if layer.blend == "add" else 0
            fp[l, F_SX] = fp[l, F_SY] = 1.0
            fp[l, F_LOW], fp[l, F_HIGH] = layer.lux_low, layer.lux_high
            p = layer.params
            if layer.kind == "solid":
                ints[l, I_KIND] = SOLID
            elif layer.kind == "gaussian":
                ints[l, I_KIND] = GAUSSIAN
                fp[l, F_SIGMA2] = 2 * p["sigma_px"] ** 2
            elif layer.kind == "pattern":
                ints[l, I_KIND] = PATTERN
                name = p["name"]
                ints[l, I_PATTERN] = PATTERN_CODES[name]
                fp[l, F_PERIOD] = p.get("period_px", 48.0 if name != "sines" else 6.0)
                if name == "sines":
                    fp[l, F_X0], fp[l, F_Y0] = layer.sines_origin()
                    depth = p.get("depth", 0.5)
                    fp[l, F_DEPTH] = depth
                    fp[l, F_MEAN] = layer.lux_high / (1 + depth)
                fp[l, F_SX], fp[l, F_SY] = p.get("scale", (1.0, 1.0))
                ints[l, I_SEED] = int(p.get("seed", 0))
            else:
                ints[l, I_KIND] = IMAGE
            if layer.texels is not None:
                h, w = layer.texels.shape
                ints[l, I_H], ints[l, I_W] = h, w
                ints[l, I_VAL] = put(layer.texels.values)
                ints[l, I_SAT] = put(layer.texels.sat)
                x, y, bw, bh = layer.image_box
                fp[l, F_IX], fp[l, F_IY] = x, y
                fp[l, F_KX], fp[l, F_KY] = w / bw, h / bh
            if layer.mask is not None:
                ints[l, I_MVAL] = put(layer.mask.values)
                ints[l, I_MSAT] = put(layer.mask.sat)
            if layer.polygon is None:
                ints[l, I_FULL] = 1
            else:
                ints[l, I_POLY0] = n_vertices
                ints[l, I_POLYN] = len(layer.polygon[0])
                n_vertices += len(layer.polygon[0])
                px.append(np.asarray(layer.polygon[0], dtype=np.float64))
                py.append(np.asarray(layer.polygon[1], dtype=np.float64))
        self.ints, self.fp = ints, fp
        self.store = np.concatenate(store)
        self.px = np.concatenate(px) if px else np.zeros(1)
        self.py = np.concatenate(py) if py else np.zeros(1)
        self.n_vertices = max(1, n_vertices)
        dyn = np.flatnonzero(self.dynamic)
        self.first = int(dyn[0]) if dyn.size else n_layers
        self.lux_max = float(scene.peak_lux())
        self._static = None
        self._base = None
        self._active = np.ones(n_layers, bool)

    # -------------------------------------------------------------- host side
    def sample_table(self, times):
        """Per sample and layer: the forward and inverse maps, the footprint and the modulation."""
        times = np.asarray(times, dtype=np.float64).ravel()
        samp = np.zeros((times.size, len(self.layers), N_SAMPLE))
        for l, layer in enumerate(self.layers):
            fwd = self.scene.layer_maps(layer, times)
            inv = _invert(fwd)
            samp[:, l, 0:6] = fwd.reshape(-1, 6)
            samp[:, l, S_INV:S_INV + 6] = inv.reshape(-1, 6)
            samp[:, l, S_JAC] = np.abs(inv[:, 0, 0]) + np.abs(inv[:, 0, 1])
            samp[:, l, S_JAC + 1] = np.abs(inv[:, 1, 0]) + np.abs(inv[:, 1, 1])
            samp[:, l, S_M] = self.scene.modulation_factors(layer, times)
        return samp

    def _prepared(self, times):
        samp = self.sample_table(times)
        n = samp.shape[0]
        qx = np.zeros((n, self.n_vertices))
        qy = np.zeros((n, self.n_vertices))
        bbox = np.zeros((n, len(self.layers), 4), np.int64)
        _prepare(samp, self.ints, self.px, self.py, qx, qy, bbox, self.height, self.width)
        return samp, qx, qy, bbox

    def _run(self, times, starts, stops, a, b, out, first, base, active):
        samp, qx, qy, bbox = self._prepared(times)
        rows, c0s, c1s, offs = ranges_to_spans(np.asarray(starts), np.asarray(stops), self.width)
        want = out.dtype == np.int64
        dummy_f = np.zeros((1, 1))
        dummy_i = np.zeros((1, 1), np.int64)
        _render(samp, bbox, self.ints, self.fp, qx, qy, self.store, base, first, active, self.width, rows, c0s, c1s,
                offs, np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(b, dtype=np.float64),
                dummy_f if want else out, out if want else dummy_i, want)

    def _static_parts(self):
        """(base, static light), flat: the static layers below the first dynamic one, and every static layer."""
        if self._static is None:
            pixels = self.height * self.width
            zero, one = np.zeros(pixels), np.ones(pixels)
            t0 = np.array([0.0])
            start, stop = np.array([0], np.int64), np.array([pixels], np.int64)
            n_layers = len(self.layers)
            base = np.zeros((1, pixels))
            if self.first > 0:
                self._run(t0, start, stop, one, one, base, 0, zero, np.arange(n_layers) < self.first)
            static = np.zeros((1, pixels))
            self._run(t0, start, stop, one, one, static, 0, zero, ~self.dynamic)
            self._base, self._static = base[0], static[0]
        return self._base, self._static

    # -------------------------------------------------------------- the sampler's interface
    def static_lux(self) -> np.ndarray:
        return self._static_parts()[1].reshape(self.height, self.width)

    def dirty_rects(self, times_s) -> np.ndarray:
        dyn = np.flatnonzero(self.dynamic)
        if dyn.size == 0:
            return np.zeros((0, 4), np.int64)
        if self.dynamic[0] or any(self.ints[l, I_FULL] for l in dyn):
            return np.array([[0, self.height, 0, self.width]], np.int64)
        _, _, _, bbox = self._prepared(times_s)
        boxes = bbox[:, dyn].reshape(-1, 4)  # col0, col1, row0, row1
        rects = boxes[:, [2, 3, 0, 1]]
        keep = (rects[:, 1] > rects[:, 0]) & (rects[:, 3] > rects[:, 2])
        return np.ascontiguousarray(rects[keep])

    def render(self, times_s, starts, stops, a, b, out) -> None:
        base, _ = self._static_parts()
        times = np.ascontiguousarray(times_s, dtype=np.float64).ravel()
        self._run(times, starts, stops, a, b, out, self.first, base, self._active)

    def row_frames(self, times_s) -> np.ndarray:
        """The light with row r at instant ``times_s[r]`` (H, W), lux: row r of :meth:`frames` at that instant."""
        times = np.ascontiguousarray(times_s, dtype=np.float64).ravel()
        if times.size != self.height:
            raise ValueError(f"{times.size} instants for {self.height} rows")
        base, _ = self._static_parts()
        samp, qx, qy, bbox = self._prepared(times)
        rows = np.arange(self.height, dtype=np.int64)
        zeros = np.zeros(self.height, np.int64)
        out = np.empty((self.height, self.width))
        one = np.ones(self.width)
        _render_rows(samp, bbox, self.ints, self.fp, qx, qy, self.store, base, self.first, self._active, self.width,
                     rows, zeros, np.full(self.height, self.width, np.int64), zeros, one, one, out,
                     np.zeros((1, 1), np.int64), max(1, self.height // (4 * get_num_threads())))
        return out

    def rates_static(self, a, b) -> np.ndarray:
        """The static light's charge per tick, rint(a·lux + b), for every pixel."""
        static = self._static_parts()[1][None]
        out = np.empty(static.shape, np.int64)
        lux_to_rates(static, a, b, out)
        return out[0]


def _invert(a: np.ndarray) -> np.ndarray:
    """Inverses of 2×3 affine maps (n, 2, 3) (:func:`viform.light.affine.invert_many`)."""
    return invert_many(a)
