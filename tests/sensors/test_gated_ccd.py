"""Gated interline CCD (seed 004): gate timing, accumulation statistics, field test, bad input."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.active import ActiveScene, Medium, field_test_scene, fog_scene
from viform.light.laser import PulsedLaser
from viform.measure.gated_metrics import expected_cnr, field_test_table, measured_cnr, pulses_needed_vs_ambient
from viform.sensors.gate_timing import GateTiming
from viform.sensors.gated_ccd import GatedInterlineCCD, InterlineCCDParameters

C = 299_792_458.0


def test_gate_timing_arithmetic():
    """Seed 004 Fig. 3: delay 2R/c, t_нак = τ + t_min to the readout pulse; light counts until
    the readout pulse ends (1 µs more); range window (R − cτ/2, R + c (t_нак + t_read)/2)."""
    t = GateTiming(150.0, PulsedLaser(pulse_width_s=135e-9), 1e-6)
    assert t.open_s == pytest.approx(2 * 150.0 / C)  # 1000.7 ns
    assert t.accumulation_s == pytest.approx(1.135e-6)
    assert t.transfer_start_s == pytest.approx(t.open_s + 1.135e-6)
    assert t.width_s == pytest.approx(2.135e-6)
    lo, hi = t.range_window_m
    assert lo == pytest.approx(150.0 - C * 135e-9 / 2)
    assert hi == pytest.approx(150.0 + C * 2.135e-6 / 2)  # ≈ 470 m
    assert lo > 100.0 and hi > 300.0  # seed: 100 m rejected, 300 m seen with the gate at 150 m
    short = GateTiming(150.0, PulsedLaser(pulse_width_s=135e-9), 1e-6, readout_pulse_s=0.25e-6)
    assert short.width_s == pytest.approx(1.385e-6)


def test_gate_beyond_unambiguous_range_rejected():
    laser = PulsedLaser(repetition_hz=15e3)  # period 66.7 µs -> c/2f = 9993 m
    with pytest.raises(ViformError, match="gate_range_m.*unambiguous"):
        GatedInterlineCCD(gate_range_m=9990.0, laser=laser)
    GatedInterlineCCD(gate_range_m=9600.0, laser=laser)  # fits


def test_bad_inputs_name_the_parameter():
    with pytest.raises(ViformError, match="gate_range_m"):
        GatedInterlineCCD(gate_range_m=-10.0)
    with pytest.raises(ViformError, match="pulses = 400.*frame_rate_hz = 25"):
        GatedInterlineCCD(pulses=400, frame_rate_hz=25.0)  # (40 ms − 16.7 ms)·12.5 kHz = 291 max
    with pytest.raises(ViformError, match="pulses"):
        GatedInterlineCCD(pulses=0)
    with pytest.raises(ViformError, match="mode"):
        GatedInterlineCCD(mode="bogus")


def test_frame_rate_at_least_25_hz_for_seed_pulse_counts():
    """Seed 004: ≥ 25 Hz frame rate. With X/f_rep + 1/60 s readout, 90 pulses at 10 kHz give 39 Hz."""
    for f_rep in (10e3, 15e3):
        ccd = GatedInterlineCCD(pulses=90, laser=PulsedLaser(repetition_hz=f_rep), frame_rate_hz=25.0)
        assert 1.0 / ccd.frame_time_s() >= 25.0
        assert ccd.max_pulses(25.0) >= 90
    # per-pulse frames: every pulse costs a readout -> 25 Hz allows one or two pulses only
    assert GatedInterlineCCD(pulses=1).max_pulses(25.0, mode="sum") == 2


def _flat_scene(ambient_lux=1e3):
    return ActiveScene(
        range_m=np.full((64, 64), 200.0), reflectance=0.9, retro_coefficient_per_sr=20.0, ambient_lux=ambient_lux
    )


def _temporal(sensor, scene, seeds=(1, 2)):
    a, b = (sensor.capture_frame(scene, seed=s).electrons for s in seeds)
    return 0.5 * (a + b).mean(), 0.5 * (a - b).var(ddof=1)  # difference cancels the fixed pattern


def test_accumulation_statistics_signal_x_shot_sqrt_x_read_once():
    """Signal ∝ X; shot variance ∝ X; read noise enters once (accumulate) vs X times (sum)."""
    scene = _flat_scene()
    params = InterlineCCDParameters()
    sig_read2 = params.pixel.read_noise_electrons**2
    k = params.pixel.system_gain_dn_per_e
    q2 = 1.0 / (12 * k * k)
    n_px = 64 * 64
    tol = 5 * np.sqrt(2.0 / (n_px - 1))  # 5σ of a variance estimate from N pixels
    base = GatedInterlineCCD(pulses=1, gate_range_m=150.0, frame_rate_hz=1.0)
    mu1 = float(base.electron_budget(scene)["photo"].mean()) + float(base.electron_budget(scene)["dark"])
    assert 5 < mu1 < 200  # a few tens of e-/pulse: read noise matters
    for x in (4, 32):
        acc = GatedInterlineCCD(pulses=x, gate_range_m=150.0, mode="accumulate", frame_rate_hz=1.0)
        mean, var = _temporal(acc, scene)
        mu_x = float(acc.electron_budget(scene)["photo"].mean() + acc.electron_budget(scene)["dark"])
        assert mu_x == pytest.approx(x * mu1, rel=1e-3)  # expected signal ∝ X (leak negligible)
        assert mean == pytest.approx(mu_x, rel=0.02)  # PRNU 1 % on the mean
        assert var == pytest.approx(mu_x * (1 + 0.01**2) + sig_read2 + q2, rel=tol)  # read once
        sm = GatedInterlineCCD(pulses=x, gate_range_m=150.0, mode="sum", frame_rate_hz=0.1)
        mean_s, var_s = _temporal(sm, scene)
        assert mean_s == pytest.approx(mean, rel=0.02)
        assert var_s == pytest.approx(mu_x + x * (sig_read2 + q2), rel=tol)  # read noise X times


def test_backscatter_before_gate_rejected_in_accumulate_not_ungated():
    fog = fog_scene(height=32, width=48, visibility_m=150.0)
    clear = fog.with_(medium=Medium(0.0))
    bg = fog.retro_coefficient_per_sr == 0
    acc = GatedInterlineCCD(pulses=20, gate_range_m=50.0, mode="accumulate")
    ung = GatedInterlineCCD(pulses=20, gate_range_m=50.0, mode="ungated")
    bs_acc = (acc.electron_budget(fog)["per_pulse"]["gated"]["backscatter"])[bg].mean()
    bs_ung = (ung.electron_budget(fog)["per_pulse"]["all"]["backscatter"])[bg].mean()
    assert bs_ung > 100 * bs_acc
    # the un-gated frame's background is mostly fog; the gated one's almost none
    excess_acc = (acc.electron_budget(fog)["photo"] - acc.electron_budget(clear)["photo"])[bg].mean()
    excess_ung = (ung.electron_budget(fog)["photo"] - ung.electron_budget(clear)["photo"])[bg].mean()
    assert excess_ung > 50 * excess_acc


def test_field_test_reproduced_200_300_visible_50_100_not():
    """Seed 004 field test: gate 150 m, sunny day; 200 and 300 m glints seen, 50 and 100 m not."""
    rows = {r["range_m"]: r for r in field_test_table(gate_range_m=150.0, pulses=20, ambient_lux=1e5)}
    assert rows[200.0]["visible"] and rows[300.0]["visible"]
    assert not rows[50.0]["visible"] and not rows[100.0]["visible"]
    # and on simulated frames, not only in expectation
    scene = field_test_scene(ambient_lux=1e5)
    ccd = GatedInterlineCCD(pulses=20, gate_range_m=150.0)
    for seed in range(3):
        img = ccd.capture_frame(scene, seed=seed).electrons
        cnr = {r.range_m: measured_cnr(img, r.row, r.col) for r in scene.retroreflectors}
        assert cnr[200.0] > 5 and cnr[300.0] > 5
        assert abs(cnr[50.0]) < 5 and abs(cnr[100.0]) < 5
    # moving the gate to 250 m hides 200 m too
    rows = {r["range_m"]: r for r in field_test_table(gate_range_m=250.0, pulses=20, ambient_lux=1e5)}
    assert not rows[200.0]["visible"] and rows[300.0]["visible"]


def test_three_modes_on_one_scene():
    """Seed 004: a single long exposure is swamped (sun + un-gated returns); per-pulse frames pay
    read noise X times and run at 60/X Hz; in-buffer accumulation is best."""
    scene = field_test_scene(ambient_lux=1e5)
    r300 = scene.retroreflectors[-1]
    cnr = {}
    for mode, fr in (("ungated", 25.0), ("sum", 2.0), ("accumulate", 25.0)):
        ccd = GatedInterlineCCD(pulses=20, gate_range_m=150.0, mode=mode, frame_rate_hz=fr)
        cnr[mode] = expected_cnr(ccd, scene, r300.row, r300.col).cnr
    assert cnr["accumulate"] > cnr["sum"] > cnr["ungated"]
    assert cnr["ungated"] < 5


def test_pulses_needed_falls_with_ambient_and_grows_with_range():
    """Not the seed's 15–20 / 70–90 (see docs/range-gated.md): the model gives 1 pulse at 300 m for
    the assumed 6.3 cd/lx reflector, and at 800 m (signal 1/R⁴ ≈ 50× lower) sunny-day ambient plus
    1 % PRNU clutter keeps CNR < 5 at any X; 72 pulses suffice at 1e4 lx and 40 at night."""
    rows = pulses_needed_vs_ambient((300.0, 800.0), (1e5, 1e4, 1e-3))
    x = {(r["range_m"], r["ambient_lux"]): r["pulses_needed"] for r in rows}
    big = 10**9
    for rng in (300.0, 800.0):
        seq = [x[(rng, a)] if x[(rng, a)] is not None else big for a in (1e5, 1e4, 1e-3)]
        assert seq == sorted(seq, reverse=True)  # fewer pulses as the ambient drops
    assert (x[(800.0, 1e-3)] or big) > x[(300.0, 1e-3)]
    night = [r for r in rows if r["ambient_lux"] == 1e-3]
    assert all(r["fits_frame_rate"] and r["frame_rate_hz_at_x"] >= 25.0 for r in night)
