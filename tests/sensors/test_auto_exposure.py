"""Auto-exposure, seed 002 §3.2.4 eq. (6) with the [R_i − 15, R_i + 15] dead band."""

import math

import numpy as np
import pytest

from viform._validate import ViformError
from viform.isp.highspeed_pipeline import HighSpeedConfig, StepsScene, metering_demo, run_highspeed
from viform.light.scenes import TranslatingScene
from viform.sensors.auto_exposure import (
    AutoExposure,
    MeanMeter,
    PercentileMeter,
    WeightedMeter,
    settle_frames,
)

T_UP, T_DOWN = 0.02, 0.05  # s: ×10 then ×0.1


def test_proportional_law_and_dead_band():
    ae = AutoExposure(max_exposure_cycles=59_999, target_gray=128, band_gray=15)
    assert ae.next_exposure(140.0, 10_000) == 10_000          # inside the band: unchanged
    assert ae.next_exposure(116.0, 10_000) == 10_000
    assert ae.next_exposure(64.0, 10_000) == 20_000           # T_i = T_p · R_i / R_p
    assert ae.next_exposure(200.0, 10_000) == 6_400
    assert ae.next_exposure(1.0, 50_000) == 59_999            # bounded by the frame
    assert ae.next_exposure(255.0, 1) == 1                    # at least one cycle
    assert isinstance(ae.next_exposure(77.7, 12_345), int)    # whole clock cycles


def test_black_level_is_subtracted():
    ae = AutoExposure(59_999, target_gray=130, black_level_gray=2)
    assert ae.next_exposure(66.0, 10_000) == 20_000


@pytest.mark.parametrize("value", [-1, 256, 300])
def test_target_gray_outside_0_255_names_the_parameter(value):
    with pytest.raises(ViformError, match="target_gray"):
        AutoExposure(59_999, target_gray=value)
    with pytest.raises(ViformError, match="target_gray"):
        run_highspeed(TranslatingScene(8, 8), HighSpeedConfig(n_frames=1, target_gray=value))


def test_meters():
    g = np.zeros((10, 10), dtype=np.uint8)
    g[4:6, 4:6] = 200
    assert MeanMeter()(g) == pytest.approx(8.0)
    assert WeightedMeter(sigma_fraction=0.05)(g) > 150          # centre dominates
    w = np.zeros((10, 10))
    w[0, 0] = 1
    assert WeightedMeter(weights=w)(g) == 0
    assert PercentileMeter(99)(g) == pytest.approx(200)
    assert settle_frames([0, 0, 128, 200, 128, 128], 128, 15, 0) == 4
    assert settle_frames([0, 0, 128, 128, 128, 0], 128, 15, 0) is None


def _step_run(latency, saturated_cut=None):
    base = TranslatingScene(36, 64, velocity_px_per_s=(0.0, 0.0), min_lux=50.0, max_lux=400.0)
    scene = StepsScene(base, [(T_UP, 10.0), (T_DOWN, 0.1)])
    cfg = HighSpeedConfig(n_frames=130, exposure_s=200e-6, equalize=False, ae_latency_frames=latency,
                          ae_saturated_cut=saturated_cut)
    return run_highspeed(scene, cfg)


def test_saturated_step_only_when_mostly_saturated():
    """(A2): N·k only when ≥ half the pixels sit at 255 and the gray is above the band;
    never a smaller cut than eq. (6) would make; invalid k named."""
    ae = AutoExposure(59_999, target_gray=128, saturated_cut=0.125)
    full = np.full((4, 4), 255, dtype=np.uint8)
    assert ae.update(full, 16_000) == (255.0, 2_000)
    half = full.copy()
    half[:2] = 200                                    # 50 % saturated: cut
    assert ae.update(half, 16_000)[1] == 2_000
    few = full.copy()
    few[:3] = 200                                     # 25 % saturated: eq. (6) only
    assert ae.update(few, 16_000)[1] == round(16_000 * 128 / few.mean())
    assert AutoExposure(59_999, target_gray=128).update(full, 16_000)[1] == round(16_000 * 128 / 255)
    for bad in (0, 1, 1.5):
        with pytest.raises(ViformError, match="saturated_cut"):
            AutoExposure(59_999, saturated_cut=bad)


@pytest.mark.parametrize("latency", [0, 1])
def test_saturated_step_settles_in_two_updates_without_oscillating(latency):
    """With (A2), k = 1/8: the cut frame is unsaturated (10/8 of the target exposure), so the
    next eq. (6) update lands in the band: ≤ 2 updates = 2 (1 + latency) frames after the step
    (the seed's eq. (6) alone needs 4 updates here); then N stays constant."""
    r = _step_run(latency, saturated_cut=0.125)
    up = int(math.floor(T_UP * 1e8 / 6e4))
    down = int(math.floor(T_DOWN * 1e8 / 6e4))
    g, n = r.metered_gray, r.exposure_cycles
    s_up = settle_frames(g[:down], 128, 15, up)
    assert s_up is not None and s_up <= 2 * (1 + latency)
    seed_only = settle_frames(_step_run(latency).metered_gray[:down], 128, 15, up)
    assert seed_only > s_up
    assert g[up:down].min() >= 128 - 15
    assert np.all(np.diff(n[up:down + 1]) <= 0)
    assert np.all(n[up + s_up + 1 + latency:down] == n[down - 1])
    assert n[down - 1] / n[up - 1] == pytest.approx(0.1, rel=0.15)


@pytest.mark.parametrize("latency", [0, 1])
def test_settles_after_10x_steps_without_oscillating(latency):
    """A 10× brighter scene saturates; the mean is then ≤ 255 so each update cuts the
    exposure by at least R_i/255 ≈ ½: ≤ ceil(log2 10) + 1 = 5 updates, each taking
    1 + latency frames, plus the frame the step falls in. A 10× darker scene is linear:
    one update (≤ 2 (1 + latency) + 1 frames)."""
    r = _step_run(latency)
    per_update = 1 + latency
    period = 1e8 / 6e4
    up = int(math.floor(T_UP * period))       # first frame whose exposure sees the step
    down = int(math.floor(T_DOWN * period))
    g, n = r.metered_gray, r.exposure_cycles
    assert abs(g[up - 1] - 128) <= 15                          # settled before the step
    s_up = settle_frames(g[:down], 128, 15, up)
    s_down = settle_frames(g, 128, 15, down)
    assert s_up is not None and s_up <= 5 * per_update + 1
    assert s_down is not None and s_down <= 2 * per_update + 1
    # No oscillation: the gray never crosses to the far side of the band, and the
    # exposure moves one way only, until the next step.
    assert g[up:down].min() >= 128 - 15
    assert np.all(np.diff(n[up:down + 1]) <= 0)
    assert g[down:].max() <= 128 + 15
    assert np.all(np.diff(n[down:]) >= 0)
    # Exposure tracks the light: 10× shorter after the up step.
    assert n[down - 1] / n[up - 1] == pytest.approx(0.1, rel=0.15)


def test_bright_background_mean_metering_fails_weighted_does_not():
    """Seed 002 §4: mean-gray feedback fails when background and target differ strongly.
    Backlit target (20× darker, 16 % of the frame): mean metering leaves it near black;
    centre-weighted metering brings it to mid-gray. A small bright spot: mean metering
    saturates it, percentile metering (p99, target 200) does not."""
    d = metering_demo(render_shape=(45, 80), n_frames=20)
    assert d["backlit/mean"]["target_mean_gray"] < 20
    assert d["backlit/weighted"]["target_mean_gray"] > 64
    assert d["backlit/weighted"]["target_saturated_fraction"] == 0
    assert d["spot/mean"]["target_saturated_fraction"] > 0.5
    assert d["spot/percentile"]["target_saturated_fraction"] < 0.05
