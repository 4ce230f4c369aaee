"""The compiled spike kernels that both devices share: state, run plan, crossings, lanes, packed bits.

:mod:`viform.sensors.spike` (the CPU path) and :mod:`viform.sensors.spike_cuda` (the same
per-pixel functions compiled as CUDA device functions) both import this module; it imports
neither. The model these kernels implement (Gamma(Q, 1) targets in integrated-charge time,
the stationary start, saturation, dead time, both reset modes) is described in
:mod:`viform.sensors.spike`.

Charge is kept in fixed point (2^-32 e⁻ units, int64): integer sums are exact and
associative, so the bits do not depend on the block size, the number of threads or the
device. The k-th interval of pixel p is drawn by a counter-based generator from
(seed, p, k) (:mod:`viform.sensors._gamma`).

Kernels: pixels sit in lanes of 64, one uint64 of spike bits per tick — the ``.dat`` bit
order, so the kernels write the file's bytes as the pixels fire. The tick loop runs inside
each work item (a tile of pixels, or a band of rows when the light is computed per tick),
the lane loop compiles to SIMD add/compare/mask code (see the notes above
:func:`_lanes_add_compare`), and only the lanes that fired take the scalar path with its
Gamma draw. A self-reset pixel with photon noise whose charge per tick exceeds every gap a
draw can leave (:func:`saturation_bound_fixed`) fires in every tick whatever its state: in
constant light the kernel only counts those ticks and replays their draws when the light
changes or the caller reads the state, so saturated light costs no more than dim light, with
the same bits and state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from llvmlite import ir
from numba import get_num_threads, njit, prange, types
from numba.core import cgutils
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import intrinsic

from viform.light.compiled import row_lux
from viform.sensors._gamma import (
    TABLE_BITS,
    TABLE_SIZE,
    event_stream,
    gamma_draw,
    splitmix64,
    stream_gamma,
    stream_poisson,
    stream_uniform,
    uniform_from_hash,
)


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


def _initial_targets(target, charge, counter, q, index, bins, keys, noise, random_initial):
    """First target (and with ``random_initial`` the stationary charge) of every pixel, each from its own
    stream (``counter[p]`` advanced): the same values whatever the thread count."""
    if noise:
        _initial_targets_noise(target, charge, counter, q, index, bins, keys, random_initial)
    else:
        _initial_targets_noise_free(target, charge, counter, q, keys, random_initial)


@njit(cache=True)
def _initial_targets_noise_free(target, charge, counter, q, keys, random_initial):
    """:func:`_initial_targets` without photon noise: :func:`_next_target` written out (the inlined helper's
    array arguments cost reference-count updates per pixel, ≈ 70 ns, more than the work); one thread (≈ 2 ns a
    pixel: less than waking a second)."""
    for p in range(q.size):
        t = max(np.int64(1), np.int64(q[p] * 4294967296.0 + 0.5))
        target[p] = t
        counter[p] += 1
        if random_initial:  # the noise-free pixel's stationary state: a uniform fraction of Q collected
            u = uniform_from_hash(splitmix64(keys[p] ^ np.uint64(0x5EED5EED5EED5EED)))
            charge[p] = np.int64(u * t)


@njit(cache=True)
def _initial_targets_noise(target, charge, counter, q, index, bins, keys, random_initial):
    """:func:`_initial_targets` with photon noise: a Gamma draw (and the stationary state's) per pixel, on one
    thread (≈ 30 ns a pixel: on two, the CPU time doubled under load for little wall time)."""
    noise = np.bool_(True)
    for p in range(q.size):
        if random_initial:
            charge[p], target[p] = _equilibrium_state(p, q, index, bins, keys, counter)
        else:
            target[p] = _next_target(p, q, index, bins, keys, noise, counter)


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


# ---------------------------------------------------------------------- lane kernels
# Layout: pixels in lanes of 64 (one uint64 of spike bits per tick: bit i of word w is pixel
# 64·w + i, which on a little-endian machine is the .dat bit order, so the words are the file's
# bytes), the tick loop inside the work item so a tile's state stays in L1, and the spikes
# written as bits the moment they are produced.
#
# The lane loop is written as LLVM vector operations on 8 lanes at a time (the intrinsics
# below): load, add and store 8 int64 charges, compare them with their targets as one vector
# and turn the 8 comparison bits into a byte (`bitcast <8 x i1> to i8`). On x86-64 with
# AVX-512 that is vpaddq / vpcmpq into a mask register / kmovb, 8 of them per 64-pixel word,
# and the same IR lowers to AVX2 (vpcmpgtq / vmovmskpd) or NEON elsewhere; a plain loop over
# the 64 lanes vectorized as well but built the word from the comparison bits with one
# masked OR per bit. The fired lanes of a word are then visited with ``tzcnt`` (count
# trailing zeros), so a tick without spikes costs no branch per pixel, and the per-spike
# Gamma draw stays off the common path. In a busy word (its lanes expect at least
# :data:`VECTOR_MIN_SPIKES` crossings per tick) the constant-light kernel takes the fired
# lanes' first crossing eight lanes at a time instead (:func:`_fire8_fast`: the draw's hash,
# its table row and the new target as vectors): the draws are pure functions of (seed,
# pixel, counter), so the bits and state are those of the lane-by-lane loop.
_LANES = 64
_TILE_WORDS = 8  # words (× 64 pixels) per work item of the constant-light kernel: one cache line of bits a tick
_TICK_CHUNK = 64  # ticks a tile's busy words run before the next word: the chunk's bits stay in L1
_NO_TARGET = np.int64(0x7FFFFFFFFFFFFFFF)  # target of padding lanes: they never fire
#: Lane modes of the constant-light kernel: any option through :func:`_fire`; the two
#: noise-free models without dead time, resolved in the vector loop itself.
MODE_GENERAL, MODE_NOISE_FREE_SELF, MODE_NOISE_FREE_READOUT = 0, 1, 2
#: Expected spikes per tick (charge per tick / Q) up to which the constant-light kernel visits a
#: word's crossings one by one instead of its ticks: there a tick by tick pass costs more than
#: the crossings it finds (the cost of a crossing is about 20 lane-ticks).
SPARSE_FIRING = 0.05


def _vector_multiply_target() -> bool:
    """Whether numba compiles for a CPU with 64-bit vector multiplies and gathers (x86-64 AVX-512F and
    AVX-512DQ): elsewhere the eight-lane spike path would be emulated lane by lane."""
    from llvmlite import binding
    from numba.core import config

    features = config.CPU_FEATURES
    if features is None:
        try:
            features = binding.get_host_cpu_features().flatten()
        except RuntimeError:  # (no feature list on this platform)
            return False
    features = set(str(features).split(","))
    return {"+avx512f", "+avx512dq"} <= features


#: Crossings per tick a 64-pixel word's lanes expect in a run (Σ charge per tick / threshold) from
#: which its crossings go eight lanes at a time (:func:`_fire8_fast`); infinite (never) where the
#: CPU has no 64-bit vector multiply. Results do not depend on it; its speed does (one thread,
#: still texture at Q = 100 e⁻, alternated with the lane-by-lane loop in one process): every
#: busy word through it was 0.63× as fast at 0.1 spikes per pixel-tick, 0.82× at 0.2, 1.03× at
#: 0.3 and 1.32× at 0.5 (on this machine's CPU the gathers of the draws' table rows cost most of
#: an eight-lane group).
VECTOR_MIN_SPIKES = 20.0 if _vector_multiply_target() else math.inf
#: The share of ``sparse_firing`` below which the noise-free modes visit crossings: their tick by tick
#: pass (:func:`_noise_free_self_chunk`) costs a few hundredths of a crossing per lane-tick.
_NOISE_FREE_SPARSE = 0.05
_VECTOR = ir.VectorType(ir.IntType(64), 8)
_I64 = ir.IntType(64)


def _vector_pointer(context, builder, array_type, array, index):
    """Pointer to the 8 int64 elements of a contiguous 1-D ``array`` from ``index``, as one vector."""
    data = context.make_array(array_type)(context, builder, array).data
    return builder.bitcast(builder.gep(data, [index]), _VECTOR.as_pointer())


def _mask_bits(builder, mask):
    """The 8 lanes of an <8 x i1> comparison as the low byte of an int64 (lane i in bit i)."""
    return builder.zext(builder.bitcast(mask, ir.IntType(8)), _I64)


@intrinsic
def _add_compare8(typingctx, c, e, t, base):
    """c[base:base + 8] += e[base:base + 8]; the byte of lanes where c >= t (lane i in bit i)."""

    def codegen(context, builder, signature, args):
        pc, pe, pt = (_vector_pointer(context, builder, signature.args[i], args[i], args[3]) for i in range(3))
        charge = builder.add(builder.load(pc, align=8), builder.load(pe, align=8))
        builder.store(charge, pc, align=8)
        return _mask_bits(builder, builder.icmp_signed(">=", charge, builder.load(pt, align=8)))

    return types.uint64(c, e, t, base), codegen


_F64_VECTOR = ir.VectorType(ir.DoubleType(), 8)
_MASK_VECTOR = ir.VectorType(ir.IntType(1), 8)


def _splat(value, kind=_VECTOR):
    """A constant vector of 8 equal elements."""
    return ir.Constant(kind, [value] * 8)


def _broadcast_address(builder, pointer):
    """A pointer's address in the 8 elements of an <8 x i64>."""
    one = builder.insert_element(ir.Constant(_VECTOR, None), builder.ptrtoint(pointer, _I64),
                                 ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(one, ir.Constant(_VECTOR, None), ir.Constant(ir.VectorType(ir.IntType(32), 8),
                                                                                 [0] * 8))


def _gather(builder, kind, addresses, mask):
    """The 8 elements of ``kind`` (<8 x i64> or <8 x double>) at ``addresses`` (<8 x i64>) where ``mask``
    is set, 0 elsewhere (``llvm.masked.gather``: lanes outside the mask are not read)."""
    pointers = builder.inttoptr(addresses, ir.VectorType(ir.IntType(8).as_pointer(), 8))
    name = "llvm.masked.gather.v8i64.v8p0" if kind == _VECTOR else "llvm.masked.gather.v8f64.v8p0"
    fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(kind, [pointers.type, ir.IntType(32),
                                                                               _MASK_VECTOR, kind]), name)
    return builder.call(fn, [pointers, ir.Constant(ir.IntType(32), 8), mask, ir.Constant(kind, None)])


def _is_lane_array(a, dtype):
    return isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and a.dtype == dtype


@intrinsic
def _fire8_fast(typingctx, c, t, drawn, key, row0, one_by_one, scaled, accept, base, fired):
    """The first crossing of the lanes ``base`` … ``base`` + 7 set in the byte ``fired``, as one vector.

    For each such lane whose charge is less than ``one_by_one`` past its target, what the lane
    loop of :func:`_run_block` does first: c −= t, then the new target is the table draw
    :func:`_target_fast` of the lane's counter (splitmix64 of key + counter·γ, the row
    ``row0`` + its top 10 bits, the squeeze test against ``accept``, edge + (k + ½)·width rounded
    to fixed point: the same integer and floating-point operations, so the same values), and
    the counter advances when the squeeze accepted. A rejected draw leaves target 0 and the
    counter unchanged (the general sampler then draws it). Other lanes are left as they are.

    The six lane arrays must hold lanes ``base`` … ``base`` + 7 (the kernel's tiles are whole
    64-lane words; nothing is checked here), and ``scaled`` and ``accept`` are
    :func:`fixed_point_tables` (C order, rows of two float64 and int64).

    Returns, as a uint64: in bits 0–7 the fired lanes too far past their target for this path
    (:func:`_fire_general` takes them, state untouched), in bits 8–15 those it did take whose
    charge is still at or above the new target, or whose draw was rejected (the lane loop
    finishes them).
    """
    lanes = (c, t, drawn, row0, one_by_one)
    if not (all(_is_lane_array(a, types.int64) for a in lanes) and _is_lane_array(key, types.uint64)
            and _is_lane_array(accept, types.int64) and isinstance(scaled, types.Array) and scaled.ndim == 2
            and scaled.layout == "C" and scaled.dtype == types.float64 and base == types.int64
            and fired == types.uint64):
        return None

    def codegen(context, builder, signature, args):
        # (scaled is (rows, 2) C-ordered: a row's edge at byte 16·row, its width 8 bytes on)
        pointers = [_vector_pointer(context, builder, signature.args[i], args[i], args[8]) for i in range(6)]
        charge, target, counter, stream_key, row_base, limit = (builder.load(p, align=8) for p in pointers)
        fired_lanes = builder.bitcast(builder.trunc(args[9], ir.IntType(8)), _MASK_VECTOR)
        over = builder.sub(charge, target)
        eligible = builder.icmp_signed("<", over, limit)
        apply = builder.and_(fired_lanes, eligible)
        # splitmix64(key + counter·γ): (x + γ), then the three xor-shift-multiply rounds
        golden = _splat(0x9E3779B97F4A7C15)
        x = builder.add(builder.add(stream_key, builder.mul(counter, golden)), golden)
        x = builder.mul(builder.xor(x, builder.lshr(x, _splat(30))), _splat(0xBF58476D1CE4E5B9))
        x = builder.mul(builder.xor(x, builder.lshr(x, _splat(27))), _splat(0x94D049BB133111EB))
        h = builder.xor(x, builder.lshr(x, _splat(31)))
        row = builder.add(row_base, builder.lshr(h, _splat(64 - TABLE_BITS)))
        accept_base = _broadcast_address(builder, context.make_array(signature.args[7])(context, builder,
                                                                                        args[7]).data)
        scaled_base = _broadcast_address(builder, context.make_array(signature.args[6])(context, builder,
                                                                                        args[6]).data)
        threshold = _gather(builder, _VECTOR, builder.add(accept_base, builder.shl(row, _splat(3))), apply)
        edge_address = builder.add(scaled_base, builder.shl(row, _splat(4)))
        edge = _gather(builder, _F64_VECTOR, edge_address, apply)
        width = _gather(builder, _F64_VECTOR, builder.add(edge_address, _splat(8)), apply)
        bits26 = _splat(0x3FFFFFF)
        accepted = builder.icmp_signed("<", builder.and_(h, bits26), threshold)
        u = builder.fadd(builder.sitofp(builder.and_(builder.lshr(h, _splat(26)), bits26), _F64_VECTOR),
                         _splat(0.5, _F64_VECTOR))
        x = builder.fadd(edge, builder.fmul(u, width))  # (no fused multiply-add: as the scalar code rounds)
        drawn_target = builder.fptosi(builder.fadd(x, _splat(0.5, _F64_VECTOR)), _VECTOR)
        drawn_target = builder.select(builder.icmp_signed("<", drawn_target, _splat(1)), _splat(1), drawn_target)
        drawn_target = builder.select(accepted, drawn_target, _splat(0))
        builder.store(builder.select(apply, over, charge), pointers[0], align=8)
        builder.store(builder.select(apply, drawn_target, target), pointers[1], align=8)
        builder.store(builder.add(counter, builder.zext(builder.and_(apply, accepted), _VECTOR)), pointers[2],
                      align=8)
        general = _mask_bits(builder, builder.and_(fired_lanes, builder.not_(eligible)))
        more = _mask_bits(builder, builder.and_(apply, builder.icmp_signed(">=", over, drawn_target)))
        return builder.or_(general, builder.shl(more, ir.Constant(_I64, 8)))

    return types.uint64(c, t, drawn, key, row0, one_by_one, scaled, accept, base, fired), codegen


@intrinsic
def _noise_free_self8(typingctx, c, e, t, base):
    """Noise-free self-reset on 8 lanes: c += e, and c -= t where c reached t. Returns the byte of
    lanes that fired, and in bits 8–15 the lanes still at or above their target (lost crossings)."""

    def codegen(context, builder, signature, args):
        pc, pe, pt = (_vector_pointer(context, builder, signature.args[i], args[i], args[3]) for i in range(3))
        target = builder.load(pt, align=8)
        charge = builder.add(builder.load(pc, align=8), builder.load(pe, align=8))
        fired = builder.icmp_signed(">=", charge, target)
        charge = builder.select(fired, builder.sub(charge, target), charge)
        builder.store(charge, pc, align=8)
        over = builder.icmp_signed(">=", charge, target)
        return builder.or_(_mask_bits(builder, fired), builder.shl(_mask_bits(builder, over), ir.Constant(_I64, 8)))

    return types.uint64(c, e, t, base), codegen


@intrinsic
def _noise_free_readout8(typingctx, c, e, t, base):
    """Noise-free readout reset on 8 lanes: c += e, drained to 0 where c reached t; the fired byte."""

    def codegen(context, builder, signature, args):
        pc, pe, pt = (_vector_pointer(context, builder, signature.args[i], args[i], args[3]) for i in range(3))
        charge = builder.add(builder.load(pc, align=8), builder.load(pe, align=8))
        fired = builder.icmp_signed(">=", charge, builder.load(pt, align=8))
        builder.store(builder.select(fired, ir.Constant(_VECTOR, [0] * 8), charge), pc, align=8)
        return _mask_bits(builder, fired)

    return types.uint64(c, e, t, base), codegen


def _noise_free_chunk_codegen(readout):
    """Code of :func:`_noise_free_self_chunk` / :func:`_noise_free_readout_chunk`."""

    def codegen(context, builder, signature, args):
        words, col, k0, k1, c, e, t, base = args
        words_type = signature.args[0]
        array = context.make_array(words_type)(context, builder, words)
        # address of the word: byte 8·col of row kk, data + kk·strides[0] + 8·col (rows of whole bytes)
        data = builder.add(builder.ptrtoint(array.data, _I64), builder.mul(col, ir.Constant(_I64, 8)))
        row_stride = builder.extract_value(array.strides, 0)
        charge, rate, target, pointers = [], [], [], []
        for j in range(8):
            index = builder.add(base, ir.Constant(_I64, 8 * j))
            pc, pe, pt = (_vector_pointer(context, builder, signature.args[4 + i], (c, e, t)[i], index)
                          for i in range(3))
            pointers.append(pc)
            charge.append(builder.load(pc, align=8))
            rate.append(builder.load(pe, align=8))
            target.append(builder.load(pt, align=8))
        start = builder.basic_block
        run = builder.append_basic_block("chunk.run")
        loop = builder.append_basic_block("chunk.loop")
        done = builder.append_basic_block("chunk.done")
        leave = builder.append_basic_block("chunk.leave")
        if readout:
            builder.branch(run)
        else:
            # self-reset: only where no lane can cross twice in a tick (c < t and e ≤ t in every lane)
            within = None
            for j in range(8):
                lane_ok = builder.and_(builder.icmp_signed("<", charge[j], target[j]),
                                       builder.icmp_signed("<=", rate[j], target[j]))
                within = lane_ok if within is None else builder.and_(within, lane_ok)
            bits = builder.bitcast(within, ir.IntType(8))
            builder.cbranch(builder.icmp_unsigned("==", bits, ir.Constant(ir.IntType(8), 0xFF)), run, leave)
        builder.position_at_end(run)
        entry = builder.basic_block
        builder.cbranch(builder.icmp_signed("<", k0, k1), loop, done)
        builder.position_at_end(loop)
        kk = builder.phi(_I64)
        kk.add_incoming(k0, entry)
        phis, after, masks = [], [], []
        zero = ir.Constant(_VECTOR, [0] * 8)
        for j in range(8):
            phis.append(builder.phi(_VECTOR))
            phis[j].add_incoming(charge[j], entry)
        for j in range(8):
            x = builder.add(phis[j], rate[j])
            fired = builder.icmp_signed(">=", x, target[j])
            after.append(builder.select(fired, zero if readout else builder.sub(x, target[j]), x))
            masks.append(fired)
        # each 8-lane comparison mask stored as its byte of the word (AVX-512: kmovb to memory, a store-port
        # uop): merging the 8 masks into one 64-bit word first (kunpck) costs 7 more uops on the vector
        # port that the add/compare/subtract already saturate (≈ 1.3× slower per tick)
        row = builder.add(data, builder.mul(kk, row_stride))
        for j in range(8):
            slot = builder.inttoptr(builder.add(row, ir.Constant(_I64, j)), ir.IntType(8).as_pointer())
            builder.store(builder.bitcast(masks[j], ir.IntType(8)), slot, align=1)
        following = builder.add(kk, ir.Constant(_I64, 1))
        kk.add_incoming(following, loop)
        for j in range(8):
            phis[j].add_incoming(after[j], loop)
        builder.cbranch(builder.icmp_signed("<", following, k1), loop, done)
        builder.position_at_end(done)
        finals = [builder.phi(_VECTOR) for _ in range(8)]
        for j in range(8):
            finals[j].add_incoming(charge[j], entry)
            finals[j].add_incoming(after[j], loop)
        for j in range(8):
            builder.store(finals[j], pointers[j], align=8)
        builder.branch(leave)
        builder.position_at_end(leave)
        ran = builder.phi(ir.IntType(1))
        ran.add_incoming(ir.Constant(ir.IntType(1), 1), done)
        if not readout:
            ran.add_incoming(ir.Constant(ir.IntType(1), 0), start)
        return ran

    return codegen


def _chunk_signature(words, col, k0, k1, c, e, t, base):
    if not (isinstance(words, types.Array) and words.ndim == 2 and words.dtype == types.uint8
            and words.layout == "C"):
        return None
    if not all(isinstance(x, types.Integer) for x in (col, k0, k1, base)):
        return None
    return types.boolean(words, types.int64, types.int64, types.int64, c, e, t, types.int64)


@intrinsic
def _noise_free_self_chunk(typingctx, words, col, k0, k1, c, e, t, base):
    """Noise-free self-reset of the 64 lanes ``base`` … ``base + 63`` through ticks ``k0`` … ``k1 − 1``:
    each tick c += e, c −= t where c reached t, and the word of lanes that fired stored at bytes
    8·col … 8·col + 7 of row kk of ``words`` (uint8; the caller checks that they are in the row). The
    8 × 8 charges stay in vector registers for the whole chunk, and each of the 8 comparison masks is
    stored as its byte of the word (AVX-512: kmovb to memory; no per-lane shifts). Runs only where every lane
    has c < t and e ≤ t (then no crossing is lost inside a tick); returns whether it ran."""
    sig = _chunk_signature(words, col, k0, k1, c, e, t, base)
    return (sig, _noise_free_chunk_codegen(False)) if sig is not None else None


@intrinsic
def _noise_free_readout_chunk(typingctx, words, col, k0, k1, c, e, t, base):
    """Noise-free readout reset of 64 lanes through ticks ``k0`` … ``k1 − 1`` (as
    :func:`_noise_free_self_chunk`, the lanes that fired drained to 0); always runs (returns True)."""
    sig = _chunk_signature(words, col, k0, k1, c, e, t, base)
    return (sig, _noise_free_chunk_codegen(True)) if sig is not None else None


@intrinsic
def _store_word(typingctx, words, kk, col, word):
    """Store the uint64 ``word`` at bytes 8·col … 8·col + 7 of row kk of the uint8 array ``words`` (C
    order), in one unaligned store (the caller checks that they are in the row)."""
    if not (isinstance(words, types.Array) and words.ndim == 2 and words.dtype == types.uint8
            and words.layout == "C"):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        kk, col, word = args[1], args[2], args[3]
        address = builder.add(builder.ptrtoint(array.data, _I64),
                              builder.add(builder.mul(kk, builder.extract_value(array.strides, 0)),
                                          builder.mul(col, ir.Constant(_I64, 8))))
        builder.store(word, builder.inttoptr(address, _I64.as_pointer()), align=1)
        return context.get_dummy_value()

    return types.none(words, types.int64, types.int64, types.uint64), codegen


@intrinsic
def _prefetch_for_write(typingctx, words, kk, byte):
    """Hint the CPU to fetch, for writing, the cache line holding byte ``byte`` of row kk of the uint8
    array ``words`` (C order); a hint only (``llvm.prefetch``, x86 PREFETCHW): it never faults and
    changes no value."""
    if not (isinstance(words, types.Array) and words.ndim == 2 and words.dtype == types.uint8
            and words.layout == "C"):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        kk, byte = args[1], args[2]
        address = builder.add(builder.ptrtoint(array.data, _I64),
                              builder.add(builder.mul(kk, builder.extract_value(array.strides, 0)), byte))
        pointer = builder.inttoptr(address, ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        prefetch = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(),
                                                                                  [pointer.type, i32, i32, i32]),
                                                  "llvm.prefetch.p0")
        # write, keep in all cache levels, data cache
        builder.call(prefetch, [pointer, ir.Constant(i32, 1), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return types.none(words, types.int64, types.int64), codegen


@njit(cache=True, inline="always")
def _put_word(words, kk, col, word):
    """Spike word ``col`` (pixels 64·col … 64·col + 63) of tick kk into its bytes of ``words`` (uint8,
    ticks × packed bytes, .dat order): a row's last word keeps only the bytes the row has."""
    byte = 8 * col
    if byte + 8 <= words.shape[1]:
        _store_word(words, kk, col, word)
    else:
        for j in range(words.shape[1] - byte):
            words[kk, byte + j] = np.uint8((word >> np.uint64(8 * j)) & np.uint64(0xFF))


@njit(cache=True, inline="always")
def _lanes_add_compare(c, e, t, base):
    """Add each lane's charge for the tick; the word of lanes that reached their target."""
    word = np.uint64(0)
    for j in range(_LANES // 8):
        word |= _add_compare8(c, e, t, base + 8 * j) << np.uint64(8 * j)
    return word


@njit(cache=True, inline="always")
def _lanes_noise_free_self(c, e, t, base):
    """Noise-free self-reset: add, compare, subtract the target where reached; also whether a
    lane is still at or above its target (light above one spike per tick: lost crossings)."""
    word = np.uint64(0)
    over = np.uint64(0)
    for j in range(_LANES // 8):
        bits = _noise_free_self8(c, e, t, base + 8 * j)
        word |= (bits & np.uint64(0xFF)) << np.uint64(8 * j)
        over |= bits
    return word, over > np.uint64(0xFF)


@njit(cache=True, inline="always")
def _lanes_noise_free_readout(c, e, t, base):
    """Noise-free readout reset: add, compare, drain the lanes that fired."""
    word = np.uint64(0)
    for j in range(_LANES // 8):
        word |= _noise_free_readout8(c, e, t, base + 8 * j) << np.uint64(8 * j)
    return word


# ---------------------------------------------------------------------- a spike's common case
def fixed_point_tables(bins) -> tuple[np.ndarray, np.ndarray]:
    """The Gamma tables (:func:`viform.sensors._gamma.build_tables`) rescaled for the kernels'
    common case, one row per (table, bin) of the flat index ``table·TABLE_SIZE + bin``:
    ``scaled[:, 0]`` = edge·2^32 and ``scaled[:, 1]`` = width·2^6 (float64), ``accept`` = the
    26-bit squeeze threshold ⌈squeeze·2^26 − 1/2⌉ (int64; 0 for the open last bin).

    With them :func:`_target_fast` computes what :func:`_next_target` computes, bit for bit:
    scaling by powers of two commutes with rounding, so edge·2^32 + (k₁ + 1/2)·(width·2^6)
    rounds to exactly 2^32 times edge + ((k₁ + 1/2)·2^-26)·width, and the uniform
    (k₂ + 1/2)·2^-26 is below the squeeze exactly when the integer k₂ is below ``accept``.
    """
    bins = np.asarray(bins, dtype=np.float64)
    scaled = np.empty((bins.shape[0] * bins.shape[1], 2))
    scaled[:, 0] = (bins[..., 0] * 4294967296.0).ravel()
    scaled[:, 1] = (bins[..., 1] * 64.0).ravel()
    accept = np.ceil(bins[..., 3] * 67108864.0 - 0.5)
    accept[:, -1] = 0.0  # the open last bin: the general sampler
    return np.ascontiguousarray(scaled), np.ascontiguousarray(np.maximum(accept, 0.0).astype(np.int64).ravel())


@njit(cache=True)
def _target_general(shape, table, bins, key, counter):
    """The fixed-point target of draw ``counter`` of a pixel's stream by the general sampler
    (:func:`viform.sensors._gamma.gamma_draw`), out of line: the rare cases of :func:`_target_fast`."""
    x = gamma_draw(shape, table, bins, key, counter)
    return max(np.int64(1), np.int64(x * 4294967296.0 + 0.5))


@njit(cache=True, inline="always")
def _target_fast(row0, scaled, accept, key, counter):
    """The fixed-point Gamma(Q) target of draw ``counter`` of a pixel's stream, the same value as
    :func:`_next_target` (see :func:`fixed_point_tables`), when the bin's squeeze accepts the
    first try (about 99 % of draws); 0 (no target is 0) when :func:`_target_general` must draw it.
    ``row0`` = the pixel's table · TABLE_SIZE. (No calls in here: an inlined function that takes
    arrays and calls another costs two reference-count updates per use.)"""
    h = splitmix64(key + np.uint64(counter) * np.uint64(0x9E3779B97F4A7C15))
    row = row0 + np.int64(h >> np.uint64(64 - TABLE_BITS))
    if np.int64(h & np.uint64(0x3FFFFFF)) < accept[row]:
        x = scaled[row, 0] + (np.int64((h >> np.uint64(26)) & np.uint64(0x3FFFFFF)) + 0.5) * scaled[row, 1]
        return max(np.int64(1), np.int64(x + 0.5))
    return np.int64(0)


@njit(cache=True)
def _settle(p, charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate):
    """Apply pixel p's pending saturated ticks (see :func:`_run_block`) to its state, exactly
    as the lane loop would have: the same draws in the same order."""
    c = charge[p]
    t = target[p]
    e = pending_rate[p]
    # typed bools, not literals: a literal gives _fire_general a signature (and a compilation) of its own
    noise = np.bool_(True)
    reset_readout = np.bool_(False)
    for _ in range(pending_ticks[p]):
        c += e
        if c >= t:
            c, t = _fire(c, t, e, 0.0, p, q, index, bins, keys, noise, reset_readout, counter)
    charge[p] = c
    target[p] = t
    pending_ticks[p] = 0


@njit(cache=True, parallel=True)
def _settle_all(charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate):
    for p in prange(charge.size):
        if pending_ticks[p] > 0:  # (a prange index may be unsigned: int64 keeps _settle to one signature)
            _settle(np.int64(p), charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate)


# error_model="numpy", as numba compiles a parallel loop's body: a division by zero gives inf/nan, no check
@njit(cache=True, error_model="numpy")
def _run_tile(tile, words, rates, seg_end, first_tick, charge, target, counter, q, index, bins, scaled, accept, keys,
              noise, reset_readout, dead_ticks, mode, lazy_bound, pending_ticks, pending_rate, sparse_firing,
              vector_min):
    """Tile ``tile`` (:data:`_TILE_WORDS` words of 64 pixels) of :func:`_run_block`, every tick of the
    block: the work item of its parallel loop, compiled on its own (the parallel compiler's passes over
    so large a loop body cost most of the kernel's compile time)."""
    n_ticks = words.shape[0]
    n_words = (words.shape[1] + 7) // 8
    n_pixels = charge.size
    lazy_ok = mode == MODE_GENERAL and noise and not reset_readout and dead_ticks == 0.0
    fast = lazy_ok  # photon noise, self-reset, no dead time: the common case inlined below
    w0 = tile * _TILE_WORDS
    nw = min(w0 + _TILE_WORDS, n_words) - w0
    p0 = w0 * _LANES
    n = min(nw * _LANES, n_pixels - p0)
    size = nw * _LANES
    tile_byte0 = 8 * w0  # the tile's first and last byte in a frame
    tile_byte1 = min(8 * (w0 + nw), words.shape[1]) - 1
    c = np.zeros(size, dtype=np.int64)
    t = np.full(size, _NO_TARGET)
    e = np.zeros(size, dtype=np.int64)
    lazy_from = np.full(size, -1, dtype=np.int64)  # tick of the block where a lane's lazy run began
    lazy_mask = np.zeros(nw, dtype=np.uint64)
    always = np.zeros(nw, dtype=np.uint64)  # noise-free self-reset: lanes that fire in every tick of the run
    # per lane, what a spike's common case reads (kept beside the lane state, in L1): the charge
    # past a crossing below which a crossing draws one target, the pixel's draw counter (the
    # lane's copy is the pixel's counter while the tile runs), stream key and table row
    one_by_one = np.zeros(size, dtype=np.int64)
    drawn = np.zeros(size, dtype=np.int64)
    key = np.zeros(size, dtype=np.uint64)
    row0 = np.zeros(size, dtype=np.int64)
    # charge per tick up to which a lane fires rarely (≤ 1 spike in 20 ticks on average): words whose
    # lanes are all below it are run crossing by crossing (same bits, less work than tick by tick)
    sparse_rate = np.zeros(size, dtype=np.int64)
    per_threshold = np.zeros(size)  # 1 / the lane's threshold (fixed point): its crossings per unit of charge
    # the tile's pixels through views indexed from 0: indices p0 + j, whose sign the compiler cannot
    # prove, made the vectorized loops gather every element (microcoded, ≈ 2 ms a block at 400×250)
    c[:n] = charge[p0:p0 + n]
    t[:n] = target[p0:p0 + n]
    drawn[:n] = counter[p0:p0 + n]
    key[:n] = keys[p0:p0 + n]
    tile_q = q[p0:p0 + n]
    tile_index = index[p0:p0 + n]
    share = 1.0 if mode == MODE_GENERAL else _NOISE_FREE_SPARSE
    for j in range(n):
        qj = tile_q[j]
        one_by_one[j] = min(_fixed_charge(_JUMP_INTERVALS * qj), _fixed_charge(8.0 * qj * qj))
        row0[j] = np.int64(tile_index[j]) * TABLE_SIZE
        sparse_rate[j] = _fixed_charge(sparse_firing * share * qj)
        per_threshold[j] = 1.0 / _fixed_charge(qj)
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
            e[:n] = rates[s, p0:p0 + n]
        else:
            for j in range(n):
                p = p0 + j
                r = rates[s, p]
                lazy = r >= lazy_bound[p]
                bit = np.uint64(1) << np.uint64(j & 63)
                if pending_ticks[p] > 0 and (not lazy or pending_rate[p] != r):
                    # the saturated stretch ends (or its light changes): its draws first
                    counter[p] = drawn[j]
                    _settle(p, charge, target, counter, q, index, bins, keys, pending_ticks, pending_rate)
                    drawn[j] = counter[p]
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
        if mode == MODE_NOISE_FREE_SELF:
            # a lane whose charge per tick reaches its (constant) target fires in every tick, and its charge
            # goes to (c + e) mod t: it runs with e mod t < t (so the 64-lane chunks can take its word) and
            # its bit is set in every tick of the run (``always``)
            for w in range(nw):
                always[w] = np.uint64(0)
            for j in range(n):
                if e[j] >= t[j]:
                    e[j] %= t[j]
                    always[j >> 6] |= np.uint64(1) << np.uint64(j & 63)
        dense = np.uint64(0)  # the words that run tick by tick
        busy = np.uint64(0)  # ... and of those, the words whose crossings go eight lanes at a time
        for w in range(nw):  # dim words: each lane's crossings through the run, then the next lane
            base = w * _LANES
            sparse = lazy_mask[w] == 0 and always[w] == 0
            for i in range(base, base + _LANES):
                sparse &= e[i] <= sparse_rate[i]
            if not sparse:
                dense |= np.uint64(1) << np.uint64(w)
                if fast:
                    expected = 0.0  # crossings per tick of the word's lanes (lazy lanes: none)
                    for i in range(base, base + _LANES):
                        expected += e[i] * per_threshold[i]
                    if expected >= vector_min:
                        busy |= np.uint64(1) << np.uint64(w)
            else:
                # every lane fires rarely in this run: visit each lane's crossings instead of each tick
                for kk in range(k, end):
                    _put_word(words, kk, w0 + w, np.uint64(0))
                for i in range(base, base + min(_LANES, n - base)):
                    ci = c[i]
                    ti = t[i]
                    ei = e[i]
                    kk = k  # the lane has run up to the start of tick kk (ci < ti)
                    while ei > 0:
                        # the crossing's tick: the smallest m ≥ 1 with ci + m·ei ≥ ti
                        need = ti - ci
                        m = max(np.int64(1), np.int64(need / ei))
                        while m * ei < need:
                            m += 1
                        while m > 1 and (m - 1) * ei >= need:
                            m -= 1
                        if m > end - kk:
                            ci += (end - kk) * ei
                            break
                        kk += m
                        ci += m * ei
                        words[kk - 1, 8 * (w0 + w) + ((i - base) >> 3)] |= np.uint8(1 << ((i - base) & 7))
                        if mode == MODE_NOISE_FREE_SELF:
                            ci -= ti
                            if ci >= ti:
                                ci %= ti
                        elif mode == MODE_NOISE_FREE_READOUT:
                            ci = 0
                        elif fast and ci - ti < one_by_one[i]:
                            while ci >= ti:
                                ci -= ti
                                ti = _target_fast(row0[i], scaled, accept, key[i], drawn[i])
                                if ti == 0:
                                    ti = _target_general(q[p0 + i], index[p0 + i], bins, key[i], drawn[i])
                                drawn[i] += 1
                        else:
                            counter[p0 + i] = drawn[i]
                            ci, ti = _fire_general(ci, ti, ei, dead_ticks, p0 + i, q, index, bins, keys, noise,
                                                   reset_readout, counter)
                            drawn[i] = counter[p0 + i]
                    c[i] = ci
                    t[i] = ti
        # busy words tick by tick, in chunks of ticks across the tile's words: each tick's bits of the
        # tile are one cache line, written while it is in L1
        if dense != 0:
            for k0 in range(k, end, _TICK_CHUNK):
                k1 = min(k0 + _TICK_CHUNK, end)
                for w in range(nw):
                    # the next chunk's rows of the tile's bytes (≤ 64: one or two cache lines a row), fetched
                    # for writing while this chunk runs, a share of the rows per word: the rows are a frame
                    # apart, so the hardware prefetchers do not see them coming and every first store to a
                    # line would wait for its read (≈ 1.4× slower per tick at 400×250)
                    for kk in range(k1 + (w * _TICK_CHUNK) // nw, min(k1 + ((w + 1) * _TICK_CHUNK) // nw, end)):
                        _prefetch_for_write(words, kk, tile_byte0)
                        _prefetch_for_write(words, kk, tile_byte1)
                    if not (dense >> np.uint64(w)) & np.uint64(1):
                        continue
                    base = w * _LANES
                    whole = 8 * (w0 + w) + 8 <= words.shape[1]  # the word's 8 bytes are in the row
                    if whole and mode == MODE_NOISE_FREE_READOUT:
                        _noise_free_readout_chunk(words, w0 + w, k0, k1, c, e, t, base)
                        continue
                    if whole and mode == MODE_NOISE_FREE_SELF and _noise_free_self_chunk(words, w0 + w, k0, k1,
                                                                                         c, e, t, base):
                        if always[w] != 0:
                            for kk in range(k0, k1):
                                for b in range(8):
                                    words[kk, 8 * (w0 + w) + b] |= np.uint8((always[w] >> np.uint64(8 * b))
                                                                            & np.uint64(0xFF))
                        continue
                    busy_word = (busy >> np.uint64(w)) & np.uint64(1) != np.uint64(0)
                    for kk in range(k0, k1):
                        if mode == MODE_NOISE_FREE_SELF:
                            word, over = _lanes_noise_free_self(c, e, t, base)
                            if over:  # crossings lost inside the tick: the charge modulo the target
                                for i in range(base, base + _LANES):
                                    if c[i] >= t[i]:
                                        c[i] %= t[i]
                            word |= always[w]
                        elif mode == MODE_NOISE_FREE_READOUT:
                            word = _lanes_noise_free_readout(c, e, t, base)
                        else:
                            word = _lanes_add_compare(c, e, t, base)
                            todo = word & ~lazy_mask[w]
                            if busy_word and todo != 0:
                                # a busy word (photon noise, self-reset, no dead time): the first crossing of
                                # its fired lanes eight at a time; the loop below finishes the lanes that need
                                # more (a rejected draw left target 0: the same counter is drawn again, rejected
                                # again, and the general sampler takes it; a second crossing) and takes those
                                # too far past their target, untouched here
                                rest = np.uint64(0)
                                for g in range(_LANES // 8):
                                    byte = (todo >> np.uint64(8 * g)) & np.uint64(0xFF)
                                    if byte != 0:
                                        r = _fire8_fast(c, t, drawn, key, row0, one_by_one, scaled, accept,
                                                        base + 8 * g, byte)
                                        rest |= ((r | (r >> np.uint64(8))) & np.uint64(0xFF)) << np.uint64(8 * g)
                                todo = rest
                            while todo != 0:
                                i = base + np.int64(trailing_zeros(todo))
                                todo &= todo - np.uint64(1)
                                ci = c[i]
                                ti = t[i]
                                if fast and ci - ti < one_by_one[i]:
                                    # _fire's common case: one Gamma target per crossing (draw `drawn[i]` of
                                    # the pixel's stream), the later crossings of the tick lost
                                    while ci >= ti:
                                        ci -= ti
                                        ti = _target_fast(row0[i], scaled, accept, key[i], drawn[i])
                                        if ti == 0:
                                            ti = _target_general(q[p0 + i], index[p0 + i], bins, key[i], drawn[i])
                                        drawn[i] += 1
                                    c[i] = ci
                                    t[i] = ti
                                else:
                                    counter[p0 + i] = drawn[i]
                                    c[i], t[i] = _fire_general(ci, ti, e[i], dead_ticks, p0 + i, q, index, bins,
                                                               keys, noise, reset_readout, counter)
                                    drawn[i] = counter[p0 + i]
                        _put_word(words, kk, w0 + w, word)
        if lazy_ok:
            for j in range(n):
                if lazy_from[j] >= 0:
                    pending_ticks[p0 + j] += end - lazy_from[j]
                    lazy_from[j] = -1
        k = end
        s += 1
    counter[p0:p0 + n] = drawn[:n]
    tile_charge = charge[p0:p0 + n]
    tile_target = target[p0:p0 + n]
    for j in range(n):
        if not lazy_mask[j >> 6] & (np.uint64(1) << np.uint64(j & 63)):
            tile_charge[j] = c[j]
            tile_target[j] = t[j]



@njit(cache=True, parallel=True)
def _run_block(words, rates, seg_end, first_tick, charge, target, counter, q, index, bins, scaled, accept, keys,
               noise, reset_readout, dead_ticks, mode, lazy_bound, pending_ticks, pending_rate, sparse_firing,
               vector_min):
    """Integrate-and-fire over one block of ticks in runs of constant light, 64 pixels per word.

    ``rates[s, p]`` is the fixed-point charge per tick of pixel p in run s, which ends
    (exclusive) at absolute tick ``seg_end[s]``; the runs cover the block. ``words`` (uint8, ticks ×
    bytes, C order) receives the spikes in the .dat bit order: bytes 8·w … 8·w + 7 of row k hold
    pixels 64·w … 64·w + 63 in tick k (bit i of the little-endian word: pixel 64·w + i); a row may end
    inside its last word (⌈H·W/8⌉ bytes: the file's frame, no copy), the word is cut there.
    Charge sums are exact integers, so adding a run's rate tick by tick gives the bits the
    event-driven form (a jump to each crossing) gave.

    Saturated pixels cost nothing per tick: with photon noise, self-reset and no dead time, a
    pixel whose charge per tick reaches ``lazy_bound[p]`` — above the largest gap between
    charge and target that any draw can leave (:func:`saturation_bound_fixed`) — fires in every
    tick whatever its state, so the kernel only counts those ticks (``pending_ticks``, at rate
    ``pending_rate``) and :func:`_settle` replays the draws when the light changes or the
    caller asks for the state: same bits, same state, and a still saturated scene draws nothing.

    ``scaled`` and ``accept`` are :func:`fixed_point_tables` of ``bins``: a spike's common case
    (photon noise, self-reset, no dead time, fewer than 48·Q e⁻ past the crossing) draws its
    target from them in the lane loop; every other case goes through :func:`_fire_general`.

    Dim words: where every lane of a word expects at most ``sparse_firing`` spikes per tick (the
    callers pass :data:`SPARSE_FIRING`) in a
    run (charge per tick ≤ ``sparse_firing``·Q), the word's lanes are run crossing by crossing
    (the tick of the next crossing from the charge still missing, then the same crossing rules)
    instead of tick by tick: the same bits and state for any ``sparse_firing``, less work.

    Busy words: where the lanes of a word expect at least ``vector_min`` crossings per tick in a
    run (the sum of charge per tick / threshold; the callers pass :data:`VECTOR_MIN_SPIKES`), the
    fired lanes' common case is taken eight lanes at a time (:func:`_fire8_fast`) and the rest
    lane by lane: the same bits and state for any ``vector_min``.
    """
    n_words = (words.shape[1] + 7) // 8
    n_tiles = (n_words + _TILE_WORDS - 1) // _TILE_WORDS
    for tile in prange(n_tiles):
        # (a prange index may be unsigned: int64 keeps _run_tile to one signature, one compile)
        _run_tile(np.int64(tile), words, rates, seg_end, first_tick, charge, target, counter, q, index, bins, scaled,
                  accept, keys, noise, reset_readout, dead_ticks, mode, lazy_bound, pending_ticks, pending_rate,
                  sparse_firing, vector_min)


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
                     counter, q, index, bins, scaled, accept, keys, noise, reset_readout, dead_ticks, band_rows,
                     first_tick, sample_ticks):
    """Integrate-and-fire with the light computed per pixel and tick in compiled code.

    The light of pixel p in tick k is :func:`viform.light.compiled.pixel_lux` from the
    tick's scalars (row k of ``scalars``, ``xtab``, ``ytab``); its charge that tick is
    int64(a[p]·lux + b[p] + 0.5) in fixed point (gain and dark current per pixel), added
    exactly; the pixel fires when the sum reaches its Gamma(Q) target (the crossing rules of
    :func:`_fire`, its common case from ``scaled`` and ``accept`` as in :func:`_run_block`; the
    noise-free models without dead time, whose target is fixed, in line as well). Per
    image row and tick: one vectorized pass for the light (:func:`~viform.light.compiled.row_lux`),
    one for the charge, one that adds, compares and packs 64 lanes per word, then only the lanes
    that fired. ``out`` (uint8,
    ticks × packed frame bytes) receives the bits in the .dat order. Work items are bands of
    ``band_rows`` rows × windows of ticks, so the light tables stay in cache. The light is held over
    light samples of ``sample_ticks`` ticks (absolute ticks j·S … j·S + S − 1; ``first_tick``: the
    block's first): a row's charge per tick is computed at a sample's first tick (or the window's)
    and reused for the rest of the sample.
    """
    n_ticks = out.shape[0]
    n_pixels = charge.size
    width = xs.size
    height = n_pixels // width
    n_row_words = (width + _LANES - 1) // _LANES
    padded = n_row_words * _LANES
    aligned = width % 8 == 0
    n_bands = (height + band_rows - 1) // band_rows
    fast = noise and not reset_readout and dead_ticks == 0.0  # _fire's common case, inlined below
    # the noise-free models without dead time, inlined too: _fire_general's arithmetic for them
    plain_self = not noise and not reset_readout and dead_ticks == 0.0
    plain_readout = not noise and reset_readout and dead_ticks == 0.0
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
                    if k > w0 and (first_tick + k) % sample_ticks != 0:
                        pass  # the same light sample as tick k − 1: its charge per tick is in `rate`
                    elif fast_round:
                        row_lux(kind, k, y, xs, scalars, xtab, ytab, frames, params, lux)
                        # charge this tick, rint(a·lux + b) in fixed point
                        # below 2^51, adding 1.5·2^52 rounds to an integer (half to even, as
                        # rint) held in the low mantissa bits: vectorizes where a float → int64
                        # conversion does not (AVX2)
                        for x in range(width):
                            rounded[x] = a[base + x] * lux[x] + b[base + x] + _ROUNDING_MAGIC
                        for x in range(width):
                            rate[x] -= _ROUNDING_MAGIC_BITS
                    else:
                        row_lux(kind, k, y, xs, scalars, xtab, ytab, frames, params, lux)
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
                            p = base + x
                            ci = cw[x]
                            ti = tw[x]
                            if fast and ci - ti < min(_fixed_charge(_JUMP_INTERVALS * q[p]),
                                                      _fixed_charge(8.0 * q[p] * q[p])):
                                # _fire's common case: one Gamma target per crossing, later ones lost
                                while ci >= ti:
                                    ci -= ti
                                    ti = _target_fast(np.int64(index[p]) * TABLE_SIZE, scaled, accept, keys[p],
                                                      counter[p])
                                    if ti == 0:
                                        ti = _target_general(q[p], index[p], bins, keys[p], counter[p])
                                    counter[p] += 1
                            elif plain_self:
                                # a fixed target: the charge past it is kept, the tick's later crossings lost
                                ci -= ti
                                if ci >= ti:
                                    ci -= ((ci - ti) // ti + 1) * ti
                            elif plain_readout:
                                # drained at the readout; the next (fixed) target counts as a draw
                                ci = 0
                                ti = max(np.int64(1), np.int64(q[p] * 4294967296.0 + 0.5))
                                counter[p] += 1
                            else:
                                ci, ti = _fire_general(ci, ti, rate[x], dead_ticks, p, q, index, bins, keys, noise,
                                                       reset_readout, counter)
                            cw[x] = ci
                            tw[x] = ti
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
