"""Spike sensor (seed 000 §3.2, §5.1): Gamma intervals, dark firing, saturation, reproducibility.

Tolerances come from the statistics: with n independent intervals the sample mean has
standard error σ/√n and the sample standard deviation a relative standard error of
√((2 + κ)/(4n)), κ = 6/Q the Gamma excess kurtosis. Intervals are measured in whole ticks,
which adds a variance of 1/6 tick² (two uniform rounding errors); the tests keep the mean
interval long (≥ 200 ticks) so that term is small, and include it anyway.
"""

import math

import numpy as np
import pytest
from scipy import stats

from viform._validate import ViformError
from viform.light.catalog import builtin_scene
from viform.light.scenes import StepScene, StillScene, TranslatingScene
from viform.sensors._gamma import gamma_samples
from viform.sensors.spike import CHIP_THRESHOLD_LEVELS_ELECTRONS, SpikeSensor


def lux_for_electrons_per_tick(sensor, electrons_per_tick):
    p = sensor.parameters
    signal = electrons_per_tick * p.clock_hz - p.dark_current_e_per_s
    return signal / p.optics.electrons_per_lux_second


def intervals_in_ticks(spikes):
    flat = spikes.reshape(spikes.shape[0], -1)
    out = []
    for p in range(flat.shape[1]):
        out.append(np.diff(np.flatnonzero(flat[:, p])))
    return np.concatenate(out)


@pytest.mark.parametrize("q", [100, 1000])
def test_interval_mean_and_rsd_follow_gamma(q):
    """Seed 000 §5.1: mean interval Q/λ, RSD 1/√Q (10 % at Q = 100, 3.16 % at Q = 1000)."""
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    mean_ticks = 250.0
    lux = lux_for_electrons_per_tick(sensor, q / mean_ticks)
    stream = sensor.capture(StillScene(np.full((16, 16), lux)), 1.0, seed=11)
    isi = intervals_in_ticks(stream.spikes)
    n = isi.size
    assert n > 30_000
    sd_expected = math.sqrt(mean_ticks ** 2 / q + 1 / 6)
    assert abs(isi.mean() - mean_ticks) < 5 * sd_expected / math.sqrt(n)
    rsd = isi.std(ddof=1) / isi.mean()
    rsd_expected = sd_expected / mean_ticks
    assert rsd_expected == pytest.approx(1 / math.sqrt(q), rel=0.01)
    assert abs(rsd / rsd_expected - 1) < 5 * math.sqrt((2 + 6 / q) / (4 * n))


@pytest.mark.parametrize("shape", [1.0, 2.0, 7.0, 100.0, 1000.0, 1e4])
def test_gamma_sampler_is_exact(shape):
    """The table sampler passes a Kolmogorov–Smirnov test against Gamma(a, 1) on 2e5 draws.

    Q = 1 and 2 stress the first bin (density 1 resp. 0 at x = 0) and the exponential tail
    envelope; 1e4 the narrow bins far from 0.
    """
    x = gamma_samples(shape, 200_000, key=12345)
    assert stats.kstest(x, stats.gamma(shape).cdf).pvalue > 1e-3
    assert x.mean() == pytest.approx(shape, abs=5 * math.sqrt(shape / x.size))


def test_gamma_tables_cached_on_disk_are_the_computed_ones(tmp_path, monkeypatch):
    """A new process loads the tables it would compute, bit for bit; a damaged file is recomputed,
    an unwritable folder only costs the computation, a SciPy build of its own gets tables of its own."""
    from viform._io import begin_outputs, completed_outputs
    from viform.sensors import _gamma

    monkeypatch.setattr(_gamma, "table_cache_folder", lambda: tmp_path / "tables")
    monkeypatch.setattr(_gamma, "_TABLES", {})
    shapes = [7.0, 100.0]
    computed = np.stack([_gamma._table(a) for a in shapes])
    begin_outputs()
    (first,) = _gamma.build_tables(shapes)
    files = list((tmp_path / "tables").iterdir())
    assert len(files) == 1 and first.tobytes() == computed.tobytes()
    assert completed_outputs() == []  # a cache, not a command's output (an interrupted command lists its outputs)
    monkeypatch.setattr(_gamma, "_TABLES", {})  # as in a new process
    monkeypatch.setattr(_gamma, "_table", lambda a: pytest.fail("computed although cached"))
    assert _gamma.build_tables(shapes)[0].tobytes() == computed.tobytes()
    monkeypatch.undo()
    monkeypatch.setattr(_gamma, "table_cache_folder", lambda: tmp_path / "tables")
    monkeypatch.setattr(_gamma, "_TABLES", {})
    files[0].write_bytes(files[0].read_bytes()[:1000])  # a truncated file
    assert _gamma.build_tables(shapes)[0].tobytes() == computed.tobytes()
    monkeypatch.setattr(_gamma, "_TABLES", {})
    monkeypatch.setattr(_gamma, "_scipy_build", lambda: "version = '0.0'")
    assert _gamma.build_tables(shapes)[0].tobytes() == computed.tobytes()
    assert len(list((tmp_path / "tables").iterdir())) == 2
    monkeypatch.setattr(_gamma, "_TABLES", {})
    (tmp_path / "file").write_text("")
    monkeypatch.setattr(_gamma, "table_cache_folder", lambda: tmp_path / "file" / "tables")
    assert _gamma.build_tables(shapes)[0].tobytes() == computed.tobytes()


def test_dark_only_pixels_fire_at_dark_current_over_q():
    """Seed 000 §4.4: with no light a pixel fires at Id/Q (τ̂ = Q/Id)."""
    q, dark = 20, 2000.0
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=dark)
    duration = 2.0
    stream = sensor.capture(StillScene(np.zeros((16, 16))), duration, seed=3, light_sample_ticks=80_000)
    rate = stream.spike_count() / (16 * 16 * duration)
    expected = dark / q
    # renewal counting: variance ≈ rate·T/Q per pixel
    se = math.sqrt(expected * duration / q / (16 * 16)) / duration
    assert abs(rate - expected) < 5 * se
    assert sensor.parameters.longest_signal_interval_s == pytest.approx(q / dark)


def test_saturation_at_one_spike_per_tick():
    """Light above Q·clock fires every tick and no more: the one-bit readout caps the rate."""
    sensor = SpikeSensor(threshold_electrons=100)
    lux = lux_for_electrons_per_tick(sensor, 10 * 100)
    stream = sensor.capture(StillScene(np.full((8, 8), lux)), 0.01, seed=1)
    assert stream.spikes.all()


@pytest.mark.parametrize("per_tick,self_rate,readout_rate", [(0.25, 0.25, 0.25), (0.6, 0.6, 0.5), (1.5, 1.0, 1.0)])
def test_noise_free_firing_and_reset_variants(per_tick, self_rate, readout_rate):
    """Deterministic model: self-reset fires at min(λdt/Q, 1); reset-at-readout at 1/ceil(Q/λdt)."""
    q = 100
    for reset, expected in (("self", self_rate), ("readout", readout_rate)):
        sensor = SpikeSensor(threshold_electrons=q, photon_noise=False, dark_current_e_per_s=0.0, reset=reset,
                             random_initial_charge=False)
        lux = lux_for_electrons_per_tick(sensor, per_tick * q)
        stream = sensor.capture(StillScene(np.full((2, 2), lux)), 0.05, seed=0)
        assert stream.spikes.mean() == pytest.approx(expected, abs=2 / stream.n_ticks)


def test_same_seed_same_bits_whatever_the_block_size():
    sensor = SpikeSensor(threshold_spread_fraction=0.05)
    scene = builtin_scene("translating", 24, 40)
    a = sensor.capture(scene, 0.02, seed=9, block_ticks=800).spikes
    b = sensor.capture(scene, 0.02, seed=9, block_ticks=37).spikes
    c = sensor.capture(scene, 0.02, seed=10, block_ticks=800).spikes
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_same_bits_whatever_the_number_of_threads():
    from numba import get_num_threads, set_num_threads

    sensor = SpikeSensor()
    scene = builtin_scene("translating", 24, 40)
    before = get_num_threads()
    try:
        set_num_threads(1)
        a = sensor.capture(scene, 0.01, seed=4).spikes
        set_num_threads(before)
        b = sensor.capture(scene, 0.01, seed=4).spikes
    finally:
        set_num_threads(before)
    assert np.array_equal(a, b)


def test_threshold_spread_is_fixed_pattern():
    sensor = SpikeSensor(threshold_spread_fraction=0.1)
    q = sensor.threshold_map_electrons(64, 64)
    assert q.std() / q.mean() == pytest.approx(0.1, rel=0.1)
    assert np.array_equal(q, SpikeSensor(threshold_spread_fraction=0.1).threshold_map_electrons(64, 64))


@pytest.mark.parametrize("spread", [0.1, 0.49])
def test_threshold_spread_is_log_normal(spread):
    """The threshold spread stays positive without a spike at a clip: ln Q_p is normal with
    σ² = ln(1 + spread²) and mean ln Q − σ²/2 (so E Q_p = Q, std/mean = spread). On 4,096
    pixels: mean within 5 standard errors (Q·spread/√n, plus ½ e⁻ of rounding), std / mean
    within 5 relative standard errors √((2 + κ)/(4n)) (κ the log-normal excess kurtosis),
    skewness of ln Q_p within 5·√(6/n), and no pixel at the floor: P(Q_p ≤ 2) < 1e-14 at
    Q = 100. The clipped Gaussian it replaces put 99 of 4,096 pixels at Q = 1 at spread 0.49."""
    q0, n = 100.0, 64 * 64
    q = SpikeSensor(threshold_electrons=q0, threshold_spread_fraction=spread).threshold_map_electrons(64, 64)
    sigma2 = math.log1p(spread ** 2)
    kurtosis = math.exp(4 * sigma2) + 2 * math.exp(3 * sigma2) + 3 * math.exp(2 * sigma2) - 6
    assert q.min() > 2
    assert abs(q.mean() - q0) < 5 * q0 * spread / math.sqrt(n) + 0.5
    assert q.std() / q.mean() == pytest.approx(spread, rel=5 * math.sqrt((2 + kurtosis) / (4 * n)))
    assert abs(stats.skew(np.log(q).ravel())) < 5 * math.sqrt(6 / n)


def test_chip_threshold_levels():
    from viform.sensors.spike_presets import threshold_level_electrons

    assert len(CHIP_THRESHOLD_LEVELS_ELECTRONS) == 16
    assert np.all(np.diff(CHIP_THRESHOLD_LEVELS_ELECTRONS) > 0)
    # one table: the presets' level k is the sensor module's level k
    assert [threshold_level_electrons(k) for k in range(16)] == list(CHIP_THRESHOLD_LEVELS_ELECTRONS)


def test_lazy_stream_equals_capture():
    sensor = SpikeSensor()
    scene = builtin_scene("rotating", 16, 24)
    lazy = sensor.stream(scene, 0.005, seed=2)
    full = sensor.capture(scene, 0.005, seed=2)
    assert np.array_equal(lazy.read_ticks(30, 90), full.spikes[30:90])


@pytest.mark.parametrize("field,value", [("threshold_electrons", 0), ("threshold_electrons", -5),
                                         ("clock_hz", 0), ("clock_hz", -1.0), ("reset", "never")])
def test_bad_parameters_name_themselves(field, value):
    with pytest.raises(ViformError, match=field):
        SpikeSensor(**{field: value})


@pytest.mark.parametrize("reset", ["self", "readout"])
def test_vectorized_noise_free_kernel_matches_the_general_lanes(reset):
    """The noise-free model resolves crossings in the SIMD loop itself; it must give the bits of the
    general path (every crossing through ``_fire``)."""
    from viform.sensors import _spike_kernels as module

    sensor = SpikeSensor(photon_noise=False, reset=reset)
    scene = builtin_scene("hdr", 20, 50)  # includes pixels above the one-spike-per-tick limit
    vectorized = sensor.capture(scene, 0.01, seed=3).spikes
    q, _, index, tables = sensor._pixel_tables(20, 50)
    state = sensor.initial_state(20, 50, 3)
    bounds = sensor._saturation_bounds(20, 50)
    blocks = []
    for first, last in ((0, 123), (123, 400)):
        words = np.empty((last - first, 16), dtype=np.uint64)
        lux = scene.illuminance_lux_many((np.arange(first, last) + 0.5) / sensor.parameters.clock_hz)
        rates = sensor._fixed_point_rates(lux.reshape(last - first, -1), 20, 50)
        seg_end = np.arange(first + 1, last + 1, dtype=np.int64)
        module._run_block(words.view(np.uint8), rates, seg_end, first, state.charge, state.target, state.counter,
                          q, index, *tables, *module.fixed_point_tables(tables[0]), state.keys, False,
                          reset == "readout", 0.0, module.MODE_GENERAL,
                          bounds, state.pending_ticks, state.pending_rate, module.SPARSE_FIRING,
                          module.VECTOR_MIN_SPIKES)
        bits = np.unpackbits(words.view(np.uint8), axis=1, count=1000, bitorder="little")
        blocks.append(bits.reshape(-1, 20, 50).astype(bool))
    assert np.array_equal(vectorized, np.concatenate(blocks))
    assert 0.05 < vectorized.mean() < 1.0


def test_reused_block_buffer_gives_the_same_bits():
    """With ``reuse_buffer`` blocks share one buffer; consumed at once they equal fresh blocks."""
    sensor = SpikeSensor()
    scene = builtin_scene("translating", 12, 20)
    fresh = np.concatenate([b for _, b in sensor.simulate(scene, 0.005, seed=6, block_ticks=33)])
    reused = np.concatenate([b.copy() for _, b in sensor.simulate(scene, 0.005, seed=6, block_ticks=33,
                                                                   reuse_buffer=True)])
    assert np.array_equal(fresh, reused)
    lazy = sensor.stream(scene, 0.005, seed=6, reuse_buffer=True)
    assert np.array_equal(lazy.read_ticks(10, 150), fresh[10:150])  # read_ticks never shares


def per_tick_reference(sensor, scene, n_ticks, seed, sample):
    """Plain tick-by-tick integration with the simulator's targets: add each tick's charge,
    fire when it reaches the target (the model the event-driven kernel must reproduce)."""
    from viform.sensors import _spike_kernels as module

    h, w = scene.shape
    q, _, index, tables = sensor._pixel_tables(h, w)
    state = sensor.initial_state(h, w, seed)
    c, t, counter = state.charge, state.target, state.counter
    p = sensor.parameters
    out = np.zeros((n_ticks, h * w), bool)
    for k in range(n_ticks):
        lux = scene.illuminance_lux((k // sample + 0.5) * sample / p.clock_hz).ravel()
        c += sensor._fixed_point_rates(lux[None], h, w)[0]
        for i in np.flatnonzero(c >= t):
            out[k, i] = True
            if p.reset == "readout":
                c[i] = 0
                t[i] = module._next_target(i, q, index, *tables, state.keys, True, counter)
            elif c[i] - t[i] >= 8 * q[i] ** 2 * module.FIXED_POINT_SCALE:
                c[i], t[i] = module._equilibrium_state(i, q, index, *tables, state.keys, counter)
            elif c[i] - t[i] >= module._JUMP_INTERVALS * q[i] * module.FIXED_POINT_SCALE:
                c[i], t[i] = module._saturated_state((c[i] - t[i]) / module.FIXED_POINT_SCALE, i, q, state.keys,
                                                     counter)
            else:
                while c[i] >= t[i]:
                    c[i] -= t[i]
                    t[i] = module._next_target(i, q, index, *tables, state.keys, True, counter)
    return out.reshape(n_ticks, h, w)


@pytest.mark.parametrize("reset", ["self", "readout"])
@pytest.mark.parametrize("q,max_lux", [(1, 5.0), (5, 5.0), (10, 100.0)])
def test_event_driven_kernel_equals_per_tick_integration(reset, q, max_lux):
    """With photon noise, jumping to the crossing tick gives the per-tick model's bits exactly,
    across light-sample intervals (7 ticks), blocks (41 ticks) and saturation (up to 36 e⁻/tick
    at 5 lux: the one-by-one drain and the ≥ 8·Q² stationary draw at Q = 1; up to 720 e⁻/tick at
    100 lux and Q = 10: all three, including the exact jump for 480–800 e⁻ past a crossing)."""
    sensor = SpikeSensor(threshold_electrons=q, reset=reset, dark_current_e_per_s=5000.0)
    scene = TranslatingScene(4, 6, velocity_px_per_s=(3000.0, 0.0), min_lux=0.01, max_lux=max_lux, period_px=4)
    expected = per_tick_reference(sensor, scene, 200, 5, 7)
    got = sensor.capture(scene, 200 / 40e3, seed=5, light_sample_ticks=7, block_ticks=41).spikes
    assert np.array_equal(got, expected)
    assert 0.3 < got.mean() < 1.0


def first_spike_charge_electrons(spikes, electrons_per_tick, after_tick=0):
    """Charge collected from ``after_tick`` to each pixel's first spike (mid-tick estimate)."""
    flat = spikes[after_tick:].reshape(spikes.shape[0] - after_tick, -1)
    assert flat.any(axis=0).all()
    return (flat.argmax(axis=0) + 0.5) * electrons_per_tick


@pytest.mark.parametrize("q,dim,bright_electrons_per_tick", [(2, 0.02, None), (2, 0.02, 20.0), (2, 0.02, 1000.0),
                                                            (20, 0.2, 2000.0)])
def test_pixels_start_and_leave_saturation_in_the_stationary_state(q, dim, bright_electrons_per_tick):
    """The charge to the first spike follows the forward-recurrence law of the Gamma(Q) renewal
    process: mean (Q + 1)/2, variance (Q + 1)(Q + 2)/3 − (Q + 1)²/4 (Q = 2: 1.5 and 1.75 e⁻²).

    At t = 0 (random initial charge) and after 10 saturated ticks — at Q = 2, 20 e⁻/tick
    (crossings drawn one by one) or 1000 e⁻/tick (≥ 8·Q², drawn at once); at Q = 20,
    2000 e⁻/tick (between 48·Q and 8·Q²: the exact Poisson jump). A pixel started empty, or a
    uniform fraction into a plain Gamma(Q) interval, has mean Q/2 = 1 at Q = 2: 24 standard
    errors off.
    """
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    lux_dim = lux_for_electrons_per_tick(sensor, dim)
    if bright_electrons_per_tick is None:
        scene, after = StillScene(np.full((64, 64), lux_dim)), 0
    else:
        bright = lux_for_electrons_per_tick(sensor, bright_electrons_per_tick)
        scene = StepScene(StillScene(np.full((64, 64), bright)), step_time_s=10 / 40e3, factor=lux_dim / bright)
        after = 10
    spikes = sensor.capture(scene, (after + 1500) / 40e3, seed=21).spikes
    if bright_electrons_per_tick == 2000.0:
        assert 48 * q <= bright_electrons_per_tick - q < 8 * q * q  # the exact-jump regime
    if after:
        assert spikes[:after].all()
    charge = first_spike_charge_electrons(spikes, dim, after)
    # raw moments of U·Gamma(Q + 1): E[R^k] = (Q + 1)···(Q + k) / (k + 1)
    m1, m2, m3, m4 = (math.prod(range(q + 1, q + k + 1)) / (k + 1) for k in (1, 2, 3, 4))
    var = m2 - m1 ** 2
    central4 = m4 - 4 * m1 * m3 + 6 * m1 ** 2 * m2 - 3 * m1 ** 4
    n = charge.size
    assert abs(charge.mean() - m1) < 5 * math.sqrt((var + dim ** 2 / 12) / n)
    assert abs(charge.var() - var) < 5 * math.sqrt((central4 - var ** 2) / n) + dim ** 2 / 12


@pytest.mark.parametrize("residual_electrons", [10.0, 150.0, 3000.0])
def test_saturated_jump_has_the_law_of_one_gamma_per_crossing(residual_electrons):
    """The constant-cost end state of a saturated tick against draining one Gamma(Q) per crossing.

    Reference: NumPy Gamma(Q) intervals summed past R; the state is (age since the last
    crossing, charge still missing). Two-sample Kolmogorov–Smirnov on 20,000 draws each.
    """
    from viform.sensors import _spike_kernels as module

    q, n = 7, 20_000
    rng = np.random.default_rng(1)
    age_ref, rest_ref = np.empty(n), np.empty(n)
    # intervals per row: enough to pass R but for a 10-sigma fluctuation (asserted per block)
    m = int(residual_electrons / q + 10 * math.sqrt(residual_electrons / q) + 10)
    for start in range(0, n, 2000):
        rows = slice(start, min(start + 2000, n))
        crossings = np.cumsum(rng.gamma(q, size=(rows.stop - rows.start, m)), axis=1)
        assert np.all(crossings[:, -1] > residual_electrons)
        first = np.argmax(crossings > residual_electrons, axis=1)  # the interval in progress at R
        index = np.arange(first.size)
        before = np.where(first > 0, crossings[index, np.maximum(first - 1, 0)], 0.0)
        age_ref[rows] = residual_electrons - before
        rest_ref[rows] = crossings[index, first] - residual_electrons
    qs = np.full(1, float(q))
    keys = np.array([np.uint64(123456789)])
    counter = np.zeros(1, dtype=np.int64)
    age, rest = np.empty(n), np.empty(n)
    for i in range(n):
        c, t = module._saturated_state(residual_electrons, 0, qs, keys, counter)
        age[i], rest[i] = c / module.FIXED_POINT_SCALE, (t - c) / module.FIXED_POINT_SCALE
    assert counter[0] == n
    assert stats.ks_2samp(age, age_ref).pvalue > 1e-3
    assert stats.ks_2samp(rest, rest_ref).pvalue > 1e-3
    assert abs(age.mean() - age_ref.mean()) < 5 * math.sqrt(2 * age_ref.var() / n)


def test_light_beyond_the_fixed_point_range_is_refused():
    sensor = SpikeSensor()
    with pytest.raises(ViformError, match="lux"):
        sensor.capture(StillScene(np.full((2, 8), 1e9)), 0.001)
    assert sensor.capture(StillScene(np.full((2, 8), 1e7)), 0.001).spikes.all()


def stationary_tick_rate(q, electrons_per_tick):
    """Spikes per tick of a steady self-reset pixel: 1 − P(no crossing in a tick).

    The crossings form a stationary renewal process with Gamma(Q) intervals in charge time;
    P(no crossing in a window r) is P(forward recurrence > r) = E[(X − r)⁺]/Q, X ~ Gamma(Q),
    and E[(X − r)⁺] = Q·S_{Q+1}(r) − r·S_Q(r) (S: the regularized upper incomplete gamma).
    Below saturation (r ≪ Q) it is r/Q; far above, 1.
    """
    from scipy import special

    r = electrons_per_tick
    return 1.0 - special.gammaincc(q + 1, r) + r / q * special.gammaincc(q, r)


@pytest.mark.parametrize("q", [1, 7, 100, 16383, 16384, 100_000, 1_000_000])
@pytest.mark.parametrize("per_q", [0.2, 1.5])
def test_firing_rate_from_tiny_to_huge_thresholds(q, per_q):
    """Q from 1 to 10⁶ e⁻ at 0.2·Q e⁻/tick (moderate) and 1.5·Q (saturated): the rate is the
    stationary renewal law above (0.2 and 1 for large Q; 1 − e^-0.2 and 1 − e^-1.5 at Q = 1).

    Q ≥ 2^14 used to fire at 0.333 at moderate light (fixed-point overflow of 8·Q²).
    Tolerance: the count of a stationary renewal process over n ticks has variance
    n·rate·CV² + O(1) with CV² = 1/Q (Bernoulli ticks at Q = 1: ≤ n·rate), so the mean over
    P pixels has standard error √((n·rate/Q + 1)/P)/n; saturated ticks are counted as at
    most twice Bernoulli variance n·p(1 − p)."""
    n_ticks, side = 2000, 8
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0)
    lux = lux_for_electrons_per_tick(sensor, per_q * q)
    spikes = sensor.capture(StillScene(np.full((side, side), lux)), n_ticks / 40e3, seed=q).spikes
    expected = stationary_tick_rate(q, per_q * q)
    if per_q < 1:
        var = n_ticks * expected / q + 1
    else:
        var = 2 * n_ticks * expected * (1 - expected)
    se = math.sqrt(var / side ** 2) / n_ticks
    assert abs(spikes.mean() - expected) <= 5 * se + 1e-12
    if q >= 16383:
        assert expected == pytest.approx(min(per_q, 1.0), abs=1e-9)


def test_threshold_above_the_fixed_point_range_is_refused():
    with pytest.raises(ViformError, match="threshold_electrons"):
        SpikeSensor(threshold_electrons=2.0 ** 27)


def test_gain_spread_is_measured_back_from_flat_field_rates():
    """PRNU: in flat light pixel i fires at g_i·λ/Q, so the spread of the rates is the gain spread.

    The shot-noise part of the count variance (renewal: mean/Q) is subtracted; with 1,024
    pixels the std estimate has relative standard error ≈ 1/√(2·1024) = 2.2 %: 5σ ≈ 11 %.
    """
    q, n_ticks, side, spread = 1000, 4000, 32, 0.03
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, gain_spread_fraction=spread)
    gain = sensor.gain_map(side, side)
    assert gain.mean() == pytest.approx(1.0, abs=5 * spread / side)
    lux = lux_for_electrons_per_tick(sensor, 0.2 * q)
    counts = sensor.capture(StillScene(np.full((side, side), lux)), n_ticks / 40e3, seed=8).spikes.sum(axis=0)
    mean = counts.mean()
    measured = math.sqrt(max(counts.var() - mean / q - 1 / 6, 0.0)) / mean
    assert measured == pytest.approx(spread, rel=0.11)
    # the pattern is the sensor's own: the rates follow the gain map pixel by pixel
    assert np.corrcoef(counts.ravel(), gain.ravel())[0, 1] > 0.95
    assert np.array_equal(gain, SpikeSensor(gain_spread_fraction=spread).gain_map(side, side))
    assert np.all(SpikeSensor().gain_map(4, 4) == 1.0)


def test_dark_current_spread_and_hot_pixels_are_measured_back_in_the_dark():
    """In the dark pixel i fires at Id_i/Q (seed 000 §4.4): the hot pixels show up as the
    fast ones, at their own dark current, and the bulk spread is the log-normal spread.

    Counts over T: renewal variance ≈ count/Q, subtracted from the bulk variance. Bulk:
    ≈ 4,000 pixels of CV 0.5 (log-normal kurtosis included) → the spread within 10 %;
    hot pixels: each pixel's count within 5 √(count/Q) + 1 of its stationary rate × T
    (Id_i·T/Q below saturation)."""
    q, side, duration = 10, 64, 0.25
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=2000.0, dark_current_spread_fraction=0.5,
                         hot_pixel_fraction=0.02, hot_pixel_dark_current_e_per_s=1e5)
    dark = sensor.dark_current_map_e_per_s(side, side)
    counts = sensor.capture(StillScene(np.zeros((side, side))), duration, seed=4).spikes.sum(axis=0)
    # hot pixels collect up to ≈ 5 e⁻ a tick: crossings lost to the readout are included
    expected = stationary_tick_rate(q, dark / 40e3) * duration * 40e3
    hot = dark > 2.5e4
    assert 0.01 < hot.mean() < 0.03
    assert counts[hot].min() > counts[~hot].max()  # the hot pixels are the fast ones
    assert np.all(np.abs(counts[hot] - expected[hot]) < 5 * np.sqrt(expected[hot] / q) + 1)
    bulk = counts[~hot]
    measured = math.sqrt(bulk.var() - bulk.mean() / q) / bulk.mean()
    assert measured == pytest.approx(0.5, rel=0.1)
    assert dark[~hot].mean() == pytest.approx(2000.0, rel=0.05)


@pytest.mark.parametrize("per_tick,dead_ticks", [(50.0, 0.5), (10_000.0, 2.0)])
def test_dead_time_compresses_the_rate(per_tick, dead_ticks):
    """Self-reset with dead time t_d: each interval is the Gamma(Q) charge time plus t_d, so
    the renewal rate is λ/(Q + λ·t_d) (per tick: r/(Q + r·d), r e⁻/tick, d ticks): 0.4 instead
    of 0.5 at r = Q/2, d = 0.5, and 1/(2 + 0.01) instead of 1 far above saturation at d = 2.
    Every interval is > 1 tick, so no crossing is lost to the readout. Tolerance: renewal count
    variance n·rate·CV² + 1 (CV = √Q/r / (Q/r + d)); the start is stationary (no start-up
    bias allowed, see :func:`test_dead_time_start_is_stationary`)."""
    q, n_ticks, side = 100, 4000, 16
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, dead_time_s=dead_ticks / 40e3)
    lux = lux_for_electrons_per_tick(sensor, per_tick)
    rate = sensor.capture(StillScene(np.full((side, side), lux)), n_ticks / 40e3, seed=2).spikes.mean()
    mean_interval = q / per_tick + dead_ticks
    expected = 1 / mean_interval
    cv2 = (q / per_tick ** 2) / mean_interval ** 2
    se = math.sqrt((n_ticks * expected * cv2 + 1) / side ** 2) / n_ticks
    assert abs(rate - expected) < 5 * se


def _stationary_rate_per_tick(q, per_tick, dead_ticks, reset, noise):
    """Steady firing probability per tick, from renewal theory (seed 000 §5.1 plus dead time).

    Self-reset: in charge time the crossings are a renewal process with cycles G + D (G ~
    Gamma(Q), or Q without noise; D = r·d); a tick (r of charge time) holds a crossing with
    probability E[min(G + D, r)]/(Q + D) (the forward recurrence time below r). Reset at
    readout: cycles of N = ⌈(G + D)/r⌉ whole ticks, rate 1/E[N].
    """
    dead = per_tick * dead_ticks
    if reset == "self":
        if not noise:
            return min(per_tick, q + dead) / (q + dead)
        if per_tick <= dead:
            return per_tick / (q + dead)
        x = per_tick - dead
        mean_min = dead + q * stats.gamma(q + 1).cdf(x) + x * stats.gamma(q).sf(x)
        return mean_min / (q + dead)
    if not noise:
        return 1 / math.ceil((q + dead) / per_tick)
    m = np.arange(1, 400)
    cdf = stats.gamma(q).cdf
    probabilities = cdf(m * per_tick - dead) - cdf((m - 1) * per_tick - dead)
    return 1 / float((m * probabilities).sum())


@pytest.mark.parametrize("q,per_tick,dead_ticks,reset,noise", [
    (100, 50.0, 2.4, "self", True),  # the audit's case: 0.49, 0.47, 0.04, 0.0005, 0.30 fired at first
    (100, 50.0, 0.5, "self", True),
    (20, 200.0, 0.3, "self", True),  # near saturation: several crossings a tick possible
    (100, 30.0, 0.5, "self", False),
    (100, 40.0, 0.7, "readout", True),
    (100, 35.0, 1.5, "readout", False),
    (100, 50.0, 0.0, "self", True),  # no dead time: unchanged
])
def test_dead_time_start_is_stationary(q, per_tick, dead_ticks, reset, noise):
    """The start is the renewal process's stationary state *with* dead time: every one of the
    first ticks fires at the steady rate r (binomial over P pixels: ± 5·√(r(1 − r)/P)), and
    the mean count over 200 ticks is 200·r within 5 standard errors of a renewal count
    (variance ≤ n·r·CV² + 1 per pixel; CV² ≤ 1/Q + 1/(6 μ²) with tick rounding, bounded by 1).
    Before the fix, the audit's case fired 0.49, 0.47, 0.04, 0.0005, 0.30 of the pixels in
    the first five ticks against 0.227, and counted 45.752 against 45.455 over 200 ticks."""
    side, n_ticks = 64, 200
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, dead_time_s=dead_ticks / 40e3,
                         reset=reset, photon_noise=noise)
    lux = lux_for_electrons_per_tick(sensor, per_tick)
    spikes = sensor.capture(StillScene(np.full((side, side), lux)), n_ticks / 40e3, seed=5).spikes
    rate = _stationary_rate_per_tick(q, per_tick, dead_ticks, reset, noise)
    pixels = side * side
    first = spikes[:8].reshape(8, -1).mean(axis=1)
    assert np.all(np.abs(first - rate) < 5 * math.sqrt(rate * (1 - rate) / pixels) + 1e-12), (first, rate)
    counts = spikes.reshape(n_ticks, -1).sum(axis=0)
    se = math.sqrt((n_ticks * rate + 1) / pixels)
    assert abs(counts.mean() - n_ticks * rate) < 5 * se, (counts.mean(), n_ticks * rate)


def test_dead_time_after_readout_reset():
    """Reset at readout, then dead for d: an interval is ceil(d + G/r) ticks, G ~ Gamma(Q);
    P(interval = m) = F((m − d)·r) − F((m − 1 − d)·r), so the rate is 1 / Σ m·P(m)."""
    q, per_tick, dead_ticks, n_ticks, side = 100, 40.0, 0.7, 4000, 16
    sensor = SpikeSensor(threshold_electrons=q, dark_current_e_per_s=0.0, reset="readout",
                         dead_time_s=dead_ticks / 40e3)
    lux = lux_for_electrons_per_tick(sensor, per_tick)
    rate = sensor.capture(StillScene(np.full((side, side), lux)), n_ticks / 40e3, seed=3).spikes.mean()
    m = np.arange(1, 20)
    cdf = stats.gamma(q).cdf
    probabilities = cdf((m - dead_ticks) * per_tick) - cdf((m - 1 - dead_ticks) * per_tick)
    assert probabilities.sum() == pytest.approx(1.0, abs=1e-12)
    mean_interval = float((m * probabilities).sum())
    var_interval = float((m ** 2 * probabilities).sum()) - mean_interval ** 2
    expected = 1 / mean_interval
    se = math.sqrt((n_ticks * expected * var_interval / mean_interval ** 2 + 1) / side ** 2) / n_ticks
    assert abs(rate - expected) < 5 * se + 1 / n_ticks
    assert expected < 1 / (q / per_tick + dead_ticks)  # rounding up to the readout costs rate


def _light_scenes():
    from viform.light.scenes import FlickerScene, VideoScene

    frames = np.random.default_rng(1).uniform(0.05, 3.0, (4, 10, 14))
    return {
        "hdr": builtin_scene("hdr", 10, 14),
        "step": builtin_scene("step", 10, 14, step_time_s=0.002, factor=8.0),
        "video-hold": VideoScene(frames, 2000.0, "hold"),
        "video-linear": VideoScene(frames, 2000.0, "linear"),
        "translating": builtin_scene("translating", 10, 14),
        "rotating": builtin_scene("rotating", 10, 14),
        "moving-edge": builtin_scene("moving-edge", 10, 14),
        "flicker": FlickerScene(builtin_scene("hdr", 10, 14, decades=2.0), frequency_hz=700.0),
    }


@pytest.mark.parametrize("name,noise", [(name, True) for name in ("hdr", "step", "video-hold", "video-linear",
                                                                  "translating", "rotating", "moving-edge", "flicker")]
                         + [("hdr", False), ("video-hold", False), ("translating", False)])
def test_compiled_light_gives_the_numpy_path_bits_whatever_the_blocks(name, noise):
    """Light evaluated in the kernel: the same bits as the NumPy per-tick path (the charge
    rates are equal to the fixed-point unit; a rate off by 2^-32 e⁻ at a rounding tie could
    move a spike, which these 56,000 pixel-ticks do not show), and the same bits whatever
    the block size and light-sample grid."""
    sensor = SpikeSensor(photon_noise=noise, gain_spread_fraction=0.05, dark_current_spread_fraction=0.3,
                         threshold_electrons=20)
    scene = _light_scenes()[name]
    duration = 400 / 40e3
    reference = sensor.capture(scene, duration, seed=7, block_ticks=400)
    numpy_path = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=7, compiled_light=False)])
    assert np.array_equal(reference.spikes, numpy_path)
    assert np.array_equal(reference.spikes, sensor.capture(scene, duration, seed=7, block_ticks=29).spikes)
    held = sensor.capture(scene, duration, seed=7, block_ticks=53, light_sample_ticks=3).spikes
    held_numpy = np.concatenate([b for _, b in sensor.simulate(scene, duration, seed=7, block_ticks=400,
                                                               light_sample_ticks=3, compiled_light=False)])
    assert np.array_equal(held, held_numpy)
    assert 0.001 < reference.spikes.mean() < 1.0


def test_block_size_follows_a_memory_budget():
    """Blocks hold about BLOCK_BYTES whatever the resolution: 1 byte a pixel-tick of spikes."""
    from viform.sensors.spike import BLOCK_BYTES

    sensor = SpikeSensor()
    for h, w in ((250, 400), (1000, 1000)):
        scene = builtin_scene("translating", h, w)
        ticks = sensor.default_block_ticks(scene, 1, scene.compiled_light())
        assert ticks * h * w <= BLOCK_BYTES
        assert ticks * h * w * 1.1 + 64 * (h + w) * ticks >= BLOCK_BYTES * 0.5
        numpy_ticks = sensor.default_block_ticks(scene, 1, None)
        assert numpy_ticks * h * w * 33 <= BLOCK_BYTES or numpy_ticks == 1
    lazy = sensor.stream(builtin_scene("hdr", 1000, 1000), 0.01)
    first, block = next(lazy.iter_blocks(4096))
    assert first == 0 and block.shape[0] * 1000 * 1000 <= BLOCK_BYTES
