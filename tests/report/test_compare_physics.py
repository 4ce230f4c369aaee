"""The comparison's conclusions follow physics, not tuning: vary the scene's speed and brightness and
check the orderings the sensor models predict; the metrics and the verdict on known inputs."""

import math

import numpy as np
import pytest

from viform.light.dilemma import DilemmaScene
from viform.measure import comparison as cmp
from viform.sensors.catalog import SENSORS
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
    shot = next(s for s in shots if s.key in (key, f"{key}-interval"))
    return float(shot.estimates[0].saturated.mean())


def _ceiling_lux_cmos():
    sensor = cmp.make_compare_sensor("cmos")
    p = sensor.parameters
    return (p.full_well_electrons - p.dark_current_e_per_s * sensor.exposure_s) / (
        p.optics.electrons_per_lux_second * sensor.exposure_s)


def _ceiling_lux_spike():
    p = cmp.make_compare_sensor("spikeone").parameters
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
        spike_frac.append(_saturated("spikeone", scene))
        assert cmos_frac[-1] == pytest.approx((truth > cmos_ceiling).mean(), abs=0.03)
    assert cmos_frac[0] < cmos_frac[1] < cmos_frac[2]
    assert spike_frac == [0.0, 0.0, 0.0]


def test_spike_camera_saturates_where_its_ceiling_says():
    """Above Q·f/η the spike camera fires every tick too: its saturated fraction is the share of
    pixels above that ceiling (the default dilemma: lamp 50 000 lux, window up to 3 000 lux)."""
    scene = DilemmaScene(32, 48)
    frac = _saturated("spikeone", scene)
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


@pytest.mark.parametrize("scale", [1e-9, 1e-3, 1.0, 30.0])
def test_psnr_is_skimages_to_the_bit(scale):
    """psnr_db gives skimage.metrics.peak_signal_noise_ratio's value exactly, from tiny to huge errors."""
    from skimage.metrics import peak_signal_noise_ratio

    rng = np.random.default_rng(7)
    a = rng.uniform(-2, 5, (33, 47))
    b = a + scale * rng.standard_normal(a.shape)
    assert cmp.psnr_db(a, b, 7.0) == peak_signal_noise_ratio(a, b, data_range=7.0)


def test_scoring_imports_no_scipy_stats():
    """Scoring an image (PSNR, SSIM) in a fresh process leaves scipy.stats unimported (its import costs every
    sweep worker 0.5-1 CPU-s)."""
    import subprocess
    import sys

    code = ("import sys, numpy as np\nfrom viform.measure import comparison as cmp\n"
            "x = np.full((16, 16), 10.0); y = x * np.linspace(0.5, 2, 16)\n"
            "print(cmp.log_fidelity(y, x, 0.1, 1e3)[0] > 0, 'scipy.stats' in sys.modules)")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["True", "False"]


def test_verdict_follows_the_metrics():
    """Swap two sensors' numbers and the text swaps its winners: nothing is written in advance."""
    demand = {"dynamic_range_db": 120.0, "time_resolution_s": 1e-4}
    a = _shot("alpha", edge_width_px=1.0, dr_captured_db=50.0)
    b = _shot("beta", edge_width_px=9.0, dr_captured_db=110.0)
    text = " ".join(cmp.verdict([a, b], demand))
    assert "Sharpest moving edge: alpha" in text and "Widest range rendered within a factor of 2: beta" in text
    assert "no sensor" in text
    a2 = _shot("alpha", edge_width_px=9.0, dr_captured_db=125.0, time_resolution_s=5e-5)
    b2 = _shot("beta", edge_width_px=1.0, dr_captured_db=50.0)
    text2 = " ".join(cmp.verdict([a2, b2], demand))
    assert "Sharpest moving edge: beta" in text2 and "Widest range rendered within a factor of 2: alpha" in text2
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
    motion = next(line for line in lines if line.startswith("Sharpest moving edge"))
    assert motion.startswith(f"Sharpest moving edge: {SENSORS['seed001-3seg'].label}")
    assert f"the most blurred is {SENSORS['cmos'].label}" in motion


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


def _sensor(key, label, *, lux=True, rate_hz=30.0, **metrics):
    s = _shot(label, **metrics)
    s.key, s.lux_units, s.frame_rate_hz = key, lux, rate_hz
    s.family = "spike" if key.startswith("spike") else "gated" if key == "gated" else "frame"
    return s


def test_verdict_ranks_every_sensor_on_sensor_metrics_and_names_ties():
    """Issue 27: the gated CCD (no lux image) was left out of 'least data' and 'longest latency'
    though the table showed it winning both, and four sensors at 33.33 ms were one 'longest'."""
    four = [_sensor(k, k, latency_s=1 / 30, data_rate_mb_per_s=0.369) for k in ("c1", "c10", "4t", "ovf")]
    fast = _sensor("hs", "hs", latency_s=0.0006, data_rate_mb_per_s=17.1, rate_hz=1667.0)
    gated = _sensor("gated", "gated", lux=False, latency_s=0.0727, data_rate_mb_per_s=0.307, rate_hz=25.0)
    for g in (gated,):
        for k in ("psnr_log_db", "ssim_log", "edge_width_px", "flicker_error", "dr_captured_db"):
            g.metrics[k] = math.nan
    skipped = cmp.Shot("x", "ex", "ex", skipped="not in range")
    lines = cmp.verdict([*four, fast, gated, skipped], None)
    by_start = {line.split(":")[0]: line for line in lines}
    assert by_start["Least data"].startswith("Least data: gated, 0.307 MB/s")
    assert by_start["Shortest latency"] == "Shortest latency: hs, 0.6 ms; longest: gated, 72.7 ms."
    # the image metrics rank only the lux sensors, and say who was left out and why
    assert "gated" not in by_start["Closest to the truth overall (PSNR of log-lux)"]
    assert any(line.startswith("Not ranked on the image") and "gated" in line for line in lines)
    assert any(line.startswith("Not in this comparison: ex: not in range") for line in lines)
    # a tie at the precision shown names every member
    gated.metrics["latency_s"] = 1 / 30
    lines = cmp.verdict([*four, fast, gated], None)
    longest = next(line for line in lines if line.startswith("Shortest latency"))
    assert "longest: 5 sensors tie: c1, c10, 4t, ovf and gated, 33.3 ms" in longest


def test_verdict_gives_the_sharpest_edge_its_frame_interval_and_explains_spike_blur():
    """Issue 27: a 0.13 ms segment 60 times a second read as the motion winner; the spike
    interval image's 41 px blur beside a 3.8 ms median integration had no cause given."""
    seg = _sensor("seed001-2seg", "seg", rate_hz=60.0, time_resolution_s=0.13e-3, edge_width_px=0.55,
                  underexposed_fraction=0.305, latency_s=1 / 60)
    spike = _sensor("spike-interval", "spike interval", rate_hz=40e3, time_resolution_s=3.8e-3, edge_width_px=40.8,
                    edge_dark_integration_s=23.5e-3)
    slow = _sensor("seed003-4t", "4t", time_resolution_s=33.3e-3, edge_width_px=61.5)
    lines = cmp.verdict([seg, spike, slow], None)
    motion = next(line for line in lines if line.startswith("Sharpest moving edge"))
    assert "integration 0.13 ms, a new image every 16.7 ms" in motion and "only 60 images a second" in motion
    assert "30% of its pixels under-exposed" in motion or "31% of its pixels under-exposed" in motion
    assert "the most blurred is 4t at 61.5 px, because its integration time is 33.3 ms" in motion
    blur = next(line for line in lines if line.startswith("spike interval:"))
    assert "40.8 px" in blur and "every 23.5 ms" in blur and "3.8 ms" in blur


def test_verdict_bounds_the_spike_range_by_the_clip():
    """The spike camera's formula (150 dB for SpikeOne) needs 812 s intervals; a 40 ms clip shows ≤ 64 dB."""
    from viform.measure.dynamic_range import clip_limited_dynamic_range_db, dynamic_range_db

    s = _sensor("spike-interval", "spike", rate_hz=40e3)
    longest = 16250 / 20.0
    s.parameters = {"clip_s": 0.04, "longest_interval_s": longest, "formula_dr_db": dynamic_range_db(25e-6, longest),
                    "clip_limited_dr_db": clip_limited_dynamic_range_db(25e-6, longest, 0.04)}
    line = next(line for line in cmp.verdict([s], None) if line.startswith("The spike camera's range"))
    assert "at most 64 dB" in line and "150 dB" in line and "812 s" in line
    assert clip_limited_dynamic_range_db(25e-6, longest, 0.04) == pytest.approx(20 * math.log10(1600))
    assert clip_limited_dynamic_range_db(25e-6, 2.0, 10.0) == pytest.approx(dynamic_range_db(25e-6, 2.0))
