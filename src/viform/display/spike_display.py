"""Spike continuous display vs sample-and-hold displays (seed 000 §7, first half of the closing section).

Seed 000 §7: "显示是摄影的对称过程，脉冲连续显示把超高速脉冲流调制为极高速光子流 … 现有电视、手机
和虚拟现实应用的信号源都是视频，只有几十赫兹，最多120 Hz，在一帧周期内，显示器件重复创新同样光强 .
信号源变为视象后 … 能够实现类似自然光的高速变化，解决低帧率刷新带来的运动模糊" — display is the
symmetric process of capture: the spike display turns the spike stream back into a photon
stream, while a video display repeats the same light for a whole frame.

Models (light in sensor-plane lux, the unit of the scene, so emitted and true light compare
directly; a real panel scales both by the same factor):

* :class:`SpikeDisplay` — each spike of pixel p emits a fixed quantum of light, the Q
  electrons it stands for (seed 000 §3.3.2: every spike has the same area Q):
  q = Q / (e⁻ per lux·s) lux·s, spread over one tick, ``delay_ticks`` after the tick in
  which it was read (1: read at the end of tick k, shown during tick k + 1). Its time-mean
  light is count·q/T = (λ + I_d)·T/Q·Q/(e_lux·T) = scene lux + I_d/e_lux: the source's
  mean plus the (tiny) dark-current bias :attr:`SpikeDisplay.dark_bias_lux`.
* :class:`HoldDisplay` — a sample-and-hold display at ``refresh_hz``. ``content="ideal"``:
  frame n is the exact scene at n/f (no capture blur, no latency: the best a hold display
  can do without predicting motion); ``"camera"``: frame n is the mean light over the
  previous frame period (a 360°-shutter camera), shown one frame later.

Metrics

* error over time: RMS over pixels and windows of (emitted − true) light, each averaged
  over consecutive windows of length w, divided by the mean true light
  (:func:`windowed_error`). For the spike display it is counting noise: the count of a
  window holding N spikes on average has variance N/Q (Gamma(Q) intervals, seed 000 §5.1:
  Fano factor 1/Q) + 1/6 (the pixel's phase at each window edge is uniform, 1/12 per
  edge), so the relative RMS error is √(N̄/Q + 1/6)/N̄ with N̄ the mean count over pixels
  (:func:`counting_error_theory`; the variance is linear in N, so the pixels' different
  light levels average exactly);
* tracking-eye blur: an eye (or a camera of exposure T_e) following the motion at v px/s
  integrates I(u + v·t, t) over T_e (shift-and-add, :func:`tracked_profile`); on a hold
  display (100 % duty cycle: each frame is lit for its whole period 1/f) the frame stays
  put while the eye moves, so each frame is swept across the retina as a box of v/f pixels
  (10 px at 600 px/s and 60 Hz), the same box for every frame when the content is the
  exact scene at the frame's start. When T_e is a whole number of frame periods the eye
  sees the edge convolved with that box: 10–90 % width 0.8·v/f
  (:func:`hold_edge_width_theory_px`; 8 px at 600 px/s and 60 Hz; a display lit for a
  fraction D of the period would give 0.8·D·v/f). The spike display follows the scene
  at the tick rate: its smear is v/clock (0.015 px).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from viform._validate import ViformError, check_choice, check_int, check_positive
from viform.light.radiometry import PixelOptics
from viform.light.scenes import Scene, TranslatingScene
from viform.sensors.spike import SpikeSensor, SpikeSensorParameters


@dataclass(frozen=True)
class SpikeDisplay:
    """A display whose pixels emit a fixed light quantum per spike (seed 000 §7)."""

    threshold_electrons: float = 100.0
    clock_hz: float = 40e3
    optics: PixelOptics = PixelOptics()
    dark_current_e_per_s: float = 0.0
    delay_ticks: int = 1

    def __post_init__(self):
        check_positive("threshold_electrons", self.threshold_electrons)
        check_positive("clock_hz", self.clock_hz)
        check_int("delay_ticks", self.delay_ticks, 0)

    @classmethod
    def for_sensor(cls, parameters: SpikeSensorParameters, delay_ticks: int = 1) -> SpikeDisplay:
        """The display matched to a spike camera: one spike → the light that made it."""
        return cls(round(parameters.threshold_electrons), parameters.clock_hz, parameters.optics,
                   parameters.dark_current_e_per_s, delay_ticks)

    @property
    def quantum_lux_s(self) -> float:
        """Light emitted per spike, lux·s: Q electrons' worth of light."""
        return self.threshold_electrons / self.optics.electrons_per_lux_second

    @property
    def dark_bias_lux(self) -> float:
        """Mean extra light from dark-current spikes, lux."""
        return self.dark_current_e_per_s / self.optics.electrons_per_lux_second

    def emitted_lux(self, spikes) -> np.ndarray:
        """Mean emitted light in each tick, (T, H, W) float32 lux; the first ``delay_ticks`` are dark."""
        spikes = np.asarray(spikes)
        if spikes.ndim != 3:
            raise ViformError(f"spikes must have shape (T, H, W); got {spikes.shape}")
        out = np.zeros(spikes.shape, np.float32)
        d = self.delay_ticks
        level = np.float32(self.quantum_lux_s * self.clock_hz)
        out[d:] = spikes[: spikes.shape[0] - d] * level
        return out


@dataclass(frozen=True)
class HoldDisplay:
    """A sample-and-hold display refreshed at ``refresh_hz`` (content "ideal" or "camera", module docstring)."""

    refresh_hz: float = 60.0
    content: str = "ideal"

    def __post_init__(self):
        check_positive("refresh_hz", self.refresh_hz)
        check_choice("content", self.content, ("ideal", "camera"))

    @property
    def name(self) -> str:
        return f"{self.refresh_hz:g} Hz hold" + (" (camera)" if self.content == "camera" else "")

    def frames(self, scene: Scene, n_frames: int) -> np.ndarray:
        period = 1.0 / self.refresh_hz
        out = np.empty((n_frames, scene.height, scene.width))
        for n in range(n_frames):
            if self.content == "ideal":
                out[n] = scene.illuminance_lux(n * period)
            else:
                t0 = max(0.0, (n - 1) * period)
                out[n] = scene.mean_illuminance_lux(t0, t0 + period, samples=64)
        return out

    def emitted_lux(self, scene: Scene, n_ticks: int, clock_hz: float) -> np.ndarray:
        """Emitted light on the tick grid of a ``clock_hz`` stream, (T, H, W) float32 lux."""
        mid = (np.arange(n_ticks) + 0.5) / clock_hz
        index = np.floor(mid * self.refresh_hz + 1e-9).astype(np.int64)
        frames = self.frames(scene, int(index.max()) + 1).astype(np.float32)
        return frames[index]


def true_lux(scene: Scene, n_ticks: int, clock_hz: float) -> np.ndarray:
    """The scene's light at every tick's midpoint, (T, H, W) float32 lux."""
    return scene.illuminance_lux_many((np.arange(n_ticks) + 0.5) / clock_hz).astype(np.float32)


def windowed_error(emitted, truth, window_ticks: int, skip_ticks: int = 0) -> float:
    """Relative RMS error of the light averaged over consecutive windows (module docstring)."""
    w = check_int("window_ticks", window_ticks, 1)
    e = np.asarray(emitted, np.float64)[skip_ticks:]
    t = np.asarray(truth, np.float64)[skip_ticks:]
    n = (e.shape[0] // w) * w
    if n == 0:
        raise ViformError(f"window of {w} ticks is longer than the {e.shape[0]} ticks compared")
    eb = e[:n].reshape(n // w, w, *e.shape[1:]).mean(axis=1)
    tb = t[:n].reshape(n // w, w, *t.shape[1:]).mean(axis=1)
    return float(np.sqrt(np.mean((eb - tb) ** 2)) / np.mean(tb))


def counting_error_theory(mean_spikes_per_window: float, threshold_electrons: float) -> float:
    """Relative RMS error of a spike display over windows of N̄ spikes: √(N̄/Q + 1/6)/N̄ (module docstring)."""
    n = check_positive("mean_spikes_per_window", mean_spikes_per_window)
    return math.sqrt(n / round(threshold_electrons) + 1 / 6) / n


def tracked_profile(emitted, clock_hz: float, velocity_px_per_s: float, start_tick: int, n_ticks: int,
                    u_step_px: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """What an eye tracking horizontal motion at ``velocity_px_per_s`` integrates (shift-and-add).

    R(u) = mean over ticks k of the row-averaged light at x = u + v·(t_k − t_start), t_k the
    tick midpoints, by linear interpolation between pixel centres. Returns (u, R).
    """
    e = np.asarray(emitted)
    if start_tick + n_ticks > e.shape[0] or n_ticks < 1 or start_tick < 0:
        raise ViformError(f"integration [{start_tick}, {start_tick + n_ticks}) ticks is outside the "
                          f"{e.shape[0]} ticks available")
    rows = e[start_tick:start_tick + n_ticks].mean(axis=1, dtype=np.float64)  # (n, W)
    width = rows.shape[1]
    x = np.arange(width, dtype=np.float64)
    shift_total = abs(velocity_px_per_s) * n_ticks / clock_hz
    u = np.arange(0.0, width - 1 - shift_total + 1e-9, u_step_px) if velocity_px_per_s >= 0 else \
        np.arange(shift_total, width - 1 + 1e-9, u_step_px)
    acc = np.zeros_like(u)
    for k in range(n_ticks):
        acc += np.interp(u + velocity_px_per_s * (k + 0.5) / clock_hz, x, rows[k])
    return u, acc / n_ticks


def edge_width_px(u, profile, low: float, high: float, centre_px: float, half_span_px: float) -> float:
    """10–90 % width of a rising edge near ``centre_px`` between the known levels ``low`` and ``high``.

    The profile inside [centre − half_span, centre + half_span] is made monotone by a running
    maximum (noise cannot undo a crossing) and the 10 % and 90 % crossings are interpolated.
    """
    u = np.asarray(u)
    sel = (u >= centre_px - half_span_px) & (u <= centre_px + half_span_px)
    uu, rr = u[sel], np.maximum.accumulate(np.asarray(profile)[sel])
    lv = (rr - low) / (high - low)
    if lv.size < 2 or lv[0] > 0.1 or lv[-1] < 0.9:
        raise ViformError("edge not found inside the measurement span: widen half_span_px or check the levels")

    def cross(level):
        i = int(np.argmax(lv >= level))
        if i == 0:
            return float(uu[0])
        f = (level - lv[i - 1]) / (lv[i] - lv[i - 1]) if lv[i] > lv[i - 1] else 0.0
        return float(uu[i - 1] + f * (uu[i] - uu[i - 1]))

    return cross(0.9) - cross(0.1)


def hold_edge_width_theory_px(velocity_px_per_s: float, refresh_hz: float) -> float:
    """10–90 % width of an edge on a hold display seen by a tracking eye: 0.8·v/f.

    Valid for ideal content, a 100 % duty cycle and an integration time of whole frame
    periods (module docstring); not defined otherwise.
    """
    return 0.8 * abs(velocity_px_per_s) / refresh_hz


def moving_bars_scene(height: int = 16, width: int = 128, velocity_px_per_s: float = 600.0, period_px: float = 48.0,
                      min_lux: float = 1.0, max_lux: float = 8.0) -> TranslatingScene:
    """The comparison scene: vertical bars (period ``period_px``) moving right at ``velocity_px_per_s``."""
    return TranslatingScene(height, width, velocity_px_per_s=(velocity_px_per_s, 0.0), pattern="bars",
                            min_lux=min_lux, max_lux=max_lux, period_px=period_px, origin_px=(0.0, 0.0))


def compare_displays(scene: TranslatingScene | None = None, duration_s: float = 0.06, refresh_hz=(60.0, 120.0),
                     windows_s=(1e-3, 4e-3, 1 / 60), eye_integration_s: float = 1 / 60,
                     sensor: SpikeSensorParameters | None = None, seed: int = 0, keep_arrays: bool = False) -> dict:
    """Spike display vs hold displays on the same moving scene: error over time and tracking-eye blur.

    The spike stream is captured by the simulated spike camera from the scene (seed 000 §3.2)
    and shown on the matched :class:`SpikeDisplay`.
    """
    scene = scene or moving_bars_scene()
    if not isinstance(scene, TranslatingScene) or scene.velocity_px_per_s[1] != 0:
        raise ViformError("compare_displays needs a TranslatingScene moving horizontally (velocity y = 0)")
    sensor = sensor or SpikeSensorParameters()
    clock = sensor.clock_hz
    v = scene.velocity_px_per_s[0]
    # the edge is measured within ±period/4 of its place, which must hold the slowest hold
    # display's smear v/f (plus a pixel of interpolation)
    v_max = (scene.period_px / 4 - 1) * min(refresh_hz)
    if not 0 < abs(v) <= v_max:
        raise ViformError(f"velocity_px_per_s = {v:g} is not allowed: it must be non-zero and at most {v_max:g} px/s "
                          f"in size, so that a {min(refresh_hz):g} Hz display's smear v/f stays inside a quarter "
                          f"of the bars' {scene.period_px:g} px period")
    stream = SpikeSensor(sensor).capture(scene, duration_s, seed=seed, light_sample_ticks=1)
    n = stream.n_ticks
    truth = true_lux(scene, n, clock)
    spike_display = SpikeDisplay.for_sensor(sensor)
    displays = {"spike": spike_display.emitted_lux(stream.spikes)}
    for f in refresh_hz:
        displays[f"hold {f:g} Hz"] = HoldDisplay(f).emitted_lux(scene, n, clock)
    eye_ticks = int(round(check_positive("eye_integration_s", eye_integration_s) * clock))
    start = max(1, n - eye_ticks - int(0.1 * n))
    # the rising edge (dark → bright bar) nearest the middle of the tracked window, in retinal u
    half = scene.period_px / 2
    u_mid = (scene.width - 1 - abs(v) * eye_ticks / clock) / 2
    # u = x − v·(t − t_start): the pattern's rising edges sit at u = x0 + half + 2m·half + v·t_start
    shift0 = v * start / clock
    m = round((u_mid - shift0 - scene.origin_px[0] - half) / (2 * half))
    edge_u = scene.origin_px[0] + half + 2 * half * m + shift0
    window_ticks = {f"{w * 1e3:.3g} ms": max(1, int(round(w * clock))) for w in windows_s}
    spikes_per_tick = float(np.mean(truth, dtype=np.float64)) * sensor.optics.electrons_per_lux_second / clock \
        / round(sensor.threshold_electrons)
    rows = {}
    for name, emitted in [("truth", truth)] + list(displays.items()):
        row = {}
        if name != "truth":
            row["error_rel_rms"] = {k: windowed_error(emitted, truth, w) for k, w in window_ticks.items()}
            row["time_mean_lux"] = float(np.mean(emitted, dtype=np.float64))
        u, prof = tracked_profile(emitted, clock, v, start, eye_ticks)
        # ±half/2 around the edge holds a hold display's one-sided smear of v/f (< half/2 here)
        row["tracked_edge_width_px"] = edge_width_px(u, prof, scene.min_lux, scene.max_lux, edge_u, half / 2)
        row["tracked_edge_width_ms"] = row["tracked_edge_width_px"] / abs(v) * 1e3
        if keep_arrays:
            row["profile"] = (u, prof)
        rows[name] = row
    rows["spike"]["error_rel_rms_theory"] = {k: counting_error_theory(spikes_per_tick * w, sensor.threshold_electrons)
                                             for k, w in window_ticks.items()}
    for f in refresh_hz:
        # the box theory needs whole frame periods (within the one-tick rounding of eye_ticks)
        whole = round(eye_ticks * f / clock) >= 1 and abs(eye_ticks - round(eye_ticks * f / clock) * clock / f) <= 1
        rows[f"hold {f:g} Hz"]["tracked_edge_width_theory_px"] = hold_edge_width_theory_px(v, f) if whole else None
    result = {
        "scene": {"pattern": scene.pattern, "velocity_px_per_s": v, "period_px": scene.period_px,
                  "min_lux": scene.min_lux, "max_lux": scene.max_lux, "height": scene.height, "width": scene.width},
        "duration_s": n / clock, "clock_hz": clock, "threshold_electrons": sensor.threshold_electrons,
        "eye_integration_s": eye_ticks / clock, "edge_u_px": edge_u,
        "true_time_mean_lux": float(np.mean(truth, dtype=np.float64)),
        "spike_display_dark_bias_lux": spike_display.dark_bias_lux,
        "spike_display_quantum_lux_s": spike_display.quantum_lux_s,
        "displays": rows,
    }
    if keep_arrays:
        result["arrays"] = {"truth": truth, **displays}
    return result

