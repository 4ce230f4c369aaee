"""The viform: an array of spike trains with its metadata (seed 000 §3.3).

Time convention used everywhere in viform: tick ``k`` (0-based) covers the interval
[start + k/f, start + (k+1)/f) of the stream, f = ``clock_hz``; its bit is 1 when the pixel
fired during that interval (read out at its end, at most one spike per pixel per tick). An
instant t falls in tick ``floor((t − start)·f)``.

:class:`SpikeSource` is the read interface shared by in-memory streams, memory-mapped
``.dat`` files and chunked zarr stores: everything downstream (imaging, coding, info)
reads through ``read_ticks`` / ``iter_blocks`` and so works on streams longer than memory.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterator

import numpy as np

from viform._validate import ViformError, check_int, check_positive, size_text

#: Bytes of unpacked spikes (one byte per pixel-tick) a reader hands out per block: blocks are
#: sized by this budget, not by a tick count, so memory stays bounded at any resolution.
BLOCK_BUDGET_BYTES = 32 << 20


def block_ticks_for(height: int, width: int, block_ticks: int | None = None,
                    budget_bytes: int = BLOCK_BUDGET_BYTES) -> int:
    """Ticks per block: ``block_ticks`` (if given) capped so a (T, H, W) bool block fits ``budget_bytes``."""
    cap = max(1, int(budget_bytes) // max(1, int(height) * int(width)))
    return cap if block_ticks is None else max(1, min(int(block_ticks), cap))


def spike_bytes(spikes: np.ndarray) -> np.ndarray:
    """``spikes`` (a ``read_ticks`` result, any shape) as one uint8 per pixel-tick, nonzero where a pixel fired.

    A bool (or other one-byte) array is viewed, not copied; a wider one — a source that hands out
    0/1 as integers or floats instead of bool — is compared with 0, so that compiled readers of
    the bytes never read past a row.
    """
    a = np.asarray(spikes)
    if a.dtype.itemsize != 1:
        a = a != 0
    return a.view(np.uint8)


#: dtype of the events view (the neuromorphic x, y, t, p convention; t in microseconds).
EVENT_DTYPE = np.dtype([("x", np.int16), ("y", np.int16), ("t", np.int64), ("p", np.int8)])


class SpikeSource(ABC):
    """Read interface of a viform. Subclasses set the attributes and implement ``read_ticks``.

    Attributes
    ----------
    height, width : int
        Resolution.
    n_ticks : int
        Number of readout ticks.
    clock_hz : float
        Readout clock, Hz.
    threshold_electrons : float or None
        Accumulation threshold Q, e⁻ (None when unknown, e.g. a recorded file).
    start_time_s : float
        Time of the start of tick 0, seconds.
    metadata : dict
        Sensor parameters and provenance.
    """

    height: int
    width: int
    n_ticks: int
    clock_hz: float
    threshold_electrons: float | None
    start_time_s: float
    metadata: dict

    @abstractmethod
    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        """Spikes of ticks [start, stop) as a bool array (stop − start, H, W)."""

    def _say_unverified(self, why: str) -> None:
        """Warn once per source (:class:`~viform._validate.UnverifiedDataWarning`) that its data is
        read without checksums viform can verify; ``why`` names the file and the reason."""
        if getattr(self, "_unverified_said", False):
            return
        self._unverified_said = True
        import warnings

        from viform._validate import UnverifiedDataWarning

        warnings.warn(UnverifiedDataWarning(f"{why}: its data is read unverified"), stacklevel=3)

    # ---- derived, shared by every source
    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.n_ticks, self.height, self.width)

    @property
    def duration_s(self) -> float:
        return self.n_ticks / self.clock_hz

    @property
    def tick_s(self) -> float:
        return 1.0 / self.clock_hz

    def tick_of(self, t_s: float, name: str = "t") -> int:
        """Tick index holding instant ``t_s``; refuses instants outside the stream."""
        if not (isinstance(t_s, (int, float, np.floating, np.integer)) and math.isfinite(t_s)):
            raise ViformError(f"{name} = {t_s!r} must be a finite time in seconds")
        end = self.start_time_s + self.duration_s
        if not self.start_time_s <= t_s < end + 1e-12 * max(1.0, abs(end)):
            raise ViformError(f"{name} = {t_s!r} s is outside the stream, which covers "
                              f"[{self.start_time_s:g}, {end:g}) s")
        k = int(math.floor((t_s - self.start_time_s) * self.clock_hz + 1e-9))
        return min(k, self.n_ticks - 1)

    def iter_blocks(self, block_ticks: int = 1024, start: int = 0,
                    stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(first_tick, spikes)`` blocks of at most ``block_ticks`` ticks.

        Blocks are also capped at :data:`BLOCK_BUDGET_BYTES` (so memory stays bounded at any
        resolution); callers use the ``first_tick`` given, never assume a block length.
        """
        block_ticks = block_ticks_for(self.height, self.width, check_int("block_ticks", block_ticks, 1))
        stop = self.n_ticks if stop is None else stop
        for first in range(start, stop, block_ticks):
            yield first, self.read_ticks(first, min(first + block_ticks, stop))

    def to_memory(self) -> SpikeStream:
        """Load all ticks into a :class:`SpikeStream`."""
        return SpikeStream(self.read_ticks(0, self.n_ticks), self.clock_hz, self.threshold_electrons,
                           self.start_time_s, dict(self.metadata))

    def spike_count(self, block_ticks: int = 4096) -> int:
        return int(sum(int(np.count_nonzero(b)) for _, b in self.iter_blocks(block_ticks)))

    def summary(self) -> dict:
        """Resolution, duration, ticks, spike count, firing rate and data rate (for ``viform info``)."""
        spikes = self.spike_count()
        pixel_ticks = self.n_ticks * self.height * self.width
        return {
            "height": self.height, "width": self.width, "n_ticks": self.n_ticks,
            "clock_hz": self.clock_hz, "duration_s": self.duration_s,
            "start_time_s": self.start_time_s, "threshold_electrons": self.threshold_electrons,
            "spike_count": spikes,
            "spikes_per_s": spikes / self.duration_s,
            "mean_firing_rate_per_tick": spikes / pixel_ticks if pixel_ticks else 0.0,
            "mean_firing_rate_hz": spikes / (self.height * self.width * self.duration_s),
            "raw_data_rate_bit_per_s": self.height * self.width * self.clock_hz,
            "raw_data_rate_mb_per_s": self.height * self.width * self.clock_hz / 8e6,
        }

    def events(self, start: int = 0, stop: int | None = None, block_ticks: int = 4096) -> np.ndarray:
        """Spikes as events: structured array with fields x, y, t (µs, tick end), p (always 1).

        The neuromorphic convention (e.g. tonic): x = column, y = row (0 at the top), t in
        microseconds. A spike in tick k is stamped at the end of the tick, when it is read.
        """
        parts = []
        stop = self.n_ticks if stop is None else stop
        for first, block in self.iter_blocks(block_ticks, start, stop):
            k, y, x = np.nonzero(block)
            ev = np.empty(k.size, EVENT_DTYPE)
            ev["x"], ev["y"] = x, y
            ev["t"] = np.rint((self.start_time_s + (first + k + 1) / self.clock_hz) * 1e6).astype(np.int64)
            ev["p"] = 1
            parts.append(ev)
        return np.concatenate(parts) if parts else np.empty(0, EVENT_DTYPE)

    def slice_time(self, t0_s: float, t1_s: float) -> SpikeStream:
        """The ticks holding instants in [t0_s, t1_s), loaded into memory."""
        k0 = self.tick_of(t0_s, "t0_s")
        if t1_s <= t0_s:
            raise ViformError(f"t1_s = {t1_s!r} must be after t0_s = {t0_s!r}")
        k1 = min(self.n_ticks, int(math.ceil((t1_s - self.start_time_s) * self.clock_hz - 1e-9)))
        return SpikeStream(self.read_ticks(k0, k1), self.clock_hz, self.threshold_electrons,
                           self.start_time_s + k0 / self.clock_hz, dict(self.metadata))


class SpikeStream(SpikeSource):
    """A viform held in memory.

    Parameters
    ----------
    spikes : array_like of bool, shape (T, H, W)
        Spike bits per tick.
    clock_hz : float
        Readout clock, Hz.
    threshold_electrons : float or None
        Threshold Q, e⁻.
    start_time_s : float
        Start of tick 0, seconds.
    metadata : dict
        Sensor parameters and provenance.
    """

    def __init__(self, spikes, clock_hz: float, threshold_electrons: float | None = None,
                 start_time_s: float = 0.0, metadata: dict | None = None):
        spikes = np.asarray(spikes)
        if spikes.ndim != 3:
            raise ViformError(f"spikes must have shape (T, H, W); got {spikes.shape}")
        if spikes.dtype != bool:
            if spikes.size and (spikes.min() < 0 or spikes.max() > 1):
                raise ViformError("spikes must hold only 0 and 1")
            spikes = spikes.astype(bool)
        self.spikes = spikes
        self.n_ticks, self.height, self.width = spikes.shape
        self.clock_hz = check_positive("clock_hz", clock_hz)
        self.threshold_electrons = (None if threshold_electrons is None
                                    else check_positive("threshold_electrons", threshold_electrons))
        if not math.isfinite(start_time_s):
            raise ViformError(f"start_time_s = {start_time_s!r} must be finite")
        self.start_time_s = float(start_time_s)
        self.metadata = dict(metadata or {})

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        return self.spikes[start:stop]

    def spike_count(self, block_ticks: int = 4096) -> int:
        return int(np.count_nonzero(self.spikes))

    def __repr__(self) -> str:
        return (f"SpikeStream({self.n_ticks} ticks × {size_text(self.height, self.width)}, "
                f"clock {self.clock_hz:g} Hz, Q={self.threshold_electrons})")

    def __eq__(self, other) -> bool:
        return (isinstance(other, SpikeSource) and other.shape == self.shape
                and other.clock_hz == self.clock_hz
                and np.array_equal(other.read_ticks(0, other.n_ticks), self.spikes))

    __hash__ = None
