"""Second-order effects of the seed-003 overflow pixel (issue 28), each measured back from
simulated frames against its closed form, across its range: comparator offset (column fixed
pattern) and noise at the overflow decision, column spread of C_F, switch charge injection and
the column bus added to C_F."""

import numpy as np
import pytest
from scipy.stats import norm

from viform.light.radiometry import ELEMENTARY_CHARGE_C
from viform.light.scenes import StillScene
from viform.sensors.overflow import OverflowSensor, paper003_pixel_parameters

W = 400  # columns: the std of W estimates is within 1/√(2W) = 3.5 % of the truth


def _quiet(**kw):
    """The seed pixel with no fixed pattern or read noise, a 16-bit ADC (K ≈ 0.037 DN/e⁻)."""
    return paper003_pixel_parameters(prnu_fraction=0.0, dsnu_electrons=0.0, read_noise_electrons=0.0, adc_bits=16,
                                    **kw)


def _signal_e(sensor, current_a, height=1, seed=0, frame_index=0):
    lux = np.full((height, W), float(sensor.lux_from_photocurrent(current_a)))
    dn = sensor.capture_frame(StillScene(lux), 0.0, seed=seed, frame_index=frame_index).astype(float)
    p = sensor.parameters
    return (dn - p.black_offset_dn) / p.system_gain_dn_per_e


def _current_for_v1(sensor, v1):
    """Photocurrent that brings the photodiode to ``v1`` at the end of t1 (eq. 3)."""
    i_dark = sensor.parameters.dark_current_e_per_s * ELEMENTARY_CHARGE_C
    return (sensor.v_reset_v - v1) * sensor.c_pd_f / sensor.integration_times_s[0] - i_dark


@pytest.mark.parametrize("sigma_v", [0.005, 0.03])
def test_comparator_offset_spread_is_the_spread_of_the_switching_points(sigma_v):
    """Column c shares when V_PD < VF + δ_c: sweeping V1 through VF, each column's output leaves
    the ideal comparator's response over (VF, VF + δ_c) when δ_c > 0; when δ_c < 0 over
    (VF + δ_c/r, VF), r = C_PD/(C_PD + C_F), because the first sharing leaves VF + r·x and the
    second decision (at t2) refuses it until r·x < δ_c. The measured δ_c have std σ."""
    times = (32.8e-3, 1e-6, 1e-6)  # short t2, t3: V2 ≈ V1, so the decision is the one at t1
    ideal = OverflowSensor(_quiet(), times, noise=False)
    off = OverflowSensor(_quiet(), times, noise=False, comparator_offset_v=sigma_v)
    r = off.c_pd_f / (off.c_pd_f + off.overflow_capacitance_f)
    step = sigma_v / 20
    xs = np.arange(-4 * sigma_v / r, 4 * sigma_v + step / 2, step)
    differs = np.array([np.abs(_signal_e(off, _current_for_v1(off, off.v_f_v + x))
                               - _signal_e(ideal, _current_for_v1(ideal, ideal.v_f_v + x)))[0] > 0 for x in xs])
    # each differing step is one step of |δ_c|; its sign is the side of VF it lies on
    delta = np.where(differs & (xs[:, None] > 0), step, 0.0).sum(0) - r * np.where(differs & (xs[:, None] < 0),
                                                                                    step, 0.0).sum(0)
    assert np.corrcoef(delta, off.column_maps(W)[0])[0, 1] > 0.99
    assert delta.std() == pytest.approx(sigma_v, rel=0.12)


@pytest.mark.parametrize("sigma_v", [0.01, 0.04])
def test_comparator_noise_flips_decisions_near_the_threshold(sigma_v):
    """With temporal noise σ a photodiode at VF + x shares with P = Φ(−x/σ) at each of the two
    decisions (t2, t3 short, so it sees the same V twice if it did not share): the fraction that
    never shared is (1 − Φ(−x/σ))², from which σ is measured back at several x."""
    times = (32.8e-3, 1e-6, 1e-6)
    s = OverflowSensor(_quiet(), times, comparator_noise_v=sigma_v, height=60, width=W)
    for k in (-1.0, 1.0, 1.5):  # |x| ≥ σ: the two outputs lie ≥ 6 shot-noise σ apart
        x = k * sigma_v
        v1 = s.v_f_v + x
        e = _signal_e(s, _current_for_v1(s, v1), height=60, seed=3)
        no_share = (s.v_reset_v - v1) / s.parameters.conversion_gain_v_per_e
        shared = (s.v_reset_v - (s.v_f_v + x * s.c_pd_f / (s.c_pd_f + s.overflow_capacitance_f))) \
            / s.parameters.conversion_gain_v_per_e
        never = np.mean(np.abs(e - no_share) < np.abs(e - shared))
        p = 1 - np.sqrt(never)
        assert -x / norm.ppf(p) == pytest.approx(sigma_v, rel=0.06), (k, p)


@pytest.mark.parametrize("spread", [0.02, 0.1])
def test_overflow_capacitor_spread_is_measured_back_per_column(spread):
    """Above C (saturated in t1, two sharings) the output depends on C_F through eqs. 5–6;
    inverting each column's output for C_F gives back the spread of the column capacitors."""
    from scipy.optimize import brentq

    s = OverflowSensor(_quiet(), noise=False, overflow_capacitance_spread=spread)
    current = 50e-12  # between C (8 pA) and D (287 pA)
    e = _signal_e(s, current)[0]
    ideal = OverflowSensor(_quiet(), noise=False)
    cg = s.parameters.conversion_gain_v_per_e

    def out(c_f, target):
        v3 = OverflowSensor(_quiet(), noise=False, overflow_capacitance_f=c_f).expected_voltages_v(current)[2]
        return (s.v_reset_v - v3) / cg - target

    c_f = np.array([brentq(out, 5e-15, 5e-12, args=(t,), xtol=1e-19) for t in e[:80]])
    truth = s.column_maps(W)[1][:80]
    np.testing.assert_allclose(c_f, truth, rtol=2e-3)
    assert np.std(c_f / ideal.overflow_capacitance_f) == pytest.approx(np.std(truth) / 500e-15, rel=0.01)
    assert np.std(truth) / 500e-15 == pytest.approx(spread, rel=0.25)  # 80 columns: ±16 % at 2σ


@pytest.mark.parametrize("q_inj", [-3000.0, 800.0, 12_000.0])
def test_charge_injection_shifts_the_output_by_the_surviving_sharings(q_inj):
    """Each sharing adds q_inj e⁻ of discharge. Below B nothing is shared (no shift); between C
    and D the first injection passes through the second sharing, which keeps r = C_PD/(C_PD + C_F)
    of it, and the second adds whole: q_inj·(1 + r); in DE the photodiode saturates in t2,
    erasing the first, so q_inj."""
    base = OverflowSensor(_quiet(), noise=False)
    inj = OverflowSensor(_quiet(), noise=False, charge_injection_electrons=q_inj)
    k = base.parameters.system_gain_dn_per_e
    r = base.c_pd_f / (base.c_pd_f + base.overflow_capacitance_f)
    for current, n_shares in ((1e-12, 0), (50e-12, 1 + r), (1e-9, 1)):
        shift = (_signal_e(inj, current) - _signal_e(base, current)).mean()
        assert shift == pytest.approx(n_shares * q_inj, abs=1.0 / k), (current, n_shares)


@pytest.mark.parametrize("c_bus_f", [0.0, 100e-15, 1e-12])
def test_column_bus_adds_to_the_overflow_capacitor(c_bus_f):
    """In DE the output is V_res − V3 with V30 = (V_sat·C_PD + VF·(C_F + C_bus))/(C_F + C_bus + C_PD)
    and V3 = V30 − I·t3/C_PD (eqs. 5–6 with the bus sharing with C_F); the end of the range E
    moves to (V30 − V_sat)·C_PD/t3."""
    s = OverflowSensor(_quiet(), noise=False, column_bus_capacitance_f=c_bus_f)
    c_pd, c_f = s.c_pd_f, 500e-15 + c_bus_f
    v30 = (s.v_sat_v * c_pd + s.v_f_v * c_f) / (c_f + c_pd)
    i_dark = s.parameters.dark_current_e_per_s * ELEMENTARY_CHARGE_C
    for current in (1e-9, 3e-9):
        v3 = v30 - (current + i_dark) * s.integration_times_s[2] / c_pd
        e = _signal_e(s, current).mean()
        assert e == pytest.approx((s.v_reset_v - v3) / s.parameters.conversion_gain_v_per_e,
                                  abs=1 / s.parameters.system_gain_dn_per_e)
    assert s.segment_boundaries_a()["E"] == pytest.approx((v30 - s.v_sat_v) * c_pd / s.integration_times_s[2])


@pytest.mark.parametrize("m", [0.33, 0.5])
def test_photodiode_capacitance_nonlinearity_is_measured_back_from_the_response(m):
    """A junction photodiode, C(V) = C_res·((1 + V_res/φ)/(1 + V/φ))^m: the gain of the simulated
    response, dV/dQ = 1/C(V), falls as the photodiode discharges; fitting ln C against
    ln(1 + V/φ) over 3.2 … 0.5 V gives back −m. The well to V_sat grows to Q(V_sat) > C_res·3 V,
    and the DR gain over a 4T with the same photodiode rises (≈ +0.4 dB at m = 1/3, +0.6 at 1/2)."""
    from viform.sensors.overflow import PhotodiodeJunction

    # VF just above V_sat: no overflow over the swept range, a plain integrating photodiode
    s = OverflowSensor(_quiet(), noise=False, v_f_v=0.32, junction_grading_m=m)
    cg, t = s.parameters.conversion_gain_v_per_e, sum(s.integration_times_s)
    i_dark = s.parameters.dark_current_e_per_s * ELEMENTARY_CHARGE_C
    q = np.linspace(0.1, 0.95, 40) * s.junction.discharge_c(0.5)   # charge reaching V from 3.2 to 0.5 V
    v = np.array([s.v_reset_v - _signal_e(s, qq / t - i_dark).mean() * cg for qq in q])
    np.testing.assert_allclose(v, s.junction.voltage_v(q), atol=1.5 * cg / s.parameters.system_gain_dn_per_e)
    c = np.gradient(q, v) * -1.0
    slope = np.polyfit(np.log1p(v[2:-2] / 0.7), np.log(c[2:-2]), 1)[0]
    assert -slope == pytest.approx(m, abs=0.02)
    linear = PhotodiodeJunction(s.c_pd_f, 3.3)
    assert s.well_electrons > 1.2 * linear.discharge_c(0.3) / ELEMENTARY_CHARGE_C
    gain = OverflowSensor(_quiet(), noise=False, junction_grading_m=m).dynamic_range_gain_db()
    assert 0.2 < gain - OverflowSensor(_quiet(), noise=False).dynamic_range_gain_db() < 1.0
    # eq. 1 with the junction conserves charge
    j = s.junction
    v_share = j.share_v(np.array([0.3, 1.0, 2.0]), 2.2, 500e-15)
    np.testing.assert_allclose(j.discharge_c(v_share) + 500e-15 * (2.2 - v_share),
                               j.discharge_c(np.array([0.3, 1.0, 2.0])), rtol=1e-9)
