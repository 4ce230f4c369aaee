"""Second-order effects of the gated interline CCD (seed 004, issue 28), each measured back from
simulated frames against its closed form, across its range: gate jitter and the SUB edge, the
smear of the vertical transfer, blooming along the register, and interlaced (field) parts."""

import numpy as np
import pytest
from scipy.stats import norm

from viform.light.active import ActiveScene, PointRetroreflector
from viform.light.laser import round_trip_time_s
from viform.sensors.gated_ccd import GatedInterlineCCD, InterlineCCDParameters, icx618_pixel_parameters

TAU = 135e-9
GATE_M = 150.0


def _params(**kw):
    pixel = icx618_pixel_parameters().__class__(**{**icx618_pixel_parameters().__dict__, "prnu_fraction": 0.0,
                                                   "dsnu_electrons": 0.0, "dark_current_e_per_s": 0.0})
    return InterlineCCDParameters(pixel=pixel, shutter_leak_ratio=kw.pop("shutter_leak_ratio", 0.0), **kw)


def _retro_scene(range_m, ambient_lux=0.0):
    return ActiveScene(range_m=np.full((15, 15), np.inf), reflectance=np.zeros((15, 15)), ambient_lux=ambient_lux,
                       retroreflectors=[PointRetroreflector(range_m, 7.0, 7.0)])


def _spot_electrons(params, range_m, pulses=4, gate_m=GATE_M):
    ccd = GatedInterlineCCD(pulses=pulses, gate_range_m=gate_m, parameters=params, noise=False)
    return ccd.capture_frame(_retro_scene(range_m)).electrons.sum()


def _whole(range_m, pulses=4):
    """The same return with the gate opened 100 m before it: all of it is collected."""
    return _spot_electrons(_params(), range_m, pulses=pulses, gate_m=range_m - 100.0)


def _g(z, sigma):
    """E[max(z − δ, 0)] for δ ~ N(0, σ²)."""
    return z * norm.cdf(z / sigma) + sigma * norm.pdf(z / sigma)


@pytest.mark.parametrize("jitter_s", [3e-9, 30e-9])
def test_gate_jitter_softens_the_opening_edge_as_a_gaussian(jitter_s):
    """A return arriving at a, gate opening at o shifted by δ ~ N(0, σ²): the kept fraction is
    E[clip(a + τ − o − δ, 0, τ)]/τ = (G(y) − G(y − τ))/τ, y = a + τ − o, G(z) = zΦ(z/σ) + σφ(z/σ).
    Measured from simulated frames at ranges across the edge, relative to a return well inside."""
    o = round_trip_time_s(GATE_M)
    for dr in (-25.0, -15.0, -8.0, 0.0, 5.0):
        a = round_trip_time_s(GATE_M + dr)
        expected = (_g(a + TAU - o, jitter_s) - _g(a - o, jitter_s)) / TAU
        measured = _spot_electrons(_params(gate_jitter_s=jitter_s), GATE_M + dr) / _whole(GATE_M + dr)
        assert measured == pytest.approx(expected, abs=0.01), dr


@pytest.mark.parametrize("fall_s", [20e-9, 100e-9])
def test_sub_fall_time_ramps_the_opening(fall_s):
    """A linear SUB ramp over t_f centred on o: kept fraction (F(y + t_f/2) − F(y − t_f/2))/(t_f·τ)
    with F the integral of clip(z, 0, τ): z²/2 up to τ, then τ²/2 + τ(z − τ)."""
    def f(z):
        return np.where(z <= 0, 0.0, np.where(z <= TAU, z * z / 2, TAU * TAU / 2 + TAU * (z - TAU)))

    o = round_trip_time_s(GATE_M)
    for dr in (-22.0, -12.0, -5.0, 0.0, 3.0):
        y = round_trip_time_s(GATE_M + dr) + TAU - o
        expected = float(f(y + fall_s / 2) - f(y - fall_s / 2)) / (fall_s * TAU)
        measured = _spot_electrons(_params(sub_fall_time_s=fall_s), GATE_M + dr) / _whole(GATE_M + dr)
        assert measured == pytest.approx(expected, abs=0.01), dr


@pytest.mark.parametrize("rise_s", [10e-9, 60e-9])
def test_laser_rise_time_smooths_both_gate_edges(rise_s):
    """A trapezoidal pulse (rise = fall = t_r, FWHM τ, same energy) is the rectangle convolved with
    a t_r box: at the closing edge c, the kept fraction is (F(z + t_r/2) − F(z − t_r/2))/(t_r·τ),
    z = c − a, F the integral of clip(z, 0, τ) (the opening is far: returns near the far end)."""
    def f(z):
        return np.where(z <= 0, 0.0, np.where(z <= TAU, z * z / 2, TAU * TAU / 2 + TAU * (z - TAU)))

    par = _params(laser_rise_time_s=rise_s)
    c = GatedInterlineCCD(pulses=4, gate_range_m=GATE_M, parameters=par).timing.close_s
    far = GATE_M + 299_792_458.0 * (c - round_trip_time_s(GATE_M)) / 2  # the range whose return starts at c
    for dr in (-25.0, -15.0, -8.0, 0.0, 4.0):
        z = c - round_trip_time_s(far + dr)
        expected = float(f(z + rise_s / 2) - f(z - rise_s / 2)) / (rise_s * TAU)
        # 200 pulses: the far glint holds ≫ 1 DN per pixel, so rounding does not bias the ratio
        measured = _spot_electrons(par, far + dr, pulses=200) / _whole(far + dr, pulses=200)
        assert measured == pytest.approx(expected, abs=0.01), dr


@pytest.mark.parametrize("smear", [1e-4, 1e-2])
def test_transfer_smear_streaks_the_column_below_a_bright_spot(smear):
    """A sunlit spot at row r0 gathers A e⁻/s: every packet that crosses it on the way out
    (rows below it, read later) gathers s·t_line·A per readout; rows above get nothing."""
    h, w, r0, c0 = 40, 9, 12, 4
    refl = np.zeros((h, w))
    refl[r0, c0] = 0.9
    scene = ActiveScene(range_m=np.full((h, w), 300.0), reflectance=refl, ambient_lux=1e5)
    on = GatedInterlineCCD(pulses=10, parameters=_params(shutter_leak_ratio=smear, transfer_smear=True), noise=False)
    off = GatedInterlineCCD(pulses=10, parameters=_params(shutter_leak_ratio=smear), noise=False)
    diff = on.capture_frame(scene).electrons - off.capture_frame(scene).electrons
    a = on.geometry.ambient_electrons_per_s(scene)[r0, c0]
    t_line = on.parameters.readout_time_s / on.parameters.sensor_height_px
    k = on.parameters.pixel.system_gain_dn_per_e
    assert np.abs(diff[: r0 + 1]).max() <= 0.5 / k + 1e-9
    assert diff[r0 + 1:, c0].mean() == pytest.approx(smear * t_line * a, abs=0.5 / k)
    assert np.abs(np.delete(diff, c0, axis=1)).max() <= 0.5 / k + 1e-9


@pytest.mark.parametrize("pulses", [40, 120])
def test_blooming_spreads_the_excess_along_the_column(pulses):
    """With blooming, a packet overfilled Q ≫ C spills up and down its column: the column keeps
    its charge (away from the ends) and shows n full packets with n ≤ Q/C ≤ n + 2 (the two
    partly filled ends of the streak)."""
    par = _params(bloom=True)
    ccd = GatedInterlineCCD(pulses=pulses, gate_range_m=110.0, parameters=par, noise=False)
    scene = ActiveScene(range_m=np.full((200, 15), np.inf), reflectance=np.zeros((200, 15)),
                        retroreflectors=[PointRetroreflector(120.0, 100.0, 7.0)])
    e = ccd.capture_frame(scene).electrons
    b = ccd.electron_budget(scene)
    cap = par.capacity_electrons
    q_col = b["photo"][:, 7].sum()
    assert q_col > 10 * cap
    assert e[:, 7].sum() == pytest.approx(q_col, rel=1e-3)
    n_full = int((e[:, 7] >= 0.999 * cap).sum())
    assert n_full <= q_col / cap <= n_full + 2
    clipped = GatedInterlineCCD(pulses=pulses, gate_range_m=110.0, parameters=_params(), noise=False)
    assert clipped.capture_frame(scene).electrons[:, 7].sum() < 0.8 * q_col  # without: the excess is lost


def test_interlaced_part_sums_row_pairs_into_a_field():
    """ICX279/ICX659 in field integration: H/2 output rows, each the sum of two photodiode rows."""
    h, w = 20, 6
    refl = np.full((h, w), 0.3)
    refl[7, :] = 0.9
    scene = ActiveScene(range_m=np.full((h, w), 150.0), reflectance=refl, ambient_lux=1e3)
    prog = GatedInterlineCCD(pulses=5, parameters=_params(), noise=False).capture_frame(scene).electrons
    field = GatedInterlineCCD(pulses=5, parameters=_params(interlaced=True), noise=False).capture_frame(scene)
    k = _params().pixel.system_gain_dn_per_e
    assert field.electrons.shape == (h // 2, w)
    np.testing.assert_allclose(field.electrons, prog[0::2] + prog[1::2], atol=1.5 / k)


@pytest.mark.parametrize("part, interlaced, rows", [("icx618", False, 494), ("icx279", True, 582),
                                                     ("icx659", True, 494)])
def test_parts_are_sensor_models_with_their_drive(part, interlaced, rows):
    """Seed 004's parts as CCD models: format, field integration and field time from the part's
    drive; the drive drawn for the sensor is the part's (readout on V1/V3 for the interlaced
    ones) with the sensor's own gate instants."""
    from viform.sensors.gated_ccd import interline_ccd_parameters
    from viform.sensors.gated_waveforms import DRIVES, V_READ_V

    par = interline_ccd_parameters(part)
    d = DRIVES[part]
    assert par.interlaced is interlaced and par.sensor_height_px == rows
    assert par.readout_time_s == pytest.approx(d.rows * d.line_time_s)
    ccd = GatedInterlineCCD(pulses=3, parameters=par)
    tr = ccd.drive_waveforms(lines=1)
    assert tr.drive.name == d.name
    fires = tr.edges("LASER", ccd.laser.peak_power_w)
    assert tr.edges(d.readout_gates[0], V_READ_V) - fires == pytest.approx([ccd.timing.transfer_start_s] * 3,
                                                                           abs=1e-12)
    scene = ActiveScene(range_m=np.full((8, 6), 150.0), reflectance=np.full((8, 6), 0.3), ambient_lux=1e3)
    assert ccd.capture_frame(scene).dn.shape == ((4, 6) if interlaced else (8, 6))
