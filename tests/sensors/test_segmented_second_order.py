"""Second-order effects of seed 001's segmented-exposure pixel (issue 28), each measured back
from simulated frames against its closed form, across its range: a soft (sub-threshold) Rpd
barrier, noise at the clamp, and the "black sun" of the CDS reset sample."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from viform.light.scenes import StillScene
from viform.sensors.frame import FrameSensor
from viform.sensors.presets import paper001_pixel_parameters
from viform.sensors.segmented import SegmentedExposureSensor

SIZE = 64


def _quiet(**kw):
    """Seed 001's pixel with no fixed pattern, read noise or dark current, 16-bit ADC (4.8 DN/e⁻)."""
    return paper001_pixel_parameters(prnu_fraction=0.0, dsnu_electrons=0.0, read_noise_electrons=0.0,
                                    dark_current_e_per_s=0.0, adc_bits=16, **kw)


def _electrons(sensor, rate_e_per_s, size=4, seed=0):
    p = sensor.parameters
    lux = np.full((size, size), rate_e_per_s / p.optics.electrons_per_lux_second)
    dn = sensor.capture_frame(StillScene(lux), 0.0, sensor.exposure_s, seed=seed).astype(float)
    return (dn - p.black_offset_dn) / p.system_gain_dn_per_e


@pytest.mark.parametrize("q_t, barrier, r_lo, r_hi", [(100.0, 4000.0, 1.2e8, 1e10), (1000.0, 2000.0, 1.5e8, 1e9)])
def test_soft_barrier_clamp_rises_with_the_log_of_the_photocurrent(q_t, barrier, r_lo, r_hi):
    """Behind a sub-threshold barrier the kept charge settles where the drain I_0·e^{(Q−B)/Q_T}
    equals the photo-rate: Q = B + Q_T·ln(r/I_0). Fitting the simulated clamp against ln r gives
    back Q_T (slope) and I_0 (intercept)."""
    i0 = 1e7
    t1, t2 = 100e-6, 1e-9  # the second segment only reads the clamp out (adds r·1 ns)
    seg = SegmentedExposureSensor(_quiet(), (t1, t2), (barrier,), noise=False, barrier_softness_electrons=q_t,
                                  barrier_reference_e_per_s=i0)
    rates = np.geomspace(r_lo, r_hi, 8)  # the clamp is reached early and ≥ 10 Q_T/r before t1 ends: settled
    kept = np.array([_electrons(seg, r).mean() - r * t2 for r in rates])
    slope, intercept = np.polyfit(np.log(rates), kept, 1)
    assert slope == pytest.approx(q_t, rel=0.01)
    assert np.exp((barrier - intercept) / slope) == pytest.approx(i0, rel=0.05)


@pytest.mark.parametrize("rate", [2e6, 5e7, 3e8])
def test_soft_barrier_follows_the_drain_equation_in_time(rate):
    """Before it settles the clamp depends on the time too: the simulated charge after segment 1
    equals the numerical solution of dQ/dt = r − I_0·exp((Q − B)/Q_T) (scipy), for short and long
    segments, dim and bright light."""
    q_t, b, i0 = 560.0, 3000.0, 1e7
    for t1 in (20e-6, 300e-6):
        seg = SegmentedExposureSensor(_quiet(), (t1, 1e-9), (b,), frame_rate_hz=60.0, noise=False,
                                      barrier_softness_electrons=q_t, barrier_reference_e_per_s=i0)
        sol = solve_ivp(lambda _t, q: rate - i0 * np.exp((q - b) / q_t), (0.0, t1), [0.0], method="LSODA",
                        rtol=1e-10, atol=1e-6)
        expected = min(sol.y[0, -1], 10_000.0) + rate * 1e-9
        assert _electrons(seg, rate).mean() == pytest.approx(expected, abs=0.2)


@pytest.mark.parametrize("sigma", [20.0, 100.0])
def test_clamp_noise_adds_to_the_noise_above_the_knee(sigma):
    """Above the first knee the output is the clamp B_1 plus the Poisson charge of segment 2:
    variance r·T_2 + σ_clamp² (+ 1/(12K²) of the ADC). σ_clamp is measured back from 64×64 pixels."""
    seg = SegmentedExposureSensor(_quiet(), (108.333e-6, 21.667e-6), (4166.7,), clamp_noise_electrons=sigma)
    rate = 5e7  # every pixel binds (r·T1 = 5417 e⁻ ≫ B1 + 5√B1)
    e = _electrons(seg, rate, size=SIZE, seed=4)
    k = seg.parameters.system_gain_dn_per_e
    var_clamp = e.var(ddof=1) - rate * 21.667e-6 - 1 / (12 * k * k)
    # sample variance of 4096 values: relative error √(2/4096) = 2.2 % of the total, 3σ
    tol = 3 * np.sqrt(2 / e.size) * e.var()
    assert var_clamp == pytest.approx(sigma**2, abs=tol)
    assert e.mean() == pytest.approx(4166.7 + rate * 21.667e-6, abs=3 * np.sqrt(e.var() / e.size) + 0.5 / k)


@pytest.mark.parametrize("beta", [1e-5, 1e-3])
def test_black_sun_darkens_the_brightest_light(beta):
    """The reset sample holds n_r = β·r·t_rs: the CDS output min(Q + n_r, FW) − min(n_r, FW) falls
    to half the full well at r = FW/(2β·t_rs) and reaches 0 (a black sun) at FW/(β·t_rs)."""
    p = _quiet(black_sun_fraction=beta, reset_sample_time_s=1e-6)
    cam = FrameSensor(p, exposure_s=130e-6, frame_rate_hz=60.0, noise=False)
    fw = p.full_well_electrons
    r_half = fw / (2 * beta * 1e-6)
    rates = np.geomspace(r_half / 3, r_half * 3, 41)
    out = np.array([_electrons(cam, r).mean() for r in rates])
    assert np.all(np.diff(out) <= 0.5 / p.system_gain_dn_per_e)  # darker with more light
    measured = np.exp(np.interp(-fw / 2, -out, np.log(rates)))
    assert measured == pytest.approx(r_half, rel=0.01)
    assert _electrons(cam, 1.01 * fw / (beta * 1e-6)).mean() == pytest.approx(0.0, abs=0.5)
    plain = FrameSensor(_quiet(), exposure_s=130e-6, frame_rate_hz=60.0, noise=False)
    assert _electrons(plain, r_half).mean() == pytest.approx(fw, abs=0.5)  # without it: saturated, white
