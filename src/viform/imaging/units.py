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
        can give): their e⁻/s and lux are lower bounds. None when Q is unknown.
    """

    spikes_per_s: np.ndarray
    electrons_per_s: np.ndarray | None = None
    lux: np.ndarray | None = None
    censored: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    saturated: np.ndarray | None = None


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
                    **info) -> LightImage:
    """Wrap a firing-rate image with its e⁻/s and lux equivalents where they are known.

    The e⁻/s invert the tick readout's rate law (:func:`~viform.imaging.rate_law.electrons_per_tick_from_rate`)
    for the sensor's Q, reset and dead time (self-reset, no dead time when only Q is
    known); ``saturated`` marks pixels at the law's ceiling, whose light is a lower bound.
    """
    from viform.imaging.rate_law import electrons_per_tick_from_rate

    params = sensor_parameters_of(source, sensor_parameters)
    q = params.threshold_electrons if params is not None else source.threshold_electrons
    rate = np.asarray(spikes_per_s, dtype=np.float64)
    electrons = saturated = lux = None
    if q is not None:
        clock = float(params.clock_hz if params is not None else source.clock_hz)
        dead_ticks = float(getattr(params, "dead_time_s", 0.0)) * clock
        reset = getattr(params, "reset", "self")
        noise = bool(getattr(params, "photon_noise", True))
        per_tick, saturated = electrons_per_tick_from_rate(rate / clock, float(q), dead_ticks, reset, noise)
        electrons = per_tick * clock
        info["rate_law"] = {"threshold_electrons": float(q), "reset": reset, "dead_time_ticks": dead_ticks,
                            "photon_noise": noise, "saturated_pixels": int(np.count_nonzero(saturated))}
    if params is not None and electrons is not None:
        lux = params.optics.lux_from_electrons_per_s(np.maximum(electrons - params.dark_current_e_per_s, 0.0))
    return LightImage(rate, electrons, lux, censored, dict(info), saturated)
