"""One scene, every sensor: shoot, turn each output into lux at chosen instants, score against the truth.

Any sensor of the catalogue (:mod:`viform.sensors.catalog`; :data:`DEFAULT_SENSORS` when none is
named) shoots the scene with its own ``capture``; its family turns the output into illuminance
estimates (:mod:`viform.measure.estimates`, each inverting the sensor's noise-free response) and
says how fast it is (:data:`SHOTS`: time resolution, latency, data rate). Metrics, per sensor,
against the analytic truth at the same instants:

* PSNR (:func:`psnr_db`) and SSIM (``skimage.metrics``) of log10-illuminance, both images clipped
  to the scene's own range, so one decade of error counts the same in shadow and sun;
* saturated fraction (the pixel's ceiling: full well, top ADC code, a spike every tick) and
  under-exposed fraction (signal below the noise floor, SNR < 1; no spike for the spike camera);
* motion-blur edge width: the 10–90 % distance of the moving vehicle's leading edge, px;
* flicker error: |estimate − truth| of the PWM LED over its on/off swing, 0 (right) … 1 (wrong);
* dynamic range captured: 20·lg(max/min) of the true illuminances that the sensor renders
  within a factor of 2 without saturating or dropping below its floor (0.1–99.9 percentile);
* data rate (MB/s) of the raw output at this resolution;
* time resolution (``time_resolution_s``, "integration time"): how long the sensor's pixel
  integrates the light behind one reading — a frame camera's exposure (the auto-exposure's
  median for the high-speed camera, the gate's total open time for the gated camera); a spike
  pixel integrates until it holds Q electrons, so its integration time is its own inter-spike
  interval τ = Q/(η·E) (seed 000 §3.3), read at each scored instant (the interval containing
  it) and reported as the median over the pixels where the scene moves at those instants
  (:func:`spike_timing`). It is the sensor's, so every reconstruction of one spike stream
  reports the same value; how a reconstruction combines intervals shows in its edge width;
* latency (``latency_s``): the time from a change of light to a reading that shows it — a
  frame camera's frame period; a spike pixel's next spike (at most its interval τ) plus the
  readout tick, median over the same pixels as the time resolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from viform._validate import ViformError, one_line
from viform.imaging import interval_image
from viform.measure.dynamic_range import clip_limited_dynamic_range_db, dynamic_range_db
from viform.measure.estimates import (  # noqa: F401 - also the comparison's API
    ACCUMULATION_WINDOW_S,
    BEST_METHODS,
    ESTIMATORS,
    Estimate,
    best_spike_image,
    best_spike_method_name,
    complete_frames,
    firing_every_tick,
    frame_at,
    frame_estimates,
    gated_estimates,
    highspeed_estimates,
    light_estimates,
    spike_estimates,
)
from viform.sensors import catalog

#: Sensors of a comparison when none are named, in report order (names of :data:`viform.sensors.catalog.SENSORS`;
#: any sensor of the catalogue can be compared).
DEFAULT_SENSORS = ("spikeone", "cmos-short", "cmos", "seed001-2seg", "seed001-3seg", "seed003-4t", "seed003-overflow",
                   "highspeed", "gated")
#: Names whose meaning changed, with where they went: ``compare``/``sweep`` called the SpikeOne chip
#: "spike", which every command now takes for seed 000's Q = 100 e⁻ model.
RENAMED = {"spike": "in compare and sweep this name meant the SpikeOne chip, which is now 'spikeone' "
                    "('spike' is seed 000's Q = 100 e⁻ model in every command; it is refused here so that an old "
                    "command line does not silently compare another camera)"}
#: Spike reconstructions reported as separate rows.
SPIKE_METHODS = ("accumulation", "interval", "best")
#: Metric keys, in table order, with units for the report.
METRICS = {
    "psnr_log_db": ("PSNR (log-lux)", "dB"),
    "ssim_log": ("SSIM (log-lux)", ""),
    "saturated_fraction": ("saturated", "fraction"),
    "underexposed_fraction": ("under-exposed", "fraction"),
    "edge_width_px": ("motion-blur edge width", "px"),
    "flicker_error": ("flicker error", "of on/off swing"),
    "dr_captured_db": ("scene DR captured", "dB"),
    "data_rate_mb_per_s": ("data rate", "MB/s"),
    "latency_s": ("latency", "s"),
    "time_resolution_s": ("integration time", "s"),
    "frame_interval_s": ("frame interval", "s"),
}


#: A sensor meets a scene's range when the range it renders is within this many dB of the scene's
#: (a factor of 2 in light): the verdict's and the demo's rule.
RANGE_MARGIN_DB = 6.0


#: How presets are named for users.
PRESET_DISPLAY_NAMES = {"spikeone": "SpikeOne", "spiketwo": "SpikeTwo", "spiketwo-40k": "SpikeTwo 40 kHz",
                        "spike": "seed 000 model"}


def _grouped(v: float) -> str:
    """16250 → "16 250" (groups of three, as the report's text writes numbers)."""
    return f"{v:,.0f}".replace(",", " ")


def spike_label(sensor, preset: str) -> str:
    """Row/panel label of the spike camera: its preset, threshold Q and clock."""
    p = sensor.parameters
    name = PRESET_DISPLAY_NAMES.get(preset, preset)
    return f"spike ({name}, Q = {_grouped(p.threshold_electrons)} e⁻, {p.clock_hz / 1e3:g} kHz)"


def spike_exposure_note(sensor, preset: str, duration_s: float) -> dict:
    """Why a real-chip threshold leaves dim regions under-exposed in a short clip.

    A pixel collects η·E electrons per second (η electrons per lux-second, E lux) and fires
    every Q/(η·E) s (seed 000 §3.3); it fires at least once in a clip of T seconds only where
    E ≥ Q/(η·T), and at every tick (its ceiling) where E ≥ Q·f/η.
    """
    p = sensor.parameters
    eta = p.optics.electrons_per_lux_second
    q = p.threshold_electrons
    once = q / (eta * duration_s)
    ceiling = q * p.clock_hz / eta
    name = PRESET_DISPLAY_NAMES.get(preset, preset)
    text = (f"The spike camera is the {name} chip preset: threshold Q = {_grouped(q)} e⁻, clock "
            f"{p.clock_hz / 1e3:g} kHz, {_grouped(eta)} e⁻ per lux-second per pixel. A pixel fires every "
            f"Q/(electrons per second) = {q / eta:.3g} s at 1 lux, so in this {duration_s * 1e3:.3g} ms clip it "
            f"fires even once only where the light exceeds {once:.3g} lux; dimmer regions have no spike (or "
            f"one interval cut by the clip) and are drawn grey as under-exposed. This is the real chip's "
            f"threshold, not a scoring artefact: a longer clip or a lower threshold level (smaller Q) lowers "
            f"that floor, and lowers its ceiling (a spike every tick, above {ceiling:.4g} lux) by the same factor.")
    return {"preset": preset, "threshold_electrons": q, "clock_hz": p.clock_hz,
            "electrons_per_lux_second": eta, "one_spike_per_clip_lux": once, "ceiling_lux": ceiling,
            "text": text}


def compare_entry(name: str, what: str = "sensor"):
    """The catalogue entry of a comparison's sensor ``name`` (names that changed meaning are refused)."""
    return catalog.entry(name, renamed=RENAMED, what=what)


def make_compare_sensor(name: str, **settings):
    """The sensor ``name`` as a comparison shoots it: at the scene's resolution, with the entry's
    comparison settings (:attr:`~viform.sensors.catalog.SensorEntry.compare_settings`) and ``settings``."""
    entry = compare_entry(name)
    return entry.build(height=None, width=None, **{**entry.compare_settings, **settings})


# ------------------------------------------------------------------ shots
@dataclass
class Shot:
    """One sensor (or one spike reconstruction) on the scene."""

    key: str
    label: str
    description: str
    estimates: list = field(default_factory=list)
    parameters: dict = field(default_factory=dict)
    time_resolution_s: float = math.nan
    latency_s: float = math.nan
    data_rate_mb_per_s: float = math.nan
    frame_rate_hz: float = math.nan
    lux_units: bool = True
    skipped: str | None = None
    metrics: dict = field(default_factory=dict)
    raw: object = None  # the sensor's native output (its capture)
    name: str = ""  # the catalogue's name of the sensor
    family: str = ""  # its family (viform.sensors.catalog.FAMILIES)
    sensor: object = None  # the sensor that shot it


def frames_in_lux(shot: Shot, duration_s: float):
    """(light images, report instants) of a frame camera's shot: each frame that ends in the clip, in lux,
    reported at the end of its exposure (the earliest it exists); None for other outputs."""
    raw = shot.raw
    if shot.family not in ("frame", "segmented", "overflow", "highspeed") or not hasattr(raw, "frames_dn"):
        return None
    n = complete_frames(raw, duration_s)
    if n == 0:
        return None
    mids = raw.start_times_s[:n] + raw.exposure_s[:n] / 2
    ests = light_estimates(shot.family, shot.sensor, raw, mids, duration_s=duration_s)
    return [e.lux for e in ests], raw.start_times_s[:n] + raw.exposure_s[:n]


def moving_pixels(scene, t_s: float, shape) -> np.ndarray:
    """Pixels where the scene moves at ``t_s``: its ``moving_mask``, else where its motion truth is not
    zero; every pixel when it says neither, or nothing moves."""
    mask = None
    if hasattr(scene, "moving_mask"):
        mask = np.asarray(scene.moving_mask(t_s), bool)
    elif "motion" in (scene.truth_kinds() if hasattr(scene, "truth_kinds") else ()):
        try:
            mask = np.hypot(*np.asarray(scene.motion_px_per_s(t_s), np.float64)[:2]) > 0
        except ViformError:  # a scene whose motion truth is unavailable at t (TruthUnavailable): no mask
            mask = None
    if mask is None or mask.shape != tuple(shape) or not mask.any():
        return np.ones(shape, bool)
    return mask


def spike_timing(stream, scene, instants_s) -> tuple[float, float, list]:
    """(time resolution s, latency s, per-pixel intervals s at each instant) of a spike stream.

    A spike pixel integrates its photo-charge until it reaches Q and fires: its integration time
    is its inter-spike interval, τ = Q/(η·E) at steady light E (seed 000 §3.3), so it falls as Q
    falls or the light rises, down to one readout tick. The interval containing each instant is
    read from the spikes (:func:`viform.imaging.interval_image`; one cut by the clip's ends is
    the part inside the clip); the time resolution is the median of τ over the pixels where the
    scene moves (:func:`moving_pixels`) at each instant, then over the instants. A change of light
    reaches the output at the pixel's next spike, at most τ later, and is read at the next tick:
    latency = time resolution + one tick.
    """
    tick = 1.0 / stream.clock_hz
    intervals, medians = [], []
    for t in instants_s:
        tau = interval_image(stream, t).info["tau_ticks"] * tick
        intervals.append(tau)
        medians.append(float(np.median(tau[moving_pixels(scene, t, tau.shape)])))
    resolution = float(np.median(medians))
    return resolution, resolution + tick, intervals


def data_rate_mb_per_s(height: int, width: int, bits_per_pixel: float, rate_hz: float) -> float:
    return height * width * bits_per_pixel * rate_hz / 8e6


def shoot(key: str, scene, duration_s: float, instants_s, *, seed: int = 0, sensor=None,
          spike_methods=None, device: str = "cpu") -> list:
    """Shoot ``scene`` with the catalogue's sensor ``key``; return its :class:`Shot` (one per
    reconstruction for a spike camera).

    ``sensor`` replaces the comparison's own sensor of that name (the same model at other settings,
    as :mod:`viform.measure.sweep` builds it); ``spike_methods`` limits the spike reconstructions
    (default: every one of :data:`SPIKE_METHODS`). The sensor's ``capture`` gives its output; its
    family turns the output into light (:data:`ESTIMATORS`) and says how fast it is (:data:`SHOTS`).
    ``device`` ("cpu" or "cuda") runs a spike camera's simulation there (the same algorithm and
    bits, :mod:`viform.sensors.spike_cuda`); the other families run on the CPU.

    Parameters
    ----------
    key : str
        A sensor of the comparison (:func:`compare_entry`; the catalogue's names).
    scene : Scene
        The scene, lux.
    duration_s : float
        Length of the capture, s.
    instants_s : sequence of float
        Instants at which the light is estimated, s.
    seed : int
        Seed of the sensor's random noise.
    sensor : Sensor, optional
        The sensor to shoot with instead of the comparison's own.
    spike_methods : sequence of str, optional
        Spike reconstructions to run (of :data:`SPIKE_METHODS`).
    device : {"cpu", "cuda"}
        Where a spike camera's simulation runs.

    Returns
    -------
    list of Shot
        One shot (light estimates, label, data rate, timing) per reconstruction.
    """
    entry = compare_entry(key)
    sensor = sensor if sensor is not None else make_compare_sensor(key)
    on_device = {"device": device} if device != "cpu" and entry.family == "spike" else {}
    try:
        output = sensor.capture(scene, duration_s, seed=seed, **on_device)
    except ViformError as exc:  # this sensor cannot shoot this scene (a scene without range for the gated CCD …)
        return [Shot(key, entry.label, entry.description, skipped=one_line(exc), name=key, family=entry.family,
                     sensor=sensor)]
    shots = SHOTS[entry.family](entry, sensor, output, scene, duration_s, list(instants_s), spike_methods)
    for shot in shots:
        shot.name, shot.family, shot.sensor = key, entry.family, sensor
    return shots


def _frame_shots(entry, sensor, stack, scene, duration_s, instants_s, spike_methods) -> list:
    h, w = scene.shape
    if complete_frames(stack, duration_s) == 0:  # its first frame integrates light beyond the clip's end
        frame_s = float(stack.exposure_s[0])
        return [Shot(entry.name, entry.label, entry.description,
                     skipped=f"its frame ({frame_s * 1e3:.3g} ms of exposure) is longer than the clip "
                             f"({duration_s * 1e3:.3g} ms); give --duration {frame_s:.4g} or more")]
    ests = light_estimates(entry.family, sensor, stack, instants_s, duration_s=duration_s)
    p = sensor.parameters
    return [Shot(entry.name, entry.label, entry.description, ests, sensor.describe(),
                 time_resolution_s=sensor.exposure_s, latency_s=1.0 / sensor.frame_rate_hz,
                 data_rate_mb_per_s=data_rate_mb_per_s(h, w, p.adc_bits, sensor.frame_rate_hz),
                 frame_rate_hz=sensor.frame_rate_hz, raw=stack)]


def _highspeed_shots(entry, sensor, stack, scene, duration_s, instants_s, spike_methods) -> list:
    h, w = scene.shape
    period = sensor.frame_period_s
    ests = light_estimates("highspeed", sensor, stack, instants_s)
    return [Shot(entry.name, entry.label, entry.description, ests, sensor.describe(),
                 time_resolution_s=float(np.median(stack.exposure_s)), latency_s=period,
                 data_rate_mb_per_s=data_rate_mb_per_s(h, w, sensor.parameters.adc_bits, 1 / period),
                 frame_rate_hz=1 / period, raw=stack)]


def _gated_shots(entry, sensor, stack, scene, duration_s, instants_s, spike_methods) -> list:
    h, w = scene.shape
    p = sensor.parameters.pixel
    return [Shot(entry.name, entry.label, entry.description, light_estimates("gated", sensor, stack, instants_s),
                 sensor.describe(), time_resolution_s=sensor.pulses * sensor.timing.width_s,
                 latency_s=1.0 / sensor.frame_rate_hz + sensor.frame_time_s(),
                 data_rate_mb_per_s=data_rate_mb_per_s(h, w, p.adc_bits, sensor.frame_rate_hz),
                 frame_rate_hz=sensor.frame_rate_hz, lux_units=False, raw=stack)]


def _spike_shots(entry, sensor, stream, scene, duration_s, instants_s, spike_methods) -> list:
    h, w = scene.shape
    preset = entry.name
    par = sensor.parameters
    rate = data_rate_mb_per_s(h, w, 1, par.clock_hz)
    methods = [m for m in (spike_methods or SPIKE_METHODS) if m != "best" or best_spike_method_name() is not None]
    head = spike_label(sensor, preset)
    note = spike_exposure_note(sensor, preset, duration_s)
    # the range this clip can show (no interval longer than the clip) beside the formula's (Q / dark current)
    longest = par.threshold_electrons / par.dark_current_e_per_s if par.dark_current_e_per_s > 0 else math.inf
    range_limits = {"clip_s": duration_s, "longest_interval_s": longest,
                    "formula_dr_db": dynamic_range_db(1 / par.clock_hz, longest),
                    "clip_limited_dr_db": clip_limited_dynamic_range_db(1 / par.clock_hz, longest, duration_s)}
    # the sensor's own integration time and latency, the same for every reconstruction of the stream
    tres, lat, intervals = spike_timing(stream, scene, instants_s)
    shots = []
    for method in methods:
        label = {"accumulation": f"{head} · accumulation {ACCUMULATION_WINDOW_S * 1e3:g} ms",
                 "interval": f"{head} · interval", "best": f"{head} · {best_spike_method_name()}"}[method]
        ests = light_estimates("spike", sensor, stream, instants_s, method=method)
        for est, tau in zip(ests, intervals, strict=True):
            est.integration_s = tau  # each pixel's own integration time at the instant
        shots.append(Shot(f"{entry.name}-{method}", label, f"{entry.description}, {preset}", ests,
                          {**sensor.describe(), "preset": preset, "reconstruction": method,
                           "exposure_note": note, **range_limits},
                          time_resolution_s=tres, latency_s=lat, data_rate_mb_per_s=rate,
                          frame_rate_hz=par.clock_hz, raw=stream))
    return shots


#: Per family: the shots of one capture, with what the sensor's timing and data say (time resolution,
#: latency, data rate): ``(entry, sensor, output, scene, duration_s, instants_s, spike_methods) → [Shot]``.
SHOTS = {"frame": _frame_shots, "segmented": _frame_shots, "overflow": _frame_shots, "highspeed": _highspeed_shots,
         "gated": _gated_shots, "spike": _spike_shots}
assert set(SHOTS) == set(ESTIMATORS) == set(catalog.FAMILIES)


# ------------------------------------------------------------------ metrics
def log_lux(lux, lo: float, hi: float) -> np.ndarray:
    """log10 of illuminance clipped to [lo, hi] (None or 0 become lo)."""
    return np.log10(np.clip(np.nan_to_num(np.asarray(lux, dtype=np.float64)), lo, hi))


def psnr_db(truth, estimate, data_range: float) -> float:
    """Peak signal-to-noise ratio (dB) of two float64 images: 10·lg(range² / mean squared error), the
    formula of ``skimage.metrics.peak_signal_noise_ratio`` (same operations, same bits) without its
    module's import of ``scipy.stats`` (≈ 0.5–1 CPU-s in every process that scores)."""
    err = np.mean((truth - estimate) ** 2, dtype=np.float64)
    return float(10 * np.log10((float(data_range) ** 2) / err))


def log_fidelity(estimate_lux, truth_lux, lo: float, hi: float) -> tuple[float, float]:
    """PSNR (dB) and SSIM of log10-lux, both clipped to [lo, hi]; data range lg(hi/lo)."""
    from skimage.metrics import structural_similarity

    a, b = log_lux(truth_lux, lo, hi), log_lux(estimate_lux, lo, hi)
    rng = math.log10(hi / lo)
    psnr = psnr_db(a, b, rng) if np.any(a != b) else math.inf
    win = min(7, min(a.shape) - (1 - min(a.shape) % 2))
    ssim = float(structural_similarity(a, b, data_range=rng, win_size=max(3, win)))
    return min(psnr, 99.0), ssim


def edge_width_px(lux, rows, dark_lux: float, bright_lux: float) -> float:
    """10–90 % width (px) of the rightmost bright→dark edge in the band ``rows``, on log-lux.

    The band's rows are averaged; the profile is normalised between the dark and bright
    plateaus (known levels of the scene) so noise in either does not move the thresholds.
    NaN when no such edge is in view.
    """
    r0, r1 = rows
    lo, hi = math.log10(dark_lux), math.log10(bright_lux)
    prof = np.log10(np.clip(np.asarray(lux, dtype=np.float64)[r0:r1], dark_lux / 10, bright_lux * 10)).mean(axis=0)
    n = (prof - lo) / (hi - lo)
    bright = np.flatnonzero(n >= 0.9)
    if bright.size == 0:
        return math.nan
    i90 = int(bright[-1])  # rightmost point still at 90 %
    after = np.flatnonzero(n[i90:] <= 0.1)
    if after.size == 0:
        return math.nan
    i10 = i90 + int(after[0])
    # linear interpolation of the crossings on either side
    x90 = i90 + (n[i90] - 0.9) / max(n[i90] - n[i90 + 1], 1e-12) if i90 + 1 < n.size else float(i90)
    x10 = i10 - (0.1 - n[i10]) / max(n[i10 - 1] - n[i10], 1e-12)
    return float(max(x10 - x90, 0.0))


def score(shot: Shot, scene, instants_s) -> dict:
    """The metrics of :data:`METRICS` for one shot (see the module notes).

    Parameters
    ----------
    shot : Shot
        A shot of :func:`shoot`.
    scene : Scene
        The scene it shot (its truth is the reference).
    instants_s : sequence of float
        The instants of the shot's estimates, s.

    Returns
    -------
    dict
        Metric name of :data:`METRICS` → value in that metric's unit (empty for a skipped shot).
    """
    if shot.skipped:
        return {}
    demand = scene.demand() if hasattr(scene, "demand") else None
    truths = [scene.illuminance_lux(float(t)) for t in instants_s]
    lo = demand["min_lux"] / 2 if demand else max(float(min(t.min() for t in truths)), 1e-4)
    hi = demand["max_lux"] * 2 if demand else float(max(t.max() for t in truths))
    regions = scene.regions() if hasattr(scene, "regions") else {}
    m = {"time_resolution_s": shot.time_resolution_s, "frame_interval_s": frame_interval_s(shot),
         "latency_s": shot.latency_s,
         "data_rate_mb_per_s": shot.data_rate_mb_per_s, "frame_rate_hz": shot.frame_rate_hz}
    sat = float(np.mean([e.saturated.mean() for e in shot.estimates]))
    under = float(np.mean([e.underexposed.mean() for e in shot.estimates]))
    m.update(saturated_fraction=sat, underexposed_fraction=under)
    if not shot.lux_units:
        m.update(psnr_log_db=math.nan, ssim_log=math.nan, edge_width_px=math.nan, flicker_error=math.nan,
                 dr_captured_db=math.nan)
        if "targets" in regions:
            m["target_cnr"] = target_cnr(shot.estimates[0].lux, regions["targets"])
        return m
    fid = [log_fidelity(e.lux, t, lo, hi) for e, t in zip(shot.estimates, truths, strict=True)]
    m["psnr_log_db"] = float(np.mean([f[0] for f in fid]))
    m["ssim_log"] = float(np.mean([f[1] for f in fid]))
    if "edge_rows" in regions:
        widths = [edge_width_px(e.lux, regions["edge_rows"], regions["edge_dark_lux"], regions["edge_bright_lux"])
                  for e in shot.estimates]
        m["edge_width_px"] = float(np.nanmedian(widths)) if np.isfinite(widths).any() else math.nan
        m["edge_dark_integration_s"] = _edge_dark_integration_s(shot, truths, regions)
    else:
        m["edge_width_px"] = math.nan
    if "led" in regions:
        swing = scene.led_on_lux - scene.led_off_lux
        errs = [abs(float(e.lux[regions["led"]].mean()) - float(t[regions["led"]].mean())) / swing
                for e, t in zip(shot.estimates, truths, strict=True)]
        m["flicker_error"] = float(min(1.0, np.mean(errs)))
    else:
        m["flicker_error"] = math.nan
    good_truth = []
    for e, t in zip(shot.estimates, truths, strict=True):
        ok = (~e.saturated) & (~e.underexposed) & (np.abs(log_lux(e.lux, lo, hi) - log_lux(t, lo, hi)) < math.log10(2))
        good_truth.append(t[ok])
    good = np.concatenate(good_truth)
    good = good[good > 0]
    if good.size >= 2:
        m["dr_captured_db"] = float(20 * math.log10(np.percentile(good, 99.9) / np.percentile(good, 0.1)))
    else:
        m["dr_captured_db"] = 0.0
    if "targets" in regions:
        m["target_cnr"] = target_cnr(shot.estimates[0].lux, regions["targets"])
    return m


def _edge_dark_integration_s(shot, truths, regions) -> float:
    """Median integration time, s, of the pixels on the dark side of the measured edge.

    A spike pixel integrates its own interval, long where the light is dim: on the dark side
    of a moving edge one interval spans much motion, which is what blurs the edge. Frame
    sensors integrate the same time everywhere (their ``time_resolution_s``).
    """
    r0, r1 = regions["edge_rows"]
    middle = math.sqrt(regions["edge_dark_lux"] * regions["edge_bright_lux"])
    medians = []
    for est, truth in zip(shot.estimates, truths, strict=True):
        if est.integration_s is None:
            continue
        dark = np.asarray(truth)[r0:r1] < middle
        if dark.any():
            medians.append(float(np.median(np.asarray(est.integration_s)[r0:r1][dark])))
    return float(np.median(medians)) if medians else shot.time_resolution_s


def target_cnr(image, targets: dict) -> dict:
    """Contrast-to-noise of each target against a ring of pixels around it (for the fog scene)."""
    from scipy.ndimage import binary_dilation

    out = {}
    anything = np.zeros(np.shape(image), bool)
    for mask in targets.values():
        anything |= binary_dilation(mask, iterations=1)
    for name, mask in targets.items():
        # the surround: a ring 2–3 px out, clear of every target (another sign is not background)
        ring = binary_dilation(mask, iterations=3) & ~anything
        if not ring.any():
            continue
        noise = float(np.std(image[ring])) or 1e-12
        out[name] = float(abs(image[mask].mean() - image[ring].mean()) / noise)
    return out


# ------------------------------------------------------------------ who wins on what
#: How each verdict line shows a metric; sensors whose values look the same at that precision tie.
VERDICT_FORMATS = {
    "edge_width_px": lambda v: f"{v:.3g} px",
    "dr_captured_db": lambda v: f"{v:.0f} dB",
    "saturated_fraction": lambda v: f"{v:.1%}",
    "underexposed_fraction": lambda v: f"{v:.1%}",
    "flicker_error": lambda v: f"{v:.2f} of the on/off swing",
    "psnr_log_db": lambda v: f"{v:.1f} dB",
    "data_rate_mb_per_s": lambda v: f"{v:.3g} MB/s",
    "latency_s": lambda v: f"{v * 1e3:.3g} ms",
}
#: Metrics of the image in lux (ranked among sensors that give one) and of the sensor itself (ranked among all).
IMAGE_METRICS = ("edge_width_px", "dr_captured_db", "flicker_error", "psnr_log_db")


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3g} ms"


def extremes(rows, key: str, higher: bool):
    """(best shots, best value, worst shots, worst value) of ``key`` over ``rows``, ties kept together.

    Sensors tie when :data:`VERDICT_FORMATS` shows their values the same. ``worst`` is empty
    when every ranked sensor ties. None when no row has a finite value.
    """
    fmt = VERDICT_FORMATS[key]
    vals = [(float(s.metrics[key]), s) for s in rows
            if isinstance(s.metrics.get(key), (int, float)) and math.isfinite(s.metrics[key])]
    if not vals:
        return None
    pick = max if higher else min
    best_v = pick(v for v, _ in vals)
    worst_v = (min if higher else max)(v for v, _ in vals)
    best = [s for v, s in vals if fmt(v) == fmt(best_v)]
    worst = [s for v, s in vals if fmt(v) == fmt(worst_v)] if fmt(worst_v) != fmt(best_v) else []
    return best, best_v, worst, worst_v


def names(shots) -> str:
    """Labels joined for a sentence; several are a tie and said so."""
    labels = [s.label for s in shots]
    if len(labels) == 1:
        return labels[0]
    return f"{len(labels)} sensors tie: " + ", ".join(labels[:-1]) + f" and {labels[-1]}"


def frame_interval_s(shot) -> float:
    """Time from one image to the next (1 / frame rate); for the spike camera one readout tick."""
    rate = shot.frame_rate_hz
    return 1.0 / rate if rate and math.isfinite(rate) and rate > 0 else math.nan


def _timing(shot) -> str:
    interval = frame_interval_s(shot)
    return f"integration {_ms(shot.time_resolution_s)}" + (
        f", a new image every {_ms(interval)}" if math.isfinite(interval) else "")


def _blur_cause(shot) -> str:
    dark = shot.metrics.get("edge_dark_integration_s")
    if shot.family == "spike" and isinstance(dark, float) and math.isfinite(dark):
        return (f"its pixels on the dark side of the edge fire only every {_ms(dark)} (dim light, long intervals) "
                f"and each image spans a whole interval, although the median integration where the scene moves "
                f"is {_ms(shot.time_resolution_s)}")
    return f"its integration time is {_ms(shot.time_resolution_s)}"


def verdict(shots, demand: dict | None) -> list[str]:
    """Sentences saying which sensor wins on what, derived from the metrics alone.

    Every line is computed from the same rows as the table: image metrics (edge, range,
    flicker, PSNR) rank the sensors that give an image in lux; sensor metrics (saturated,
    under-exposed, data rate, latency) rank every sensor that ran. Sensors tied at the
    precision shown are all named; those left out of a ranking are named, with the reason.

    Parameters
    ----------
    shots : sequence of Shot
        Every sensor's shots, scored (``shot.metrics``, :func:`score`).
    demand : dict, optional
        The scene's demands (``scene.demand()``: the dynamic range it holds ...), which the sentences quote.

    Returns
    -------
    list of str
        The sentences, most important first.
    """
    ran = [s for s in shots if not s.skipped]
    image_rows = [s for s in ran if s.lux_units]
    lines = []

    def line(key, higher, text_best, text_worst=""):
        found = extremes(image_rows if key in IMAGE_METRICS else ran, key, higher)
        if found is None:
            return None
        best, v, worst, wv = found
        fmt = VERDICT_FORMATS[key]
        out = text_best.format(who=names(best), value=fmt(v), first=best[0])
        if worst and text_worst:
            out += text_worst.format(who=names(worst), value=fmt(wv), first=worst[0])
        lines.append(out + ".")
        return found

    found = extremes(image_rows, "edge_width_px", higher=False)
    if found is not None:
        best, v, worst, wv = found
        text = f"Sharpest moving edge: {names(best)}, {VERDICT_FORMATS['edge_width_px'](v)} ({_timing(best[0])}"
        caveats = []
        if frame_interval_s(best[0]) > 10 * best[0].time_resolution_s:
            caveats.append(f"only {best[0].frame_rate_hz:.3g} images a second, latency {_ms(best[0].latency_s)}")
        if best[0].metrics.get("underexposed_fraction", 0) > 0.05:
            caveats.append(f"{best[0].metrics['underexposed_fraction']:.0%} of its pixels under-exposed")
        text += ")" + (f", but {' and '.join(caveats)}" if caveats else "")
        if worst:
            text += (f"; the most blurred is {names(worst)} at {VERDICT_FORMATS['edge_width_px'](wv)}, because "
                     f"{_blur_cause(worst[0])}")
        lines.append(text + ".")
    for s in image_rows:  # a spike image's blur comes from its dimmest pixels' long intervals: say so
        dark = s.metrics.get("edge_dark_integration_s")
        if s.family == "spike" and isinstance(dark, float) and math.isfinite(s.metrics.get("edge_width_px",
                                                                                                  math.nan)) \
                and dark > 2 * s.time_resolution_s and s not in (found[2] if found else []):
            lines.append(f"{s.label}: {VERDICT_FORMATS['edge_width_px'](s.metrics['edge_width_px'])} of edge blur, "
                         f"because {_blur_cause(s)}.")
    need = f" of the {demand['dynamic_range_db']:.0f} dB the scene holds" if demand else ""
    found = line("dr_captured_db", True, "Widest range rendered within a factor of 2: {who}, {value}" + need,
                 "; narrowest: {who}, {value}")
    spike_limit = next((s.parameters["clip_limited_dr_db"] for s in ran if "clip_limited_dr_db" in s.parameters),
                       None)
    if found is not None and spike_limit is not None:
        p = next(s.parameters for s in ran if "clip_limited_dr_db" in s.parameters)
        lines.append(f"The spike camera's range here is bounded by the clip: no interval longer than the "
                     f"{_ms(p['clip_s'])} clip can be measured in it, so at most {spike_limit:.0f} dB; the "
                     f"{p['formula_dr_db']:.0f} dB of its formula (viform dr) needs intervals of "
                     f"{p['longest_interval_s']:.3g} s (threshold / dark current).")
    line("saturated_fraction", False, "Fewest saturated pixels: {who} ({value})", "; most: {who} ({value})")
    line("underexposed_fraction", False, "Fewest pixels lost in the dark: {who} ({value})",
         "; most: {who} ({value})")
    line("flicker_error", False, "Flickering LED seen in its true state: {who} (error {value})",
         "; worst: {who} ({value})")
    found = extremes(image_rows, "psnr_log_db", True)
    if found is not None:
        best, v, worst, wv = found
        lines.append(f"Closest to the truth overall (PSNR of log-lux): {names(best)}, {v:.1f} dB "
                     f"(SSIM {best[0].metrics['ssim_log']:.2f})"
                     + (f"; last: {names(worst)}, {wv:.1f} dB" if worst else "") + ".")
    line("data_rate_mb_per_s", False, "Least data: {who}, {value}", "; most: {who}, {value}")
    line("latency_s", False, "Shortest latency: {who}, {value}", "; longest: {who}, {value}")
    cnr = [(s, s.metrics["target_cnr"]) for s in shots if not s.skipped and s.metrics.get("target_cnr")]
    if cnr:
        seen = {s.label: [k for k, v in c.items() if v >= 3] for s, c in cnr}
        best_s, best_c = max(cnr, key=lambda sc: sum(v >= 3 for v in sc[1].values()) + max(sc[1].values()) / 1e3)
        others = [label for label, targets in seen.items() if not targets]
        lines.append(f"Targets seen through the fog (contrast-to-noise ≥ 3): {best_s.label} sees "
                     f"{', '.join(seen[best_s.label]) or 'none'} (best contrast-to-noise "
                     f"{max(best_c.values()):.1f}); "
                     + (f"{len(others)} of {len(cnr)} sensors see none." if others else "every sensor sees some."))
    if demand and image_rows:
        meets = [r.label for r in image_rows
                 if r.metrics.get("dr_captured_db", 0) >= demand["dynamic_range_db"] - RANGE_MARGIN_DB
                 and r.time_resolution_s <= demand["time_resolution_s"]]
        lines.append("Meets both the scene's range and its speed: " + (", ".join(meets) + "." if meets else
                     "no sensor compared here, at these settings."))
    not_lux = [s for s in ran if not s.lux_units]
    if not_lux:
        lines.append(f"Not ranked on the image (edge, range, flicker, PSNR): {', '.join(s.label for s in not_lux)}, "
                     "whose output is not an image of the scene's light in lux (gated laser returns in DN); "
                     "ranked on the rest.")
    for s in shots:
        if s.skipped:
            lines.append(f"Not in this comparison: {s.label}: {s.skipped}.")
    return lines
