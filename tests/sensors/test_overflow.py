"""Conditional-overflow triple-integration pixel (seed 003): equations, curve, timing, bad input."""

import numpy as np
import pytest

from viform._validate import ViformError
from viform.light.radiometry import ELEMENTARY_CHARGE_C
from viform.light.scenes import Scene, StillScene
from viform.measure.emva1288 import measure_response, plateau_onset
from viform.sensors.overflow import (
    OverflowSensor,
    overflow_voltages_v,
    seed003_pixel_parameters,
    segment_boundaries_a,
    share_charge_v,
)
from viform.sensors.presets import make_sensor


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
    lux = sensor.parameters.optics.lux_from_electrons_per_s(currents_a / ELEMENTARY_CHARGE_C)
    resp = measure_response(sensor, lux, height=16, width=16, seed=seed)
    return plateau_onset(currents_a, resp["signal_dn"]), resp


def test_dynamic_range_gain_over_4t():
    """Seed 003 claims ≈ 62 dB = 20·lg(10 nA / 8 pA); this model gives ≈ 55.5 dB. NOT reproduced.

    Why: the curve ends where the photodiode saturates within the short integration, at
    E = (V30 − V_sat)·C_PD/t3, while the 4T saturates at (V_res − V_sat)·C_PD/T_frame.
    Their ratio is (T_frame/t3)·(V30 − V_sat)/(V_res − V_sat) ≤ 1111 × (V30 − V_sat)/(V_res −
    V_sat); with VF = 2.2 V, VCC = 3.3 V and C_F = 500 fF, V30 ≤ 1.91 V, so the gain cannot
    exceed ~56 dB for any C_PD and V_sat. The seed's 10 nA is the end of its plot axis
    (fig. 6(d)), not a saturation it computed. The test checks the simulated (noisy) gain
    against the equations' bound within 1 dB, and that it lies within 7 dB of the seed's.
    """
    currents = np.geomspace(1e-14, 3e-8, 260)
    over, _ = measured_saturation_current_a(OverflowSensor(height=16, width=16), currents)
    four_t, _ = measured_saturation_current_a(make_sensor("seed003-4t"), currents)
    bound = segment_boundaries_a(OverflowSensor().c_pd_f, v_sat_v=0.3)
    assert abs(db(four_t / 8e-12)) < 1.0
    gain = db(over / four_t)
    assert abs(gain - db(bound["E"] / 8e-12)) < 1.0
    assert 55.0 < gain < 62.0


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

    # Local slopes of the noise-free curve (signal e⁻ per pA) in each segment.
    def slope(i0, i1):
        s0, s1 = overflow.expected_signal_electrons(np.array([i0, i1]))
        return (s1 - s0) / (i1 - i0)

    ab = slope(0.2 * b["B"], 0.8 * b["B"])
    bc = slope(1.2 * b["B"], 0.9 * b["C"])
    cd = slope(1.2 * b["C"], 0.8 * b["D"])
    de = slope(1.2 * b["D"], 0.8 * b["E"])
    assert ab == pytest.approx((1 / 30) / ELEMENTARY_CHARGE_C * (33.33e-3 * 30), rel=0.01)
    assert ab > 10 * bc and bc > 0 and de > 0
    assert cd == pytest.approx(0.0, abs=1e-3 * ab) or cd > 0


def test_response_is_monotonic():
    s = OverflowSensor(height=4, width=4, noise=False)
    currents = np.geomspace(1e-15, 1e-7, 3000)
    sig = s.expected_signal_electrons(currents)
    assert np.all(np.diff(sig) >= -1e-6)
    _, resp = measured_saturation_current_a(s, currents[::60])
    assert np.all(np.diff(resp["signal_dn"]) >= 0)


def test_noisy_capture_matches_equations_on_average():
    """Mean of noisy frames ≈ eqs. 1–6 (Poisson noise, 64 px × 2 frames, tolerance 4 standard errors)."""
    s = OverflowSensor(seed003_pixel_parameters(prnu_fraction=0.0, dsnu_electrons=0.0), height=32, width=32)
    for current in (1e-12, 50e-12, 1e-9):
        lux = s.lux_from_photocurrent(current)
        resp = measure_response(s, [lux, lux * 1.0001], height=32, width=32, seed=7)
        expected_dn = s.expected_signal_electrons(current) * s.parameters.system_gain_dn_per_e
        se = np.sqrt(resp["sigma2_y"][0] / (2 * 32 * 32) + 1 / 12)
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
    s = OverflowSensor(seed003_pixel_parameters(prnu_fraction=0.0, dsnu_electrons=0.0), height=32, width=4, noise=False)
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
    ],
)
def test_bad_input_names_the_parameter(kwargs, name):
    with pytest.raises(ViformError, match=name):
        OverflowSensor(**kwargs)
