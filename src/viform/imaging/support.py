"""Is a spike stream dense enough for an estimate? One check shared by everything that estimates from spikes.

A spike camera's pixel reports its light only when it fires. An estimate made over a window
of W ticks (an image, a flow field, a tracker's background level) needs some number n of
spikes from a pixel inside that window — one interval (2 spikes) for interval imaging, K a
side for multi-interval imaging, a few for an accumulation image to be more than noise. A
pixel firing r spikes per tick gets r·W of them on average; where most pixels get fewer than
n, the estimate is made of what the window happens to hold — zeros, or the same value
everywhere — and looks confident while it is not.

:func:`spike_support` measures each pixel's firing over a span of the stream and reports the
share of pixels whose expected count over the window reaches the need, and the typical
(median) pixel's count; :meth:`SpikeSupport.warning` turns a shortfall into one line with the
figures. :func:`imaging_need` says what each imaging method of :mod:`viform.imaging` needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_int, check_positive

#: Below this share of pixels getting the spikes an estimate needs, the stream is too sparse for it.
MIN_SHARE = 0.5
#: Ticks counted at most (centred on the span asked for) to measure the firing.
MAX_SAMPLE_TICKS = 4096


@dataclass(frozen=True)
class SpikeSupport:
    """How well a stream's spikes support an estimate over a window.

    Attributes
    ----------
    firing_per_pixel_tick : float
        Mean spikes per pixel per tick over the span measured.
    typical_spikes : float
        The median pixel's expected spikes over the window.
    spikes_needed : float
        Spikes a pixel needs within the window for the estimate.
    window_ticks : int
        The estimate's window, ticks.
    share_enough : float
        Share of pixels expected to get ``spikes_needed`` within the window.
    sampled_ticks : int
        Ticks the firing was measured over.
    """

    firing_per_pixel_tick: float
    typical_spikes: float
    spikes_needed: float
    window_ticks: int
    share_enough: float
    sampled_ticks: int

    @property
    def enough(self) -> bool:
        """True when at least :data:`MIN_SHARE` of the pixels get the spikes needed."""
        return self.share_enough >= MIN_SHARE

    def warning(self, estimate: str, remedy: str) -> str | None:
        """One line saying the stream is too sparse for ``estimate`` and what would help (``remedy``); None if not."""
        if self.enough:
            return None
        return (f"warning: the stream is too sparse for {estimate}: it fires {self.firing_per_pixel_tick:.2g} spikes "
                f"per pixel-tick, so a typical pixel gets {self.typical_spikes:.2g} spikes in the {self.window_ticks}-"
                f"tick window where {self.spikes_needed:g} are needed ({100 * self.share_enough:.0f} % of pixels get "
                f"them); {remedy}")

    def as_dict(self) -> dict:
        return {"firing_per_pixel_tick": self.firing_per_pixel_tick, "typical_spikes": self.typical_spikes,
                "spikes_needed": self.spikes_needed, "window_ticks": self.window_ticks,
                "share_enough": self.share_enough, "sampled_ticks": self.sampled_ticks, "enough": self.enough}


def support_from_rates(rate_per_tick, window_ticks: int, spikes_needed: float, sampled_ticks: int = 0) -> SpikeSupport:
    """:class:`SpikeSupport` from each pixel's firing rate (spikes per tick, any shape)."""
    window_ticks = check_int("window_ticks", window_ticks, 1)
    spikes_needed = check_positive("spikes_needed", spikes_needed)
    rate = np.asarray(rate_per_tick, dtype=np.float64).ravel()
    if rate.size == 0:
        raise ViformError("rate_per_tick is empty: a stream with no pixels supports no estimate")
    expected = rate * window_ticks
    return SpikeSupport(float(rate.mean()), float(np.median(expected)), spikes_needed, window_ticks,
                        float(np.mean(expected >= spikes_needed)), int(sampled_ticks))


def spike_support(source, window_ticks: int, spikes_needed: float, start_tick: int = 0,
                  stop_tick: int | None = None) -> SpikeSupport:
    """Measure the firing of ``source`` over ticks [start_tick, stop_tick) (at most
    :data:`MAX_SAMPLE_TICKS` of them, centred) and judge it against an estimate's need.

    Parameters
    ----------
    source : SpikeSource
    window_ticks : int
        The estimate's window, ticks.
    spikes_needed : float
        Spikes a pixel needs within the window.
    start_tick, stop_tick : int
        The part of the stream the estimate uses (default: all of it).
    """
    stop = source.n_ticks if stop_tick is None else min(int(stop_tick), source.n_ticks)
    start = max(0, int(start_tick))
    if stop <= start:
        raise ViformError(f"start_tick = {start_tick!r} … stop_tick = {stop_tick!r} holds no tick of the stream "
                          f"[0, {source.n_ticks})")
    if stop - start > MAX_SAMPLE_TICKS:
        middle = (start + stop) // 2
        start, stop = middle - MAX_SAMPLE_TICKS // 2, middle + MAX_SAMPLE_TICKS // 2
    counts = np.zeros(source.height * source.width, np.int64)
    for _, block in source.iter_blocks(1024, start, stop):
        counts += block.reshape(block.shape[0], -1).sum(axis=0, dtype=np.int64)
    return support_from_rates(counts / (stop - start), window_ticks, spikes_needed, stop - start)


def imaging_need(method: str, n_ticks: int, window_ticks: int = 41, spikes_per_side: int = 4) -> tuple[int, float]:
    """(window ticks, spikes needed) of an image by ``method`` of :func:`viform.imaging.reconstruct_ticks`.

    Accumulation: 4 spikes in its window (a count of n has relative noise 1/√n: ±50 %);
    interval: one spike on each side of the instant anywhere in the stream; multi-interval and
    motion (which falls back to multi-interval): K on each side, anywhere in the stream.
    """
    n_ticks = check_int("n_ticks", n_ticks, 1)
    if method == "accumulation":
        return check_int("window_ticks", window_ticks, 1), 4.0
    if method == "interval":
        return n_ticks, 2.0
    if method in ("multi-interval", "motion", "best"):
        return n_ticks, 2.0 * check_int("spikes_per_side", spikes_per_side, 1)
    raise ViformError(f"method = {method!r} is not allowed: choose accumulation, interval, multi-interval or motion")
