"""Compiled polygon clipping for the described scenes' object truth (:func:`viform.light.layered.clip_convex`)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def clip_convex_ccw(sx, sy, cx, cy):  # pragma: no cover - compiled
    """Sutherland–Hodgman: polygon (``sx``, ``sy``) clipped by each edge of the convex, counter-clockwise
    (``cx``, ``cy``) in turn; per edge and vertex q (p the one before it) the crossing of p → q when they lie
    on different sides, then q when it is inside. The arithmetic of each point is written out as
    :func:`~viform.light.layered.clip_convex` states it (the same values)."""
    n = cx.size
    x, y = sx.copy(), sy.copy()
    for k in range(n):
        m = x.size
        if m == 0:
            break
        ax, ay, bx, by = cx[k], cy[k], cx[(k + 1) % n], cy[(k + 1) % n]
        ox = np.empty(2 * m)
        oy = np.empty(2 * m)
        j = 0
        for i in range(m):
            p = i - 1 if i > 0 else m - 1
            px_, py_, qx, qy = x[p], y[p], x[i], y[i]
            sp = (bx - ax) * (py_ - ay) - (by - ay) * (px_ - ax)
            sq = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
            if sq >= 0:  # (the tests in this order: the same points where a side is NaN)
                if sp < 0:
                    w = sp / (sp - sq)
                    ox[j] = px_ + w * (qx - px_)
                    oy[j] = py_ + w * (qy - py_)
                    j += 1
                ox[j] = qx
                oy[j] = qy
                j += 1
            elif sp >= 0:
                w = sp / (sp - sq)
                ox[j] = px_ + w * (qx - px_)
                oy[j] = py_ + w * (qy - py_)
                j += 1
        x, y = ox[:j].copy(), oy[:j].copy()
    return x, y
