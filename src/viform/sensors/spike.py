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
number of threads and the device. The compiled kernels, shared by the CPU path here and the
CUDA path (:mod:`viform.sensors.spike_cuda`), live in :mod:`viform.sensors._spike_kernels`:
they write the ``.dat`` file's packed bits as the pixels fire (:meth:`SpikeSensor.simulate_packed`;
:meth:`SpikeSensor.simulate` unpacks them to bool).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
)
from viform.light.radiometry import PixelOptics
from viform.light.scenes import Scene
from viform.sensors.base import Sensor
from viform.stream.container import SpikeSource, SpikeStream

if TYPE_CHECKING:  # at run time these load with the kernels, on first use (see __getattr__)
    from viform.sensors._spike_kernels import FIXED_POINT_SCALE, SpikeSimulationState, _RunPlan, simulation_threads

__all__ = ["BLOCK_BYTES", "CHIP_THRESHOLD_LEVELS_ELECTRONS", "CLOCK_20KHZ", "CLOCK_40KHZ", "FIXED_POINT_SCALE",
           "MAX_THRESHOLD_ELECTRONS", "SimulatedSpikes", "SpikeSensor", "SpikeSensorParameters",
           "SpikeSimulationState", "simulation_threads"]


_FROM_KERNELS = ("FIXED_POINT_SCALE", "SpikeSimulationState", "simulation_threads")


def __getattr__(name: str):
    """``FIXED_POINT_SCALE``, ``SpikeSimulationState`` and ``simulation_threads`` live with the compiled
    kernels (:mod:`viform.sensors._spike_kernels`, numba); they are imported on first use, so that a
    command that only lists or checks sensors does not load numba (PEP 562)."""
    if name in _FROM_KERNELS:
        from viform.sensors import _spike_kernels

        return getattr(_spike_kernels, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_FROM_KERNELS])


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
        from viform.sensors._spike_kernels import FIXED_POINT_SCALE
        key = ("light", height, width)
        if key not in self._tables:
            p = self.parameters
            scale = FIXED_POINT_SCALE / p.clock_hz
            a = (self.gain_map(height, width) * (p.optics.electrons_per_lux_second * scale)).ravel()
            b = (self.dark_current_map_e_per_s(height, width) * scale).ravel()
            self._tables[key] = (np.ascontiguousarray(a), np.ascontiguousarray(b))
        return self._tables[key]

    def _pixel_tables(self, height: int, width: int):
        from viform.sensors._gamma import build_tables
        key = (height, width)
        if key not in self._tables:
            q = self.threshold_map_electrons(height, width).ravel()
            shapes, index = np.unique(q, return_inverse=True)
            tables = build_tables(shapes) if self.parameters.photon_noise else \
                (np.zeros((1, 1, 4)),)
            self._tables[key] = (q, shapes, index.astype(np.int32), tables)
        return self._tables[key]

    def _fixed_point_tables(self, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
        """The Gamma tables rescaled for the kernels' common case (:func:`fixed_point_tables`)."""
        from viform.sensors._spike_kernels import fixed_point_tables
        key = ("fixed", height, width)
        if key not in self._tables:
            self._tables[key] = fixed_point_tables(self._pixel_tables(height, width)[3][0])
        return self._tables[key]

    def _saturation_bounds(self, height: int, width: int) -> np.ndarray:
        """Per pixel, the charge per tick (fixed point) from which it fires every tick whatever its
        state (:func:`saturation_bound_fixed`; photon noise only)."""
        from viform.sensors._spike_kernels import saturation_bound_fixed
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
        from viform.sensors._spike_kernels import MAX_RATE_FIXED_POINT
        a, b = self._pixel_light(height, width)
        rates = lux * a
        rates += b
        if rates.size and float(rates.max()) >= MAX_RATE_FIXED_POINT:
            raise self._too_bright(float(lux.max()))
        return np.rint(rates, out=rates).astype(np.int64)  # half to even, as the compiled light

    def _too_bright(self, lux_max: float) -> ViformError:
        from viform.sensors._spike_kernels import FIXED_POINT_SCALE, MAX_RATE_FIXED_POINT
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
        from viform.sensors._spike_kernels import (
            _LANES,
            MAX_RATE_FIXED_POINT,
            MODE_GENERAL,
            MODE_NOISE_FREE_READOUT,
            MODE_NOISE_FREE_SELF,
            _RunPlan,
        )
        check_positive("duration_s", duration_s)
        p = self.parameters
        n_ticks = max(1, int(round(duration_s * p.clock_hz)))
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        sample = self.light_sample_ticks_for(scene, light_sample_ticks, duration_s)
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
                        dead_ticks, mode, light is not None and light.kind not in ("frames", "sampled"))

    def start_state(self, scene: Scene, sample: int, height: int, width: int, seed: int, q,
                    state: SpikeSimulationState | None = None) -> SpikeSimulationState:
        """The state at t = 0 that every device starts from (CPU and GPU share this host code).

        ``state`` (a fresh :meth:`initial_state`) or a new one; with dead time and a random
        start, replaced by the stationary state with dead time, which depends on the light
        of the first tick (see :func:`_dead_time_stationary_state`).
        """
        from viform.sensors._spike_kernels import _dead_time_stationary_state
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
        from viform.sensors._gamma import stream_keys
        from viform.sensors._spike_kernels import SpikeSimulationState, _initial_targets
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
                 light_sample_ticks: int | str = "auto", progress: bool = False,
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
        light_sample_ticks : int or "auto"
            The scene is evaluated at the middle of every interval of ``light_sample_ticks``
            ticks and held over it; 1 evaluates it at the middle of every tick. "auto" (default):
            the scene's choice (:meth:`light_sample_ticks_for`): for a moving or flickering built-in
            scene, and a described scene rendered per sample, the longest hold that misplaces its
            fastest edge by at most :data:`~viform.light.sampled.LIGHT_ERROR_PX` and keeps 32 samples
            per flicker period; 1 for still scenes, steps, videos, described full-field patterns and
            scenes whose light is not compiled.
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
        from viform.sensors._spike_kernels import _unpack_bits
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
                        light_sample_ticks: int | str = "auto", progress: bool = False, flip: bool = False,
                        compiled_light: bool = True, device: str = "cpu") -> Iterator[tuple[int, np.ndarray]]:
        """As :meth:`simulate`, but yields the spikes as they are produced: packed bits in the
        ``.dat`` layout, ``(first_tick, frames)`` with uint8 frames (T, H·W/8), pixel k = r·W + c
        in bit k mod 8 of byte k // 8; ``flip`` stores the rows bottom-up, as the cameras write.
        Every block is a fresh array. Needs H·W to be a multiple of 8 (whole bytes per frame).
        ``device`` as in :meth:`simulate`."""
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        if pixels % 8:
            raise ViformError(f"width × height = {width}×{height} is not a multiple of 8 pixels; packed frames "
                              "(.dat) hold whole bytes")
        # a block that the flip or the cut of the row padding copies reuses the kernels' buffer; one that is the
        # kernels' output itself (constant light: the .dat frames are written in place) is a fresh array
        for first, packed in self._packed_blocks(scene, duration_s, seed, block_ticks, light_sample_ticks, progress,
                                                 None, "copied" if flip else "padded", compiled_light,
                                                 packed_only=True, device=device):
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
        """(first tick, packed bits uint8 (T, ⌈H·W/8⌉) in constant light, else (T, 8·⌈H·W/64⌉)) per block:
        the kernels' own output. ``reuse_buffer``: one buffer for every block (True or "copied": the caller
        copies each block), a fresh one per block (False), or "padded": reused only where the rows are
        padded past the frame's ⌈H·W/8⌉ bytes (the caller then copies the frame out)."""
        from viform.sensors._spike_kernels import (
            _FAST_ROUND_LIMIT,
            SPARSE_FIRING,
            VECTOR_MIN_SPIKES,
            _band_rows,
            _run_block,
            _run_block_ticks,
            _Segments,
            _settle_all,
        )
        from viform.sensors.spike_cuda import packed_blocks_cuda, resolve_device
        light_sample_ticks = self.light_sample_ticks_for(scene, light_sample_ticks, duration_s)
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
        fixed_tables = self._fixed_point_tables(height, width)
        sampled = None
        if light is not None and light.kind == "sampled":
            from viform.sensors._sampled_runs import SampledRuns

            sampled = SampledRuns(self, light, sample, height, width, plan, bounds)
        segments = _Segments(self, scene, light, sample, height, width)
        # constant light: the kernel writes the .dat frames themselves (⌈H·W/8⌉ bytes a tick, no copy)
        out_bytes = row_bytes if per_tick_light or sampled is not None else (plan.pixels + 7) // 8
        if reuse_buffer == "padded":  # the caller copies each block only where its rows carry padding
            reuse_buffer = out_bytes > plan.pixels // 8
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
                        buffer = np.empty((last - first, out_bytes), dtype=np.uint8)
                    out = buffer[: last - first]
                else:
                    out = np.empty((last - first, out_bytes), dtype=np.uint8)
                if per_tick_light:
                    # light at the middle of each interval of `sample` ticks, held over it
                    n = last - first
                    if sample == 1:
                        times = (np.arange(first, last) // sample + 0.5) * (sample / p.clock_hz)
                        tick_scalars(times, params, kind, scalars[:n], xtab[:n], ytab[:n])
                    else:  # each sample's scalars once, copied to its ticks (the kernel reads its first)
                        j = np.arange(first, last) // sample
                        u = int(j[-1] - j[0]) + 1
                        times = (np.arange(j[0], j[-1] + 1) + 0.5) * (sample / p.clock_hz)
                        tick_scalars(times, params, kind, scalars[:u], xtab[:u], ytab[:u])
                        at = j - j[0]
                        scalars[:n] = scalars[at]
                        if xtab.shape[0] > 1:
                            xtab[:n] = xtab[at]
                        if ytab.shape[0] > 1:
                            ytab[:n] = ytab[at]
                    _run_block_ticks(out, kind, scalars, xtab, ytab, frames, params, a, b, xs, fast_round,
                                     state.charge, state.target, state.counter, q, index, *tables, *fixed_tables,
                                     state.keys, p.photon_noise, reset_readout, dead_ticks, band_rows, first, sample)
                elif sampled is not None:
                    sampled.run(out, first, last, state)
                    if caller_state:
                        _settle_all(state.charge, state.target, state.counter, q, index, *tables, state.keys,
                                    state.pending_ticks, state.pending_rate)
                else:
                    rates, seg_end = segments.block(first, last)
                    _run_block(out, rates, seg_end, first, state.charge, state.target,
                               state.counter, q, index, *tables, *fixed_tables, state.keys, p.photon_noise,
                               reset_readout, dead_ticks, mode, bounds, state.pending_ticks, state.pending_rate,
                               SPARSE_FIRING, VECTOR_MIN_SPIKES)
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

    def light_sample_ticks_for(self, scene: Scene, light_sample_ticks, duration_s: float | None = None) -> int:
        """Ticks per light sample: ``light_sample_ticks`` checked, or for "auto" (or None) the scene's
        :meth:`~viform.light.scenes.Scene.auto_light_sample_ticks` at this clock over ``duration_s``."""
        if light_sample_ticks is None or (isinstance(light_sample_ticks, str) and light_sample_ticks == "auto"):
            return int(scene.auto_light_sample_ticks(self.parameters.clock_hz, duration_s))
        return check_int("light_sample_ticks", light_sample_ticks, 1)

    def default_block_ticks(self, scene: Scene, light_sample_ticks: int = 1, light=None,
                            budget_bytes: int | None = None, packed: bool = False) -> int:
        """Ticks per block so that a block's buffers take about ``budget_bytes`` (default
        :data:`BLOCK_BYTES`): spike bits (packed, 1/8 byte per pixel-tick, plus 1 byte per
        pixel-tick when unpacked to bool, unless ``packed``) plus the light it needs (compiled
        light: a few per-tick scalars, or one int64 rate row per run of constant light;
        otherwise float64 light and int64 charge rates, plus the scene's own temporaries, per
        light sample)."""
        from viform.sensors._spike_kernels import _ticks_per_run
        height, width = self.check_scene(scene, self.height, self.width)
        pixels = height * width
        budget = BLOCK_BYTES if budget_bytes is None else budget_bytes
        spikes = pixels / 8 + (0 if packed else pixels)
        if light is None:
            per_tick = spikes + pixels * 32 / light_sample_ticks
        elif light.kind == "frames":
            per_tick = spikes + pixels * 8 / _ticks_per_run(light, light_sample_ticks, self.parameters.clock_hz)
        elif light.kind == "sampled":
            per_tick = spikes  # the rendered charge is held in chunks of its own budget (sensors._sampled_runs)
        else:
            from viform.light.compiled import tick_bytes

            per_tick = spikes + tick_bytes(light)
        return max(1, int(budget // per_tick))

    def capture(self, scene: Scene, duration_s: float, *, seed: int = 0, block_ticks: int | None = None,
                light_sample_ticks: int | str = "auto", progress: bool = False, device: str = "cpu") -> SpikeStream:
        """Simulate into memory and return the :class:`SpikeStream` (``device`` as in :meth:`simulate`)."""
        from viform.sensors.spike_cuda import resolve_device
        device = resolve_device(device)
        light_sample_ticks = self.light_sample_ticks_for(scene, light_sample_ticks, duration_s)
        blocks = [b for _, b in self.simulate(scene, duration_s, seed=seed, block_ticks=block_ticks,
                                              light_sample_ticks=light_sample_ticks, progress=progress,
                                              device=device)]
        return SpikeStream(np.concatenate(blocks), self.parameters.clock_hz, self.parameters.threshold_electrons,
                           0.0, self.capture_metadata(scene, seed, light_sample_ticks, device))

    def stream(self, scene: Scene, duration_s: float, *, seed: int = 0, light_sample_ticks: int | str = "auto",
               progress: bool = False, reuse_buffer: bool = False, device: str = "cpu") -> SimulatedSpikes:
        """A lazy :class:`SpikeSource` that simulates as it is read (bounded memory).

        With ``reuse_buffer`` the blocks of ``iter_blocks`` share one buffer (see
        :meth:`simulate`): for writers that consume each block at once. ``device`` as in
        :meth:`simulate` ("auto" is resolved here, once).
        """
        return SimulatedSpikes(self, scene, duration_s, seed, light_sample_ticks, progress, reuse_buffer, device)

    def capture_metadata(self, scene: Scene, seed: int, light_sample_ticks: int, device: str = "cpu") -> dict:
        """Provenance of a simulated stream; ``device`` ("cpu" or "cuda") names the machine that ran it."""
        from viform.sensors.spike_cuda import device_description
        meta = {"sensor": self.describe(), "scene": scene.describe(), "seed": seed,
                "light_sample_ticks": light_sample_ticks}
        if device == "cuda":
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
                 light_sample_ticks: int | str = "auto", progress: bool = False, reuse_buffer: bool = False,
                 device: str = "cpu"):
        from viform.sensors.spike_cuda import resolve_device
        self.device = resolve_device(device)
        p = sensor.parameters
        self.sensor, self.scene, self.seed = sensor, scene, seed
        self.light_sample_ticks = sensor.light_sample_ticks_for(scene, light_sample_ticks, duration_s)
        self.progress = progress
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
