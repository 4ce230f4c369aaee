"""End-to-end high-frame-rate camera (seed 002).

sensor → auto-exposure → DDR ring → decimation → equalization → link.

Data path of the seed's camera (seed 002 Fig. 2): the LUX13HS (reduced mode, 100 MHz,
1280 × 720 → 1 666.7 fps) feeds the FPGA, which meters every frame for auto-exposure
(§3.2.4), writes every frame into a DDR4 ring (§3.2.5), reads one frame in N for the link
(3:1 for CameraLink Full, §3.3) and equalizes it with a histogram (§3.2.2-§3.2.3).

The pixel physics is :class:`viform.sensors.frame.FramePixelArray` with LUX13HS-like
parameters (:func:`lux13hs_pixel_parameters`). Timing, links and the ring are computed for
the *readout window* (``roi``); the image itself may be *rendered* on a coarser grid
(``render_shape``) so a run takes seconds: each rendered pixel is one real pixel of the
window (every k-th pixel), so its noise statistics are those of a real pixel, and the
histogram of the rendered grid estimates the window's histogram.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.isp.histogram import StreamEqualizer
from viform.isp.link import RingBuffer, link_plan
from viform.light.scenes import Scene
from viform.sensors.auto_exposure import settle_frames
from viform.sensors.base import FrameStack
from viform.sensors.frame import FramePixelParameters, FrameSensor
from viform.sensors.highspeed import HighSpeedCamera, lux13hs_pixel_parameters, to_gray8
from viform.sensors.highspeed_timing import Window, lux13hs_timing


@dataclass
class HighSpeedConfig:
    """Settings of one run (defaults: the seed's operating point).

    Attributes
    ----------
    roi : str or Window
        Readout window on the 1280 × 864 sensor ("WxH" centred or "X,Y,W,H").
    mode, pixel_clock_hz : sensor readout mode and clock (see :func:`lux13hs_timing`).
    interface : str
        Link name (:data:`viform.isp.link.INTERFACES`).
    decimation : int or None
        N of N:1 frame sampling; None chooses it (:func:`viform.isp.link.choose_decimation`).
    ae : bool
        Auto-exposure on.
    meter : str
        "mean" (the seed), "weighted" or "percentile".
    target_gray, band_gray : float
        R_i and the dead band half-width (128 and 15).
    ae_latency_frames : int
        Frames between the metered frame and the one that gets the new exposure; 1 because
        frame k+1 is already exposing while frame k is read out (seed 002 §3.2.4).
    ae_saturated_cut : float or None
        k of the optional saturation-aware step (A2) of :mod:`viform.sensors.auto_exposure`;
        None (default) runs the seed's eq. (6) alone.
    equalize : bool
    eq_source, eq_method, eq_compensate : see :class:`viform.isp.histogram.StreamEqualizer`.
    exposure_s : float
        Initial (or fixed, without AE) exposure.
    n_frames : int
        Sensor frames to capture.
    scene_samples : int
        Points of the midpoint rule for the light during one exposure.
    """

    roi: str | Window = "1280x720"
    mode: str = "reduced"
    pixel_clock_hz: float | None = None
    interface: str = "cameralink"
    decimation: int | None = None
    max_decimation: int = 64
    ae: bool = True
    meter: str = "mean"
    target_gray: float = 128.0
    band_gray: float = 15.0
    ae_latency_frames: int = 1
    ae_saturated_cut: float | None = None
    equalize: bool = True
    eq_source: str = "same"
    eq_method: str = "shift"
    eq_compensate: bool = True
    exposure_s: float = 100e-6
    n_frames: int = 200
    scene_samples: int = 4
    seed: int = 0
    pixel_parameters: FramePixelParameters = field(default_factory=lux13hs_pixel_parameters)

    def camera(self) -> HighSpeedCamera:
        """The sensor of these settings (:data:`SENSOR_FIELDS`)."""
        kw = {k: getattr(self, k) for k in SENSOR_FIELDS}
        return HighSpeedCamera(kw.pop("pixel_parameters"), **kw)


#: Fields of :class:`HighSpeedConfig` that set the sensor (:class:`~viform.sensors.highspeed.HighSpeedCamera`);
#: the others set the link, the sampling, the equalization and the run.
SENSOR_FIELDS = ("pixel_parameters", "roi", "mode", "pixel_clock_hz", "ae", "meter", "target_gray", "band_gray",
                 "ae_latency_frames", "ae_saturated_cut", "exposure_s", "scene_samples")


@dataclass
class HighSpeedResult:
    """Output of :func:`run_highspeed`."""

    gray8: np.ndarray            # (N, h, w) every sensor frame, 8-bit
    exposure_cycles: np.ndarray  # (N,)
    exposure_s: np.ndarray       # (N,)
    metered_gray: np.ndarray     # (N,) what the AE meter saw
    mean_gray: np.ndarray        # (N,) plain mean gray
    frame_times_s: np.ndarray    # (N,) end of each exposure (frame transfer)
    transmitted_indices: np.ndarray
    output_frames: np.ndarray    # (M, h, w) frames leaving the link (equalized if on)
    timing: dict
    plan: dict
    account: dict
    equalizer: dict
    config: dict


def run_highspeed(scene: Scene, config: HighSpeedConfig | None = None, progress=None,
                  camera: HighSpeedCamera | None = None) -> HighSpeedResult:
    """Shoot ``scene`` with the LUX13HS-like camera and return every stage's output.

    The scene is rendered at its own resolution (the rendered grid); the window's size sets
    the timing, the link and the buffer. ``progress(1)`` is called after each sensor frame.
    ``camera`` (e.g. the catalogue's ``highspeed`` with settings) replaces the sensor that
    ``config``'s sensor fields describe; ``config`` still gives the frames, seed, link and ISP.

    Parameters
    ----------
    scene : Scene
        The scene, lux.
    config : HighSpeedConfig, optional
        Sensor, frames, seed, link and ISP settings (default: the seed's camera).
    progress : callable, optional
        Called with 1 after each sensor frame.
    camera : HighSpeedCamera, optional
        The sensor to use instead of the one ``config`` describes.

    Returns
    -------
    HighSpeedResult
        Every frame (8-bit), its exposure and meter reading, the frames sent over the link, the
        timing and the link plan.
    """
    cfg = config or HighSpeedConfig()
    camera = camera if camera is not None else cfg.camera()
    n = check_int("n_frames", cfg.n_frames, 1)
    window = camera.window
    plan = link_plan(camera.frame_rate_hz, window.height, window.width, cfg.interface, 8, cfg.decimation,
                     cfg.max_decimation)
    stack = camera.capture_frames(scene, n, seed=cfg.seed, progress=progress)
    return process_frames(stack, camera, cfg, scene, plan)


def process_frames(stack: FrameStack, camera: HighSpeedCamera, config: HighSpeedConfig | None = None,
                   scene: Scene | None = None, plan: dict | None = None) -> HighSpeedResult:
    """What the camera's FPGA does with the sensor's frames (``camera.capture``): every frame into
    the DDR ring, one in N read out for the link, equalized (seed 002 §3.2–3.3).

    ``config`` gives the link, sampling and equalization settings (its sensor settings are
    ``camera``'s); ``scene`` is recorded in the result's ``config``.

    Parameters
    ----------
    stack : FrameStack
        The sensor's frames (``camera.capture``).
    camera : HighSpeedCamera
        The camera that took them.
    config : HighSpeedConfig, optional
        Link, sampling and equalization settings.
    scene : Scene, optional
        The scene, recorded in the result.
    plan : dict, optional
        A :func:`~viform.isp.link.link_plan` (default: computed from ``camera`` and ``config``).

    Returns
    -------
    HighSpeedResult
        The pipeline's outputs.
    """
    cfg = config or HighSpeedConfig()
    window = camera.window
    rate_hz = camera.frame_rate_hz
    if plan is None:
        plan = link_plan(rate_hz, window.height, window.width, cfg.interface, 8, cfg.decimation, cfg.max_decimation)
    gray = stack.frames_dn
    n = len(stack)
    meta = stack.metadata
    ring = RingBuffer(plan["buffer_capacity_frames"], rate_hz, plan["link_max_frame_rate_hz"],
                      plan["decimation"])
    account = ring.run(n)
    sent = account.transmitted_indices
    eq = StreamEqualizer(cfg.eq_source, cfg.eq_method, cfg.eq_compensate)
    if cfg.equalize:
        out = np.stack([eq(gray[i]) for i in sent]) if sent.size else gray[:0]
    else:
        out = gray[sent]
    described = {k: v for k, v in cfg.__dict__.items() if k not in ("pixel_parameters", "roi")}
    described.update({k: getattr(camera, k) for k in SENSOR_FIELDS if k not in ("pixel_parameters", "roi")})
    described["n_frames"] = n
    return HighSpeedResult(
        gray8=gray, exposure_cycles=meta["exposure_cycles"], exposure_s=stack.exposure_s,
        metered_gray=meta["metered_gray"], mean_gray=gray.reshape(n, -1).mean(axis=1),
        frame_times_s=meta["frame_end_s"], transmitted_indices=sent,
        output_frames=out, timing=camera.timing.summary(window), plan=plan, account=account.to_dict(),
        equalizer={"on": cfg.equalize, "source": cfg.eq_source, "method": cfg.eq_method,
                   "compensate": cfg.eq_compensate},
        config=described | {"roi": asdict(window), "pixel_parameters": camera.parameters.to_dict(),
                            "render_shape": list(gray.shape[1:]),
                            **({"scene": scene.describe()} if scene is not None else {})})


# ----------------------------------------------------------------------------- scenes

class ScaledScene(Scene):
    """``base`` with its illuminance multiplied by ``gain`` (lux → lux)."""

    name = "scaled"

    def __init__(self, base: Scene, gain: float):
        super().__init__(base.height, base.width, base.duration_s)
        self.base = base
        self.gain = check_positive("gain", gain)

    def illuminance_lux(self, t_s):
        return self.base.illuminance_lux(t_s) * self.gain

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        return self.base.mean_illuminance_lux(t0_s, t1_s, samples) * self.gain

    def describe(self):
        return {**super().describe(), "gain": self.gain, "base": self.base.describe()}


class AspectFitScene(Scene):
    """``base`` cropped at its centre to the aspect ratio of ``height`` × ``width`` and resized
    to it (area-averaging), so an image of another shape is never stretched."""

    name = "aspect-fit"

    def __init__(self, base: Scene, height: int, width: int):
        super().__init__(height, width, base.duration_s)
        self.base = base
        bh, bw = base.height, base.width
        if bh * width > bw * height:       # too tall: keep the full width
            ch, cw = max(1, round(bw * height / width)), bw
        else:
            ch, cw = bh, max(1, round(bh * width / height))
        self.crop = (ch, cw)
        self._r0, self._c0 = (bh - ch) // 2, (bw - cw) // 2

    def _fit(self, img):
        from skimage.transform import resize

        c = img[self._r0:self._r0 + self.crop[0], self._c0:self._c0 + self.crop[1]]
        if c.shape == (self.height, self.width):
            return c
        return resize(c, (self.height, self.width), anti_aliasing=True, preserve_range=True)

    def illuminance_lux(self, t_s):
        return self._fit(self.base.illuminance_lux(t_s))

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        return self._fit(self.base.mean_illuminance_lux(t0_s, t1_s, samples))

    def describe(self):
        return {**super().describe(), "crop": list(self.crop), "base": self.base.describe()}


class StepsScene(Scene):
    """``base`` multiplied by a piecewise-constant factor: ×f_j from t_j on (exact window mean)."""

    name = "steps"

    def __init__(self, base: Scene, steps):
        super().__init__(base.height, base.width, base.duration_s)
        self.base = base
        steps = sorted((float(t), check_positive("step factor", f)) for t, f in steps)
        self.times_s = np.array([t for t, _ in steps])
        self.levels = np.cumprod([1.0] + [f for _, f in steps])

    def factor(self, t_s: float) -> float:
        return float(self.levels[np.searchsorted(self.times_s, t_s, side="right")])

    def illuminance_lux(self, t_s):
        return self.base.illuminance_lux(t_s) * self.factor(t_s)

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        if t1_s <= t0_s:
            return self.illuminance_lux(t0_s)
        edges = np.concatenate([[t0_s], self.times_s[(self.times_s > t0_s) & (self.times_s < t1_s)],
                                [t1_s]])
        acc = 0.0
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            acc = acc + self.base.mean_illuminance_lux(a, b, samples) * self.factor(a) * (b - a)
        return acc / (t1_s - t0_s)

    def describe(self):
        return {**super().describe(), "step_times_s": self.times_s.tolist(),
                "levels": self.levels.tolist(), "base": self.base.describe()}


def parse_steps(text: str | None):
    """``"0.03:10,0.07:0.1"`` → [(0.03, 10.0), (0.07, 0.1)] (time_s:factor pairs)."""
    if not text:
        return []
    out = []
    for part in str(text).split(","):
        try:
            t, f = part.split(":")
            out.append((float(t), float(f)))
        except ValueError:
            raise ViformError(f"steps = {text!r} is not allowed: write "
                              "TIME_S:FACTOR[,TIME_S:FACTOR…]") from None
    return out


def backlit_scene(height: int = 90, width: int = 160, background_lux: float = 3_000.0,
                  target_lux: float = 150.0, target_fraction: float = 0.4) -> Scene:
    """A dark central target (``target_fraction`` of each side) before a bright background.

    The seed's failure case for mean metering (§4): background and target differ strongly
    (here 20×, the target covering 16 % of the frame).
    """
    from viform.light.scenes import StillScene

    lux = np.full((height, width), float(background_lux))
    lux[target_mask(height, width, target_fraction)] = target_lux
    return StillScene(lux)


def spot_scene(height: int = 90, width: int = 160, background_lux: float = 150.0,
               spot_lux: float = 5_000.0, spot_px: int = 16) -> Scene:
    """A small bright square (``spot_px`` wide) on a dim background: mean metering saturates it."""
    from viform.light.scenes import StillScene

    lux = np.full((height, width), float(background_lux))
    r0, c0 = (height - spot_px) // 2, (width - spot_px) // 2
    lux[r0:r0 + spot_px, c0:c0 + spot_px] = spot_lux
    return StillScene(lux)


def target_mask(height: int, width: int, target_fraction: float = 0.4) -> np.ndarray:
    """The central target region of :func:`backlit_scene`."""
    m = np.zeros((height, width), dtype=bool)
    h0, w0 = int(height * (1 - target_fraction) / 2), int(width * (1 - target_fraction) / 2)
    m[h0:height - h0, w0:width - w0] = True
    return m


def metering_demo(render_shape=(90, 160), n_frames: int = 30, seed: int = 0) -> dict:
    """Mean versus weighted metering on :func:`backlit_scene`, mean versus percentile on
    :func:`spot_scene` (seed 002 §4-§5: mean-gray feedback fails when target and background
    differ strongly). Returns the target's gray and saturated fraction after settling."""
    h, w = render_shape
    out = {}
    cases = (("backlit", backlit_scene(h, w), target_mask(h, w), (("mean", 128.0),
                                                                  ("weighted", 128.0))),
             ("spot", spot_scene(h, w), None, (("mean", 128.0), ("percentile", 200.0))))
    for name, scene, mask, meters in cases:
        if mask is None:
            mask = scene.illuminance_lux(0.0) > scene.illuminance_lux(0.0).min()
        for meter, target in meters:
            r = run_highspeed(scene, HighSpeedConfig(n_frames=n_frames, meter=meter,
                                                     target_gray=target, equalize=False,
                                                     seed=seed))
            g = r.gray8[-1]
            out[f"{name}/{meter}"] = {
                "target_gray_setting": target, "exposure_s": float(r.exposure_s[-1]),
                "metered_gray": float(r.metered_gray[-1]),
                "target_mean_gray": float(g[mask].mean()),
                "target_saturated_fraction": float((g[mask] >= 255).mean()),
                "background_mean_gray": float(g[~mask].mean())}
    return out


def ae_settling(result: HighSpeedResult, step_times_s, target_gray: float,
                band_gray: float) -> list:
    """Per step: frames from the first frame the step touches until the meter stays in band."""
    out = []
    for t in step_times_s:
        first = int(np.searchsorted(result.frame_times_s, t, side="right"))
        if first >= len(result.frame_times_s):
            continue
        nxt = [s for s in step_times_s if s > t]
        stop = (int(np.searchsorted(result.frame_times_s, nxt[0], side="right")) if nxt
                else len(result.frame_times_s))
        frames = settle_frames(result.metered_gray[:stop], target_gray, band_gray, first)
        period = result.timing["frame_period_s"]
        out.append({"step_time_s": float(t), "first_frame": first, "settle_frames": frames,
                    "settle_s": None if frames is None else frames * period})
    return out


def photo_scene(height: int = 90, width: int = 160, mean_lux: float = 200.0) -> Scene:
    """A photograph (scikit-image's bundled ``camera``, 512 × 512) cropped to the aspect
    ratio, resized to ``height`` × ``width`` and scaled to ``mean_lux`` on the sensor."""
    from skimage.data import camera
    from skimage.transform import resize

    from viform.light.scenes import StillScene

    img = camera().astype(np.float64)
    rows = int(round(img.shape[1] * height / width))
    r0 = max(0, (img.shape[0] - rows) // 2)
    img = resize(img[r0:r0 + rows], (height, width), anti_aliasing=True)
    img = np.maximum(img, 1.0)  # keep every pixel lit (the photograph has true blacks)
    return StillScene(img * (check_positive("mean_lux", mean_lux) / img.mean()))


def before_after(render_shape=(90, 160), n_frames: int = 40, seed: int = 0,
                 bright_lux: float = 3_000.0, dark_lux: float = 40.0,
                 exposure_s: float = 500e-6, dark_exposure_s: float = 100e-6) -> dict:
    """Seed 002 Fig. 9 as a model run: auto-exposure off/on on an over-exposed scene and
    histogram equalization off/on on a dark one.

    Over-exposed: the photograph at ``bright_lux`` with ``exposure_s`` (AE off saturates it;
    AE on brings the mean gray into 128 ± 15). Dark: the photograph at ``dark_lux`` with a
    fixed ``dark_exposure_s`` (AE off, so the frame stays dark), shown without and with the
    seed's same-frame equalization (eq. (3) by shifts, (E1)).

    Returns the four last frames (uint8) and, for each, its mean gray, the fraction of
    saturated (255) pixels and the number of distinct gray levels in use.
    """
    h, w = render_shape
    bright, dark = photo_scene(h, w, bright_lux), photo_scene(h, w, dark_lux)
    runs = {
        "AE off": run_highspeed(bright, HighSpeedConfig(n_frames=n_frames, ae=False, equalize=False,
                                                        exposure_s=exposure_s, seed=seed)),
        "AE on": run_highspeed(bright, HighSpeedConfig(n_frames=n_frames, ae=True, equalize=False,
                                                       exposure_s=exposure_s, seed=seed)),
        "equalization off": run_highspeed(dark, HighSpeedConfig(n_frames=1, ae=False, equalize=False,
                                                                exposure_s=dark_exposure_s, seed=seed)),
    }
    runs["equalization on"] = runs["equalization off"]
    out = {}
    for name, r in runs.items():
        frame = r.gray8[-1]
        if name == "equalization on":
            frame = StreamEqualizer("same")(frame)  # what the link sends (seed eq. (3), (E1))
        out[name] = {"image": frame, "exposure_s": float(r.exposure_s[-1]),
                     "mean_gray": float(frame.mean()),
                     "saturated_fraction": float((frame >= 255).mean()),
                     "gray_levels_used": int(np.unique(frame).size),
                     "gray_p1_p99": [float(v) for v in np.percentile(frame, [1, 99])]}
    return out


def plot_before_after(path, panels: dict) -> None:
    """2 × 2 figure of :func:`before_after` (one 0–255 gray scale for every panel)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform._io import save_figure

    fig, axes = plt.subplots(2, 2, figsize=(8.6, 5.6))
    for ax, (name, p) in zip(axes.ravel(), panels.items(), strict=True):
        im = ax.imshow(p["image"], cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        ax.set_title(f"{name}: exposure {p['exposure_s'] * 1e6:.0f} µs\nmean gray {p['mean_gray']:.0f}, "
                     f"{100 * p['saturated_fraction']:.0f} % at 255, {p['gray_levels_used']} levels",
                     fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])  # keep the frame: a saturated panel is white, not missing
    fig.suptitle("Over-exposed scene without/with auto-exposure (top); "
                 "dark scene without/with equalization (bottom)", fontsize=10)
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="output gray level (0–255)")
    save_figure(path, fig)


def equalizer_step_flash(source: str, levels=(60.0, 600.0), shape=(36, 64), seed: int = 0) -> list:
    """Mean output gray of three frames around a 10× light step, equalized with ``source``
    ("same" or "previous"): frame 0 before the step, frames 1 and 2 after it."""
    h, w = shape
    scene = photo_scene(h, w, 1.0)
    base = scene.illuminance_lux(0.0)
    eq = StreamEqualizer(source)
    pixels = FrameSensor(lux13hs_pixel_parameters(), exposure_s=1e-4, frame_rate_hz=1e3).pixel_array(h, w)
    out = []
    for k, lux in enumerate((levels[0], levels[1], levels[1])):
        rng = pixels.rng(seed, k)
        dn = pixels.digitize(pixels.collect_electrons(base * lux, 100e-6, rng), rng)
        out.append(float(eq(to_gray8(dn, 10)).mean()))
    return out


# ----------------------------------------------------------------------------- outputs

def exposure_figure(result, step_times_s=()):
    """Exposure and gray level of every sensor frame, with the light steps; legends beside the plots."""
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10.5, 5.5), sharex=True)
    # legends go right of the plots: inside they covered the trace after a light step
    fig.subplots_adjust(left=0.08, right=0.68, top=0.92, bottom=0.1)
    k = np.arange(len(result.exposure_s))
    ax1.plot(k, result.exposure_s * 1e6, drawstyle="steps-post", color="C0", label="exposure")
    longest_s = result.timing.get("max_exposure_s")
    if longest_s:
        # auto-exposure cannot lengthen the exposure past the frame time: say so, or a flat line
        # after the light drops reads as a controller that gave up
        ax1.axhline(longest_s * 1e6, color="0.4", ls="--", lw=1,
                    label=f"longest possible: the frame time ({longest_s * 1e6:.0f} µs)")
        ax1.set_ylim(0, longest_s * 1e6 * 1.15)
        ax1.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0)
    ax1.set_ylabel("exposure (µs)")
    ax1.set_title(f"{result.timing['frame_rate_hz']:.1f} fps, meter={result.config['meter']}, "
                  f"AE {'on' if result.config['ae'] else 'off'}")
    cfg = result.config
    ax2.axhspan(cfg["target_gray"] - cfg["band_gray"], cfg["target_gray"] + cfg["band_gray"],
                color="C2", alpha=0.2, label="dead band")
    ax2.plot(k, result.mean_gray, color="C1", label="mean gray")
    if cfg["meter"] != "mean":
        ax2.plot(k, result.metered_gray, color="C3", label=f"{cfg['meter']} meter")
    sent = result.transmitted_indices
    ax2.plot(sent, result.mean_gray[sent], "k.", ms=3, label="transmitted")
    first_step = True
    for t in step_times_s:
        if t > result.frame_times_s[-1]:
            continue  # after the recording
        idx = np.searchsorted(result.frame_times_s, t)
        for ax in (ax1, ax2):
            ax.axvline(idx, color="0.5", ls=":", label="light step" if (first_step and ax is ax2) else None)
        first_step = False
    ax2.set_ylim(0, 260)
    ax2.set_xlabel("sensor frame")
    ax2.set_ylabel("gray (0–255)")
    ax2.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0)
    return fig


def write_outputs(result: HighSpeedResult, out_dir, video_format: str = "gif", step_times_s=(),
                  playback_fps: float = 25.0) -> dict:
    """Write ``video.<fmt>``, ``exposure.png`` and ``report.json`` atomically; return the report."""
    from pathlib import Path

    import imageio.v3 as iio
    import matplotlib

    matplotlib.use("Agg")

    from viform._io import atomic_path, save_figure, write_json

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    video = out / f"video.{video_format}"
    frames = result.output_frames if len(result.output_frames) else result.gray8[:1]
    with atomic_path(video) as tmp:
        if video_format == "gif":
            iio.imwrite(tmp, frames, extension=".gif", duration=1000.0 / playback_fps, loop=0)
        else:
            iio.imwrite(tmp, frames, extension=".mp4", fps=playback_fps, macro_block_size=1)

    fig = exposure_figure(result, step_times_s)
    cfg = result.config
    save_figure(out / "exposure.png", fig)

    report = {
        "frames_captured": result.account["frames_captured"],
        "frames_buffered_at_end": result.account["frames_buffered_at_end"],
        "frames_transmitted": result.account["frames_transmitted"],
        "frames_dropped": result.account["frames_dropped"],
        "selected_but_overwritten": result.account["selected_but_overwritten"],
        # Not sent in real time but still in the DDR ring: can be read out after the recording.
        "frames_only_in_buffer": (result.account["frames_captured"] - result.account["frames_transmitted"]
                                  - result.account["frames_dropped"]),
        "fraction_sent_in_real_time": result.account["frames_transmitted"] / result.account["frames_captured"],
        "sensor_frame_rate_hz": result.timing["frame_rate_hz"],
        "link": {k: v for k, v in result.plan.items() if k != "link"},
        "timing": result.timing,
        "ae_settling": ae_settling(result, step_times_s, cfg["target_gray"], cfg["band_gray"]),
        "equalizer": result.equalizer,
        "config": result.config,
        "files": {"video": video.name, "plot": "exposure.png", "report": "report.json"},
    }
    write_json(out / "report.json", report)
    return report


# ----------------------------------------------------------------------------- figures

def shutter_figures(timing, roi, pixel: FramePixelParameters | None = None,
                    exposures_s=(1e-6, 10e-6, 100e-6, 590e-6)) -> dict:
    """What the global shutter's 99 % efficiency costs (seed 002 Table 1), predicted from the pixel
    and the readout timing.

    After the frame transfer row r of H waits w_r = (r + 1)/H · T_read in its storage node (T_read
    the window's readout, data cycles / clock), where PLS = 1 − efficiency of the photo-rate still
    reaches it. For still light that is an extra exposure of PLS·w_r: on average PLS·T_read·(H + 1)/(2H)
    (``parasitic_exposure_equivalent_s``), so a frame of exposure t carries the parasitic share
    PLS·w̄/(t + PLS·w̄); and the brightest light the last row holds below its full well at the shortest
    exposure (one clock) falls from FW/(η·Φ·T_H) to FW/(η·Φ·(T_H + PLS·T_read)).
    """
    p = pixel or lux13hs_pixel_parameters()
    w = timing.window(roi)
    read = timing.readout_time_s(w)
    pls = p.parasitic_light_sensitivity
    mean_wait = read * (w.height + 1) / (2 * w.height)
    equivalent = pls * mean_wait
    per_lux_s = p.optics.electrons_per_lux_second  # e⁻ per lux·s of the pixel
    shortest = timing.clock_period_s
    return {"shutter_efficiency": 1.0 - pls, "parasitic_light_sensitivity": pls, "readout_time_s": read,
            "mean_wait_s": mean_wait, "parasitic_exposure_equivalent_s": equivalent,
            "parasitic_share_at_exposure": {f"{t:g}": equivalent / (t + equivalent) for t in exposures_s},
            "brightest_lux_shortest_exposure": {
                "without_parasitic_light": p.full_well_electrons / (per_lux_s * shortest),
                "with_parasitic_light": p.full_well_electrons / (per_lux_s * (shortest + pls * read))},
            "seed": "99 % shutter efficiency (Table 1); readout 57 600 cycles at 100 MHz (§3.1.1)"}


def simulated_parasitic_share(exposure_s: float, lux: float = 200.0, shape=(36, 64), seed: int = 0) -> float:
    """The parasitic share measured on the simulated camera: one frame of still uniform light at
    ``exposure_s``, with and without the shutter's parasitic light, mean electrons (DN above black
    / gain) − 1 over the with-light mean, the same noise seeds."""
    from viform.light.scenes import StillScene

    scene = StillScene(np.full(shape, float(lux)))
    means = []
    for pls in (0.0, lux13hs_pixel_parameters().parasitic_light_sensitivity):
        px = lux13hs_pixel_parameters(parasitic_light_sensitivity=pls, read_noise_electrons=0.0, dsnu_electrons=0.0,
                                      dark_current_e_per_s=0.0, prnu_fraction=0.0, adc_bits=16,
                                      adc_range_v=30_000.0 * 40e-6)
        cam = HighSpeedCamera(px, ae=False, exposure_s=exposure_s)
        pixels = FrameSensor(cam.parameters, exposure_s=exposure_s, frame_rate_hz=cam.frame_rate_hz).pixel_array(
            *shape)
        rng = pixels.rng(seed, 0)
        e = pixels.collect_electrons(scene.mean_illuminance_lux(0.0, exposure_s), exposure_s, rng)
        e = e + pixels.storage_electrons(scene, exposure_s, rng)
        means.append(float(e.mean()))
    return 1.0 - means[0] / means[1]


def seed_figures(include_simulation: bool = True) -> dict:
    """The seed-002 numbers next to this model's (``viform highspeed-figures``)."""
    from viform.isp.histogram import shift_error
    from viform.isp.link import INTERFACES, DDRBuffer
    from viform.light.scenes import TranslatingScene
    from viform.sensors.highspeed_timing import SEED_ROI

    red = lux13hs_timing("reduced")
    nor = lux13hs_timing("normal")
    red166 = lux13hs_timing("reduced", 166e6)
    f2500 = red.clock_for_frame_rate_hz(2500.0)
    red2500 = lux13hs_timing("reduced", f2500)
    rate = red.frame_rate_hz(SEED_ROI)
    plan = link_plan(rate, 720, 1280, "cameralink")
    eq = shift_error(1280 * 720)
    fig = {
        "reduced_1280x720_100MHz": {"cycles_per_frame": red.cycles_per_frame(SEED_ROI),
                                    "data_cycles": red.data_cycles(SEED_ROI), "fps": rate,
                                    "seed": "57 600 data + overhead = 60 000 cycles, 1 666 fps"},
        "normal_full_1280x864_133MHz": {"fps": nor.frame_rate_hz(), "seed": "3 500 fps at full frame"},
        "reduced_166MHz": {"fps_1280x720": red166.frame_rate_hz(SEED_ROI),
                           "fps_1280x864": red166.frame_rate_hz(), "seed": "reduced mode up to 2 500 fps"},
        "reduced_2500fps_full_frame": {"pixel_clock_hz": f2500, "core_clock_hz": red2500.core_clock_hz,
                                       "core_limit_hz": red2500.max_clock_hz,
                                       "fps_1280x864": red2500.frame_rate_hz(),
                                       "seed": "2 500 fps: the halved core clock is not bound by the "
                                               "maximum clock"},
        "links_fps_1280x720x8": {k: v.max_frame_rate_hz(720, 1280, 8) for k, v in INTERFACES.items()},
        "cameralink_seed": "555 fps",
        "ddr": {"capacity_frames": DDRBuffer().capacity_frames(720, 1280, 8),
                "record_s_at_sensor_rate": plan["buffer_record_s"], "seed": "2 330 frames"},
        "decimation": {"strict": plan["decimation_strict"], "with_ring_1h": plan["decimation_with_buffer"],
                       "time_to_first_overrun_s_at_3to1": plan["time_to_first_overrun_s"], "seed": "3:1"},
        "equalization_shift": {**eq, "seed": "<<8, >>20 (net >>12); error 0.00003*c; + >>15; "
                                             "compensated error 'close to 0'"},
    }
    # every published figure's status: predicted from the paper's parameters, or
    # fitted to the figure (the 2,500 fps clock is back-solved from it)
    fig["status"] = {"reduced_1280x720_100MHz": "predicted", "normal_full_1280x864_133MHz": "predicted",
                     "reduced_166MHz": "predicted",
                     "reduced_2500fps_full_frame": "fitted: the pixel clock is solved from the 2,500 fps figure",
                     "cameralink_seed": "predicted", "ddr": "predicted", "decimation": "predicted",
                     "equalization_shift": "predicted"}
    fig["shutter"] = shutter_figures(red, SEED_ROI)
    fig["status"]["shutter"] = "input: the seed's 99 % shutter efficiency (Table 1) and its readout timing"
    fig["status"]["shutter_consequences"] = ("predicted: the parasitic share of a frame and the brightest light "
                                             "(no published number)")
    if include_simulation:
        fig["shutter"]["simulated_parasitic_share_at_10us"] = simulated_parasitic_share(10e-6)
        fig["status"]["ae_10x_steps_latency1"] = ("predicted (the seed shows the loop only in images; the "
                                                  "exposure includes the shutter's parasitic light)")
        base = TranslatingScene(36, 64, velocity_px_per_s=(0.0, 0.0), min_lux=50.0, max_lux=400.0)
        scene = StepsScene(base, [(0.02, 10.0), (0.05, 0.1)])
        r = run_highspeed(scene, HighSpeedConfig(n_frames=130, exposure_s=200e-6, equalize=False))
        fig["ae_10x_steps_latency1"] = ae_settling(r, [0.02, 0.05], 128.0, 15.0)
        fig["metering_demo"] = metering_demo()
    return fig
