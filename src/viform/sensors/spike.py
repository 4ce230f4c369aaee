"""The spike camera: pulse-sequence modulation pixels read on a synchronous clock (seed 000 §3.2).

Each pixel integrates photoelectrons (signal + dark current) until its charge reaches the
threshold Q electrons, fires a spike and resets itself; the spikes are read out on a
synchronous clock (40 kHz by default, seed 000 §6), one bit per pixel per tick.

Photon statistics are exact (seed 000 §5.1). Photoelectrons arrive as a Poisson process
of rate λ(t), so in *integrated-charge time* Λ(t) = ∫λ dt the arrivals form a unit-rate
Poisson process and the charge needed for the next spike is Gamma(Q, 1) — the
time-rescaling theorem. The simulator therefore adds the expected charge of each tick,
∫λ over the tick, to a per-pixel accumulator and fires when it passes a Gamma(Q, 1)
target; no per-tick Poisson draw and no Gaussian approximation is made. With
``photon_noise=False`` the target is Q itself (the deterministic, noise-free model).

Initial state: with ``random_initial_charge`` each pixel starts in the stationary state
of its renewal process, as if it had been exposed long before t = 0: the interval in
progress is length-biased, Gamma(Q + 1, 1), and the pixel sits a uniform fraction of the
way into it, so the charge still missing is the forward-recurrence law (1 − F_Q(x))/Q
(mean (Q + 1)/2 e⁻, not Q/2). The firing rate is then λ/Q from the first tick, with no
start-up transient. With a dead time the cycle is the charge to the threshold plus the
dead charge time λ·t_d, and the pixel starts in the stationary state of *that* cycle
(length-biased, for the light of the first tick; the readout-reset pixel in whole ticks),
see :func:`_dead_time_stationary_state`. (Without dead time the readout-reset pixel starts
in the self-reset pixel's state.) Without ``random_initial_charge`` every pixel starts empty.

Saturation: readout allows at most one spike per pixel per tick, so light above
Q·clock_hz electrons/s (τ̌ = 1/clock_hz, seed 000 §4.3) gives a spike every tick; the
extra threshold crossings inside a tick are lost (self-reset pixel) or the charge after
the crossing is drained at readout (``reset="readout"``). The expected firing rate of the
self-reset pixel is therefore 1 − P(no crossing in a tick), which tends to one per tick.
The self-reset pixel's lost crossings are drawn one by one, except where a tick brings
≥ 8·Q² e⁻ after its first crossing: the number of electrons modulo Q is then uniform to
within e^-64, so the pixel leaves the tick in the stationary state above, drawn at once.

Reproducibility: the k-th interval of pixel p is drawn by a counter-based generator from
(seed, p, k) (:mod:`viform.sensors._gamma`), and the light of each tick is computed from
absolute tick indices, so the same seed gives the same bits whatever the block size, the
number of threads and the device (:mod:`viform.sensors.spike_cuda` runs the same functions
on a CUDA GPU).

Kernels (issue 30): pixels sit in lanes of 64, one uint64 of spike bits per tick — the
``.dat`` bit order, so the kernels write the file's bytes as the pixels fire
(:meth:`SpikeSensor.simulate_packed`; :meth:`SpikeSensor.simulate` unpacks them to bool). The
tick loop runs inside each work item (a tile of pixels, or a band of rows when the light is
computed per tick), the lane loop compiles to SIMD add/compare/mask code (see the notes
above :func:`_lanes_add_compare`), and only the lanes that fired take the scalar path with
its Gamma draw. A self-reset pixel with photon noise whose charge per tick exceeds every gap a
draw can leave (:func:`saturation_bound_fixed`) fires in every tick whatever its state: in
constant light the kernel only counts those ticks and replays their draws when the light
changes or the caller reads the state, so saturated light costs no more than dim light, with
the same bits and state.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from numba import get_num_threads, njit, prange
from numba.cpython.unsafe.numbers import trailing_zeros

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
)
from viform.light.compiled import row_lux
from viform.light.radiometry import PixelOptics
from viform.light.scenes import Scene
from viform.sensors._gamma import (
    build_tables,
    event_stream,
    gamma_draw,
    splitmix64,
    stream_gamma,
    stream_keys,
    stream_poisson,
    stream_uniform,
    uniform_from_hash,
)
from viform.sensors.base import Sensor
from viform.stream.container import SpikeSource, SpikeStream

#: The chip's 16 selectable threshold levels, e⁻. Seed 000 §6 says the threshold "supports
#: 16 levels of adjustment" without listing them; viform assumes a linear threshold DAC,
#: (k + 1)·1,250 e⁻, which puts the effective Q calibrated on a real recording (≥ 15,903 e⁻,
#: docs/calibration.md) at level 12. The same table as
#: :func:`viform.sensors.spike_presets.threshold_level_electrons`. Any other positive Q is allowed.
CHIP_THRESHOLD_LEVELS_ELECTRONS = tuple(1250.0 * (k + 1) for k in range(16))

#: Readout clocks of the chips (seed 000 §6): 40 kHz, and the 20 kHz mode.
CLOCK_40KHZ = 40_000.0
CLOCK_20KHZ = 20_000.0

#: Default memory budget of one simulated block (spike bits + light), bytes.
BLOCK_BYTES = 48 << 20
#: Largest threshold, e⁻: targets (≈ Q·2^32 in fixed point) plus a tick's charge stay inside int64.
MAX_THRESHOLD_ELECTRONS = 1 << 26


@dataclass(frozen=True)
class SpikeSensorParameters:
    """Parameters of a spike-camera pixel array (units in the names).

    Attributes
    ----------
    optics : PixelOptics
        Pitch (10 µm: the seed's 100 µm² pixel), fill factor, QE (0.7, seed 000 §4.3).
    threshold_electrons : float
        Accumulation threshold Q, e⁻ (rounded to a whole number of electrons per pixel).
        ``CHIP_THRESHOLD_LEVELS_ELECTRONS`` lists the chip's 16 levels.
    clock_hz : float
        Synchronous readout clock, Hz (40 kHz; 20 kHz mode).
    dark_current_e_per_s : float
        Dark current, e⁻/s (< 100 e⁻/s in modern CMOS, seed 000 §4.4).
    threshold_spread_fraction : float
        Fixed-pattern spread of Q across pixels (std / mean; log-normal, mean Q, so no
        pixel's threshold piles up at a clip).
    random_initial_charge : bool
        Start each pixel in the stationary state of its spike train (True: a uniform
        fraction of the way into a length-biased Gamma(Q + 1) interval, see the module
        notes), or empty (False).
    reset : {"self", "readout"}
        Self-reset at the threshold crossing (charge after it is kept), or reset at the next
        readout tick (charge collected after the crossing is drained).
    photon_noise : bool
        Exact Poisson photon/dark statistics (True) or the deterministic model (False).
    fixed_pattern_seed : int
        Seed of the sensor's own fixed patterns (threshold, gain, dark current, hot pixels).
    gain_spread_fraction : float
        Photo-response non-uniformity (PRNU): std / mean of the per-pixel gain that multiplies
        the photoelectron rate (log-normal, mean 1). Dark current is not affected by it.
    dark_current_spread_fraction : float
        Dark-signal non-uniformity: std / mean of the per-pixel dark current (log-normal
        around ``dark_current_e_per_s``; hot pixels get the same relative spread).
    hot_pixel_fraction : float
        Fraction of pixels that are hot: their dark current is ``hot_pixel_dark_current_e_per_s``
        (times the log-normal spread) instead of ``dark_current_e_per_s``.
    hot_pixel_dark_current_e_per_s : float
        Mean dark current of a hot pixel, e⁻/s.
    dead_time_s : float
        Reset dead time after each spike, s: the pixel collects no charge for this long after
        its threshold crossing (self-reset) or after the readout that resets it (``reset =
        "readout"``). The firing rate becomes λ/(Q + λ·dead_time_s) below saturation.
    """

    optics: PixelOptics = field(default_factory=lambda: PixelOptics(pixel_pitch_m=10e-6,
                                                                    quantum_efficiency=0.7))
    threshold_electrons: float = 100.0
    clock_hz: float = CLOCK_40KHZ
    dark_current_e_per_s: float = 20.0
    threshold_spread_fraction: float = 0.0
    random_initial_charge: bool = True
    reset: str = "self"
    photon_noise: bool = True
    fixed_pattern_seed: int = 2015
    gain_spread_fraction: float = 0.0
    dark_current_spread_fraction: float = 0.0
    hot_pixel_fraction: float = 0.0
    hot_pixel_dark_current_e_per_s: float = 1e4
    dead_time_s: float = 0.0

    def __post_init__(self):
        check_positive("threshold_electrons", self.threshold_electrons)
        if round(self.threshold_electrons) < 1:
            raise ViformError(f"threshold_electrons = {self.threshold_electrons!r} is not allowed: "
                              "it must be at least 1 electron")
        check_positive("clock_hz", self.clock_hz)
        check_non_negative("dark_current_e_per_s", self.dark_current_e_per_s)
        spread = check_non_negative("threshold_spread_fraction", self.threshold_spread_fraction)
        if spread >= 0.5:
            raise ViformError(f"threshold_spread_fraction = {spread!r} is not allowed: it must be < 0.5")
        check_choice("reset", self.reset, ("self", "readout"))
        if round(self.threshold_electrons) > MAX_THRESHOLD_ELECTRONS:
            raise ViformError(f"threshold_electrons = {self.threshold_electrons!r} is not allowed: it must be at "
                              f"most {MAX_THRESHOLD_ELECTRONS} electrons (2^26, the fixed-point charge range)")
        gain = check_non_negative("gain_spread_fraction", self.gain_spread_fraction)
        if gain >= 1.0:
            raise ViformError(f"gain_spread_fraction = {gain!r} is not allowed: it must be < 1")
        dark = check_non_negative("dark_current_spread_fraction", self.dark_current_spread_fraction)
        if dark > 10.0:
            raise ViformError(f"dark_current_spread_fraction = {dark!r} is not allowed: it must be ≤ 10")
        hot = check_non_negative("hot_pixel_fraction", self.hot_pixel_fraction)
        if hot > 1.0:
            raise ViformError(f"hot_pixel_fraction = {hot!r} is not allowed: it must lie in [0, 1]")
        check_non_negative("hot_pixel_dark_current_e_per_s", self.hot_pixel_dark_current_e_per_s)
        check_non_negative("dead_time_s", self.dead_time_s)
        if not math.isfinite(self.dead_time_s):
            raise ViformError(f"dead_time_s = {self.dead_time_s!r} is not allowed: it must be finite")

    @property
    def shortest_interval_s(self) -> float:
        """τ̌: the readout period, the shortest representable interval (seed 000 §4.3)."""
        return 1.0 / self.clock_hz

    @property
    def longest_signal_interval_s(self) -> float:
        """τ̂ = Q / Id: intervals longer than this are dark current (seed 000 §4.4)."""
        if self.dark_current_e_per_s == 0:
            return math.inf
        return self.threshold_electrons / self.dark_current_e_per_s

    def to_dict(self) -> dict:
        return asdict(self)


class SpikeSimulationState:
    """Per-pixel state carried between time blocks: charge and target (fixed point, 2^-32 e⁻), interval counter."""

    def __init__(self, charge, target, counter, keys, next_tick: int = 0):
        self.charge = charge
        self.target = target
        self.counter = counter
        self.keys = keys  # per-pixel random-stream keys derived from the seed
        self.next_tick = next_tick
        # saturated ticks not yet applied to charge/target (see _run_block): count and charge per tick
        self.pending_ticks = np.zeros(np.shape(charge), dtype=np.int64)
        self.pending_rate = np.zeros(np.shape(charge), dtype=np.int64)


@dataclass
class _RunPlan:
    """What :meth:`SpikeSensor.run_plan` fixes before the first tick (shared by the CPU and GPU paths)."""

    p: object
    n_ticks: int
    height: int
    width: int
    pixels: int
    row_bytes: int
    sample: int
    light: object
    block_ticks: int
    q: np.ndarray
    shapes: object
    index: np.ndarray
    tables: tuple
    a: np.ndarray
    b: np.ndarray
    rate_bound: float | None
    state: object
    caller_state: bool
    reset_readout: bool
    dead_ticks: float
    mode: int
    per_tick_light: bool


class SpikeSensor(Sensor):
    """A spike camera (pulse-sequence modulation, seed 000 §3.2) of a given resolution.

    Parameters
    ----------
    parameters : SpikeSensorParameters, optional
    height, width : int, optional
        Resolution; None takes the scene's.
    **overrides
        Any :class:`SpikeSensorParameters` field, e.g. ``threshold_electrons=400``.

    Examples
    --------
    >>> from viform.light.scenes import StillScene
    >>> sensor = SpikeSensor(threshold_electrons=100)
    >>> stream = sensor.capture(StillScene(np.full((4, 4), 2.0)), 0.01, seed=1)
    >>> stream.shape
    (400, 4, 4)
    """

    name = "spike"

    def __init__(self, parameters: SpikeSensorParameters | None = None, height: int | None = None,
                 width: int | None = None, **overrides):
        parameters = parameters or SpikeSensorParameters()
        if overrides:
            try:
                parameters = replace(parameters, **overrides)
            except TypeError as exc:
                raise ViformError(f"unknown spike-sensor parameter: {exc}") from None
        self.parameters = parameters
        self.height, self.width = height, width
        self._tables: dict[tuple[int, int], tuple] = {}

    # ------------------------------------------------------------------ fixed pattern
    def threshold_map_electrons(self, height: int, width: int) -> np.ndarray:
        """Per-pixel threshold Q (whole electrons) including the fixed-pattern spread.

        The spread is log-normal (mean Q, std / mean ``threshold_spread_fraction``, see
        :func:`_threshold_spread_draw`), rounded to whole electrons, at least 1 e⁻.
        """
        p = self.parameters
        q = np.full((height, width), float(round(p.threshold_electrons)))
        if p.threshold_spread_fraction > 0:
            q = _threshold_spread_draw(p.threshold_electrons, p.threshold_spread_fraction, p.fixed_pattern_seed,
                                       (height, width))
        return np.clip(q, 1.0, MAX_THRESHOLD_ELECTRONS)

    def _pattern_rng(self, stream: int) -> np.random.Generator:
        seq = np.random.SeedSequence([self.parameters.fixed_pattern_seed, stream])
        return np.random.Generator(np.random.PCG64(seq))

    @staticmethod
    def _log_normal(rng, fraction: float, shape) -> np.ndarray:
        """Log-normal factors of mean 1 and std / mean ``fraction`` (positive, as a rate must be)."""
        if fraction == 0:
            return np.ones(shape)
        sigma = math.sqrt(math.log1p(fraction * fraction))
        return np.exp(sigma * rng.standard_normal(shape) - 0.5 * sigma * sigma)

    def gain_map(self, height: int, width: int) -> np.ndarray:
        """Per-pixel photo-response gain (PRNU), mean 1, std / mean ``gain_spread_fraction``.

        It multiplies the photoelectron rate of each pixel (QE × fill factor × microlens
        non-uniformity); the firing rate in flat light is then gain·λ/Q. Log-normal so a
        gain is never negative; at the few-percent spreads of real chips it is
        indistinguishable from the usual Gaussian PRNU. All ones when the spread is 0.
        """
        p = self.parameters
        return self._log_normal(self._pattern_rng(0x6A1), p.gain_spread_fraction, (height, width))

    def dark_current_map_e_per_s(self, height: int, width: int) -> np.ndarray:
        """Per-pixel dark current, e⁻/s: a log-normal bulk plus a fraction of hot pixels.

        Dark current comes from thermal generation at defects, whose density varies from
        pixel to pixel: the bulk is log-normal with mean ``dark_current_e_per_s`` and
        std / mean ``dark_current_spread_fraction`` (seed 000 §4.4 gives < 100 e⁻/s for the
        mean). A fraction ``hot_pixel_fraction`` of pixels, chosen at random, hold a strong
        defect: their mean is ``hot_pixel_dark_current_e_per_s``, with the same relative
        spread. In the dark a pixel fires at its dark current / Q.
        """
        p = self.parameters
        rng = self._pattern_rng(0xDA4C)
        spread = self._log_normal(rng, p.dark_current_spread_fraction, (height, width))
        hot = rng.random((height, width)) < p.hot_pixel_fraction if p.hot_pixel_fraction > 0 else \
            np.zeros((height, width), bool)
        return np.where(hot, p.hot_pixel_dark_current_e_per_s, p.dark_current_e_per_s) * spread

    def _pixel_light(self, height: int, width: int):
        """(a, b) per pixel: charge per tick in fixed point is rint(a·lux + b)."""
        key = ("light", height, width)
        if key not in self._tables:
            p = self.parameters
            scale = FIXED_POINT_SCALE / p.clock_hz
            a = (self.gain_map(height, width) * (p.optics.electrons_per_lux_second * scale)).ravel()
            b = (self.dark_current_map_e_per_s(height, width) * scale).ravel()
            self._tables[key] = (np.ascontiguousarray(a), np.ascontiguousarray(b))
        return self._tables[key]

    def _pixel_tables(self, height: int, width: int):
        key = (height, width)
        if key not in self._tables:
            q = self.threshold_map_electrons(height, width).ravel()
            shapes, index = np.unique(q, return_inverse=True)
            tables = build_tables(shapes) if self.parameters.photon_noise else \
                (np.zeros((1, 1, 4)),)
            self._tables[key] = (q, shapes, index.astype(np.int32), tables)
        return self._tables[key]

    def _saturation_bounds(self, height: int, width: int) -> np.ndarray:
        """Per pixel, the charge per tick (fixed point) from which it fires every tick whatever its
        state (:func:`saturation_bound_fixed`; photon noise only)."""
        key = ("saturation", height, width)
        if key not in self._tables:
            q, shapes, index, tables = self._pixel_tables(height, width)
            if self.parameters.photon_noise:
                bounds = saturation_bound_fixed(shapes, tables[0])[index]
            else:
                bounds = np.full(q.size, np.iinfo(np.int64).max, dtype=np.int64)
            self._tables[key] = np.ascontiguousarray(bounds)
        return self._tables[key]

    # ------------------------------------------------------------------ light
    def electrons_per_tick(self, lux) -> np.ndarray:
        """Expected electrons (signal + dark) collected per tick at illuminance ``lux``."""
        p = self.parameters
        return (p.optics.electrons_per_s(lux) + p.dark_current_e_per_s) / p.clock_hz

    def _fixed_point_rates(self, lux, height: int, width: int) -> np.ndarray:
        """Charge per tick of each pixel (``lux`` shape (N, H·W)) in the kernels' fixed point
        (2^-32 e⁻): rint(a·lux + b) with the per-pixel gain and dark current; refuses light
        that overflows it."""
        a, b = self._pixel_light(height, width)
        rates = lux * a
        rates += b
        if rates.size and float(rates.max()) >= MAX_RATE_FIXED_POINT:
            raise self._too_bright(float(lux.max()))
        return np.rint(rates, out=rates).astype(np.int64)  # half to even, as the compiled light

    def _too_bright(self, lux_max: float) -> ViformError:
        p = self.parameters
        limit = p.optics.lux_from_electrons_per_s(MAX_RATE_FIXED_POINT / FIXED_POINT_SCALE * p.clock_hz)
        limit = float(limit) / (1 + 5 * p.gain_spread_fraction)
        return ViformError(f"scene illuminance {lux_max:.3g} lux is above the simulator's limit of about "
                           f"{limit:.3g} lux for this pixel and clock (the pixel saturates long before: "
                           "one spike per tick)")

    def expected_firing_rate_per_tick(self, lux) -> np.ndarray:
        """Mean spikes per tick of a steady pixel (deterministic model, self-reset).

        min(λ·dt / Q, 1): the clock caps the rate at one spike per tick.
        """
        return np.minimum(self.electrons_per_tick(lux) / round(self.parameters.threshold_electrons), 1.0)

    # ------------------------------------------------------------------ simulation
    def run_plan(self, scene: Scene, duration_s: float, seed: int, block_ticks: int | None, light_sample_ticks: int,
                 state, compiled_light: bool, packed: bool, drop_light_kinds: tuple = ()) -> _RunPlan:
        """Everything a simulation run fixes before its first tick, the same for every device: sizes, the
        compiled light (None for kinds in ``drop_light_kinds``: the NumPy light, same bits), block size,
        per-pixel tables and light factors, the start state and the kernel mode."""
        check_positive("duration_s", duration_s)
        p = self.parameters
        n_ticks = max(1, int(round(duration_s * p.clock_hz)))
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        sample = check_int("light_sample_ticks", light_sample_ticks, 1)
        light = scene.compiled_light() if compiled_light else None
        if light is not None and light.kind in drop_light_kinds:
            light = None
        if block_ticks is None:
            block_ticks = self.default_block_ticks(scene, sample, light, packed=packed)
        block_ticks = check_int("block_ticks", block_ticks, 1)
        q, shapes, index, tables = self._pixel_tables(height, width)
        a, b = self._pixel_light(height, width)
        rate_bound = None
        if light is not None:
            rate_bound = float(a.max()) * light.lux_max + float(b.max())
            if rate_bound >= MAX_RATE_FIXED_POINT:
                raise self._too_bright(light.lux_max)
        caller_state = state is not None
        state = self.start_state(scene, sample, height, width, seed, q, state)
        reset_readout = p.reset == "readout"
        dead_ticks = p.dead_time_s * p.clock_hz
        if not p.photon_noise and dead_ticks == 0:
            mode = MODE_NOISE_FREE_READOUT if reset_readout else MODE_NOISE_FREE_SELF
        else:
            mode = MODE_GENERAL
        return _RunPlan(p, n_ticks, height, width, pixels, 8 * ((pixels + _LANES - 1) // _LANES), sample, light,
                        block_ticks, q, shapes, index, tables, a, b, rate_bound, state, caller_state, reset_readout,
                        dead_ticks, mode, light is not None and light.kind != "frames")

    def start_state(self, scene: Scene, sample: int, height: int, width: int, seed: int, q,
                    state: SpikeSimulationState | None = None) -> SpikeSimulationState:
        """The state at t = 0 that every device starts from (CPU and GPU share this host code).

        ``state`` (a fresh :meth:`initial_state`) or a new one; with dead time and a random
        start, replaced by the stationary state with dead time, which depends on the light
        of the first tick (see :func:`_dead_time_stationary_state`).
        """
        if state is None:
            state = self.initial_state(height, width, seed)
        elif state.next_tick != 0:
            raise ViformError(f"state has already run to tick {state.next_tick}; simulate starts at tick 0, "
                              "so pass a fresh initial_state")
        p = self.parameters
        dead_ticks = p.dead_time_s * p.clock_hz
        if dead_ticks > 0 and p.random_initial_charge:
            _dead_time_stationary_state(state.charge, state.target, state.counter, q, state.keys,
                                        _first_tick_rates(self, scene, sample, height, width), dead_ticks,
                                        p.photon_noise, p.reset == "readout")
        return state

    def initial_state(self, height: int, width: int, seed: int) -> SpikeSimulationState:
        """State at t = 0: first targets and (optionally) a random initial charge."""
        q, shapes, index, tables = self._pixel_tables(height, width)
        n = q.size
        counter = np.zeros(n, dtype=np.int64)
        target = np.empty(n, dtype=np.int64)
        charge = np.zeros(n, dtype=np.int64)
        keys = stream_keys(seed, n)
        _initial_targets(target, charge, counter, q, index, *tables, keys,
                         self.parameters.photon_noise, self.parameters.random_initial_charge)
        return SpikeSimulationState(charge, target, counter, keys, 0)

    def simulate(self, scene: Scene, duration_s: float, *, seed: int = 0, block_ticks: int | None = None,
                 light_sample_ticks: int = 1, progress: bool = False,
                 state: SpikeSimulationState | None = None,
                 reuse_buffer: bool = False, compiled_light: bool = True,
                 device: str = "cpu") -> Iterator[tuple[int, np.ndarray]]:
        """Simulate tick by tick in time blocks; yields ``(first_tick, spikes)`` with bool (T, H, W).

        Memory is bounded by the block (default: about :data:`BLOCK_BYTES` of spike bits and
        light, see :meth:`default_block_ticks`), whatever the resolution and duration. The
        kernels produce packed bits (:meth:`simulate_packed`, what file writers use); this
        unpacks them.

        Light: a scene that describes itself (``scene.compiled_light()``, see
        :mod:`viform.light.compiled`: still images, image sequences, the built-in synthetic
        scenes) is evaluated inside the compiled kernel; any other scene is evaluated by
        NumPy (``illuminance_lux_many``) per light sample.

        Parameters
        ----------
        scene : Scene
            The light.
        duration_s : float
            Length of the stream, seconds (rounded to whole ticks).
        seed : int
            Photon-noise seed. Same seed, same bits, whatever ``block_ticks``.
        block_ticks : int, optional
            Ticks per block.
        light_sample_ticks : int
            The scene is evaluated at the middle of every interval of ``light_sample_ticks``
            ticks and held over it; 1 (default) evaluates it at the middle of every tick.
        reuse_buffer : bool
            Yield every block in the same output buffer, overwritten by the next block: for
            consumers that use each block at once (writers, reducers), it saves allocating and
            page-faulting fresh memory for every block. Copy a block to keep it.
        state : SpikeSimulationState, optional
            A fresh :meth:`initial_state` (t = 0) that the simulation updates in place, so a
            caller can read the pixels' charge between blocks. The stream always starts at
            tick 0: a state already advanced is refused rather than restarted.
        compiled_light : bool
            Use the scene's compiled light when it has one (True); False forces the NumPy path.
        device : {"cpu", "cuda", "auto"}
            Where the kernels run: the CPU cores, a CUDA GPU through numba-cuda
            (:mod:`viform.sensors.spike_cuda`: the same algorithm and draws), or a GPU when
            numba-cuda finds one, else the CPU.
        """
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        buffer = None
        for first, packed in self._packed_blocks(scene, duration_s, seed, block_ticks, light_sample_ticks, progress,
                                                 state, reuse_buffer, compiled_light, device=device):
            n = packed.shape[0]
            if reuse_buffer:
                if buffer is None or buffer.shape[0] < n:
                    buffer = np.empty((n, pixels), dtype=np.bool_)
                out = buffer[:n]
            else:
                out = np.empty((n, pixels), dtype=np.bool_)
            _unpack_bits(packed, out.view(np.uint8))
            yield first, out.reshape(n, height, width)

    def simulate_packed(self, scene: Scene, duration_s: float, *, seed: int = 0, block_ticks: int | None = None,
                        light_sample_ticks: int = 1, progress: bool = False, flip: bool = False,
                        compiled_light: bool = True, device: str = "cpu") -> Iterator[tuple[int, np.ndarray]]:
        """As :meth:`simulate`, but yields the spikes as they are produced: packed bits in the
        ``.dat`` layout, ``(first_tick, frames)`` with uint8 frames (T, H·W/8), pixel k = r·W + c
        in bit k mod 8 of byte k // 8; ``flip`` stores the rows bottom-up, as the cameras write.
        Every block is a fresh array. Needs H·W to be a multiple of 8 (whole bytes per frame).
        ``device`` as in :meth:`simulate`."""
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        if pixels % 8:
            raise ViformError(f"height × width = {height}×{width} is not a multiple of 8 pixels; packed frames "
                              "(.dat) hold whole bytes")
        for first, packed in self._packed_blocks(scene, duration_s, seed, block_ticks, light_sample_ticks, progress,
                                                 None, True, compiled_light, packed_only=True, device=device):
            frames = packed[:, : pixels // 8]
            if flip:
                if width % 8 == 0:
                    frames = frames.reshape(-1, height, width // 8)[:, ::-1].reshape(-1, pixels // 8)
                else:  # rows do not start on bytes: through bits
                    bits = np.unpackbits(frames, axis=1, bitorder="little").reshape(-1, height, width)
                    frames = np.packbits(bits[:, ::-1].reshape(-1, pixels), axis=1, bitorder="little")
            yield first, np.ascontiguousarray(frames)

    def _packed_blocks(self, scene, duration_s, seed, block_ticks, light_sample_ticks, progress, state,
                       reuse_buffer, compiled_light, packed_only=False, device="cpu"):
        """(first tick, packed bits uint8 (T, 8·⌈H·W/64⌉)) per block: the kernels' own output."""
        from viform.sensors.spike_cuda import packed_blocks_cuda, resolve_device

        if resolve_device(device) == "cuda":
            if block_ticks is None:
                block_ticks = self.default_block_ticks(scene, light_sample_ticks,
                                                       scene.compiled_light() if compiled_light else None,
                                                       packed=packed_only)
            yield from packed_blocks_cuda(self, scene, duration_s, seed, block_ticks, light_sample_ticks, progress,
                                          state, compiled_light)
            return
        plan = self.run_plan(scene, duration_s, seed, block_ticks, light_sample_ticks, state, compiled_light,
                             packed_only)
        p, n_ticks, height, width, row_bytes = plan.p, plan.n_ticks, plan.height, plan.width, plan.row_bytes
        sample, light, block_ticks, q, index, tables = (plan.sample, plan.light, plan.block_ticks, plan.q,
                                                        plan.index, plan.tables)
        a, b, state, caller_state, reset_readout = plan.a, plan.b, plan.state, plan.caller_state, plan.reset_readout
        dead_ticks, mode, per_tick_light = plan.dead_ticks, plan.mode, plan.per_tick_light
        if light is not None:
            fast_round = plan.rate_bound < _FAST_ROUND_LIMIT
        if per_tick_light:
            from viform.light.compiled import tick_buffers, tick_scalars

            kind, params, frames = light.kernel_kind(), light.parameters(), light.flat_frames()
            scalars, xtab, ytab = tick_buffers(light, min(block_ticks, n_ticks))
            xs = np.arange(width, dtype=np.float64)
            band_rows = _band_rows(height, width)
        else:
            bounds = self._saturation_bounds(height, width)
        segments = _Segments(self, scene, light, sample, height, width)
        buffer = None
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=n_ticks, unit="tick", desc="simulate", leave=False, unit_scale=True)
        try:
            for first in range(0, n_ticks, block_ticks):
                last = min(first + block_ticks, n_ticks)
                if reuse_buffer:
                    if buffer is None or buffer.shape[0] < last - first:
                        buffer = np.empty((last - first, row_bytes), dtype=np.uint8)
                    out = buffer[: last - first]
                else:
                    out = np.empty((last - first, row_bytes), dtype=np.uint8)
                if per_tick_light:
                    # light at the middle of each interval of `sample` ticks, held over it
                    times = (np.arange(first, last) // sample + 0.5) * (sample / p.clock_hz)
                    n = last - first
                    tick_scalars(times, params, kind, scalars[:n], xtab[:n], ytab[:n])
                    _run_block_ticks(out, kind, scalars, xtab, ytab, frames, params, a, b, xs, fast_round,
                                     state.charge, state.target, state.counter, q, index, *tables, state.keys,
                                     p.photon_noise, reset_readout, dead_ticks, band_rows)
                else:
                    rates, seg_end = segments.block(first, last)
                    _run_block(out.view(np.uint64), rates, seg_end, first, state.charge, state.target,
                               state.counter, q, index, *tables, state.keys, p.photon_noise, reset_readout,
                               dead_ticks, mode, bounds, state.pending_ticks, state.pending_rate)
                    if caller_state:  # the caller reads the state between blocks: no tick left pending
                        _settle_all(state.charge, state.target, state.counter, q, index, *tables, state.keys,
                                    state.pending_ticks, state.pending_rate)
                state.next_tick = last
                if bar is not None:
                    bar.update(last - first)
                yield first, out
        finally:
            if bar is not None:
                bar.close()

    def default_block_ticks(self, scene: Scene, light_sample_ticks: int = 1, light=None,
                            budget_bytes: int | None = None, packed: bool = False) -> int:
        """Ticks per block so that a block's buffers take about ``budget_bytes`` (default
        :data:`BLOCK_BYTES`): spike bits (packed, 1/8 byte per pixel-tick, plus 1 byte per
        pixel-tick when unpacked to bool, unless ``packed``) plus the light it needs (compiled
        light: a few per-tick scalars, or one int64 rate row per run of constant light;
        otherwise float64 light and int64 charge rates, plus the scene's own temporaries, per
        light sample)."""
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        budget = BLOCK_BYTES if budget_bytes is None else budget_bytes
        spikes = pixels / 8 + (0 if packed else pixels)
        if light is None:
            per_tick = spikes + pixels * 32 / light_sample_ticks
        elif light.kind == "frames":
            per_tick = spikes + pixels * 8 / _ticks_per_run(light, light_sample_ticks, self.parameters.clock_hz)
        else:
            from viform.light.compiled import tick_bytes

            per_tick = spikes + tick_bytes(light)
        return max(1, int(budget // per_tick))

    def capture(self, scene: Scene, duration_s: float, *, seed: int = 0, block_ticks: int | None = None,
                light_sample_ticks: int = 1, progress: bool = False, device: str = "cpu") -> SpikeStream:
        """Simulate into memory and return the :class:`SpikeStream` (``device`` as in :meth:`simulate`)."""
        from viform.sensors.spike_cuda import resolve_device

        device = resolve_device(device)
        blocks = [b for _, b in self.simulate(scene, duration_s, seed=seed, block_ticks=block_ticks,
                                              light_sample_ticks=light_sample_ticks, progress=progress,
                                              device=device)]
        return SpikeStream(np.concatenate(blocks), self.parameters.clock_hz, self.parameters.threshold_electrons,
                           0.0, self.capture_metadata(scene, seed, light_sample_ticks, device))

    def stream(self, scene: Scene, duration_s: float, *, seed: int = 0, light_sample_ticks: int = 1,
               progress: bool = False, reuse_buffer: bool = False, device: str = "cpu") -> SimulatedSpikes:
        """A lazy :class:`SpikeSource` that simulates as it is read (bounded memory).

        With ``reuse_buffer`` the blocks of ``iter_blocks`` share one buffer (see
        :meth:`simulate`): for writers that consume each block at once. ``device`` as in
        :meth:`simulate` ("auto" is resolved here, once).
        """
        return SimulatedSpikes(self, scene, duration_s, seed, light_sample_ticks, progress, reuse_buffer, device)

    def capture_metadata(self, scene: Scene, seed: int, light_sample_ticks: int, device: str = "cpu") -> dict:
        """Provenance of a simulated stream; ``device`` ("cpu" or "cuda") names the machine that ran it."""
        meta = {"sensor": self.describe(), "scene": scene.describe(), "seed": seed,
                "light_sample_ticks": light_sample_ticks}
        if device == "cuda":
            from viform.sensors.spike_cuda import device_description

            meta["device"] = f"cuda: {device_description()}"
        else:
            meta["device"] = "cpu"
        return meta

    def describe(self) -> dict:
        d = self.parameters.to_dict()
        d["model"] = self.name
        d["shortest_interval_s"] = self.parameters.shortest_interval_s
        d["longest_signal_interval_s"] = self.parameters.longest_signal_interval_s
        return d


class SimulatedSpikes(SpikeSource):
    """A spike stream simulated on demand, block by block, for files longer than memory.

    Reading is sequential: ``iter_blocks`` simulates from the start each time;
    ``read_ticks`` does so up to the requested ticks (simple, not fast).
    """

    def __init__(self, sensor: SpikeSensor, scene: Scene, duration_s: float, seed: int,
                 light_sample_ticks: int = 1, progress: bool = False, reuse_buffer: bool = False,
                 device: str = "cpu"):
        from viform.sensors.spike_cuda import resolve_device

        self.device = resolve_device(device)
        p = sensor.parameters
        self.sensor, self.scene, self.seed = sensor, scene, seed
        self.light_sample_ticks, self.progress = light_sample_ticks, progress
        self.reuse_buffer = reuse_buffer  # blocks from iter_blocks valid only until the next one
        self.height, self.width = sensor.check_scene(scene, sensor.height, sensor.width)
        self.n_ticks = max(1, int(round(check_positive("duration_s", duration_s) * p.clock_hz)))
        self.clock_hz = p.clock_hz
        self.threshold_electrons = p.threshold_electrons
        self.start_time_s = 0.0
        self.metadata = sensor.capture_metadata(scene, seed, light_sample_ticks, self.device)

    def iter_blocks(self, block_ticks: int = 1024, start: int = 0, stop: int | None = None,
                    reuse_buffer: bool | None = None):
        stop = self.n_ticks if stop is None else min(stop, self.n_ticks)
        reuse = self.reuse_buffer if reuse_buffer is None else reuse_buffer
        # the caller's block size, but never more than the memory budget allows
        block_ticks = min(check_int("block_ticks", block_ticks, 1),
                          self.sensor.default_block_ticks(self.scene, self.light_sample_ticks,
                                                          self.scene.compiled_light()))
        sim = self.sensor.simulate(self.scene, self.n_ticks / self.clock_hz, seed=self.seed,
                                   block_ticks=block_ticks, light_sample_ticks=self.light_sample_ticks,
                                   progress=self.progress, reuse_buffer=reuse, device=self.device)
        for first, block in sim:
            if first + block.shape[0] <= start:
                continue
            if first >= stop:
                break
            a, b = max(start - first, 0), min(stop - first, block.shape[0])
            yield first + a, block[a:b]

    def iter_packed_blocks(self, block_ticks: int = 1 << 20, flip: bool = True):
        """The whole stream as packed ``.dat`` frames, ``(first_tick, uint8 (T, H·W/8))``, straight
        from the kernels (no bool round trip): what :func:`viform.stream.dat.write_dat` writes.
        Blocks are at most ``block_ticks`` and the simulator's memory budget."""
        block_ticks = min(check_int("block_ticks", block_ticks, 1),
                          self.sensor.default_block_ticks(self.scene, self.light_sample_ticks,
                                                          self.scene.compiled_light(), packed=True))
        yield from self.sensor.simulate_packed(self.scene, self.n_ticks / self.clock_hz, seed=self.seed,
                                               block_ticks=block_ticks, light_sample_ticks=self.light_sample_ticks,
                                               progress=self.progress, flip=flip, device=self.device)

    def read_ticks(self, start: int, stop: int) -> np.ndarray:
        parts = [b for _, b in self.iter_blocks(max(1, stop - start), start, stop, reuse_buffer=False)]
        return np.concatenate(parts) if parts else np.zeros((0, self.height, self.width), bool)


class _Segments:
    """Charge rates of a block as runs of constant light: (rates (n, H·W) int64, seg_end (n,)).

    ``seg_end[s]`` is the absolute tick where run s ends (exclusive). Compiled "frames"
    light (still image, step, image sequence held) gives one run per frame in effect;
    any other scene one run per light sample, evaluated by NumPy.
    """

    def __init__(self, sensor, scene, light, sample, height, width):
        self.sensor, self.scene, self.light, self.sample = sensor, scene, light, sample
        self.height, self.width = height, width
        self._cached = (None, None)  # (frame index, rates) of the last frame used

    def block(self, first: int, last: int):
        sample = self.sample
        j0, j1 = first // sample, -(-last // sample)
        clock = self.sensor.parameters.clock_hz
        # light sampled at the middle of each interval of `sample` ticks, held over it
        times = (np.arange(j0, j1) + 0.5) * (sample / clock)
        if self.light is None or self.light.kind != "frames":
            lux = self.scene.illuminance_lux_many(times).reshape(times.size, -1)
            return (self.sensor._fixed_point_rates(lux, self.height, self.width),
                    (np.arange(j0, j1, dtype=np.int64) + 1) * sample)
        index = np.asarray(self.light.frame_index(times), dtype=np.int64)
        change = np.flatnonzero(np.diff(index)) + 1
        starts = np.concatenate(([0], change))
        ends = np.concatenate((change, [index.size]))
        seg_end = (j0 + ends).astype(np.int64) * sample
        rates = np.empty((starts.size, self.height * self.width), dtype=np.int64)
        for i, start in enumerate(starts):
            k = int(index[start])
            if self._cached[0] != k:
                lux = self.light.frames[k].reshape(1, -1)
                self._cached = (k, self.sensor._fixed_point_rates(lux, self.height, self.width)[0])
            rates[i] = self._cached[1]
        return rates, seg_end


# ---------------------------------------------------------------------- fixed pattern and start-up helpers

def _threshold_spread_draw(threshold_electrons: float, spread_fraction: float, fixed_pattern_seed: int,
                           shape) -> np.ndarray:
    """Per-pixel thresholds, e⁻: log-normal of mean Q and std / mean ``spread_fraction``, rounded.

    A threshold is a comparator level set by a reference voltage and a capacitance, both
    positive; a log-normal law (σ² = ln(1 + spread²), median Q·e^(−σ²/2)) stays positive with
    no mass piled up at a clip, where a Gaussian clipped at 1 e⁻ put 99 of 4,096 pixels at
    Q = 1 at a spread of 0.49. At the few-percent spreads of real chips the two laws agree.
    The same law as the gain spread (:meth:`SpikeSensor.gain_map`). Rounding to whole
    electrons (and the 1 e⁻ floor the caller applies) matters only where Q·spread is a few e⁻.
    """
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([fixed_pattern_seed, 0x51])))
    sigma = math.sqrt(math.log1p(spread_fraction * spread_fraction))
    return np.rint(threshold_electrons * np.exp(sigma * rng.standard_normal(shape) - 0.5 * sigma * sigma))


def _first_tick_rates(sensor: SpikeSensor, scene: Scene, sample: int, height: int, width: int) -> np.ndarray:
    """Each pixel's charge in tick 0 (fixed point, int64), as the kernels compute it."""
    clock = sensor.parameters.clock_hz
    lux = scene.illuminance_lux_many(np.array([0.5 * sample / clock])).reshape(1, -1)
    return sensor._fixed_point_rates(lux, height, width)[0]


@njit(cache=True)
def _dead_time_stationary_state(charge, target, counter, q, keys, rates, dead_ticks, noise, reset_readout):
    """Replace each pixel's state by the stationary state of its spike train *with* dead time.

    With a dead time every cycle of the pixel is the charge to the threshold, G (Gamma(Q, 1)
    in charge time, or Q without photon noise, seed 000 §5.1), plus the dead charge time
    D = λ·t_d (λ e⁻/tick of the first tick, t_d in ticks), during which the charge sits
    below zero (the kernels subtract D at each reset). An observer at a time unrelated to
    the spikes sees a cycle chosen with probability ∝ its length and sits a uniform fraction
    of the way into it (renewal theory, e.g. Cox, *Renewal Theory*, 1962, §1.4):

    * self-reset (cycle G + D in charge time): G is Gamma(Q + 1) with probability Q/(Q + D)
      and Gamma(Q) otherwise (the length-biased law of G + D), the charge is U·(G + D) − D;
    * reset at readout (cycle N = ⌈(G + D)/λ⌉ whole ticks): the cycle is chosen ∝ N and the
      observer stands at one of its N tick boundaries, m uniform, with charge m·λ − D.
      Drawn by rejection from the law ∝ (G + D + λ)·f(G), accepting with N·λ/(G + D + λ)
      (≥ 1/2, since N ≥ max(1, (G + D)/λ) and N ≤ (G + D)/λ + 1).

    The firing rate is then the steady rate from the first tick (the whole array does not
    fire in step). Exact for light that is steady over the first cycle. Uses one event of
    each pixel's random stream (``counter[p]``, advanced).
    """
    scale = 4294967296.0
    for p in range(q.size):
        e = rates[p]
        dead = np.int64(e * dead_ticks + 0.5)  # as the kernels' reset
        state = event_stream(keys[p], counter[p])
        counter[p] += 1
        qq = float(q[p])
        d_e = dead / scale
        e_e = e / scale
        if not reset_readout or e <= 0:
            if noise:
                u, state = stream_uniform(state)
                shape = qq + 1.0 if u * (qq + d_e) < qq else qq
                g, state = stream_gamma(shape, state)
            else:
                g = qq
            t = max(np.int64(1), np.int64(g * scale + 0.5))
            u, state = stream_uniform(state)
            charge[p] = np.int64(u * (t + dead)) - dead
            target[p] = t
            continue
        while True:
            if noise:
                u, state = stream_uniform(state)
                shape = qq + 1.0 if u * (qq + d_e + e_e) < qq else qq
                g, state = stream_gamma(shape, state)
            else:
                g = qq
            t = max(np.int64(1), np.int64(g * scale + 0.5))
            cycle = (t + dead + e - 1) // e  # ticks from a reset to the next crossing, ⌈(G + D)/λ⌉
            u, state = stream_uniform(state)
            if not noise or u * (t + dead + e) < cycle * e:
                break
        u, state = stream_uniform(state)
        m = min(np.int64(u * cycle), cycle - 1)
        charge[p] = m * e - dead
        target[p] = t


# ---------------------------------------------------------------------- kernels
# Charge is kept in fixed point (2^-32 e⁻ units, int64): integer sums are exact and
# associative, so the event-driven kernel below, which jumps straight to the next
# threshold crossing, gives the same bits as tick-by-tick summation, whatever the block size.
FIXED_POINT_SCALE = float(1 << 32)
#: Largest charge per tick, fixed point: sums of charge and target then stay inside int64.
MAX_RATE_FIXED_POINT = float(1 << 61)
# From 8·Q² e⁻ past a tick's first crossing, P(N mod Q = m) for N ~ Poisson(r) differs from
# 1/Q by at most exp(−r·(1 − cos 2π/Q)) ≤ exp(−8r/Q²), below e^-64: the pixel leaves the
# tick in the stationary state (see :func:`_run_block`).
# Below that, a tick with more than this many Q of charge after its first crossing jumps to
# its end state exactly (:func:`_saturated_state`, ~0.2 µs) instead of one Gamma per crossing.
_JUMP_INTERVALS = 48.0


@njit(cache=True)
def _initial_targets(target, charge, counter, q, index, bins, keys,
                     noise, random_initial):
    for p in range(q.size):
        if noise and random_initial:
            charge[p], target[p] = _equilibrium_state(p, q, index, bins, keys, counter)
        else:
            target[p] = _next_target(p, q, index, bins, keys, noise, counter)
            if random_initial:
                # the noise-free pixel's stationary state: a uniform fraction of Q collected
                u = uniform_from_hash(splitmix64(keys[p] ^ np.uint64(0x5EED5EED5EED5EED)))
                charge[p] = np.int64(u * target[p])


@njit(cache=True, inline="always")
def _equilibrium_state(p, q, index, bins, keys, counter):
    """(charge, target) of pixel p drawn from the stationary state of its renewal process.

    In charge time the spikes of a self-reset pixel are a renewal process with Gamma(Q, 1)
    intervals (seed 000 §5.1). Observed at a time unrelated to its spikes, the interval in
    progress is length-biased, Gamma(Q + 1, 1) = Gamma(Q, 1) + Exp(1), and the observer sits
    a uniform fraction of the way into it; the charge still missing is then the stationary
    forward-recurrence law (1 − F_Q(x))/Q. Used for the random initial charge (so the stream
    is stationary from t = 0) and after a tick of heavy saturation (see :func:`_run_block`).
    Uses draw ``counter[p]`` of the pixel's stream and advances it.
    """
    g = gamma_draw(q[p], index[p], bins, keys[p], counter[p])
    h = splitmix64(keys[p] + np.uint64(counter[p]) * np.uint64(0x9E3779B97F4A7C15)
                   ^ np.uint64(0x5EED5EED5EED5EED))
    counter[p] += 1
    length = g - np.log(uniform_from_hash(h))  # Gamma(Q, 1) + Exp(1)
    target = max(np.int64(1), np.int64(length * 4294967296.0 + 0.5))
    charge = np.int64(uniform_from_hash(splitmix64(h)) * target)
    return charge, target


@njit(cache=True, inline="always")
def _saturated_state(residual, p, q, keys, counter):
    """(charge, target) of pixel p after ``residual`` e⁻ of charge time past a crossing, exactly.

    In charge time the electrons are a unit-rate Poisson process and a spike every Q-th of
    them (seed 000 §5.1), so the state at the end of the tick follows from N ~ Poisson(R)
    electrons in the remaining charge time R: k = N mod Q electrons belong to the interval
    in progress; its age (charge since the last crossing) is R when N < Q, else the distance
    back to the (k + 1)-th last of N uniform arrivals, R·Beta(k + 1, N − k); the Q − k
    electrons still missing take Gamma(Q − k, 1) more (memoryless). Constant cost, the same
    law as drawing one Gamma(Q) per lost crossing. Uses event ``counter[p]`` and advances it.
    """
    whole_q = np.int64(q[p])
    state = event_stream(keys[p], counter[p])
    counter[p] += 1
    n, state = stream_poisson(residual, state)
    k = n % whole_q
    if n < whole_q:
        age = residual
    else:
        x, state = stream_gamma(k + 1.0, state)
        y, state = stream_gamma(float(n - k), state)
        age = residual * x / (x + y)
    rest, state = stream_gamma(float(whole_q - k), state)
    charge = np.int64(age * 4294967296.0)
    target = max(charge + 1, np.int64((age + rest) * 4294967296.0 + 0.5))
    return charge, target


@njit(cache=True, inline="always")
def _next_target(p, q, index, bins, keys, noise, counter):
    if noise:
        t = gamma_draw(q[p], index[p], bins, keys[p], counter[p])
    else:
        t = q[p]
    counter[p] += 1
    return max(np.int64(1), np.int64(t * 4294967296.0 + 0.5))


@njit(cache=True, inline="always")
def _fixed_charge(electrons):
    """``electrons`` in fixed point, capped at 2^62 (a bound no tick's charge reaches, so the cap
    only disables a shortcut, never overflows: 8·Q²·2^32 passes 2^63 from Q = 2^14)."""
    x = electrons * 4294967296.0
    return np.int64(x) if x < 4611686018427387904.0 else np.int64(4611686018427387904)


@njit(cache=True)
def _fire_general(c, t, e, dead_ticks, p, q, index, bins, keys, noise, reset_readout, counter):
    """(charge, target) of pixel p after its charge ``c`` reached its target ``t`` in a tick
    of charge ``e`` (fixed point); the spike itself is the caller's (:func:`_fire` inlines
    the common case of this).

    Self-reset: the charge past the crossing is kept; further crossings inside the same tick
    are lost to the one-bit readout. Dead time: no charge is collected for ``dead_ticks``
    ticks after each crossing — in charge time (where the photoelectrons are a unit-rate
    Poisson process, seed 000 §5.1) the pixel skips ``e·dead_ticks`` of charge, exact while
    the light is constant over the dead time (the crossing tick's light is used).
    Readout reset: the charge is drained at the readout that ends the tick; the dead time
    runs from there.
    """
    dead = np.int64(0)
    if dead_ticks > 0.0:
        dead = np.int64(e * dead_ticks + 0.5)
    if reset_readout:
        return -dead, _next_target(p, q, index, bins, keys, noise, counter)
    if not noise:
        period = t + dead
        c -= period
        if c >= t:
            c -= ((c - t) // period + 1) * period
        return c, t
    if dead > 0:
        # the stationary shortcuts below assume no dead time: drain one crossing at a time
        # (at most e / (Q + dead) crossings a tick)
        while c >= t:
            c -= t + dead
            t = _next_target(p, q, index, bins, keys, noise, counter)
        return c, t
    over = c - t
    # charge past a crossing above which a saturated tick jumps / is stationary
    stationary_from = _fixed_charge(8.0 * q[p] * q[p])
    if over < min(_fixed_charge(_JUMP_INTERVALS * q[p]), stationary_from):
        while c >= t:
            c -= t
            t = _next_target(p, q, index, bins, keys, noise, counter)
        return c, t
    if over >= stationary_from:
        # ≥ 8·Q² e⁻ after the first crossing: the electron count mod Q is uniform to within
        # e^-64, so the pixel leaves the tick in the stationary state, drawn at once
        return _equilibrium_state(p, q, index, bins, keys, counter)
    # many crossings lost in this tick: jump to its end state exactly
    return _saturated_state(over / 4294967296.0, p, q, keys, counter)


@njit(cache=True, inline="always")
def _fire(c, t, e, dead_ticks, p, q, index, bins, keys, noise, reset_readout, counter):
    """(charge, target) of pixel p after its charge ``c`` reached its target ``t`` (see
    :func:`_fire_general`). The common case — self-reset with photon noise, no dead time,
    fewer than 48·Q e⁻ past the crossing — is inlined into the kernels; every other case is a
    call (kept out of line so the kernels compile fast)."""
    if noise and not reset_readout and dead_ticks == 0.0:
        if c - t < min(_fixed_charge(_JUMP_INTERVALS * q[p]), _fixed_charge(8.0 * q[p] * q[p])):
            # further crossings inside the same tick are lost to the one-bit readout
            while c >= t:
                c -= t
                t = _next_target(p, q, index, bins, keys, noise, counter)
            return c, t
    return _fire_general(c, t, e, dead_ticks, p, q, index, bins, keys, noise, reset_readout, counter)


# ---------------------------------------------------------------------- lane kernels (issue 30)
# Layout: pixels in lanes of 64 (one uint64 of spike bits per tick: bit i of word w is pixel
# 64·w + i, which on a little-endian machine is the .dat bit order, so the words are the file's
# bytes), the tick loop inside the work item so a tile's state stays in L1, and the spikes
# written as bits the moment they are produced.
#
# What the lane loop compiles to (checked with ``inspect_asm`` on x86-64 AVX-512, Zen 4;
# ``NUMBA_DEBUG_ARRAY_OPT_STATS`` reports only prange fusion, not LLVM's loop vectorizer):
# :func:`_lanes_add_compare` is fully unrolled into 8 × (vpaddq, vpcmpnltq → k-mask) per
# 64 lanes, the mask expanded and shifted into place (vpsllq / vporq) and OR-reduced to the
# word; on AVX2 the same code runs as 16 × 4 lanes. The fired lanes of a word are then
# visited with ``tzcnt`` (count trailing zeros), so a tick without spikes costs no branch
# per pixel, and the per-spike Gamma draw stays off the common path.
_LANES = 64
_TILE_WORDS = 4  # words (× 64 pixels) per work item of the constant-light kernel: state, rates in L1
_NO_TARGET = np.int64(0x7FFFFFFFFFFFFFFF)  # target of padding lanes: they never fire
#: Lane modes of the constant-light kernel: any option through :func:`_fire`; the two
#: noise-free models without dead time, resolved in the vector loop itself.
MODE_GENERAL, MODE_NOISE_FREE_SELF, MODE_NOISE_FREE_READOUT = 0, 1, 2


@njit(cache=True, inline="always")
def _lanes_add_compare(c, e, t, base):
    """Add each lane's charge for the tick; the word of lanes that reached their target."""
    word = np.uint64(0)
    for i in range(_LANES):
        cc = c[base + i] + e[base + i]
        c[base + i] = cc
        word |= np.uint64(cc >= t[base + i]) << np.uint64(i)
    return word


@njit(cache=True, inline="always")
def _lanes_noise_free_self(c, e, t, base):
    """Noise-free self-reset: add, compare, subtract the target where reached; also whether a
    lane is still at or above its target (light above one spike per tick: lost crossings)."""
    word = np.uint64(0)
    over = False
    for i in range(_LANES):
        tt = t[base + i]
        cc = c[base + i] + e[base + i]
        fired = cc >= tt
        cc = cc - tt if fired else cc
        c[base + i] = cc
        word |= np.uint64(fired) << np.uint64(i)
        over |= cc >= tt
    return word, over


@njit(cache=True, inline="always")
def _lanes_noise_free_readout(c, e, t, base):
    """Noise-free readout reset: add, compare, drain the lanes that fired."""
    word = np.uint64(0)
    for i in range(_LANES):
        cc = c[base + i] + e[base + i]
        fired = cc >= t[base + i]
        c[base + i] = 0 if fired else cc
        word |= np.uint64(fired) << np.uint64(i)
    return word


@njit(cache=True)
def _settle(p, charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate):
    """Apply pixel p's pending saturated ticks (see :func:`_run_block`) to its state, exactly
    as the lane loop would have: the same draws in the same order."""
    c = charge[p]
    t = target[p]
    e = pending_rate[p]
    for _ in range(pending_ticks[p]):
        c += e
        if c >= t:
            c, t = _fire(c, t, e, 0.0, p, q, index, bins, keys, True, False, counter)
    charge[p] = c
    target[p] = t
    pending_ticks[p] = 0


@njit(cache=True, parallel=True)
def _settle_all(charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate):
    for p in prange(charge.size):
        if pending_ticks[p] > 0:
            _settle(p, charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate)


@njit(cache=True, parallel=True)
def _run_block(words, rates, seg_end, first_tick, charge, target, counter, q, index, bins, keys, noise,
               reset_readout, dead_ticks, mode, lazy_bound, pending_ticks, pending_rate):
    """Integrate-and-fire over one block of ticks in runs of constant light, 64 pixels per word.

    ``rates[s, p]`` is the fixed-point charge per tick of pixel p in run s, which ends
    (exclusive) at absolute tick ``seg_end[s]``; the runs cover the block. ``words[k, w]``
    receives the spikes of pixels 64·w … 64·w + 63 in tick k (bit i: pixel 64·w + i).
    Charge sums are exact integers, so adding a run's rate tick by tick gives the bits the
    event-driven form (a jump to each crossing) gave.

    Saturated pixels cost nothing per tick: with photon noise, self-reset and no dead time, a
    pixel whose charge per tick reaches ``lazy_bound[p]`` — above the largest gap between
    charge and target that any draw can leave (:func:`saturation_bound_fixed`) — fires in every
    tick whatever its state, so the kernel only counts those ticks (``pending_ticks``, at rate
    ``pending_rate``) and :func:`_settle` replays the draws when the light changes or the
    caller asks for the state: same bits, same state, and a still saturated scene draws nothing.
    """
    n_ticks, n_words = words.shape
    n_pixels = charge.size
    lazy_ok = mode == MODE_GENERAL and noise and not reset_readout and dead_ticks == 0.0
    n_tiles = (n_words + _TILE_WORDS - 1) // _TILE_WORDS
    for tile in prange(n_tiles):
        w0 = tile * _TILE_WORDS
        nw = min(w0 + _TILE_WORDS, n_words) - w0
        p0 = w0 * _LANES
        n = min(nw * _LANES, n_pixels - p0)
        size = nw * _LANES
        c = np.zeros(size, dtype=np.int64)
        t = np.full(size, _NO_TARGET)
        e = np.zeros(size, dtype=np.int64)
        lazy_from = np.full(size, -1, dtype=np.int64)  # tick of the block where a lane's lazy run began
        lazy_mask = np.zeros(nw, dtype=np.uint64)
        # per lane, what a spike's common case reads (kept beside the lane state, in L1): the charge
        # past a crossing below which _fire draws crossing by crossing, and the draw's arguments
        one_by_one = np.zeros(size, dtype=np.int64)
        shape = np.ones(size)
        table = np.zeros(size, dtype=np.int64)
        key = np.zeros(size, dtype=np.uint64)
        drawn = np.zeros(size, dtype=np.int64)
        for j in range(n):
            p = p0 + j
            c[j] = charge[p]
            t[j] = target[p]
            one_by_one[j] = min(_fixed_charge(_JUMP_INTERVALS * q[p]), _fixed_charge(8.0 * q[p] * q[p]))
            shape[j] = q[p]
            table[j] = index[p]
            key[j] = keys[p]
        fast = lazy_ok  # photon noise, self-reset, no dead time: the common case inlined below
        s = 0
        while seg_end[s] <= first_tick:
            s += 1
        k = 0
        while k < n_ticks:
            end = min(seg_end[s] - first_tick, n_ticks)
            if end <= k:  # an empty run
                s += 1
                continue
            if not lazy_ok:
                for j in range(n):
                    e[j] = rates[s, p0 + j]
            else:
                for j in range(n):
                    p = p0 + j
                    r = rates[s, p]
                    lazy = r >= lazy_bound[p]
                    bit = np.uint64(1) << np.uint64(j & 63)
                    if drawn[j]:  # the lane's draws so far, into the pixel's counter
                        counter[p] += drawn[j]
                        drawn[j] = 0
                    if pending_ticks[p] > 0 and (not lazy or pending_rate[p] != r):
                        # the saturated stretch ends (or its light changes): its draws first
                        _settle(p, charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate)
                        c[j] = charge[p]
                        t[j] = target[p]
                    if lazy:
                        if pending_ticks[p] == 0:  # a new stretch starts from the lane's state
                            charge[p] = c[j]
                            target[p] = t[j]
                            pending_rate[p] = r
                        lazy_from[j] = k
                        c[j] = 0  # fires every tick and stays put
                        t[j] = 0
                        e[j] = 0
                        lazy_mask[j >> 6] |= bit
                    else:
                        if lazy_mask[j >> 6] & bit:  # left laziness above: its state is back
                            lazy_mask[j >> 6] &= ~bit
                        e[j] = r
            for w in range(nw):  # a word's 64 lanes through the run's ticks, then the next word
                base = w * _LANES
                for kk in range(k, end):
                    if mode == MODE_NOISE_FREE_SELF:
                        word, over = _lanes_noise_free_self(c, e, t, base)
                        if over:  # crossings lost inside the tick: the charge modulo the target
                            for i in range(base, base + _LANES):
                                if c[i] >= t[i]:
                                    c[i] %= t[i]
                    elif mode == MODE_NOISE_FREE_READOUT:
                        word = _lanes_noise_free_readout(c, e, t, base)
                    else:
                        word = _lanes_add_compare(c, e, t, base)
                        todo = word & ~lazy_mask[w]
                        while todo != 0:
                            i = base + np.int64(trailing_zeros(todo))
                            todo &= todo - np.uint64(1)
                            ci = c[i]
                            ti = t[i]
                            if fast and ci - ti < one_by_one[i]:
                                # _fire's common case, from the lane's copies: one Gamma target per crossing
                                # (the k-th draw of the pixel's stream: counter + drawn), later ones lost
                                while ci >= ti:
                                    ci -= ti
                                    x = gamma_draw(shape[i], table[i], bins, key[i], counter[p0 + i] + drawn[i])
                                    drawn[i] += 1
                                    ti = max(np.int64(1), np.int64(x * 4294967296.0 + 0.5))
                                c[i] = ci
                                t[i] = ti
                            else:
                                if drawn[i]:
                                    counter[p0 + i] += drawn[i]
                                    drawn[i] = 0
                                c[i], t[i] = _fire(ci, ti, e[i], dead_ticks, p0 + i, q, index, bins, keys, noise,
                                                   reset_readout, counter)
                    words[kk, w0 + w] = word
            if lazy_ok:
                for j in range(n):
                    if lazy_from[j] >= 0:
                        pending_ticks[p0 + j] += end - lazy_from[j]
                        lazy_from[j] = -1
            k = end
            s += 1
        for j in range(n):
            counter[p0 + j] += drawn[j]
            if not lazy_mask[j >> 6] & (np.uint64(1) << np.uint64(j & 63)):
                charge[p0 + j] = c[j]
                target[p0 + j] = t[j]


_LIGHT_WINDOW = 16  # ticks per window of the per-tick kernel: the window's light tables stay in cache
_ROUNDING_MAGIC = 6755399441055744.0  # 1.5·2^52
_ROUNDING_MAGIC_BITS = np.int64(0x4338000000000000)  # its bit pattern
#: Charge rates (fixed point) below which the per-tick kernel rounds by the magic number.
_FAST_ROUND_LIMIT = float(1 << 51)


@njit(cache=True, inline="always")
def _store_row_bits(out, k, bit0, n_bits, row_words, aligned):
    """Write the ``n_bits`` spike bits of one image row (``row_words``) at bit ``bit0`` of tick k's
    packed frame. ``aligned``: the row starts on a byte and is whole bytes (plain stores);
    otherwise its bytes are OR-ed into a frame zeroed beforehand (rows share edge bytes)."""
    byte0 = bit0 >> 3
    if aligned:
        for j in range(n_bits >> 3):
            out[k, byte0 + j] = np.uint8((row_words[j >> 3] >> np.uint64((j & 7) * 8)) & np.uint64(0xFF))
        return
    last = (bit0 + n_bits - 1) >> 3
    n_words = row_words.size
    for j in range(byte0, last + 1):
        rel = j * 8 - bit0  # row bit held by bit 0 of byte j (negative: the byte starts in the row before)
        if rel < 0:
            v = row_words[0] << np.uint64(-rel)
        else:
            wi = rel >> 6
            o = rel & 63
            v = row_words[wi] >> np.uint64(o)
            if o > 56 and wi + 1 < n_words:
                v |= row_words[wi + 1] << np.uint64(64 - o)
        out[k, j] |= np.uint8(v & np.uint64(0xFF))


@njit(cache=True, parallel=True)
def _run_block_ticks(out, kind, scalars, xtab, ytab, frames, params, a, b, xs, fast_round, charge, target,
                     counter, q, index, bins, keys, noise, reset_readout, dead_ticks, band_rows):
    """Integrate-and-fire with the light computed per pixel and tick in compiled code.

    The light of pixel p in tick k is :func:`viform.light.compiled.pixel_lux` from the
    tick's scalars (row k of ``scalars``, ``xtab``, ``ytab``); its charge that tick is
    int64(a[p]·lux + b[p] + 0.5) in fixed point (gain and dark current per pixel), added
    exactly; the pixel fires when the sum reaches its Gamma(Q) target (the same
    :func:`_fire` as the constant-light kernel). Per image row and tick: one vectorized pass
    for the light (:func:`~viform.light.compiled.row_lux`), one for the charge, one that adds,
    compares and packs 64 lanes per word, then only the lanes that fired. ``out`` (uint8,
    ticks × packed frame bytes) receives the bits in the .dat order. Work items are bands of
    ``band_rows`` rows × windows of ticks, so the light tables stay in cache.
    """
    n_ticks = out.shape[0]
    n_pixels = charge.size
    width = xs.size
    height = n_pixels // width
    n_row_words = (width + _LANES - 1) // _LANES
    padded = n_row_words * _LANES
    aligned = width % 8 == 0
    n_bands = (height + band_rows - 1) // band_rows
    for band in prange(n_bands):
        y0 = band * band_rows
        y1 = min(y0 + band_rows, height)
        lux = np.empty(width)
        rounded = np.zeros(padded)  # lanes past the row stay 0: no charge
        rate = rounded.view(np.int64)
        cw = np.zeros(padded, dtype=np.int64)
        tw = np.full(padded, _NO_TARGET)
        row_words = np.empty(n_row_words, dtype=np.uint64)
        byte_lo = (y0 * width) >> 3
        byte_hi = (y1 * width + 7) >> 3
        for w0 in range(0, n_ticks, _LIGHT_WINDOW):
            w1 = min(w0 + _LIGHT_WINDOW, n_ticks)
            if not aligned:
                for k in range(w0, w1):
                    out[k, byte_lo:byte_hi] = 0
            for y in range(y0, y1):
                base = y * width
                # the row's state in local buffers for the window: plain loops over them vectorize
                cw[:width] = charge[base:base + width]
                tw[:width] = target[base:base + width]
                for k in range(w0, w1):
                    row_lux(kind, k, y, xs, scalars, xtab, ytab, frames, params, lux)
                    # charge this tick, rint(a·lux + b) in fixed point
                    if fast_round:
                        # below 2^51, adding 1.5·2^52 rounds to an integer (half to even, as
                        # rint) held in the low mantissa bits: vectorizes where a float → int64
                        # conversion does not (AVX2)
                        for x in range(width):
                            rounded[x] = a[base + x] * lux[x] + b[base + x] + _ROUNDING_MAGIC
                        for x in range(width):
                            rate[x] -= _ROUNDING_MAGIC_BITS
                    else:
                        for x in range(width):
                            rate[x] = np.int64(np.rint(a[base + x] * lux[x] + b[base + x]))
                    for w in range(n_row_words):
                        row_words[w] = _lanes_add_compare(cw, rate, tw, w * _LANES)
                    _store_row_bits(out, k, base, width, row_words, aligned)
                    for w in range(n_row_words):
                        todo = row_words[w]
                        while todo != 0:
                            x = w * _LANES + np.int64(trailing_zeros(todo))
                            todo &= todo - np.uint64(1)
                            cw[x], tw[x] = _fire(cw[x], tw[x], rate[x], dead_ticks, base + x, q, index, bins, keys,
                                                 noise, reset_readout, counter)
                charge[base:base + width] = cw[:width]
                target[base:base + width] = tw[:width]


@njit(cache=True, parallel=True)
def _unpack_bits(packed, out):
    """Spike bits (ticks × packed bytes, .dat bit order) → bool (ticks × pixels)."""
    n_pixels = out.shape[1]
    whole = n_pixels >> 3
    for k in prange(out.shape[0]):
        for j in range(whole):
            byte = packed[k, j]
            for i in range(8):
                out[k, 8 * j + i] = (byte >> i) & 1
        for p in range(whole * 8, n_pixels):
            out[k, p] = (packed[k, p >> 3] >> (p & 7)) & 1


def saturation_bound_fixed(shapes, bins) -> np.ndarray:
    """Per Gamma table, a charge per tick (fixed point, 2^-32 e⁻) above which a self-reset
    pixel with photon noise and no dead time fires in every tick, whatever its state.

    After any draw the gap between a pixel's target and its charge is at most the largest
    value a draw can return (the samplers' uniforms have finite resolution): a table Gamma(Q)
    draw is below the last quantile plus 18.72 (= ln 2^27, the smallest 26-bit uniform) over
    its envelope's rate; the stationary state adds an Exp(1) below 37.5 (53-bit uniforms);
    the saturated jump leaves a Marsaglia–Tsang Gamma(≤ Q) draw d·(1 + c·x)³ with the
    Box–Muller |x| ≤ 8.66. One electron of margin covers the fixed-point roundings.
    """
    shapes = np.asarray(shapes, dtype=np.float64)
    bounds = np.empty(shapes.size, dtype=np.int64)
    for i, shape in enumerate(shapes):
        last = float(bins[i, -1, 0]) if bins.shape[0] > i and bins.shape[1] > 1 else shape
        rate = 1.0 - (shape - 1.0) / last if last > 0 else 1.0
        table_max = last + 18.72 / rate
        # d·(1 + 8.66/√(9d))³ = (√d + 2.887)³/√d is convex in √d: its largest value over the
        # shapes 1 … Q of the jump's draw is at one end
        marsaglia_max = max(((math.sqrt(d) + 8.66 / 3.0) ** 3) / math.sqrt(d) for d in (2.0 / 3.0, shape - 1.0 / 3.0))
        electrons = max(table_max + 37.5, marsaglia_max) + 3.0
        bounds[i] = min(int(math.ceil(electrons * FIXED_POINT_SCALE)), (1 << 63) - 1)
    return bounds


def _ticks_per_run(light, light_sample_ticks: int, clock_hz: float, probe: int = 4096) -> float:
    """Ticks per run of constant light of "frames" light, from its first ``probe`` light samples
    (each run is one int64 rate row of the block)."""
    times = (np.arange(probe) + 0.5) * (light_sample_ticks / clock_hz)
    index = np.asarray(light.frame_index(times))
    return probe * light_sample_ticks / (1 + int(np.count_nonzero(np.diff(index))))


def _band_rows(height: int, width: int) -> int:
    """Rows per work item of the per-tick kernel: 8, or fewer so that small images still give
    every thread a few bands (only where rows are whole bytes: bands must not share a byte)."""
    if width % 8:
        return 8
    threads = max(1, get_num_threads())
    return max(1, min(8, -(-height // (4 * threads))))


def simulation_threads() -> int:
    """Threads numba uses for the simulation kernel."""
    return get_num_threads()
