"""Pass-through: the spike camera feeding the spike display directly (seed 000 §7).

Seed 000 §7: "脉冲连续摄影采集的视象通过高速通道直连脉冲连续显示输出，实现单向透明光传输，用于虚拟现实
眼镜" — the vform captured by the spike camera goes over a high-speed link straight to a spike
display: one-way transparent glass.

Pipeline: scene → :class:`~viform.sensors.spike.SpikeSensor` (exact photon statistics,
seed 000 §3.2, §5.1) → spike bits read at the end of each tick → link of
``link_latency_ticks`` → :class:`~viform.display.spike_display.SpikeDisplay` emitting Q
electrons' worth of light per spike during the next tick.

Latency (mean delay of the light). For a step of the scene from L₀ to L₁ the mean delay of
a linear, unbiased pipe is the area between the input and output steps divided by the
step: D = ∫[(T(t) − T₀) − (E(t) − E₀)] dt / (L₁ − L₀) (:func:`step_latency_s`).
Theory for the spike pipe: the integrate-and-fire pixel's expected firing rate is λ(t)/Q at
every instant (in charge time the threshold crossings form a stationary renewal process, so
a change of λ changes the rate at once), a crossing is uniform within its tick, and the
display emits during tick k + 1 + link: D = (1 + link_latency_ticks)/clock, 25 µs at 40 kHz.
A conventional pipe (camera exposing each frame period, frame shown during the next frame
on a hold display) has D = 1/f: 16.7 ms at 60 Hz.

Fidelity: relative RMS error of the emitted light against the scene over windows of
length w (:func:`viform.display.spike_display.windowed_error`); the spike pipe's error is
the photon/threshold quantisation ~ 1/√(spikes per window) and falls with w, the
conventional pipe's error is set by the motion in one frame.
"""

from __future__ import annotations

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.display.spike_display import HoldDisplay, SpikeDisplay, moving_bars_scene, true_lux, windowed_error
from viform.light.scenes import Scene, StepScene, StillScene
from viform.sensors.spike import SpikeSensor, SpikeSensorParameters


def spike_passthrough(scene: Scene, duration_s: float, sensor: SpikeSensorParameters | None = None,
                      link_latency_ticks: int = 0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Capture ``scene`` with the spike camera and show it on the matched spike display.

    Returns ``(emitted, truth)``: light per tick, (T, H, W) float32 lux.
    """
    sensor = sensor or SpikeSensorParameters()
    check_int("link_latency_ticks", link_latency_ticks, 0)
    stream = SpikeSensor(sensor).capture(scene, duration_s, seed=seed, light_sample_ticks=1)
    display = SpikeDisplay.for_sensor(sensor, delay_ticks=1 + link_latency_ticks)
    return display.emitted_lux(stream.spikes), true_lux(scene, stream.n_ticks, sensor.clock_hz)


def conventional_passthrough(scene: Scene, n_ticks: int, clock_hz: float, frame_rate_hz: float = 60.0):
    """A frame camera (exposure = frame period, noise-free) feeding a hold display one frame later."""
    return HoldDisplay(frame_rate_hz, "camera").emitted_lux(scene, n_ticks, clock_hz)


def step_latency_s(emitted, truth, clock_hz: float, step_tick: int, settle_ticks: int,
                   pre_ticks: int | None = None) -> float:
    """Mean delay of the pipe from a step at ``step_tick``: area between the steps / step size.

    Levels before the step are the means over the ``pre_ticks`` (default ``settle_ticks``)
    ticks before it (so a constant bias such as the dark-current light cancels; keep the
    pipe's start-up, when nothing is shown yet, out of them); the area is summed over the
    ``settle_ticks`` ticks after it, which must exceed the pipe's delay.
    """
    e = np.asarray(emitted, np.float64).reshape(np.shape(emitted)[0], -1).mean(axis=1)
    t = np.asarray(truth, np.float64).reshape(np.shape(truth)[0], -1).mean(axis=1)
    a = step_tick - (settle_ticks if pre_ticks is None else pre_ticks)
    b = step_tick + settle_ticks
    if a < 0 or b > e.size:
        raise ViformError(f"settle_ticks = {settle_ticks} around tick {step_tick} runs outside the "
                          f"{e.size} ticks")
    t0, e0 = t[a:step_tick].mean(), e[a:step_tick].mean()
    step = t[step_tick:b].mean() - t0
    if step == 0:
        raise ViformError("the scene has no step at step_tick")
    return float(np.sum((t[step_tick:b] - t0) - (e[step_tick:b] - e0)) / step / clock_hz)


def run_passthrough(sensor: SpikeSensorParameters | None = None, link_latency_ticks: int = 0,
                    frame_rate_hz: float = 60.0, windows_s=(1e-3, 4e-3, 1 / 60), seed: int = 0,
                    step_lux=(2.0, 8.0), size: int = 16, keep_arrays: bool = False) -> dict:
    """Latency (step scene) and fidelity (moving bars) of the spike pass-through vs a 60 Hz pipe."""
    sensor = sensor or SpikeSensorParameters()
    clock = sensor.clock_hz
    check_positive("frame_rate_hz", frame_rate_hz)
    frame_ticks = int(round(clock / frame_rate_hz))
    lat = measure_step_latency(sensor, link_latency_ticks, frame_rate_hz, step_lux, size, seed,
                               keep_arrays=keep_arrays)
    # fidelity on the moving scene
    scene = moving_bars_scene()
    n_move = int(round(0.06 * clock))
    e_move, t_move = spike_passthrough(scene, n_move / clock, sensor, link_latency_ticks, seed + 1)
    c_move = conventional_passthrough(scene, n_move, clock, frame_rate_hz)
    skip = frame_ticks  # the conventional pipe shows nothing useful before its first frame is exposed

    def fidelity(emitted):
        return {f"{w * 1e3:.3g} ms": windowed_error(emitted, t_move, max(1, int(round(w * clock))), skip)
                for w in windows_s}

    result = {
        "clock_hz": clock, "threshold_electrons": sensor.threshold_electrons,
        "link_latency_ticks": link_latency_ticks, "frame_rate_hz": frame_rate_hz,
        "step_lux": list(step_lux),
        "spike": {"latency_s": lat["spike_latency_s"], "latency_theory_s": (1 + link_latency_ticks) / clock,
                  "error_rel_rms": fidelity(e_move)},
        "conventional": {"latency_s": lat["conventional_latency_s"], "latency_theory_s": 1.0 / frame_rate_hz,
                         "error_rel_rms": fidelity(c_move)},
    }
    if keep_arrays:
        result["arrays"] = lat["arrays"]
    return result


def measure_step_latency(sensor: SpikeSensorParameters | None = None, link_latency_ticks: int = 0,
                         frame_rate_hz: float = 60.0, step_lux=(2.0, 8.0), size: int = 16, seed: int = 0,
                         keep_arrays: bool = False, spike_settle_ticks: int | None = None) -> dict:
    """Latency of the spike pipe and of the conventional pipe from a uniform step scene.

    The step lies on a tick edge and a frame edge two frame periods in; the levels before it
    are taken over the frame period before it (after both pipes have started up). The area
    is summed over two frame periods after it for the conventional pipe, and over
    ``spike_settle_ticks`` (default 40 + link) for the spike pipe, whose expected output
    has settled after 1 + link ticks: a short window keeps out the Gamma jitter of a long
    one (σ of the delay ≈ 0.05 tick with 32×32 pixels instead of 0.3).
    """
    sensor = sensor or SpikeSensorParameters()
    clock = sensor.clock_hz
    lo, hi = (check_positive("step_lux", v) for v in step_lux)
    frame_ticks = int(round(clock / check_positive("frame_rate_hz", frame_rate_hz)))
    step_tick = 2 * frame_ticks
    step_scene = StepScene(StillScene(np.full((size, size), float(lo))), step_time_s=step_tick / clock,
                           factor=hi / lo)
    if 1 + link_latency_ticks >= frame_ticks:
        raise ViformError(f"link_latency_ticks = {link_latency_ticks} is longer than a frame period "
                          f"({frame_ticks} ticks): the step would not settle")
    spike_settle = 40 + link_latency_ticks if spike_settle_ticks is None else spike_settle_ticks
    check_int("spike_settle_ticks", spike_settle, 2 + link_latency_ticks, 2 * frame_ticks)
    n_ticks = 4 * frame_ticks
    e_spk, truth = spike_passthrough(step_scene, n_ticks / clock, sensor, link_latency_ticks, seed)
    e_conv = conventional_passthrough(step_scene, n_ticks, clock, frame_rate_hz)
    out = {"spike_latency_s": step_latency_s(e_spk, truth, clock, step_tick, spike_settle, frame_ticks),
           "conventional_latency_s": step_latency_s(e_conv, truth, clock, step_tick, 2 * frame_ticks, frame_ticks),
           "latency_theory_s": (1 + link_latency_ticks) / clock, "spike_settle_ticks": spike_settle,
           "pre_ticks": frame_ticks}
    if keep_arrays:
        out["arrays"] = {"step_truth": truth, "step_spike": e_spk, "step_conventional": e_conv,
                         "step_tick": step_tick}
    return out
