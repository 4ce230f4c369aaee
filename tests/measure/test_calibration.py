"""Calibration of a spike-sensor preset from a recording (issue 10 item 5; seed 000 §5.1)."""

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from viform._validate import ViformError
from viform.cli import main
from viform.light.scenes import FlickerScene, StillScene
from viform.measure.calibration import (
    calibrate,
    interval_statistics,
    pixel_intervals,
    preset_from_calibration,
    rounding_variance,
    statistics_of,
)
from viform.sensors.spike import SpikeSensor
from viform.sensors.spike_presets import load_spike_preset
from viform.stream.container import SpikeStream
from viform.stream.io import open_spikes, save_spikes

REAL = Path(os.environ.get("VIFORM_SPIKE_DATA")
            or Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "spike") / "real_uhsr_250x250.npz"


def _ramp_recording(q, prnu, size=96, ticks=400, seed=1, **kw):
    """Steady light whose mean interval runs from 6 to 40 ticks across the columns (a ramp, like
    a real scene's spread of levels), with PRNU ``prnu``."""
    s = SpikeSensor(threshold_electrons=q, gain_spread_fraction=prnu, dark_current_e_per_s=0.0, **kw)
    clock = s.parameters.clock_hz
    mu = np.geomspace(6, 40, size)[None, :].repeat(size, 0)
    lux = s.parameters.optics.lux_from_electrons_per_s(q / mu * clock)
    return s.capture(StillScene(lux), ticks / clock, seed=seed)


def test_rounding_variance_limits_and_monte_carlo():
    """G = E[frac(S)(1 − frac(S))]: 1/4 at a half-tick, 0 on a whole tick without jitter,
    1/6 for jitter ≫ 1 tick; and a Monte Carlo mean at a jitter of 0.22 tick (10⁶ draws,
    standard error < 1e-4, checked at 5e-4)."""
    assert rounding_variance(10.5, 0.0) == pytest.approx(0.25, abs=1e-3)
    assert rounding_variance(10.0, 0.0) == pytest.approx(0.0, abs=1e-2)  # 12 Fourier terms: 1/(12π²)
    assert rounding_variance(10.3, 4.0) == pytest.approx(1 / 6, abs=1e-9)
    x = np.random.default_rng(0).normal(23.3, np.sqrt(0.05), 1_000_000)
    f = x - np.floor(x)
    assert rounding_variance(23.3, 0.05) == pytest.approx(np.mean(f * (1 - f)), abs=5e-4)


@pytest.mark.parametrize("q, prnu", [(1000, 0.03), (10_000, 0.03), (10_000, 0.01)])
def test_recovers_threshold_and_gain_spread(q, prnu):
    """Simulated steady scene with known Q and PRNU: Q_eff within 10 % (its 2σ fit error is
    ≈ 7 % at Q = 10⁴ on 96×96 pixels × 400 ticks, so the 95 % range must also hold Q) and
    the flat-field spread within 1 point."""
    r = calibrate(_ramp_recording(q, prnu))
    th = r["threshold"]
    assert th["q_eff_electrons"] is not None, th.get("reason")
    assert abs(th["q_eff_electrons"] / q - 1) < 0.10
    lo, hi = th["q_eff_range_electrons"]  # ±2σ; widened to ±3σ
    assert lo - (hi - lo) / 4 <= q <= hi + (hi - lo) / 4
    assert abs(r["gain_spread"]["gain_spread_fraction"] - prnu) < 0.01
    # a steady pixel's successive intervals: lag-1 correlation as the rounding predicts
    for row in r["interval_table"]:
        assert row["static_consistent"], row
    assert r["defects"]["hot_pixels"] == 0 and r["defects"]["dead_pixels"] == 0


@pytest.mark.parametrize("interval_ticks", [12.5, 23.0])
def test_uniform_field_without_pixel_spread(interval_ticks):
    """Every pixel at the same interval, no PRNU: the tick phases of all pixels are coherent
    (half-tick: 12,13,12,13…; whole tick: 23,23,23…), the rounding term far exceeds σ² and
    depends on σ itself; Q_eff is still recovered within 10 % (the per-pixel rounding
    terms, unbiased for the noise of each pixel's mean interval, and the first root)."""
    q = 10_000
    s = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    clock = s.parameters.clock_hz
    lux = s.parameters.optics.lux_from_electrons_per_s(np.full((64, 64), q / interval_ticks * clock))
    r = calibrate(s.capture(StillScene(lux), 400 / clock, seed=1))
    assert r["threshold"]["q_eff_electrons"] == pytest.approx(q, rel=0.10), r["threshold"].get("reason")


@pytest.mark.parametrize("frequency_hz, depth", [(100.0, 0.3), (1000.0, 0.1)])
def test_light_that_changes_gives_a_lower_bound_only(frequency_hz, depth):
    """Flicker (a mains lamp at 100 Hz, 30 %; a PWM source at 1 kHz, 10 %) over the 10 ms
    recording: the intervals follow the light (slow flicker: positively correlated; fast:
    more anti-correlated than a steady pixel can be), so Q_eff is reported only as a lower
    bound, which must hold."""
    q = 10_000
    s = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    clock = s.parameters.clock_hz
    mu = np.geomspace(6, 40, 64)[None, :].repeat(64, 0)
    base = StillScene(s.parameters.optics.lux_from_electrons_per_s(q / mu * clock))
    rec = s.capture(FlickerScene(base, frequency_hz=frequency_hz, depth=depth), 400 / clock, seed=2)
    th = calibrate(rec)["threshold"]
    assert th["q_eff_electrons"] is None
    assert "not static" in th["reason"]
    assert th["q_eff_lower_bound_electrons"] <= q


def test_too_short_recording_says_so():
    rec = _ramp_recording(10_000, 0.03, size=32, ticks=30)
    r = calibrate(rec)
    assert r["threshold"]["q_eff_electrons"] is None
    assert "too short" in r["threshold"]["reason"]
    assert r["dark_current"]["dark_current_e_per_s"] is None


@pytest.mark.parametrize("shape", [(60, 1, 1), (60, 9, 1), (60, 3, 40)])
@pytest.mark.parametrize("fill", [False, True])
def test_degenerate_recordings_give_reasons_not_errors(shape, fill):
    """Dark (no spike) or saturated (a spike every tick) recordings of odd sizes: every figure
    is None with a reason; no preset is written from them unless the caller names the
    threshold to assume (then listed as assumed)."""
    r = calibrate(SpikeStream(np.full(shape, fill), 40e3))
    assert r["threshold"]["q_eff_electrons"] is None and r["threshold"]["reason"]
    assert r["gain_spread"]["gain_spread_fraction"] is None and r["gain_spread"]["reason"]
    with pytest.raises(ViformError, match="no threshold"):
        preset_from_calibration(r)
    preset = preset_from_calibration(r, fallback_threshold_electrons=5000.0)
    assert preset.calibration["assumed"] == {"threshold_electrons": 5000.0}
    assert preset.parameters.threshold_electrons == 5000.0


def test_too_bright_recording_uses_its_recorded_threshold_or_writes_nothing(tmp_path, capsys):
    """A recording at 1.4 ticks per interval (Q = 1,000 in its sidecar) measures no threshold
    and bounds no gain spread (every pixel near one spike a tick reads the same whatever its
    gain): the preset takes the Q its sidecar records and says so; without a recorded Q the
    CLI writes no preset and exits 2 with one line naming --out."""
    s = SpikeSensor(threshold_electrons=1000, dark_current_e_per_s=0.0, gain_spread_fraction=0.03)
    clock = s.parameters.clock_hz
    lux = s.parameters.optics.lux_from_electrons_per_s(np.full((32, 32), 1000 / 1.4 * clock))
    rec = s.capture(StillScene(lux), 200 / clock, seed=3)
    path = save_spikes(tmp_path / "bright.dat", rec)
    out = tmp_path / "p.json"
    code = main(["calibrate", str(path), "--out", str(out)])
    text, err = capsys.readouterr()
    assert code == 0, err
    assert "1,000 e⁻" in text and "not a measurement" in text
    preset = load_spike_preset(str(out))
    assert preset.parameters.threshold_electrons == 1000.0
    assert preset.calibration["recorded"] == {"threshold_electrons": 1000.0}
    assert "threshold_electrons" not in preset.calibration["measured"]
    assert "gain_spread_fraction" not in preset.calibration["bounds"]  # nothing bounded it
    assert "16,250" not in preset.description and "1.625e+04" not in preset.description
    # the same bits without a sidecar: nothing to write
    raw = tmp_path / "raw.dat"
    raw.write_bytes(path.read_bytes())
    out2 = tmp_path / "q.json"
    code = main(["calibrate", str(raw), "--height", "32", "--width", "32", "--out", str(out2)])
    _, err = capsys.readouterr()
    # one line of error (a raw file without its sidecar is also said to be read unverified)
    errors = [line for line in err.splitlines() if not line.startswith("viform: warning:")]
    assert code == 2 and len(errors) == 1 and "--out" in errors[0] and "no threshold" in errors[0], err
    assert not out2.exists()


def test_hot_and_dead_pixels_found():
    """Hot pixels (dark current 4·10⁷ e⁻/s at Q = 10⁴: 40 spikes in the 10 ms on top of the light)
    and pixels made silent are found; the preset carries the hot-pixel fraction."""
    rec = _ramp_recording(10_000, 0.0, size=64, ticks=400, hot_pixel_fraction=0.005,
                          hot_pixel_dark_current_e_per_s=4e7)
    spikes = rec.spikes.copy()
    spikes[:, 10, 20] = False
    spikes[:, 40, 50] = False
    r = calibrate(SpikeStream(spikes, rec.clock_hz, rec.threshold_electrons))
    d = r["defects"]
    sensor = SpikeSensor(threshold_electrons=10_000, hot_pixel_fraction=0.005, hot_pixel_dark_current_e_per_s=4e7)
    expected_hot = int((sensor.dark_current_map_e_per_s(64, 64) > 1e6).sum())
    assert d["dead_pixels"] == 2
    assert abs(d["hot_pixels"] - expected_hot) <= 2
    preset = preset_from_calibration(r, "hot")
    assert preset.parameters.hot_pixel_fraction == pytest.approx(d["hot_pixel_fraction"])


@pytest.mark.parametrize("hot_fraction", [0.0, 0.005])
def test_moving_scene_gives_no_false_hot_pixels(hot_fraction):
    """A translating scene (Q = 100 e⁻, ~6 spikes a pixel a ms) makes single pixels outshine
    their neighbours while a bright feature passes; hot pixels must stand out in both halves
    of the recording, so none is reported without real ones, and real ones (2·10⁵ e⁻/s at
    Q = 100: 20 extra spikes in 10 ms, ≥ 6 Poisson σ above the local median in each half)
    are still found."""
    from viform.light.catalog import builtin_scene

    sensor = SpikeSensor(threshold_electrons=100, hot_pixel_fraction=hot_fraction,
                         hot_pixel_dark_current_e_per_s=2e5)
    rec = sensor.capture(builtin_scene("translating", 64, 96), 400 / sensor.parameters.clock_hz, seed=0)
    d = calibrate(rec)["defects"]
    expected = int((sensor.dark_current_map_e_per_s(64, 96) > 1e5).sum())
    assert expected == 0 if hot_fraction == 0 else expected > 10
    if expected == 0:
        assert d["hot_pixels"] == 0
    else:  # a hot pixel on a bright moving feature can hide below 6 σ in one half: most are found
        assert 0.7 * expected <= d["hot_pixels"] <= expected


def test_cli_writes_a_preset_that_loads(tmp_path, capsys):
    rec = _ramp_recording(10_000, 0.03, size=64, ticks=400)
    path = save_spikes(tmp_path / "rec.npz", rec)
    out = tmp_path / "fitted.json"
    code = main(["calibrate", str(path), "--out", str(out), "--json", "--json-file", str(tmp_path / "r.json")])
    text, err = capsys.readouterr()
    assert code == 0, err
    result = json.loads(text)
    assert json.loads((tmp_path / "r.json").read_text()) == result
    preset = load_spike_preset(str(out))
    assert (preset.height, preset.width) == (64, 64)
    assert preset.parameters.threshold_electrons == pytest.approx(result["threshold"]["q_eff_electrons"], abs=1)
    code = main(["calibrate", str(path)])
    text, _ = capsys.readouterr()
    assert code == 0 and "effective threshold" in text and "e⁻" in text
    assert "nearest chip threshold level" in text  # Q = 10⁴ lies inside the chip's levels
    code = main(["calibrate", str(path), "--out", str(tmp_path / "p.txt")])
    _, err = capsys.readouterr()
    assert code == 2 and "--out" in err and err.count("\n") == 1
    (tmp_path / "no").write_text("a file")  # a missing folder would be created, as for --out
    code = main(["calibrate", str(path), "--json-file", str(tmp_path / "no" / "r.json")])
    _, err = capsys.readouterr()
    assert code == 2 and "--json-file" in err and err.count("\n") == 1 and (tmp_path / "no").is_file()


@pytest.mark.skipif(not REAL.exists(), reason="shared real recording ../shared/data/spike not present")
def test_real_recording_and_a_simulation_from_its_preset():
    """The shared real clip (a displayed picture, 200 ticks at 40 kHz) and data simulated from
    the preset fitted to it.

    What this recording can and cannot give: its pixels' successive intervals are not
    anti-correlated as a steady pixel's are (lag-1 ≈ 0 where a steady pixel gives −0.45: the
    light at each pixel changes by a few % over the 5 ms), so Q_eff is only bounded from
    below; the bound is far above the old default Q = 100 e⁻. A simulation from the
    preset (its scene: the clip's own rate map, smoothed so the preset's gain spread makes
    the pixel-to-pixel spread) must reproduce, within 15 %, the flat-field spread and the
    per-interval-bin RSD of the intervals about each pixel's linear trend (``rsd_detrended``;
    the plain RSD of the clip also holds the light's drift, which no steady sensor
    reproduces, so for it only "clip ≥ simulation" is asserted).
    """
    source = open_spikes(REAL)
    rec = calibrate(source)
    th = rec["threshold"]
    assert th["q_eff_electrons"] is None and "not static" in th["reason"]
    assert th["q_eff_lower_bound_electrons"] > 5000
    preset = preset_from_calibration(rec, "uhsr")
    assert preset.parameters.threshold_electrons == round(th["q_eff_lower_bound_electrons"])

    iv = pixel_intervals(source)
    h, w = iv.height, iv.width
    mu = iv.mean_interval.reshape(h, w)
    counts = iv.n_spikes.reshape(h, w)
    rate = np.where((counts >= 3) & np.isfinite(mu), 1 / np.where(np.isfinite(mu), mu, 1), counts / iv.n_ticks)
    sensor = preset.sensor()
    p = sensor.parameters
    e = np.maximum(ndimage.gaussian_filter(rate, 1.0) * p.threshold_electrons * p.clock_hz
                   - p.dark_current_e_per_s, 0.0)
    sim = sensor.capture(StillScene(p.optics.lux_from_electrons_per_s(e)), iv.n_ticks / p.clock_hz, seed=5)
    out = calibrate(sim)
    # the simulation is steady: its fit finds the preset's threshold again
    assert out["threshold"]["q_eff_electrons"] == pytest.approx(p.threshold_electrons, rel=0.10)
    g_rec = rec["gain_spread"]["gain_spread_fraction"]
    assert out["gain_spread"]["gain_spread_fraction"] == pytest.approx(g_rec, rel=0.15)
    # the simulation's RSD at each of the clip's bins, interpolated (log-log) at the clip's
    # mean interval: a bin's pixels need not have the same mean interval in both
    sim_rows = [row for row in out["interval_table"] if row["pixels"] >= 100]
    log_mu = np.log([row["mean_interval_ticks"] for row in sim_rows])
    compared = 0
    for row in rec["interval_table"]:
        x = np.log(row["mean_interval_ticks"])
        if row["pixels"] < 100 or not log_mu[0] - 0.05 <= x <= log_mu[-1] + 0.05:  # ±5 %: end value
            continue
        for key in ("rsd_detrended", "rsd"):
            sim_value = np.exp(np.interp(x, log_mu, np.log([r[key] for r in sim_rows])))
            if key == "rsd_detrended":
                assert sim_value == pytest.approx(row[key], rel=0.15)
            else:
                assert row[key] >= 0.98 * sim_value
        compared += 1
    assert compared >= 3


def test_reading_stops_at_the_spike_budget():
    """Memory is bounded: reading stops at the block where the spike budget is reached."""
    rec = _ramp_recording(10_000, 0.03, size=32, ticks=400)
    whole = pixel_intervals(rec, block_ticks=50)
    part = pixel_intervals(rec, block_ticks=50, max_spikes=whole.n_spikes.sum() // 3)
    assert part.n_ticks < whole.n_ticks and part.n_ticks % 50 == 0
    assert part.n_spikes.sum() < whole.n_spikes.sum()
    # the same spikes as the first part of the whole read
    spikes = rec.spikes[: part.n_ticks]
    assert np.array_equal(part.n_spikes, spikes.reshape(part.n_ticks, -1).sum(axis=0))


@pytest.mark.parametrize("block_ticks,budget", [(37, None), (50, 3)])
def test_streamed_statistics_equal_the_collected_intervals(block_ticks, budget):
    """Calibration reads per-pixel sums block by block (bounded memory: one block and 19
    numbers per pixel, not every interval). They equal the sums of the collected intervals
    (to float rounding), whatever the block size, and stop at the same spike budget."""
    rec = _ramp_recording(10_000, 0.03, size=24, ticks=300)
    max_spikes = 20_000_000 if budget is None else int(rec.spikes.sum()) // budget
    whole = pixel_intervals(rec, block_ticks=block_ticks, max_spikes=max_spikes)
    streamed = interval_statistics(rec, block_ticks=block_ticks, max_spikes=max_spikes)
    collected = statistics_of(whole)
    assert streamed.n_ticks == whole.n_ticks
    for name in collected.__dataclass_fields__:
        value = getattr(collected, name)
        if isinstance(value, np.ndarray):
            assert np.allclose(getattr(streamed, name), value, rtol=1e-12, atol=0), name


def _textured_recording(hot_fraction, q=1000, ticks=800, h=64, w=96):
    """A static smooth texture (log-normal, ≈ 30 % contrast, correlated over ≈ 1.5 px) on a ramp
    from dark (300 ticks a spike) to bright (4 ticks), with hot pixels of 10⁶ e⁻/s."""
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, hot_pixel_fraction=hot_fraction,
                         hot_pixel_dark_current_e_per_s=1e6)
    clock = sensor.parameters.clock_hz
    texture = np.exp(0.3 * ndimage.gaussian_filter(np.random.default_rng(7).standard_normal((h, w)), 1.5) / 0.19)
    mu = np.geomspace(300, 4, w)[None, :] / texture
    lux = sensor.parameters.optics.lux_from_electrons_per_s(q / mu * clock)
    rec = sensor.capture(StillScene(lux), ticks / clock, seed=1)
    return rec, sensor.dark_current_map_e_per_s(h, w) > 5e5


@pytest.mark.parametrize("hot_fraction", [0.0, 0.013])
def test_texture_is_not_taken_for_hot_pixels(hot_fraction):
    """A texture peak lifts a pixel in proportion to its light; a dark current adds the same
    charge whatever the light. Hot pixels are therefore called only above the scene's
    relative contrast (8 robust σ) as well as the photon noise, in both halves: no false
    ones on a textured scene (the old 5×5-median test called 179 here), every one reported
    is truly hot, and where the scene is dark enough they are found: their dark current
    within 5 standard errors of 10⁶ e⁻/s (≈ 10 extra spikes per half at Q = 1,000), their
    fraction among the pixels dark enough to show them within 5 binomial standard errors of
    the true fraction. The gain spread (which this texture inflates to ≈ 15 % without any
    PRNU) and a "no hot pixel" finding go into the preset as bounds, not as measured."""
    rec, truth = _textured_recording(hot_fraction)
    r = calibrate(rec)
    d = r["defects"]
    found = np.zeros(truth.shape, bool)
    for y, x in d["hot_pixel_positions"]:
        found[y, x] = True
    assert d["hot_pixels"] == found.sum()
    assert not (found & ~truth).any()  # no false hot pixel
    preset = preset_from_calibration(r)
    bounds = preset.calibration["bounds"]
    assert bounds["gain_spread_fraction"]["kind"] == "upper bound"
    assert "gain_spread_fraction" not in preset.calibration["measured"]
    if hot_fraction == 0:
        assert d["hot_pixels"] == 0
        assert bounds["hot_pixel_fraction"]["kind"] == "upper bound"
        assert preset.parameters.hot_pixel_fraction == 0.0
        return
    assert d["hot_pixels"] >= 20
    se = d["hot_pixel_dark_current_standard_error_e_per_s"]
    assert abs(d["hot_pixel_dark_current_e_per_s"] - 1e6) < 5 * se
    assert abs(d["hot_pixel_fraction"] - truth.mean()) < 5 * d["hot_pixel_fraction_standard_error"]
    assert preset.calibration["measured"]["hot_pixel_fraction"] == d["hot_pixel_fraction"]


def _uniform_recording(q, drift, side=16, ticks=400, seed=0, interval_ticks=12.5):
    """Every pixel at the same mean interval (coherent tick phases, no PRNU): the light rises
    linearly by ``drift`` (relative) over the recording."""
    from viform.light.scenes import VideoScene

    s = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    clock = s.parameters.clock_hz
    lux = s.parameters.optics.lux_from_electrons_per_s(np.full((side, side), q / interval_ticks * clock))
    scene = StillScene(lux) if drift == 0 else VideoScene(np.stack([lux, lux * (1 + drift)]), clock / ticks, "linear")
    return s.capture(scene, ticks / clock, seed=seed)


@pytest.mark.parametrize("seed", [0, 1])
def test_drift_of_the_light_moves_the_rounding_term(seed):
    """2 % of linear drift over a uniform field (every pixel at 12.5 ticks, Q = 10⁴: tick phases
    coherent, the rounding term ≫ σ²) moves each pixel's tick phase by 0.25 tick over the
    recording; the rounding term is averaged over that drift (sinc factors, the drift fitted
    from the intervals' trends). Before, the estimate read 27–35 % low (z ≈ 8–11); now the
    95 % range holds Q."""
    r = calibrate(_uniform_recording(10_000, 0.02, side=64, seed=seed))
    th = r["threshold"]
    assert th["median_relative_drift_over_recording"] == pytest.approx(0.02, abs=0.004)
    lo, hi = th["q_eff_range_electrons"]
    assert lo <= 10_000 <= hi


@pytest.mark.slow
def test_stated_q_eff_figures_hold_the_truth_over_seeds():
    """20 seeds × Q = 300, 3,000, 30,000 × 0 and 2 % drift on a 16×16 uniform field (the hard
    case: coherent tick phases): every figure stated — a 95 % range, or a bound — must hold
    the true Q in ≥ 90 % of the 120 trials (a calibrated 95 % range misses 6 ± 2.4 times:
    ≥ 108 holds is 2.5 binomial σ below), and an estimate must be given in ≥ half of them.
    Before, 18 of the 20 trials at Q = 3,000 with drift stated a lower bound above the true Q
    (the fit found no root and called the rounding "unresolved"); now 103 of 108 ranges and
    both bounds hold, and 10 trials say the drift leaves no figure."""
    stated = held = estimates = 0
    for q in (300, 3000, 30000):
        for drift in (0.0, 0.02):
            for seed in range(20):
                th = calibrate(_uniform_recording(q, drift, seed=500 + seed))["threshold"]
                if th.get("q_eff_electrons"):
                    lo, hi = th["q_eff_range_electrons"]
                    stated, held, estimates = stated + 1, held + (lo <= q <= hi), estimates + 1
                elif th.get("q_eff_lower_bound_electrons"):
                    stated, held = stated + 1, held + (th["q_eff_lower_bound_electrons"] <= q)
    assert held >= 0.9 * stated
    assert estimates >= 60


@pytest.mark.parametrize("ticks", [200, 2000])
def test_lag1_correlation_is_free_of_the_window(ticks):
    """A steady pixel's lag-1 correlation of successive intervals, −0.45 at 18 ticks and
    Q = 16,188 e⁻ (tick rounding, module notes), read −0.32 in a 200-tick recording: about each
    pixel's own mean, the n − 1 divisor overestimates γ₀ by ≈ (1/6)/(n − 1) for intervals that
    are anti-correlated. The table's figure is now mean-free, 1 − D₁/D₂, and matches the
    steady-pixel value from the model at any length: within 5 standard errors (batch means
    over 16 column bands of pixels) plus 0.01 for the fitted Q_eff's own error."""
    q = 16_188
    s = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, gain_spread_fraction=0.03)
    clock = s.parameters.clock_hz
    mu = np.geomspace(16, 21, 64)[None, :].repeat(64, 0)
    rec = s.capture(StillScene(s.parameters.optics.lux_from_electrons_per_s(q / mu * clock)), ticks / clock, seed=3)
    r = calibrate(rec)
    row = max(r["interval_table"], key=lambda x: x["pairs"])
    st = interval_statistics(rec)
    band = np.arange(64 * 64) % 64 // 4  # 16 bands of 4 columns
    d1 = np.bincount(band, st.sum_lag1) / np.bincount(band, st.n_pairs)
    d2 = np.bincount(band, st.sum_lag2) / np.bincount(band, st.n_triples)
    se = np.std(1 - d1 / d2, ddof=1) / 4
    assert abs(row["lag1_correlation"] - row["expected_lag1_correlation"]) < 5 * se + 0.01
    assert row["static_consistent"]


def _scene_light(kind, h, w):
    """Relative light of the texture scenes of benchmarks/bench_hot_pixels.py (0–1)."""
    if kind == "strip":  # a 3.4-px bright strip under a dark edge, edges at sub-pixel positions
        y = np.arange(h)[:, None].astype(float)
        top = h * 0.4 + 0.3 * np.sin(np.arange(w)[None] / 17.0)

        def inside(a, b):
            return np.clip(np.minimum(b, y + 1) - np.maximum(a, y), 0.0, 1.0)

        dark, bright = inside(-np.inf, top), inside(top, top + 3.4)
        return 0.45 * (1 - dark - bright) + 0.03 * dark + bright
    from skimage import data, transform

    return transform.resize(getattr(data, kind)() / 255.0, (h, w), anti_aliasing=True, order=1)


@pytest.mark.parametrize("kind", ["strip", "camera", "coins"])
@pytest.mark.parametrize("q", [1000.0, 16250.0])
def test_hot_pixels_on_realistic_texture(kind, q):
    """Hot pixels on a bright strip under a dark edge and on natural images (skimage's camera, a
    tuning scene, and coins, a report scene; 2 % PRNU; light 0.01–0.30 spikes a tick): the twin
    without hot pixels gets no report (the old rule reported 320–1,100 per 10⁵ pixels here);
    with 1 % hot pixels of 0.1 spikes a tick, those in the pixels the calibration says can show
    them are found at a rate not 3 binomial σ below 90 %, ≤ 5 % of the reports are false, the dark current is within
    5 standard errors, and the hot fraction's 95 % range holds this twin's own hot fraction."""
    from viform.measure.calibration import _hot_dead, hot_pixel_statistics

    h, w, ticks, clock, hot_rate = 96, 128, 400, 40e3, 0.1
    rate = 0.01 + 0.29 * _scene_light(kind, h, w)
    reports = []
    for fraction in (0.0, 0.01):
        s = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=20.0, gain_spread_fraction=0.02,
                        hot_pixel_fraction=fraction, hot_pixel_dark_current_e_per_s=hot_rate * q * clock,
                        fixed_pattern_seed=31)
        lux = s.parameters.optics.lux_from_electrons_per_s(rate * q * clock)
        st = interval_statistics(s.capture(StillScene(lux), ticks / clock, seed=2))
        d, hot, dead = _hot_dead(st, q)
        truth = s.dark_current_map_e_per_s(h, w) > 0.5 * hot_rate * q * clock
        reports.append((d, hot, truth, st, dead))
    d0, hot0, _, _, _ = reports[0]
    assert d0["hot_pixels"] == 0 and hot0.sum() == 0
    d, hot, truth, st, dead = reports[1]
    assert (hot & ~truth).sum() <= 0.05 * hot.sum()
    level = d["hot_pixel_dark_current_e_per_s"]
    assert abs(level - hot_rate * q * clock) <= 5 * d["hot_pixel_dark_current_standard_error_e_per_s"]
    searchable = (hot_pixel_statistics(st, q)["limit"] * q * clock <= 0.5 * level) & ~dead
    n = int((truth & searchable).sum())  # found ~ Binomial(n, recall): not 3σ below a recall of 0.9
    assert n >= 10 and (hot & truth & searchable).sum() >= 0.9 * n - 3 * math.sqrt(0.09 * n)
    lo, hi = d["hot_pixel_fraction_range"]
    assert lo <= truth.mean() <= hi
    assert d["hot_pixels_with_reported_neighbour_fraction"] <= 3 * d["hot_pixels_with_reported_neighbour_if_random"] \
        + 0.05
