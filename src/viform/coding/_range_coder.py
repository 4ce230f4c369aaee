"""The binary range coder every range-coded ``.vfc`` model shares (LZMA-style carry handling, byte output).

A model gives each binary decision its probability; this module only turns decisions into bytes
and back. The coder state is a tuple of int64 that the caller threads through (``rc =
encode_bit(rc, out, p, shift, bit)``; ``bit, rc = decode_bit(rc, data, p, shift)``): every
function is inlined by numba, so the state lives in registers inside a model's coding loop.

* encoder state ``(low, range, cache, cache_size, pos)``: ``low`` may carry into bit 32, ``cache`` is
  the byte held back for a carry, ``pos`` the next output byte (bytes past ``out.size`` are counted,
  not written: the caller retries with a bigger buffer);
* decoder state ``(range, code, pos, error)``: reading past the data gives zero bytes (``pos`` tells
  the caller), an impossible value sets ``error``.

``P(bit = 0) = p / 2**shift`` with ``1 ≤ p < 2**shift`` and ``shift ≤ 16`` (the range keeps ≥ 24 bits).
"""

from __future__ import annotations

import numpy as np
from numba import njit

TOP = np.int64(1) << 24
MASK32 = (np.int64(1) << 32) - 1
#: uniform values are coded in digits of this many bits (the range keeps ≥ 24 bits)
_DIGIT = 12
_DIGIT_N = 1 << _DIGIT


@njit(cache=True, inline="always")
def encoder_start():
    """A fresh encoder state."""
    return (np.int64(0), MASK32, np.int64(0), np.int64(1), np.int64(0))


@njit(cache=True, inline="always")
def _encode(rc, out, add, rng):
    """Add ``add`` to ``low``, set the range to ``rng`` and shift out whole bytes (LZMA carry rule).

    The only function with loops: numba inlines it once into each caller (its callers have none, so
    the coding loops stay in registers).
    """
    low, _, cache, csize, pos = rc
    low += add
    while rng < TOP:
        rng <<= 8
        if low < 0xFF000000 or low > MASK32:
            carry = low >> 32
            temp = cache
            while True:
                if pos < out.size:
                    out[pos] = (temp + carry) & 0xFF
                pos += 1
                temp = np.int64(0xFF)
                csize -= 1
                if csize == 0:
                    break
            cache = (low >> 24) & 0xFF
        csize += 1
        low = (low & 0x00FFFFFF) << 8
    return (low, rng, cache, csize, pos)


@njit(cache=True, inline="always")
def encode_bit(rc, out, p, shift, bit):
    """Code ``bit`` with ``P(bit = 0) = p / 2**shift``."""
    bound = (rc[1] >> shift) * p
    add = np.int64(0)
    rng = bound
    if bit != 0:
        add = bound
        rng = rc[1] - bound
    return _encode(rc, out, add, rng)


@njit(cache=True, inline="always")
def encode_plain(rc, out, bit):
    """Code ``bit`` with probability ½ (no model)."""
    half = rc[1] >> 1
    return _encode(rc, out, half if bit else np.int64(0), half)


@njit(cache=True, inline="always")
def _encode_digit(rc, out, v, n):
    r = rc[1] // n
    return _encode(rc, out, v * r, r)


@njit(cache=True)
def encode_uniform(rc, out, v, n):
    """Code ``v`` uniform in ``[0, n)`` (``n < 2**48``): 12-bit digits, most significant first.

    A digit below the top one holds 4,096 values, except under the top value of the digit above
    it, where it holds what is left of ``n``.
    """
    levels = 0
    m = n
    while m > _DIGIT_N:
        m = ((m - 1) >> _DIGIT) + 1
        levels += 1
    if m > 1:
        rc = _encode_digit(rc, out, v >> (_DIGIT * levels), m)
    for j in range(levels - 1, -1, -1):
        nj = n
        for _ in range(j):
            nj = ((nj - 1) >> _DIGIT) + 1
        top = (((nj - 1) >> _DIGIT) + 1) - 1
        lo_n = ((nj - 1) & (_DIGIT_N - 1)) + 1 if (v >> (_DIGIT * (j + 1))) == top else _DIGIT_N
        rc = _encode_digit(rc, out, (v >> (_DIGIT * j)) & (_DIGIT_N - 1), lo_n)
    return rc


@njit(cache=True)
def encoder_flush(rc, out):
    """Push the last bytes out; returns the byte count (more than ``out.size``: retry bigger)."""
    for _ in range(5):  # five bytes out: the range is set to 1 so that each round shifts one
        rc = _encode((rc[0], rc[1], rc[2], rc[3], rc[4]), out, np.int64(0), np.int64(1) << 16)
    return rc[4]


@njit(cache=True, inline="always")
def _read(data, pos):
    return np.int64(data[pos]) if pos < data.size else np.int64(0)


@njit(cache=True)
def decoder_start(data):
    """A decoder state at the start of ``data`` (the encoder's first byte is always 0)."""
    code = np.int64(0)
    for pos in range(5):
        code = ((code << 8) | _read(data, pos)) & MASK32
    return (MASK32, code, np.int64(5), np.int64(0))


@njit(cache=True, inline="always")
def _decode(rc, data, sub, rng):
    """Take ``sub`` from the code, set the range to ``rng`` and read whole bytes (zeros past the data)."""
    _, code, pos, err = rc
    code -= sub
    while rng < TOP:
        rng <<= 8
        code = ((code << 8) | (np.int64(data[pos]) if pos < data.size else np.int64(0))) & MASK32
        pos += 1
    return (rng, code, pos, err)


@njit(cache=True, inline="always")
def decode_bit(rc, data, p, shift):
    """Inverse of :func:`encode_bit`: ``(bit, state)``."""
    bound = (rc[0] >> shift) * p
    bit = np.int64(0)
    sub = np.int64(0)
    rng = bound
    if rc[1] >= bound:
        bit = np.int64(1)
        sub = bound
        rng = rc[0] - bound
    return bit, _decode(rc, data, sub, rng)


@njit(cache=True, inline="always")
def decode_plain(rc, data):
    """Inverse of :func:`encode_plain`: ``(bit, state)``."""
    half = rc[0] >> 1
    bit = np.int64(1) if rc[1] >= half else np.int64(0)
    return bit, _decode(rc, data, half if bit else np.int64(0), half)


@njit(cache=True, inline="always")
def _decode_digit(rc, data, n):
    r = rc[0] // n
    v = rc[1] // r
    err = rc[3]
    if v >= n:  # impossible in a valid stream
        v = n - 1
        err = np.int64(1)
    return v, _decode((rc[0], rc[1], rc[2], err), data, v * r, r)


@njit(cache=True)
def decode_uniform(rc, data, n):
    """Inverse of :func:`encode_uniform`: ``(v, state)``."""
    levels = 0
    m = n
    while m > _DIGIT_N:
        m = ((m - 1) >> _DIGIT) + 1
        levels += 1
    v = np.int64(0)
    if m > 1:
        v, rc = _decode_digit(rc, data, m)
    for j in range(levels - 1, -1, -1):
        nj = n
        for _ in range(j):
            nj = ((nj - 1) >> _DIGIT) + 1
        top = (((nj - 1) >> _DIGIT) + 1) - 1
        lo_n = ((nj - 1) & (_DIGIT_N - 1)) + 1 if v == top else _DIGIT_N
        d, rc = _decode_digit(rc, data, lo_n)
        v = (v << _DIGIT) | d
    return v, rc
