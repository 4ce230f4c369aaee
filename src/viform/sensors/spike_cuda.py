"""The spike simulator on a CUDA GPU (numba-cuda): the CPU kernels' algorithm, the same bits.

One algorithm, two targets. The per-pixel functions the CPU kernels call — the counter-based
Gamma draws of :mod:`viform.sensors._gamma`, the crossing handling of
:mod:`viform.sensors._spike_kernels` (:func:`~viform.sensors._spike_kernels._fire` and what it
calls, dead time, readout reset, saturated ticks), the compiled light :func:`~viform.light.compiled.pixel_lux` —
are compiled a second time as CUDA device functions from the same Python source; the initial
state, the runs of constant light and the per-tick light scalars come from the same host code
as on the CPU. So a pixel's k-th interval is the same draw from (seed, pixel, k) and its charge
the same fixed-point sums on both devices.

What runs on the device: one thread per pixel, the tick loop inside the thread (charge and
target in registers), the warp's 32 spike bits gathered by a warp ballot into one 32-bit word
— pixels 32·w … 32·w + 31, the ``.dat`` bit order — written by lane 0. Blocks of ticks are
double-buffered: the copy of a block's packed bits to pinned host memory (its own stream)
overlaps the next block's kernel; device and host memory are a few blocks whatever the
duration.

Exactness across devices: floating-point contraction is disabled (NVVM ``-fma=0``: a·b + c is
rounded twice, as on the CPU). Additions, products, square roots and roundings are IEEE-exact
on both devices, so the common draws are bit-identical. The rare paths that evaluate a
logarithm, exponential or cosine (the open last bin of the Gamma tables, about 1 draw in
1,000, the squeeze's fallback, and the jumps through heavily saturated ticks) use the GPU's
libdevice functions, which may differ from the CPU's libm in the last bit; a different last
bit changes a target's fixed-point rounding with probability about 2⁻¹⁴. The simulator tests
(``NUMBA_ENABLE_CUDASIM=1``) check the algorithm bit for bit against the CPU kernels;
``benchmarks/bench_gpu.py`` counts differing bits on a real GPU.

The simulator has no warp ballot: there the warp's bits are gathered through shared memory
(the same word), so the ballot itself is checked on a GPU only (by the benchmark).
"""

from __future__ import annotations

import contextlib
import os
from types import FunctionType

import numpy as np

from viform._validate import ViformError

#: Threads per CUDA block (a multiple of the warp size, 32).
THREADS_PER_BLOCK = 256
DEVICES = ("cpu", "cuda", "auto")

_GAMMA_FUNCTIONS = ("splitmix64", "hash3", "uniform_from_hash", "gamma_draw", "event_stream", "stream_uniform",
                    "stream_normal", "stream_gamma", "stream_poisson")
_SPIKE_FUNCTIONS = ("_equilibrium_state", "_saturated_state", "_next_target", "_fixed_charge", "_fire_general",
                    "_fire")
_LIGHT_FUNCTIONS = ("_modulation", "pixel_lux")
_kernels: dict = {}
#: numba.cuda inside the kernels' namespace (set by :func:`kernels`; numba-cuda is optional)
cuda = None
libdevice = None
# device functions of the kernels' namespace, also set by kernels()
_fire = pixel_lux = _warp_bits = _rint = None


def simulator_enabled() -> bool:
    """True when numba-cuda runs kernels in its CPU simulator (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def cuda_available() -> bool:
    """Whether numba-cuda is installed and finds a CUDA GPU (or its simulator is enabled)."""
    try:
        from numba import cuda
    except ImportError:
        return False
    try:
        return bool(cuda.is_available())
    except Exception:  # a broken driver install: no GPU for us
        return False


def device_description() -> str:
    """The GPU numba-cuda uses, e.g. "NVIDIA H100 80GB HBM3 (compute capability 9.0)"."""
    from numba import cuda

    if simulator_enabled():
        return "numba-cuda simulator (NUMBA_ENABLE_CUDASIM=1)"
    device = cuda.get_current_device()
    name = device.name.decode() if isinstance(device.name, bytes) else str(device.name)
    return f"{name} (compute capability {device.compute_capability[0]}.{device.compute_capability[1]})"


def resolve_device(device: str, flag: str = "device") -> str:
    """"cpu" or "cuda" for a requested ``device`` in :data:`DEVICES` ("auto": a GPU when there is one)."""
    if device not in DEVICES:
        raise ViformError(f"{flag} = {device!r} is not allowed: use one of {', '.join(DEVICES)}")
    if device == "cpu":
        return "cpu"
    if cuda_available():
        return "cuda"
    if device == "auto":
        return "cpu"
    try:
        import numba.cuda  # noqa: F401
    except ImportError:
        raise ViformError(f"{flag} = 'cuda' needs numba-cuda: pip install \"viform[cuda]\" (or use cpu)") from None
    raise ViformError(f"{flag} = 'cuda': numba-cuda finds no CUDA GPU on this machine (use cpu or auto)")


@contextlib.contextmanager
def _no_contraction():
    """Compile with NVVM's -fma=0 so that a·b + c rounds twice, as the CPU code does (numba-cuda
    exposes no option for it: its compile_ir is wrapped while our kernels compile)."""
    if simulator_enabled():
        yield
        return
    from numba.cuda.cudadrv import nvvm

    original = nvvm.compile_ir

    def compile_ir(llvmir, **options):
        options.setdefault("fma", False)
        return original(llvmir, **options)

    nvvm.compile_ir = compile_ir
    try:
        yield
    finally:
        nvvm.compile_ir = original


def _device_numpy():
    """A stand-in for ``np`` inside the device twins: the same scalar types, and the scalar math
    functions from libdevice (numba-cuda types ``np.log`` & co. only on arrays). The simulator
    runs the real ``np``."""
    import types as pytypes

    from numba.cuda import libdevice

    shim = pytypes.ModuleType("viform_device_numpy")
    for name in ("uint64", "int64", "uint32", "int32", "uint8", "float64", "bool_", "pi"):
        setattr(shim, name, getattr(np, name))
    for name in ("log", "exp", "sqrt", "cos", "sin", "floor", "rint"):
        setattr(shim, name, getattr(libdevice, name))
    return shim


def _twins(module, names, namespace, device_jit):
    """CUDA device functions compiled from the Python source of ``module``'s njit functions
    ``names``; their calls to each other resolve in ``namespace`` (a copy of the module's globals
    whose entries are replaced by the twins)."""
    for name in names:
        py_func = getattr(module, name).py_func
        twin = FunctionType(py_func.__code__, namespace, py_func.__name__, py_func.__defaults__,
                            py_func.__closure__)
        namespace[name] = device_jit(twin)


def _warp_bits_ballot(fired, scratch):
    return cuda.ballot_sync(0xFFFFFFFF, fired)


def _warp_bits_shared(fired, scratch):
    # the simulator has no ballot: each lane posts its bit, every lane ORs its warp's 32
    lane = cuda.threadIdx.x
    scratch[lane] = np.uint32(1 << (lane & 31)) if fired else np.uint32(0)
    cuda.syncthreads()
    word = np.uint32(0)
    first = lane - (lane & 31)
    for i in range(32):
        word |= scratch[first + i]
    cuda.syncthreads()
    return word


def _kernel_runs(words, rates, seg_end, first_tick, charge, target, counter, q, index, bins, keys, noise,
                 reset_readout, dead_ticks, mode):
    """Runs of constant light (the GPU form of :func:`viform.sensors._spike_kernels._run_block`): thread p
    adds ``rates[s, p]`` each tick of run s and fires at its target; ``words[k, p // 32]`` gets
    the warp's bits."""
    scratch = cuda.shared.array(THREADS_PER_BLOCK, np.uint32)
    p = cuda.grid(1)
    n_pixels = charge.size
    active = p < n_pixels
    c = np.int64(0)
    t = np.int64(0x7FFFFFFFFFFFFFFF)
    if active:
        c = charge[p]
        t = target[p]
    s = 0
    while seg_end[s] <= first_tick:
        s += 1
    for k in range(words.shape[0]):
        while seg_end[s] <= first_tick + k:
            s += 1
        e = rates[s, p] if active else np.int64(0)
        c += e
        fired = c >= t
        word = _warp_bits(fired, scratch)
        if (p & 31) == 0 and (p >> 5) < words.shape[1]:
            words[k, p >> 5] = word
        if fired:
            if mode == 1:  # noise-free self-reset
                c -= t
                if c >= t:
                    c %= t
            elif mode == 2:  # noise-free readout reset
                c = np.int64(0)
            else:
                c, t = _fire(c, t, e, dead_ticks, p, q, index, bins, keys, noise, reset_readout, counter)
    if active:
        charge[p] = c
        target[p] = t


def _kernel_ticks(words, kind, scalars, xtab, ytab, frames, params, a, b, width, charge, target, counter, q, index,
                  bins, keys, noise, reset_readout, dead_ticks):
    """Light computed per pixel and tick (the GPU form of :func:`viform.sensors._spike_kernels._run_block_ticks`):
    the charge of a tick is rint(a·lux + b) in fixed point, lux from :func:`pixel_lux`."""
    scratch = cuda.shared.array(THREADS_PER_BLOCK, np.uint32)
    p = cuda.grid(1)
    n_pixels = charge.size
    active = p < n_pixels
    c = np.int64(0)
    t = np.int64(0x7FFFFFFFFFFFFFFF)
    x = 0
    y = 0
    if active:
        c = charge[p]
        t = target[p]
        x = p % width
        y = p // width
    for k in range(words.shape[0]):
        e = np.int64(0)
        if active:
            lux = pixel_lux(kind, p, x, y, k, scalars, xtab, ytab, frames, params)
            e = np.int64(_rint(a[p] * lux + b[p]))
        c += e
        fired = c >= t
        word = _warp_bits(fired, scratch)
        if (p & 31) == 0 and (p >> 5) < words.shape[1]:
            words[k, p >> 5] = word
        if fired:
            c, t = _fire(c, t, e, dead_ticks, p, q, index, bins, keys, noise, reset_readout, counter)
    if active:
        charge[p] = c
        target[p] = t


def _rint_simulator(x):
    return np.rint(x)


def _rint_device(x):
    return libdevice.rint(x)


def kernels():
    """(runs kernel, per-tick kernel), compiled on first use."""
    if "runs" in _kernels:
        return _kernels["runs"], _kernels["ticks"]
    from numba import cuda as numba_cuda

    from viform.light import compiled as light_module
    from viform.sensors import _gamma, _spike_kernels

    device_jit = numba_cuda.jit(device=True)
    simulated = simulator_enabled()
    device_np = {} if simulated else {"np": _device_numpy()}
    gamma_ns = dict(_gamma.__dict__, **device_np)
    _twins(_gamma, _GAMMA_FUNCTIONS, gamma_ns, device_jit)
    spike_ns = dict(_spike_kernels.__dict__, **device_np)
    spike_ns.update({name: gamma_ns[name] for name in _GAMMA_FUNCTIONS})
    _twins(_spike_kernels, _SPIKE_FUNCTIONS, spike_ns, device_jit)
    light_ns = dict(light_module.__dict__, **device_np)
    _twins(light_module, _LIGHT_FUNCTIONS, light_ns, device_jit)
    ns = dict(globals())
    ns.update(cuda=numba_cuda, _fire=spike_ns["_fire"], pixel_lux=light_ns["pixel_lux"])
    if not simulated:
        from numba.cuda import libdevice as device_library

        ns["libdevice"] = device_library
    ns["_warp_bits"] = device_jit(FunctionType((_warp_bits_shared if simulated else _warp_bits_ballot).__code__, ns))
    ns["_rint"] = device_jit(FunctionType((_rint_simulator if simulated else _rint_device).__code__, ns))
    _kernels["runs"] = numba_cuda.jit(FunctionType(_kernel_runs.__code__, ns))
    _kernels["ticks"] = numba_cuda.jit(FunctionType(_kernel_ticks.__code__, ns))
    return _kernels["runs"], _kernels["ticks"]


def packed_blocks_cuda(sensor, scene, duration_s, seed, block_ticks, light_sample_ticks, progress, state,
                       compiled_light):
    """As :meth:`SpikeSensor._packed_blocks`, on the GPU: (first tick, packed bits uint8 (T, 8·⌈H·W/64⌉))."""
    from numba import cuda

    from viform.sensors._spike_kernels import _Segments

    # pixel_lux does not draw the sampled kind: the scene's light per sample, which gives the same bits
    plan = sensor.run_plan(scene, duration_s, seed, block_ticks, light_sample_ticks, state, compiled_light, True,
                           drop_light_kinds=("sampled",))
    p, n_ticks, height, width, pixels, row_bytes = (plan.p, plan.n_ticks, plan.height, plan.width, plan.pixels,
                                                    plan.row_bytes)
    sample, light, block_ticks, q, index, tables = (plan.sample, plan.light, plan.block_ticks, plan.q,
                                                    plan.index, plan.tables)
    a, b, state, caller_state, reset_readout = plan.a, plan.b, plan.state, plan.caller_state, plan.reset_readout
    dead_ticks, mode, per_tick_light = plan.dead_ticks, plan.mode, plan.per_tick_light
    runs_kernel, ticks_kernel = kernels()
    # whole warps; small images launch fewer threads per block (the simulator runs every one)
    threads = min(THREADS_PER_BLOCK, 32 * ((pixels + 31) // 32))
    grid = (pixels + threads - 1) // threads
    compute, copy = cuda.stream(), cuda.stream()
    d_charge, d_target, d_counter = (cuda.to_device(x, stream=compute) for x in (state.charge, state.target,
                                                                                  state.counter))
    d_q, d_index, d_keys, d_bins = (cuda.to_device(x, stream=compute) for x in (q, index, state.keys, tables[0]))
    if per_tick_light:
        from viform.light.compiled import tick_buffers, tick_scalars

        kind, params, frames = light.kernel_kind(), light.parameters(), light.flat_frames()
        scalars, xtab, ytab = tick_buffers(light, min(block_ticks, n_ticks))
        d_params, d_frames, d_a, d_b = (cuda.to_device(x, stream=compute) for x in (params, frames, a, b))
    segments = _Segments(sensor, scene, light, sample, height, width)
    rows = min(block_ticks, n_ticks)
    d_out = [cuda.device_array((rows, row_bytes // 4), dtype=np.uint32, stream=compute) for _ in range(2)]
    host = [cuda.pinned_array((rows, row_bytes), dtype=np.uint8) for _ in range(2)]
    copied = [None, None]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_ticks, unit="tick", desc="simulate (GPU)", leave=False, unit_scale=True)

    def launch(i, first, last):
        n = last - first
        slot = i % 2
        if copied[slot] is not None:  # the copy out of this buffer must be done before it is rewritten
            copied[slot].wait(compute)
        out = d_out[slot][:n]
        with _no_contraction():
            if per_tick_light:
                times = (np.arange(first, last) // sample + 0.5) * (sample / p.clock_hz)
                tick_scalars(times, params, kind, scalars[:n], xtab[:n], ytab[:n])
                d_scalars, d_xtab, d_ytab = (cuda.to_device(np.ascontiguousarray(x[:n]), stream=compute)
                                             for x in (scalars, xtab, ytab))
                ticks_kernel[grid, threads, compute](
                    out, kind, d_scalars, d_xtab, d_ytab, d_frames, d_params, d_a, d_b, width, d_charge, d_target,
                    d_counter, d_q, d_index, d_bins, d_keys, p.photon_noise, reset_readout, dead_ticks)
            else:
                rates, seg_end = segments.block(first, last)
                runs_kernel[grid, threads, compute](
                    out, cuda.to_device(rates, stream=compute), cuda.to_device(seg_end, stream=compute), first,
                    d_charge, d_target, d_counter, d_q, d_index, d_bins, d_keys, p.photon_noise, reset_readout,
                    dead_ticks, mode)
        done = cuda.event()
        done.record(compute)
        done.wait(copy)
        out.copy_to_host(host[slot][:n].view(np.uint32), stream=copy)
        copied[slot] = cuda.event()
        copied[slot].record(copy)

    # a caller that reads the state between blocks gets it after each block: no block ahead then
    ahead = not caller_state
    quiet = np.errstate(over="ignore") if simulator_enabled() else contextlib.nullcontext()
    quiet.__enter__()  # the simulator's NumPy scalars warn where the device's hash arithmetic wraps
    try:
        starts = list(range(0, n_ticks, block_ticks))
        launch(0, 0, min(block_ticks, n_ticks))
        for i, first in enumerate(starts):
            last = min(first + block_ticks, n_ticks)
            if ahead and i + 1 < len(starts):  # the next block computes while this one is copied and used
                launch(i + 1, starts[i + 1], min(starts[i + 1] + block_ticks, n_ticks))
            copied[i % 2].synchronize()
            block = host[i % 2][: last - first].copy()
            if caller_state:
                compute.synchronize()
                for d, h in ((d_charge, state.charge), (d_target, state.target), (d_counter, state.counter)):
                    d.copy_to_host(h, stream=compute)
                compute.synchronize()
                if i + 1 < len(starts):
                    launch(i + 1, starts[i + 1], min(starts[i + 1] + block_ticks, n_ticks))
            state.next_tick = last
            if bar is not None:
                bar.update(last - first)
            yield first, block
    finally:
        quiet.__exit__(None, None, None)
        if bar is not None:
            bar.close()
