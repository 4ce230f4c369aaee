"""Reconstructed light in physical units: spikes/s → electrons/s → lux.

A spike is Q electrons, so far below saturation a firing rate r (spikes/s) is a
photo-current of r·Q e⁻/s (seed 000 §3.3.2: light = Q/τ). Near one spike per tick the
one-bit readout hides crossings, so the light is taken from the exact rate law of the tick
readout instead (:mod:`viform.imaging.rate_law`: carried-over charge, reset mode, dead
time); where the rate reaches the law's ceiling the pixel is flagged ``saturated`` and its
light is a lower bound. Subtracting the dark current and dividing by the pixel's electrons
per lux·second (optics) gives the illuminance. Q, the reset, the dead time and the optics
come from the stream's metadata when a viform simulated the stream, or from the sensor
parameters given.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from viform.light.radiometry import PixelOptics
from viform.stream.container import SpikeSource


@dataclass
class LightImage:
    """Light reconstructed at an instant.

    Attributes
    ----------
    spikes_per_s : ndarray (H, W)
        Firing rate estimate.
    electrons_per_s : ndarray or None
        Photo-current (signal + dark), e⁻/s; None when Q is unknown.
    lux : ndarray or None
        Illuminance estimate (dark current removed, clipped at 0); None without optics.
    censored : ndarray of bool or None
        Interval imaging: pixels whose interval was cut by an end of the stream.
    info : dict
        Method and window.
    saturated : ndarray of bool or None
        Pixels whose firing rate reached the readout's ceiling (one spike every tick it
        can give): their e⁻/s and lux are lower bounds (accumulation) or the interval
        estimator's value for that outcome. None when Q is unknown.
    unresolved : ndarray of bool or None
        Interval-based light (interval, multi-interval, motion): pixels whose light lies at the
        rate law's flat end, where no function of their K spikes a side is unbiased to 0.3 %
        (:func:`~viform.imaging.rate_law.unbiased_electrons_per_tick`; ``info["rate_law"]``
        gives the bias left there). None where not computed.
    """

    spikes_per_s: np.ndarray
    electrons_per_s: np.ndarray | None = None
    lux: np.ndarray | None = None
    censored: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    saturated: np.ndarray | None = None
    unresolved: np.ndarray | None = None


def sensor_parameters_of(source: SpikeSource, sensor_parameters=None):
    """The spike-sensor parameters for ``source``: given, or rebuilt from its metadata."""
    if sensor_parameters is not None:
        return sensor_parameters
    meta = source.metadata.get("sensor") if isinstance(source.metadata, dict) else None
    if not meta or meta.get("model") != "spike":
        return None
    from viform.sensors.spike import SpikeSensorParameters

    optics = meta.get("optics") or {}
    return SpikeSensorParameters(
        optics=PixelOptics(**optics) if optics else PixelOptics(),
        threshold_electrons=meta.get("threshold_electrons", source.threshold_electrons or 100.0),
        clock_hz=meta.get("clock_hz", source.clock_hz),
        dark_current_e_per_s=meta.get("dark_current_e_per_s", 0.0),
        reset=meta.get("reset", "self"),
        photon_noise=meta.get("photon_noise", True),
        dead_time_s=meta.get("dead_time_s", 0.0))


def light_from_rate(spikes_per_s, source: SpikeSource, sensor_parameters=None, censored=None,
                    *, spikes_per_side=None, window_ticks=None, **info) -> LightImage:
    """Wrap a firing-rate image with its e⁻/s and lux equivalents where they are known.

    The e⁻/s invert the tick readout's rate law for the sensor's Q, reset and dead time
    (self-reset, no dead time when only Q is known). A noisy rate through the law's convex
    inverse reads high, so (:mod:`~viform.imaging.rate_law`):

    * ``spikes_per_side`` (K, one value or per pixel; K = 1 for interval imaging): the rate
      is an interval estimate from K spikes a side and the light is the unbiased estimator
      of :func:`~viform.imaging.rate_law.unbiased_electrons_per_tick`; ``unresolved`` marks
      pixels at the law's flat end, where it cannot be;
    * ``window_ticks`` (n, one value or per pixel): the rate is a count over n ticks and the
      light is corrected to second order (:func:`~viform.imaging.rate_law.accumulation_electrons_per_tick`);
    * neither: the plain inverse.

    ``saturated`` marks pixels at the law's ceiling.
    """
    from viform.imaging import rate_law

    params = sensor_parameters_of(source, sensor_parameters)
    q = params.threshold_electrons if params is not None else source.threshold_electrons
    rate = np.asarray(spikes_per_s, dtype=np.float64)
    electrons = saturated = lux = unresolved = None
    if q is not None:
        clock = float(params.clock_hz if params is not None else source.clock_hz)
        dead_ticks = float(getattr(params, "dead_time_s", 0.0)) * clock
        reset = getattr(params, "reset", "self")
        noise = bool(getattr(params, "photon_noise", True))
        if spikes_per_side is not None:
            per_tick, saturated, unresolved = rate_law.unbiased_electrons_per_tick(
                rate / clock, float(q), dead_ticks, reset, noise, spikes_per_side)
            estimator = "interval: unbiased for K spikes a side"
        elif window_ticks is not None:
            per_tick, saturated = rate_law.accumulation_electrons_per_tick(rate / clock, window_ticks, float(q),
                                                                           dead_ticks, reset, noise)
            estimator = "count over a window: second-order correction"
        else:
            per_tick, saturated = rate_law.electrons_per_tick_from_rate(rate / clock, float(q), dead_ticks, reset,
                                                                         noise)
            estimator = "plain inverse"
        electrons = per_tick * clock
        info["rate_law"] = {"threshold_electrons": float(q), "reset": reset, "dead_time_ticks": dead_ticks,
                            "photon_noise": noise, "saturated_pixels": int(np.count_nonzero(saturated)),
                            "estimator": estimator}
        if unresolved is not None:
            info["rate_law"]["unresolved_pixels"] = int(np.count_nonzero(unresolved))
            if noise:
                k = int(np.max(spikes_per_side))
                est = rate_law.light_estimator(float(q), dead_ticks, reset, k)
                info["rate_law"]["unresolved_from_electrons_per_s"] = est.unresolved_from_electrons_per_tick * clock
    if params is not None and electrons is not None:
        lux = params.optics.lux_from_electrons_per_s(np.maximum(electrons - params.dark_current_e_per_s, 0.0))
    for name, value in (("spikes_per_side", spikes_per_side), ("window_ticks", window_ticks)):
        if value is not None and np.ndim(value) == 0:
            info[name] = int(value)
    return LightImage(rate, electrons, lux, censored, dict(info), saturated, unresolved)
