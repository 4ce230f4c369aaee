"""Exact, counter-based Gamma(a, 1) sampling for the spike sensor's hot loop.

Why counter-based: the k-th spike interval of pixel p must be the same random number
whatever the time-block size or the number of threads, so each draw is a pure function of
(seed, pixel, k) — a SplitMix64 hash, no sequential generator state.

Why tables: Marsaglia–Tsang needs a normal deviate and a log per draw, too slow at 1e8
draws/s. Instead the Gamma(a) law is cut into M equiprobable bins by its exact quantiles
(``scipy.special.gammaincinv``); a draw picks a bin uniformly (probability exactly 1/M)
and samples inside it by rejection under the bin's maximum density, with a precomputed
squeeze that accepts almost every draw without evaluating the density. The open last
bin [q, ∞) is sampled exactly by rejection from an exponential envelope of rate
1 − (a − 1)/q. Each step is an exact rejection sampler, so the draws follow Gamma(a, 1)
up to the resolution of the uniforms: 26 bits each, i.e. a position within a bin to
2^-26 of its width, and an exponential tail cut at 18.7/rate past the last quantile
(probability < 1e-11). Tested by Kolmogorov–Smirnov for a = 1, 2, 7, 100, 1e3, 1e4.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit

#: Bins per table (a power of two: the bin index is the top bits of the hash).
TABLE_BITS = 10
TABLE_SIZE = 1 << TABLE_BITS

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True, inline="always")
def splitmix64(x):
    """SplitMix64 finalizer: a bijective 64-bit mix (Steele, Lea & Flood 2014)."""
    x = (x + np.uint64(0x9E3779B97F4A7C15))
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True, inline="always")
def hash3(seed, a, b):
    """A 64-bit hash of three integers (seed, stream position a, counter b)."""
    h = splitmix64(np.uint64(seed) ^ np.uint64(0x243F6A8885A308D3))
    h = splitmix64(h ^ np.uint64(a))
    return splitmix64(h ^ (np.uint64(b) * np.uint64(0xD1B54A32D192ED03)))


@njit(cache=True, inline="always")
def uniform_from_hash(h):
    """A uniform double in (0, 1) from the top 53 bits of a hash."""
    return (np.int64(h >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)


def build_tables(shapes) -> tuple[np.ndarray]:
    """Quantile tables for Gamma(a, 1) for each shape in ``shapes`` (each ≥ 1).

    Returns a one-element tuple holding an (n, M, 4) array: per bin its lower quantile
    (edge), its width, the log of the maximum of x^(a−1)·e^(−x) over the bin, and the
    squeeze — the min/max density ratio over the bin, below which a draw is accepted
    without evaluating the density. The four values of a bin share a cache line.

    The tables of up to :data:`TABLE_CACHE_MAX_SHAPES` shapes are kept on disk beside the
    compiled kernels (:func:`table_cache_folder`), keyed by the shapes, the table size and the
    SciPy build that computed them, so that a new process loads them instead of importing
    ``scipy.special``; the loaded values are the computed ones, bit for bit.
    """
    shapes = np.asarray(shapes, dtype=np.float64).ravel()
    key = _cache_key(shapes) if shapes.size <= TABLE_CACHE_MAX_SHAPES else None
    if key is not None and key in _TABLES:
        return (_TABLES[key],)
    tables = _load_tables(key, shapes.size) if key is not None else None
    if tables is None:
        tables = np.empty((shapes.size, TABLE_SIZE, 4))
        for i, a in enumerate(shapes):
            tables[i] = _table(a)
        tables = np.ascontiguousarray(tables)
        if key is not None:
            _save_tables(key, tables)
    if key is not None:
        _TABLES[key] = tables  # shared by the sensors of this process: read, never written
    return (tables,)


#: Tables of at most this many shapes (one threshold, or a few levels) are cached on disk
#: (a fixed-pattern threshold spread has thousands: those are computed each time).
TABLE_CACHE_MAX_SHAPES = 64
_TABLES: dict = {}
_TABLE_FORMAT = 1


def table_cache_folder() -> Path:
    """Where the tables are kept: numba's cache folder when ``NUMBA_CACHE_DIR`` is set, else this
    module's ``__pycache__`` (where numba keeps the kernels' machine code)."""
    from numba.core import config

    if config.CACHE_DIR:
        return Path(config.CACHE_DIR) / "viform-gamma-tables"
    return Path(__file__).resolve().parent / "__pycache__" / "viform-gamma-tables"


def _scipy_build() -> str:
    """SciPy's version record (the text of ``scipy/version.py``: version and git revision), read
    without importing SciPy; '' when it cannot be read."""
    import importlib.util

    try:
        spec = importlib.util.find_spec("scipy")
        return (Path(spec.origin).parent / "version.py").read_text()
    except (ImportError, AttributeError, OSError, TypeError, ValueError):
        return ""


def _cache_key(shapes: np.ndarray) -> str:
    import hashlib

    digest = hashlib.sha256(f"{_TABLE_FORMAT} {TABLE_BITS} {_scipy_build()}".encode())
    digest.update(shapes.astype("<f8").tobytes())
    return digest.hexdigest()[:32]


def _load_tables(key: str, n: int):
    """The cached tables of ``key``, or None (absent, unreadable or not of the expected form)."""
    try:
        tables = np.load(table_cache_folder() / f"{key}.npy", allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    if tables.dtype != np.float64 or tables.shape != (n, TABLE_SIZE, 4):
        return None
    return np.ascontiguousarray(tables)


def _save_tables(key: str, tables: np.ndarray) -> None:
    """Keep ``tables`` on disk, written atomically; a folder that cannot be written is skipped."""
    from viform._io import atomic_open
    from viform._validate import ViformError

    try:
        with atomic_open(table_cache_folder() / f"{key}.npy", output=False) as f:  # (a cache, not an output)
            np.save(f, tables, allow_pickle=False)
    except (OSError, ViformError):
        pass


def _table(a: np.float64) -> np.ndarray:
    """The (M, 4) table of Gamma(a, 1) (see :func:`build_tables`). scipy.special is imported here,
    where it is used: commands that draw no photon noise do without it."""
    from scipy import special

    probabilities = np.arange(TABLE_SIZE + 1) / TABLE_SIZE
    q = special.gammaincinv(a, probabilities)
    q[0], q[-1] = 0.0, np.inf
    lo, hi = q[:-1], q[1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        log_f_lo = np.where(lo > 0, (a - 1) * np.log(np.where(lo > 0, lo, 1.0)) - lo,
                            0.0 if a == 1 else -np.inf)
        log_f_hi = (a - 1) * np.log(hi) - hi
    mode = a - 1.0
    log_f_mode = (a - 1) * np.log(mode) - mode if mode > 0 else 0.0
    peak = np.maximum(log_f_lo, log_f_hi)
    inside = (lo <= mode) & (mode <= hi)
    peak = np.where(inside, log_f_mode, peak)
    low = np.minimum(log_f_lo, log_f_hi)
    widths = hi - lo
    squeeze = np.exp(low - peak)
    # the open last bin is sampled from its exponential envelope instead
    widths[-1] = 0.0
    squeeze[-1] = 0.0
    return np.stack([lo, widths, peak, squeeze], axis=-1)


def stream_keys(seed: int, n: int) -> np.ndarray:
    """Per-pixel SplitMix64 stream keys: pixel p's k-th draw hashes ``key[p] + k·γ``."""
    return _stream_keys(np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF), n)


@njit(cache=True)
def _stream_keys(seed, n):
    keys = np.empty(n, dtype=np.uint64)
    for p in range(n):
        keys[p] = hash3(seed, p, 0x5CA1AB1E)
    return keys


@njit(cache=True, inline="always")
def gamma_draw(shape, table, bins, key, counter):
    """One Gamma(shape, 1) variate, a pure function of the pixel's stream ``key`` and ``counter``.

    The k-th output of a SplitMix64 stream whose state starts at ``key``.
    """
    base = splitmix64(key + np.uint64(counter) * np.uint64(0x9E3779B97F4A7C15))
    # the bin is chosen once (probability exactly 1/M); rejection retries inside it
    b = np.int64(base >> np.uint64(64 - TABLE_BITS))
    h = base
    attempt = np.uint64(0)
    while True:
        if attempt > 0:
            h = splitmix64(base ^ (attempt * np.uint64(0xA0761D6478BD642F)))
        attempt += np.uint64(1)
        # two 26-bit uniforms from the bits below the bin index
        # (through int64: unsigned-to-float conversion is slow on x86)
        u1 = (np.int64((h >> np.uint64(26)) & np.uint64(0x3FFFFFF)) + 0.5) * (1.0 / 67108864.0)
        u2 = (np.int64(h & np.uint64(0x3FFFFFF)) + 0.5) * (1.0 / 67108864.0)
        if b < TABLE_SIZE - 1:
            x = bins[table, b, 0] + u1 * bins[table, b, 1]
            if u2 < bins[table, b, 3]:
                return x
            if x > 0.0 and np.log(u2) < (shape - 1.0) * np.log(x) - x - bins[table, b, 2]:
                return x
        else:
            q = bins[table, b, 0]
            rate = 1.0 - (shape - 1.0) / q
            x = q - np.log(u1) / rate
            if np.log(u2) <= (shape - 1.0) * (np.log(x / q) - (x - q) / q):
                return x


def gamma_samples(shape: float, n: int, key: int = 0) -> np.ndarray:
    """``n`` draws of Gamma(shape, 1) from the stream ``key`` (the sampler the simulator uses)."""
    (bins,) = build_tables([shape])
    return _draw_many(float(shape), bins, np.uint64(key), int(n))


@njit(cache=True)
def _draw_many(shape, bins, key, n):
    out = np.empty(n)
    for i in range(n):
        out[i] = gamma_draw(shape, 0, bins, key, i)
    return out


# ----------------------------------------------------------- general samplers on a hash stream
# For the rare events that need other laws (a saturated tick's end state in
# :mod:`viform.sensors.spike`), draws come from a short SplitMix64 stream started at
# ``event_stream(key, counter)``: still a pure function of (seed, pixel, event index).
_STREAM_DOMAIN = np.uint64(0xD6E8FEB86659FD93)


@njit(cache=True, inline="always")
def event_stream(key, counter):
    """Start of the random stream of one event of a pixel (its key and event counter)."""
    return splitmix64(key ^ _STREAM_DOMAIN ^ (np.uint64(counter) * np.uint64(0x9E3779B97F4A7C15)))


@njit(cache=True, inline="always")
def stream_uniform(state):
    """(u in (0, 1), next state) from a SplitMix64 stream."""
    state = state + np.uint64(0xBF58476D1CE4E5B9)
    return uniform_from_hash(splitmix64(state)), state


@njit(cache=True)
def stream_normal(state):
    """(standard normal deviate, next state) by the Box–Muller transform (exact)."""
    u1, state = stream_uniform(state)
    u2, state = stream_uniform(state)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2), state


@njit(cache=True)
def stream_gamma(shape, state):
    """(Gamma(shape, 1) deviate, next state), shape ≥ 1, by Marsaglia & Tsang (2000) — exact rejection."""
    d = shape - 1.0 / 3.0
    c = 1.0 / np.sqrt(9.0 * d)
    while True:
        x, state = stream_normal(state)
        v = 1.0 + c * x
        if v <= 0.0:
            continue
        v = v * v * v
        u, state = stream_uniform(state)
        if u < 1.0 - 0.0331 * x * x * x * x:
            return d * v, state
        if np.log(u) < 0.5 * x * x + d * (1.0 - v + np.log(v)):
            return d * v, state


@njit(cache=True)
def stream_poisson(mean, state):
    """(Poisson(mean) deviate, next state): multiplication below mean 10, else Hörmann's PTRS (1993).

    Both are exact (PTRS is a transformed rejection with the exact acceptance test).
    """
    if mean < 10.0:
        limit = np.exp(-mean)
        n = np.int64(0)
        product, state = stream_uniform(state)
        while product > limit:
            n += 1
            u, state = stream_uniform(state)
            product *= u
        return n, state
    slam = np.sqrt(mean)
    loglam = np.log(mean)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    vr = 0.9277 - 3.6224 / (b - 2.0)
    while True:
        u, state = stream_uniform(state)
        u -= 0.5
        v, state = stream_uniform(state)
        us = 0.5 - abs(u)
        k = np.floor((2.0 * a / us + b) * u + mean + 0.43)
        if us >= 0.07 and v <= vr:
            return np.int64(k), state
        if k < 0.0 or (us < 0.013 and v > us):
            continue
        if np.log(v) + np.log(invalpha) - np.log(a / (us * us) + b) <= -mean + k * loglam - math.lgamma(k + 1.0):
            return np.int64(k), state


def stream_samples(kind: str, parameter: float, n: int, key: int = 0) -> np.ndarray:
    """``n`` draws of 'normal', 'gamma' (shape) or 'poisson' (mean), one event each (for tests)."""
    code = {"normal": 0, "gamma": 1, "poisson": 2}[kind]
    return _stream_many(code, float(parameter), np.uint64(key), int(n))


@njit(cache=True)
def _stream_many(code, parameter, key, n):
    out = np.empty(n)
    for i in range(n):
        state = event_stream(key, i)
        if code == 0:
            out[i], state = stream_normal(state)
        elif code == 1:
            out[i], state = stream_gamma(parameter, state)
        else:
            value, state = stream_poisson(parameter, state)
            out[i] = value
    return out
