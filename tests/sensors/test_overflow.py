"""Conditional-overflow triple-integration pixel (seed 003): equations, curve, timing, bad input."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.radiometry import ELEMENTARY_CHARGE_C
from viform.light.scenes import Scene, StillScene
from viform.measure.emva1288 import measure_response, plateau_onset
from viform.sensors.catalog import make_sensor
from viform.sensors.overflow import (
    PAPER003_INTEGRATIONS_S,
    OverflowSensor,
    dynamic_range_gain_db,
    overflow_voltages_v,
    paper003_pixel_parameters,
    segment_boundaries_a,
    share_charge_v,
)


def db(ratio):
    return 20 * np.log10(ratio)


def test_charge_sharing_eq1_by_hand():
    """Eq. 1: V' = (V_PD·C_PD + V_CF·C_F)/(C_F + C_PD) only when V_PD < V_CF."""
    # (1.0·100 + 2.2·500)/600 = 1200/600 = 2.0 V
    assert float(share_charge_v(1.0, 2.2, 100e-15, 500e-15)) == pytest.approx(2.0, abs=1e-12)
    # (0.3·100 + 2.2·500)/600 = 1130/600
    assert float(share_charge_v(0.3, 2.2, 100e-15, 500e-15)) == pytest.approx(1130 / 600, abs=1e-12)
    # V_PD above V_CF: untouched.
    assert float(share_charge_v(2.7, 2.2, 100e-15, 500e-15)) == 2.7
    np.testing.assert_allclose(share_charge_v([2.7, 1.0], 2.2, 100e-15, 500e-15), [2.7, 2.0])


def test_eqs_3_5_6_chain_by_hand():
    """V1 = V_res − I·t1/C; V20 (eq. 5); V2; V30 (eq. 6); V3 — for I = 50 pA, C_PD = 100 fF."""
    i, c = 50e-12, 100e-15
    v1, v2, v3 = overflow_voltages_v(i, c, 500e-15, 3.3, 2.2, 0.3, (32.8e-3, 0.5e-3, 0.03e-3))
    # t1: 3.3 − 50e-12·32.8e-3/1e-13 = 3.3 − 16.4 → floored at V_sat = 0.3 V
    assert float(v1) == pytest.approx(0.3)
    v20 = (0.3 * 100 + 2.2 * 500) / 600  # 1.88333 V
    assert float(v2) == pytest.approx(v20 - 50e-12 * 0.5e-3 / 100e-15)  # − 0.25 V = 1.63333 V
    v30 = (float(v2) * 100 + 2.2 * 500) / 600  # V2 < V_CF, so eq. 6 applies: 2.10556 V
    assert float(v3) == pytest.approx(v30 - 50e-12 * 0.03e-3 / 100e-15)  # − 0.015 V


def test_segment_boundaries_match_seed003_fig6():
    """Seed 003 §6: the 4T saturates at ~8 pA; DE spans 270 pA < I_ph < 10 nA.

    C_PD is calibrated so the plain 4T saturates at 8 pA (seed gives no capacitance); the
    overflow pixel's C (saturation in t1) then lands at 8.1 pA and D (saturation in t2
    after the first sharing) at 287 pA, 0.5 dB from the seed's 270 pA.
    """
    s = OverflowSensor(height=32, width=32)
    b = s.segment_boundaries_a()
    assert b["B"] < b["C"] < b["D"] < b["E"]
    assert abs(db(b["C"] / 8e-12)) < 1.0
    assert abs(db(b["D"] / 270e-12)) < 1.0
    # Same numbers from the free function.
    assert segment_boundaries_a(s.c_pd_f, 500e-15, 3.3, 2.2, s.v_sat_v)["D"] == pytest.approx(b["D"])


def measured_saturation_current_a(sensor, currents_a, seed=0):
    """Plateau onset (A) of the mean response measured on 16×16 noisy flat fields."""
    lux = sensor.parameters.optics.lux_from_electrons_per_s(currents_a / ELEMENTARY_CHARGE_C)
    resp = measure_response(sensor, lux, height=16, width=16, seed=seed)
    return plateau_onset(currents_a, resp["signal_dn"]), resp


#: The response sweep below: 260 log-spaced currents over 6.5 decades.
SWEEP_CURRENTS_A = np.geomspace(1e-14, 3e-8, 260)


def test_dynamic_range_gain_over_4t():
    """Seed 003 §6 claims ≈ 62 dB = 20·lg(10 nA / 8 pA); this model gives 55.5 dB. NOT reproduced.

    The low ends coincide (segment AB is the 4T response), so the gain is E / I_4T with
    I_4T = (V_res − V_sat)·C_PD/T (T = t1 + t2 + t3 = 33.33 ms) and E = (V30 − V_sat)·C_PD/t3,
    where in segment DE eqs. 5–6 give V30 = (V_sat·C_PD + VF·C_F)/(C_F + C_PD) = 1.913 V
    (C_PD = 88.9 fF, V_sat = 0.3 V). E / I_4T = 1111 × (1.613 / 3.0) = 597 → 55.53 dB,
    E = 4.78 nA. The charge moved to C_F is never read, so C_F does not enlarge the well that
    t3 fills; see test_62db_is_out_of_reach_of_eqs_1_to_6 for the general bound.

    Tolerance: the plateau onset is interpolated on a grid with 5.9 % (0.50 dB) steps, which
    places it up to one step past the kink, and the 1 % PRNU delays the 99.9 % point by ~0.9 %
    (0.08 dB); each end is late by 0…0.6 dB, so the gain is within ±0.6 dB of the equations.
    """
    step_db = db(SWEEP_CURRENTS_A[1] / SWEEP_CURRENTS_A[0])
    tol_db = step_db + 0.1
    sensor = OverflowSensor(height=16, width=16)
    over, _ = measured_saturation_current_a(sensor, SWEEP_CURRENTS_A)
    four_t, _ = measured_saturation_current_a(make_sensor("seed003-4t"), SWEEP_CURRENTS_A)
    e_a = sensor.segment_boundaries_a()["E"]
    i_4t_a = (sensor.v_reset_v - sensor.v_sat_v) * sensor.c_pd_f / sum(PAPER003_INTEGRATIONS_S)
    assert i_4t_a == pytest.approx(8e-12, rel=1e-3)  # the C_PD calibration (seed: ~8 pA)
    assert e_a == pytest.approx(1.613 * sensor.c_pd_f / 0.03e-3, rel=1e-3)  # 4.78 nA
    assert -0.1 < db(four_t / i_4t_a) < tol_db
    assert -0.1 < db(over / e_a) < tol_db
    gain = db(over / four_t)
    assert sensor.dynamic_range_gain_db() == pytest.approx(55.53, abs=0.01)
    assert abs(gain - sensor.dynamic_range_gain_db()) < tol_db
    assert gain < 62.0 - 5.0  # the seed's figure is not reached (documented above)


def test_62db_is_out_of_reach_of_eqs_1_to_6():
    """Seed 003's 62 dB exceeds what eqs. 1, 3, 5, 6 allow for ANY C_PD, C_F and V_sat.

    E / I_4T = (T/t3)·(VF − V_sat)/(V_res − V_sat)·C_F/(C_F + C_PD) < (T/t3)·VF/V_res
    = 1111 × 2.2/3.3 → 57.39 dB < 62 dB: t3 starts at V30 ≤ VF = 2.2 V, so it has less swing
    than the 4T's 3.3 V reset, and the 4T integrates T/t3 = 1111× longer (60.9 dB); 62 dB
    = 1250× would need more. The seed's own numbers agree: D (saturation within t2) and E
    both start from V20 = V30, so E/D = t2/t3 = 16.7 exactly, and its D = 270 pA gives
    E = 4.5 nA → 55.0 dB; "10 nA" (10 nA / 270 pA = 37) is inconsistent with eqs. 5–6.
    """
    t_frame_s, t3_s = sum(PAPER003_INTEGRATIONS_S), PAPER003_INTEGRATIONS_S[2]
    sup_db = db(t_frame_s / t3_s * 2.2 / 3.3)
    assert sup_db == pytest.approx(57.39, abs=0.01)
    gains = [
        dynamic_range_gain_db(c_pd, c_f, 3.3, 2.2, v_sat)
        for c_pd in np.geomspace(1e-15, 1e-11, 9)
        for c_f in np.geomspace(1e-15, 1e-10, 11)
        for v_sat in (0.0, 0.1, 0.3, 1.0, 2.0)
    ]
    assert max(gains) < sup_db
    assert max(gains) > sup_db - 0.01  # the bound is tight (V_sat = 0, C_F ≫ C_PD)
    # Seed self-consistency check through the model: E/D = t2/t3 for any capacitances.
    for c_pd in (10e-15, 88.9e-15, 1e-12):
        b = segment_boundaries_a(c_pd, 500e-15, 3.3, 2.2, 0.3)
        assert b["E"] / b["D"] == pytest.approx(0.5e-3 / 0.03e-3, rel=1e-12)
    assert db(270e-12 * (0.5e-3 / 0.03e-3) / 8e-12) == pytest.approx(55.0, abs=0.01)


def test_low_light_identical_to_4t_and_compressed_above():
    """Segment AB: same response as the plain 4T APS (noise-free, identical DN); BC…DE: lower slope."""
    overflow = OverflowSensor(height=8, width=8, noise=False)
    four_t = make_sensor("seed003-4t", noise=False)
    b = overflow.segment_boundaries_a()
    currents = np.linspace(0.02, 0.95, 64).reshape(8, 8) * b["B"]
    scene = StillScene(overflow.lux_from_photocurrent(currents))
    np.testing.assert_array_equal(
        overflow.capture_frame(scene, 0.0), four_t.capture_frame(scene, 0.0, four_t.exposure_s)
    )

    # Local slopes of the noise-free curve, signal e⁻ per ampere, against eqs. 3, 5, 6:
    # AB: V3 = V_res − I·T/C_PD → T/q. CD (t1 saturated): V30 = (V2·C_PD + VF·C_F)/(C_F + C_PD)
    # with V2 = V20 − I·t2/C_PD, then − I·t3/C_PD → (t2·C_PD/(C_F + C_PD) + t3)/q.
    # DE (t1 and t2 saturated): only t3 counts → t3/q. AB/DE = T/t3 = 1111 (the compression).
    def slope(i0, i1):
        s0, s1 = overflow.expected_signal_electrons(np.array([i0, i1]))
        return (s1 - s0) / (i1 - i0)

    t1, t2, t3 = overflow.integration_times_s
    c_pd, c_f, q = overflow.c_pd_f, overflow.overflow_capacitance_f, ELEMENTARY_CHARGE_C
    ab = slope(0.2 * b["B"], 0.8 * b["B"])
    bc = slope(1.2 * b["B"], 0.9 * b["C"])
    cd = slope(1.2 * b["C"], 0.8 * b["D"])
    de = slope(1.2 * b["D"], 0.8 * b["E"])
    assert ab == pytest.approx((t1 + t2 + t3) / q, rel=1e-9)
    assert cd == pytest.approx((t2 * c_pd / (c_f + c_pd) + t3) / q, rel=1e-9)
    assert de == pytest.approx(t3 / q, rel=1e-9)
    assert ab > bc > cd > de > 0


def test_response_is_monotonic():
    s = OverflowSensor(height=4, width=4, noise=False)
    currents = np.geomspace(1e-15, 1e-7, 3000)
    sig = s.expected_signal_electrons(currents)
    assert np.all(np.diff(sig) >= -1e-6)
    _, resp = measured_saturation_current_a(s, currents[::60])
    assert np.all(np.diff(resp["signal_dn"]) >= 0)


def test_noisy_capture_matches_equations_on_average():
    """Mean of noisy frames (Poisson charge, read noise, ADC) ≈ eqs. 1–6, dark-subtracted.

    32 × 32 px × 2 frames per level: standard error se = √((σ²_y + σ²_y.dark)/2048) (0.007–0.024
    DN here); tolerance 4·se plus half an LSB, because the dark frame's read noise (60 e⁻ =
    0.14 DN at K = 2.3e-3 DN/e⁻) is far below one LSB, so its mean is rounded, not dithered.
    """
    s = OverflowSensor(paper003_pixel_parameters(prnu_fraction=0.0, dsnu_electrons=0.0), height=32, width=32)
    k_dn_per_e = s.parameters.system_gain_dn_per_e
    for current in (1e-12, 50e-12, 1e-9):  # segments AB, CD, DE
        lux = s.lux_from_photocurrent(current)
        resp = measure_response(s, [lux, lux * 1.0001], height=32, width=32, seed=7)
        expected_dn = (s.expected_signal_electrons(current) - s.expected_signal_electrons(0.0)) * k_dn_per_e
        se = np.sqrt((resp["sigma2_y"][0] + resp["sigma2_y_dark"]) / (2 * 32 * 32))
        assert abs(resp["signal_dn"][0] - expected_dn) < 4 * se + 0.5


def test_column_shared_unit_timing():
    """Seed 003 §5: rows × 0.51 ms must fit in 33.33 ms: 32 rows fit, 66 do not."""
    s = OverflowSensor(height=32, width=32)
    assert s.row_share_time_s == pytest.approx(0.51e-3)
    assert 32 * s.row_share_time_s < 1 / 30
    assert s.max_rows() == 65
    with pytest.raises(ViformError, match="height = 66 rows do not fit"):
        OverflowSensor(height=66, width=32)
    # Also refused at capture time when the scene sets the size.
    with pytest.raises(ViformError, match="column-shared"):
        OverflowSensor().capture_frame(StillScene(np.ones((100, 4))), 0.0)


class _TurnOn(Scene):
    """Dark until ``t_on_s``, then ``lux`` (exact window means)."""

    def __init__(self, lux, t_on_s, height, width):
        super().__init__(height, width)
        self.lux, self.t_on_s = lux, t_on_s

    def illuminance_lux(self, t_s):
        return np.full(self.shape, self.lux if t_s >= self.t_on_s else 0.0)

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        on = max(0.0, t1_s - max(t0_s, self.t_on_s))
        return np.full(self.shape, self.lux * on / (t1_s - t0_s))


def test_row_stagger_for_time_varying_scenes():
    """Rows start frame_period/rows apart (row-by-row exposure): light that turns on mid-frame
    is integrated longer by the later rows."""
    s = OverflowSensor(paper003_pixel_parameters(prnu_fraction=0.0, dsnu_electrons=0.0), height=32, width=4,
                       noise=False)
    scene = _TurnOn(s.lux_from_photocurrent(1e-12), 0.5 / 30, 32, 4)
    frame = s.capture_frame(scene, 0.0).astype(float)
    assert np.all(np.diff(frame[:, 0]) >= 0)
    assert frame[-1, 0] > frame[0, 0] + 100


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(integration_times_s=(-1e-3, 0.5e-3, 0.03e-3)), "integration_times_s"),
        (dict(integration_times_s=(40e-3, 0.5e-3, 0.03e-3)), "exceeds the frame period"),
        (dict(integration_times_s=(30e-3, 0.5e-3)), "three durations"),
        (dict(overflow_capacitance_f=0.0), "overflow_capacitance_f"),
        (dict(v_f_v=3.5), "v_f_v"),
        (dict(v_reset_v=1.0), "v_f_v"),
        (dict(parameters=paper003_pixel_parameters(full_well_electrons=3e6)), "full_well_electrons"),
        (dict(parameters=paper003_pixel_parameters(full_well_electrons=2e5)), "v_f_v"),
    ],
)
def test_bad_input_names_the_parameter(kwargs, name):
    with pytest.raises(ViformError, match=name):
        OverflowSensor(**kwargs)


# ----------------------------------------------------------------------------- issue 16: kTC, LOFIC, PGA

def test_reset_ktc_noise_as_the_seed_samples_it():
    """Seed 003 §3 reads the signal, then resets the photodiode and reads the reset level, so
    the two samples hold two independent resets' kTC noise: √(kT·C_PD)/q = 119.8 e⁻ per reset
    at 88.9 fF and 300 K (issue 16: ≈ 120 e⁻), √2 × that = 169.4 e⁻ in the difference. A
    sharing adds √(kT·C_F)/q · C_PD/(C_F + C_PD) (C_F's reset) ⊕ √(kT·C_PD·C_F/(C_PD + C_F))/q
    (the switch's partition) = 118.4 e⁻."""
    from viform.sensors.overflow import ktc_noise_electrons, share_ktc_noise_electrons

    s = OverflowSensor(paper003_pixel_parameters(), ktc_noise=True)
    assert s.c_pd_f == pytest.approx(88.9e-15, rel=1e-3)
    assert s.reset_ktc_electrons == pytest.approx(120.0, abs=0.5)
    assert s.readout_reset_noise_electrons() == pytest.approx(np.sqrt(2) * 119.76, abs=0.1)
    assert share_ktc_noise_electrons(88.9e-15, 500e-15) == pytest.approx(
        np.hypot(ktc_noise_electrons(500e-15) * 88.9 / 588.9, ktc_noise_electrons(88.9 * 500 / 588.9 * 1e-15)))
    assert s.share_ktc_electrons == pytest.approx(118.4, abs=0.2)


def test_ktc_noise_adds_its_variance_in_the_dark():
    """Monte Carlo, 64 × 64 dark pixels, 16-bit ADC (1 DN = 27 e⁻, quantization negligible):
    turning the kTC noise on adds 2 × 119.8² e⁻² of variance (no sharing in the dark).
    Tolerance 4·√(2/N) of the total variance (N = 4 096)."""
    p = paper003_pixel_parameters(adc_bits=16, dsnu_electrons=0.0)
    dark = StillScene(np.zeros((64, 64)))
    var = {}
    for ktc in (False, True):
        s = OverflowSensor(p, ktc_noise=ktc, height=64, width=64)
        dn = s.capture_frame(dark, 0.0, seed=11).astype(float)
        var[ktc] = (dn / p.system_gain_dn_per_e).var()
    added = var[True] - var[False]
    assert added == pytest.approx(2 * 119.76 ** 2, abs=4 * np.sqrt(2 / 4096) * var[True])


def test_lofic_baseline_fig5_drb():
    """Seed 003 Fig. 5: (a) plain 4T, DR_a = 20 lg E3/E1; (b) lateral-overflow capacitor read
    at low gain, DR_b = 20 lg E4/E2 — a larger well but a higher floor ("low sensitivity and
    SNR at low light"); (c) this pixel, DR_c = 20 lg E4/E1. Model with C_S = 500 fF: the
    LOFIC's saturation is (C_PD + C_S)/C_PD = 6.6 × the 4T's (±10 %: plateau detection on a
    150-point grid), its floor E2 ≥ 5 × E1, so DR_b stays within 6 dB of DR_a, while DR_c
    exceeds DR_a by the 55.5 dB the equations give (±3 dB: floors measured on 16 × 16 px)."""
    from viform.report.response_plots import paper003_fig5
    from viform.sensors.overflow import lofic_pixel_parameters

    p = lofic_pixel_parameters()
    assert p.full_well_electrons == pytest.approx(3.0 * 588.9e-15 / 1.602176634e-19, rel=1e-3)
    assert p.read_noise_electrons == pytest.approx(590, abs=2)
    r = paper003_fig5(size=12)
    a, b, c = r.values()
    assert b["i_sat_a"] / a["i_sat_a"] == pytest.approx(588.9 / 88.9, rel=0.1)
    assert b["i_min_a"] / a["i_min_a"] > 5
    assert abs(b["dynamic_range_db"] - a["dynamic_range_db"]) < 6
    assert c["dynamic_range_db"] - a["dynamic_range_db"] == pytest.approx(55.5, abs=3)


def test_pga_gain_scales_the_system_gain():
    """Seed 003 §2: CDS → PGA → ADC. A PGA gain g multiplies K by g (one DN is 1/g of the
    electrons) and the ADC then clips at 1/g of the photodiode swing."""
    p1, p4 = paper003_pixel_parameters(), paper003_pixel_parameters(analog_gain=4.0)
    assert p4.system_gain_dn_per_e == pytest.approx(4 * p1.system_gain_dn_per_e)
    s = OverflowSensor(p4, height=4, width=4, noise=False)
    bright = StillScene(np.full((4, 4), 1e4))
    assert s.capture_frame(bright, 0.0).max() == p4.max_dn
