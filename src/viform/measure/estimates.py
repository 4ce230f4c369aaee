"""Each sensor's output turned into light: the illuminance (lux) a capture shows at chosen instants.

One way per family of the sensor catalogue (:data:`ESTIMATORS`, looked up by
:attr:`viform.sensors.catalog.SensorEntry.family`), each inverting the sensor's own noise-free response:

* linear frame cameras: E = ((DN − black)/K − I_dark·T) / (η_lux · T) (EMVA 1288 linear model);
* segmented exposure (seed 001 §3.3, fig. 6) and conditional overflow (seed 003 eqs. 1–6):
  the inverse of the piecewise-linear response, tabulated on a fine lux grid;
* high-speed camera (seed 002): its 8-bit frames with the exposure the AE chose per frame;
* gated CCD (seed 004): its first frame in electrons (laser returns, not light in lux);
* spike camera (seed 000 §3.3): accumulation (count·Q / window) and interval (Q/τ) imaging,
  and the best method the imaging package offers.

The image "at instant t" of a frame camera is the frame whose exposure contains t, or else the
last frame started before t (what a viewer holds on screen). Each :class:`Estimate` marks the
pixels at the sensor's ceiling (saturated) and below its noise floor (under-exposed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import viform.imaging as imaging
from viform.imaging import accumulation_image, interval_image, spike_counts

#: Accumulation window of the spike camera's accumulation image, s.
ACCUMULATION_WINDOW_S = 1e-3


@dataclass
class Estimate:
    """One sensor's light estimate at one instant."""

    lux: np.ndarray
    saturated: np.ndarray
    underexposed: np.ndarray
    source_time_s: tuple  # (start, end) of the light this image integrates
    integration_s: np.ndarray | None = None  # per pixel, s, where each pixel integrates its own time (spike: τ)


def frame_at(starts_s, exposures_s, t_s: float) -> int:
    """Index of the frame shown at ``t_s``: the one exposing at t, else the last started before t."""
    starts = np.asarray(starts_s)
    ends = starts + np.asarray(exposures_s)
    inside = np.flatnonzero((starts <= t_s) & (t_s < ends))
    if inside.size:
        return int(inside[-1])
    before = np.flatnonzero(starts <= t_s)
    return int(before[-1]) if before.size else 0


def _linear_lux(params, dn, exposure_s):
    k = params.system_gain_dn_per_e
    electrons = (np.asarray(dn, dtype=np.float64) - params.black_offset_dn) / k
    signal = electrons - params.dark_current_e_per_s * exposure_s
    return signal, np.maximum(signal, 0.0) / (params.optics.electrons_per_lux_second * exposure_s)


def _noise_floor_electrons(params, exposure_s) -> float:
    """Temporal noise with no light, e⁻: a signal below it has SNR < 1."""
    return max(1.0, math.sqrt(params.read_noise_electrons ** 2 + params.dark_current_e_per_s * exposure_s
                              + 1.0 / (12 * params.system_gain_dn_per_e ** 2)))


def _inverse_table(sensor, kind):
    """(electrons kept, lux) of the noise-free response on a fine lux grid, for inversion."""
    lux = np.logspace(-6, 7, 4000)
    if kind == "segmented":
        kept = sensor.expected_charge_electrons(lux) - sensor.parameters.dark_current_e_per_s * sensor.exposure_s
    else:  # overflow: CDS signal (dark included), minus the dark part at zero light
        kept = sensor.expected_signal_electrons(sensor.photocurrent_a(lux))
        kept = kept - sensor.expected_signal_electrons(sensor.photocurrent_a(np.zeros(1)))[0]
    top = int(np.argmax(kept >= kept.max() * (1 - 1e-9)))  # first point of the final plateau
    return kept[: top + 1], lux[: top + 1]


def complete_frames(stack, duration_s: float) -> int:
    """Number of leading frames whose exposure ends inside the clip ``[0, duration_s]``.

    A frame still exposing when the clip ends would integrate light the clip does not hold.
    """
    ends = np.asarray(stack.start_times_s) + np.asarray(stack.exposure_s)
    return int(np.count_nonzero(ends <= duration_s * (1 + 1e-9) + 1e-12))


def frame_estimates(sensor, stack, instants_s, kind: str = "linear", duration_s: float | None = None) -> list:
    """Light estimates of a frame camera's :class:`~viform.sensors.base.FrameStack` at ``instants_s``.

    With ``duration_s``, only frames whose exposure ends inside the clip are shown.
    """
    p = sensor.parameters
    out = []
    table = None if kind == "linear" else _inverse_table(sensor, kind)
    n = len(stack.start_times_s) if duration_s is None else max(1, complete_frames(stack, duration_s))
    for t in instants_s:
        i = frame_at(stack.start_times_s[:n], stack.exposure_s[:n], t)
        dn = stack.frames_dn[i]
        exposure = float(stack.exposure_s[i])
        signal, lux = _linear_lux(p, dn, exposure)
        if table is not None:
            lux = np.interp(np.maximum(signal, 0.0), table[0], table[1], left=0.0)
            ceiling = table[0][-1]
        else:
            ceiling = p.full_well_electrons - p.dark_current_e_per_s * exposure
        saturated = (signal >= 0.98 * ceiling) | (dn >= p.max_dn)
        under = signal < _noise_floor_electrons(p, exposure)
        out.append(Estimate(lux, saturated, under, (float(stack.start_times_s[i]),
                                                     float(stack.start_times_s[i]) + exposure)))
    return out


def spike_estimates(stream, instants_s, method: str, window_s: float = ACCUMULATION_WINDOW_S) -> list:
    """Light estimates of a spike stream by ``method`` ("accumulation", "interval", "best")."""
    out = []
    tick = 1.0 / stream.clock_hz
    for t in instants_s:
        if method == "accumulation":
            img = accumulation_image(stream, t, window_s)
            n = img.info.get("window_ticks", round(window_s * stream.clock_hz))
            count = img.spikes_per_s * n * tick
            saturated = count >= 0.98 * n
            under = count < 0.5
            # the window the imaging package used (centred on t by default; ending at t in older trees)
            k0 = img.info.get("first_tick", stream.tick_of(t) + 1 - n)
            out.append(Estimate(img.lux, saturated, under, (k0 * tick, (k0 + n) * tick)))
        elif method == "interval":
            img = interval_image(stream, t)
            tau = img.info["tau_ticks"]
            saturated = firing_every_tick(stream, t)
            under = img.censored if img.censored is not None else np.zeros(tau.shape, bool)
            out.append(Estimate(img.lux, saturated, under, (t, t), tau * tick))
        else:
            best = best_spike_image(stream, t)
            out.append(best)
    return out


#: Public reconstructions of :mod:`viform.imaging` better than accumulation and interval, best first.
BEST_METHODS = ("motion_compensated_image", "multi_interval_image")


def firing_every_tick(stream, t_s: float, ticks: int = 8) -> np.ndarray:
    """Pixels that fired at every one of the ``ticks`` ticks around ``t_s``: at the spike camera's
    ceiling (Q·f electrons per second). A single 1-tick interval is not enough: a pixel at 0.6 of
    the ceiling alternates 1- and 2-tick intervals."""
    k = stream.tick_of(t_s)
    k0 = max(0, min(k - ticks // 2, stream.n_ticks - ticks))
    k1 = min(stream.n_ticks, k0 + ticks)
    return spike_counts(stream, k0, k1) >= (k1 - k0)


def best_spike_method_name() -> str | None:
    """Name of the reconstruction used as "best" (the imaging package's best public method), or
    None when the package offers nothing beyond accumulation and interval imaging."""
    for name in BEST_METHODS:
        if hasattr(imaging, name):
            return name.replace("_image", "").replace("_", "-")
    return None


def best_spike_image(stream, t_s: float) -> Estimate:
    """The imaging package's best reconstruction at ``t_s``."""
    name = next(n for n in BEST_METHODS if hasattr(imaging, n))
    img = getattr(imaging, name)(stream, t_s)
    lux = np.nan_to_num(img.lux) if img.lux is not None else np.zeros(stream.shape[1:])
    window = img.info.get("window_ticks")
    if window:
        count = img.spikes_per_s * window / stream.clock_hz
        sat, under = count >= 0.98 * window, count < 0.5
    else:
        sat = firing_every_tick(stream, t_s)
        under = img.censored if img.censored is not None else ~(lux > 0)
    return Estimate(lux, sat, under, (t_s, t_s))


def highspeed_estimates(sensor, stack, instants_s) -> list:
    """Light estimates from the high-speed camera's 8-bit frames (its ``capture``, before equalization)."""
    p = sensor.parameters
    shift = p.adc_bits - 8
    starts, exposures = stack.start_times_s, stack.exposure_s
    ends = stack.metadata.get("frame_end_s", starts + exposures)
    out = []
    for t in instants_s:
        i = frame_at(starts, exposures, t)
        gray = stack.frames_dn[i].astype(np.float64)
        dn = gray * (1 << shift) + ((1 << shift) - 1) / 2.0  # middle of the dropped low bits
        exposure = float(exposures[i])
        signal, lux = _linear_lux(p, dn, exposure)
        saturated = stack.frames_dn[i] >= 255
        under = signal < max(_noise_floor_electrons(p, exposure), (1 << shift) / p.system_gain_dn_per_e)
        out.append(Estimate(lux, saturated, under, (float(starts[i]), float(ends[i]))))
    return out


def gated_estimates(sensor, stack, instants_s) -> list:
    """The gated camera's first frame, in electrons (laser returns: not an image of the light in lux),
    at every instant (its scene is static)."""
    p = sensor.parameters.pixel
    readouts = int(stack.metadata.get("readouts", 1))
    dn = stack.frames_dn[0]
    e = (dn - p.black_offset_dn * readouts) / p.system_gain_dn_per_e
    est = Estimate(np.maximum(e, 0.0), dn >= p.max_dn * readouts, e < _noise_floor_electrons(p, 0.0),
                   (0.0, sensor.frame_time_s()))
    return [est] * len(instants_s)


#: Output → light estimates, one way per family (viform.sensors.catalog.FAMILIES): ``(sensor, output,
#: instants_s, duration_s, method) → [Estimate]``; ``method`` is a spike reconstruction (SPIKE_METHODS).
ESTIMATORS = {
    "frame": lambda sensor, out, t, duration_s, method: frame_estimates(sensor, out, t, "linear", duration_s),
    "segmented": lambda sensor, out, t, duration_s, method: frame_estimates(sensor, out, t, "segmented", duration_s),
    "overflow": lambda sensor, out, t, duration_s, method: frame_estimates(sensor, out, t, "overflow", duration_s),
    "highspeed": lambda sensor, out, t, duration_s, method: highspeed_estimates(sensor, out, t),
    "gated": lambda sensor, out, t, duration_s, method: gated_estimates(sensor, out, t),
    "spike": lambda sensor, out, t, duration_s, method: spike_estimates(out, t, method or "interval"),
}


def light_estimates(family: str, sensor, output, instants_s, *, duration_s: float | None = None,
                    method: str | None = None) -> list:
    """The light a sensor's ``output`` (its ``capture``) shows at ``instants_s``, by the sensor's family.

    Parameters
    ----------
    family : str
        The sensor's family (:data:`~viform.sensors.catalog.FAMILIES`).
    sensor : Sensor
        The sensor that captured ``output``.
    output : FrameStack or SpikeStream
        Its ``capture``.
    instants_s : sequence of float
        Instants, s.
    duration_s : float, optional
        Length of the capture, s.
    method : str, optional
        A spike camera's reconstruction (default: the family's best).

    Returns
    -------
    list of Estimate
        Per instant: light (lux), saturated and under-exposed pixels, the time the light integrates.
    """
    return ESTIMATORS[family](sensor, output, list(instants_s), duration_s, method)
