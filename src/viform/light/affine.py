"""2×3 affine maps of the image plane, shared by the layered scenes and their compiled renderer.

A map ``a`` (…, 2, 3) takes (x, y) to (a00·x + a01·y + a02, a10·x + a11·y + a12), pixels.
"""

from __future__ import annotations

import numpy as np


def invert_many(a: np.ndarray) -> np.ndarray:
    """Inverses of 2×3 affine maps (..., 2, 3), in closed form (the 2×2 part by its adjugate over
    its determinant, the shift by −M⁻¹·t)."""
    a = np.asarray(a, dtype=np.float64)
    a00, a01, a02 = a[..., 0, 0], a[..., 0, 1], a[..., 0, 2]
    a10, a11, a12 = a[..., 1, 0], a[..., 1, 1], a[..., 1, 2]
    det = a00 * a11 - a01 * a10
    out = np.empty(a.shape)
    m00, m01, m10, m11 = a11 / det, -a01 / det, -a10 / det, a00 / det
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = m00, m01, -(m00 * a02 + m01 * a12)
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = m10, m11, -(m10 * a02 + m11 * a12)
    return out
