"""The comparison's conclusions follow physics, not tuning: vary the scene's speed and brightness and
check the orderings the sensor models predict; the metrics and the verdict on known inputs."""

import math

import numpy as np
import pytest

from viform.light.dilemma import DilemmaScene
from viform.measure import comparison as cmp
from viform.sensors.frame import FramePixelParameters, FrameSensor


def _edge_width(sensor, scene, t_s):
    stack = sensor.capture(scene, sensor.exposure_s, seed=3)
    est = cmp.frame_estimates(sensor, stack, [t_s])[0]
    r = scene.regions()
    return cmp.edge_width_px(est.lux, r["edge_rows"], r["edge_dark_lux"], r["edge_bright_lux"])


def test_blur_width_grows_with_exposure_times_speed():
    """A box-blurred step of length L = v·T has a 10–90 % width of 0.8·L (plus < 1 px of pixel
    sampling): checked for three exposures at two speeds, and the order follows v·T."""
    results = []
    for speed in (0.5, 1.0):
        scene = DilemmaScene(40, 96, speed=speed)
        for exposure_s in (0.4e-3, 1.6e-3, 6.4e-3):
            sensor = FrameSensor(FramePixelParameters(), exposure_s=exposure_s, frame_rate_hz=30.0)
            width = _edge_width(sensor, scene, exposure_s / 2)
            blur_px = scene.vehicle_speed_px_per_s * exposure_s
            assert width == pytest.approx(0.8 * blur_px, abs=1.0 + 0.1 * blur_px), (speed, exposure_s)
            results.append((blur_px, width))
    results.sort()
    widths = [w for _, w in results]
    blurs = [b for b, _ in results]
    # strictly growing wherever v·T differs by more than the 1 px sampling slack
    for (b0, w0), (b1, w1) in zip(results, results[1:], strict=False):
        if b1 - b0 > 2.0:
            assert w1 > w0, (blurs, widths)


def _saturated(key, scene, duration_s=0.012):
    shots = cmp.shoot(key, scene, duration_s, [duration_s / 2], seed=5)
    shot = next(s for s in shots if s.key in (key, "spike-interval"))
    return float(shot.estimates[0].saturated.mean())


def _ceiling_lux_cmos():
    sensor = cmp.make_compare_sensor("cmos")
    p = sensor.parameters
    return (p.full_well_electrons - p.dark_current_e_per_s * sensor.exposure_s) / (
        p.optics.electrons_per_lux_second * sensor.exposure_s)


def _ceiling_lux_spike():
    p = cmp.spike_preset()[0].parameters
    return p.threshold_electrons * p.clock_hz / p.optics.electrons_per_lux_second  # one spike every tick


def test_saturation_grows_with_brightness_for_the_cmos_not_the_spike_camera():
    """The 10 ms CMOS saturates above FW/(η·T) ≈ 24 lux, the spike camera above Q·f/η ≈ 1 400 lux
    (one spike per tick at Q = 10 000 e⁻, 40 kHz). In a scene whose brightest light stays below the
    spike camera's ceiling, raising the brightness raises the CMOS's saturated fraction and leaves
    the spike camera's at zero; each fraction is the share of pixels whose light exceeds the
    sensor's ceiling (PRNU and noise move the edge by a few % of it: tolerance 0.03)."""
    cmos_ceiling, spike_ceiling = _ceiling_lux_cmos(), _ceiling_lux_spike()
    assert cmos_ceiling < 100 < 1000 < spike_ceiling
    cmos_frac, spike_frac = [], []
    for brightness in (0.5, 2.0, 8.0):
        scene = DilemmaScene(32, 48, brightness=brightness, window_lux=40.0, lamp_lux=100.0)
        truth = scene.mean_illuminance_lux(0.0, 0.010)  # the CMOS integrates the first 10 ms
        assert truth.max() < spike_ceiling
        cmos_frac.append(_saturated("cmos", scene))
        spike_frac.append(_saturated("spike", scene))
        assert cmos_frac[-1] == pytest.approx((truth > cmos_ceiling).mean(), abs=0.03)
    assert cmos_frac[0] < cmos_frac[1] < cmos_frac[2]
    assert spike_frac == [0.0, 0.0, 0.0]


def test_spike_camera_saturates_where_its_ceiling_says():
    """Above Q·f/η the spike camera fires every tick too: its saturated fraction is the share of
    pixels above that ceiling (the default dilemma: lamp 50 000 lux, window up to 3 000 lux)."""
    scene = DilemmaScene(32, 48)
    frac = _saturated("spike", scene)
    truth = scene.illuminance_lux(0.006)
    expected = (truth > _ceiling_lux_spike()).mean()
    assert expected > 0.02
    assert frac == pytest.approx(expected, abs=0.03)


# ------------------------------------------------------------------ metrics on known inputs
def test_edge_width_of_a_known_ramp():
    """A linear ramp of 10 px between the plateaus has a 10–90 % width of 8 px (in log-lux)."""
    x = np.arange(80, dtype=float)
    log_profile = np.clip((50 - x) / 10, 0, 1)  # 1 (bright) left of 40 … 0 (dark) right of 50
    lux = 10 ** (log_profile * 1.0) * 1.5  # 1.5 lux dark, 15 lux bright: one decade
    image = np.tile(lux, (10, 1))
    assert cmp.edge_width_px(image, (2, 8), 1.5, 15.0) == pytest.approx(8.0, abs=0.05)
    assert math.isnan(cmp.edge_width_px(np.full((10, 80), 1.5), (2, 8), 1.5, 15.0))


def test_log_fidelity_bounds():
    rng = np.random.default_rng(0)
    truth = 10 ** rng.uniform(-1, 3, (24, 24))
    psnr, ssim = cmp.log_fidelity(truth, truth, 0.05, 2e3)
    assert psnr == 99.0 and ssim == pytest.approx(1.0)
    psnr2, _ = cmp.log_fidelity(truth * 2, truth, 0.05, 2e3)  # a uniform 0.301-decade error
    assert psnr2 == pytest.approx(20 * math.log10(math.log10(4e4) / math.log10(2)), abs=0.3)


def _shot(label, **metrics):
    s = cmp.Shot(label, label, label, time_resolution_s=metrics.pop("time_resolution_s", 1e-3))
    base = dict(psnr_log_db=20.0, ssim_log=0.5, saturated_fraction=0.1, underexposed_fraction=0.1,
                edge_width_px=5.0, flicker_error=0.5, dr_captured_db=60.0, data_rate_mb_per_s=1.0, latency_s=0.01)
    base.update(metrics)
    s.metrics = base
    s.data_rate_mb_per_s, s.latency_s = base["data_rate_mb_per_s"], base["latency_s"]
    return s


def test_verdict_follows_the_metrics():
    """Swap two sensors' numbers and the text swaps its winners: nothing is written in advance."""
    demand = {"dynamic_range_db": 120.0, "time_resolution_s": 1e-4}
    a = _shot("alpha", edge_width_px=1.0, dr_captured_db=50.0)
    b = _shot("beta", edge_width_px=9.0, dr_captured_db=110.0)
    text = " ".join(cmp.verdict([a, b], demand))
    assert "Sharpest motion: alpha" in text and "Widest range rendered within a factor of 2: beta" in text
    assert "no sensor" in text
    a2 = _shot("alpha", edge_width_px=9.0, dr_captured_db=125.0, time_resolution_s=5e-5)
    b2 = _shot("beta", edge_width_px=1.0, dr_captured_db=50.0)
    text2 = " ".join(cmp.verdict([a2, b2], demand))
    assert "Sharpest motion: beta" in text2 and "Widest range rendered within a factor of 2: alpha" in text2
    assert "Meets both the scene's range and its speed: alpha" in text2


@pytest.mark.parametrize("speed", [1.0, 2.0])
def test_motion_verdict_holds_when_the_speed_changes(speed):
    """At either speed the shortest exposure (seed 001's 130 µs) has the sharpest edge and the
    longest (10 ms) the most blurred: blur is v·T, so the order of T decides (once the 1 ms
    camera's blur, 2.5 px at speed 1, exceeds the ~1 px of pixel sampling both share)."""
    from viform.light.dilemma import DilemmaScene

    scene = DilemmaScene(40, 96, speed=speed)
    instants = [0.0005, 0.0009]  # inside every camera's first exposure window but the 10 ms one's start
    shots = []
    for key in ("cmos", "cmos-short", "seed001-3seg"):
        for shot in cmp.shoot(key, scene, 0.012, instants, seed=2):
            shot.metrics = cmp.score(shot, scene, instants)
            shots.append(shot)
    lines = cmp.verdict(shots, scene.demand())
    motion = next(line for line in lines if line.startswith("Sharpest motion"))
    assert motion.startswith(f"Sharpest motion: {cmp.SENSOR_LABELS['seed001-3seg']}")
    assert f"the most blurred is {cmp.SENSOR_LABELS['cmos']}" in motion


def test_fog_hides_targets_from_a_passive_camera_not_from_the_gated_one():
    """Contrast-to-noise of the signs: in clear air (V = 3 km) the 10 ms CMOS sees all three. In fog
    of V = 150 m their passive contrast falls as T(R)² under the airlight: the 60 m sign (contrast
    exp(−3.912·60/150) ≈ 0.2 by Koschmieder) stays visible, the 90 and 120 m ones are lost; the gated
    camera, which records only returns from beyond 40 m (seed 004), keeps a higher contrast-to-noise
    than the CMOS on every sign and still sees the 90 m one."""
    from viform.light.dilemma import NightRoadFogScene

    cnr = {}
    for visibility in (3000.0, 150.0):
        scene = NightRoadFogScene(48, 96, visibility_m=visibility)
        for key in ("cmos", "gated"):
            shot = cmp.shoot(key, scene, 0.04, [0.02], seed=4)[0]
            cnr[visibility, key] = cmp.score(shot, scene, [0.02])["target_cnr"]
    signs = [k for k in cnr[150.0, "gated"] if k.startswith("sign")]
    assert len(signs) == 3
    assert all(cnr[3000.0, "cmos"][s] > 3 for s in signs)
    assert cnr[150.0, "cmos"]["sign 90 m"] < 3 and cnr[150.0, "cmos"]["sign 120 m"] < 3
    assert cnr[150.0, "gated"]["sign 90 m"] > 3
    assert all(cnr[150.0, "gated"][s] > cnr[150.0, "cmos"][s] for s in signs)
