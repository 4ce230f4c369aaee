"""Scenes: illuminance on the sensor plane (lux) per pixel, as a function of time (seconds).

Every sensor model in viform captures a :class:`Scene`, so one scene can be shot by every
sensor and the results compared on the same light. A scene answers two questions:

* :meth:`Scene.illuminance_lux` — the light at an instant t (the analytic ground truth
  for the synthetic scenes), shape ``(height, width)``;
* :meth:`Scene.mean_illuminance_lux` — the mean light over a window [t0, t1], what an
  exposure integrates (exact for the step and flicker scenes, a midpoint rule otherwise).

Illuminance is on the *sensor plane* (after the lens). Mapping from stored pixel values to
lux is explicit: integer images map linearly from 0 to ``max_lux`` at full scale; float
images are taken as lux already (``max_lux=None``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import replace
from pathlib import Path

import numpy as np

from viform._validate import (
    ViformError,
    check_choice,
    check_int,
    check_non_negative,
    check_positive,
    one_line,
)
from viform.light.radiometry import check_lux
from viform.light.truth import (
    FlowTruth,
    ObjectTruth,
    TruthUnavailable,
    flow_from_layers,
    rotate_about,
    static_motion,
    translate_by,
)

#: Pixels of the frames :meth:`Scene.mean_illuminance_lux` asks for at once (scenes that draw many instants at once).
MEAN_BATCH_PIXELS = 1 << 22


def _midpoints(t0_s, t1_s, samples: int) -> np.ndarray:
    """The midpoint rule's ``samples`` instants of [t0_s, t1_s], (samples,) — or (samples, N) for N windows."""
    t0, t1 = np.asarray(t0_s), np.asarray(t1_s)
    k = (np.arange(samples) + 0.5).reshape((samples,) + (1,) * t0.ndim)
    return t0 + k * (t1 - t0) / samples


class Scene(ABC):
    """Light per pixel over time.

    Subclasses implement :meth:`illuminance_lux`; the rest has generic defaults.
    """

    #: Name shown in reports.
    name: str = "scene"

    def __init__(self, height: int, width: int, duration_s: float | None = None):
        self.height = check_int("height", height, 1)
        self.width = check_int("width", width, 1)
        self.duration_s = None if duration_s is None else check_positive("duration_s", duration_s)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @abstractmethod
    def illuminance_lux(self, t_s: float) -> np.ndarray:
        """Illuminance (lux) of every pixel at instant ``t_s`` (seconds), shape (H, W), float64."""

    def illuminance_lux_many(self, times_s) -> np.ndarray:
        """Illuminance at several instants, shape (N, H, W)."""
        times_s = np.asarray(times_s, dtype=np.float64).ravel()
        out = np.empty((times_s.size, self.height, self.width), dtype=np.float64)
        for i, t in enumerate(times_s):
            out[i] = self.illuminance_lux(float(t))
        return out

    def mean_illuminance_lux(self, t0_s: float, t1_s: float, samples: int = 32) -> np.ndarray:
        """Mean illuminance over [t0_s, t1_s] (lux), by the midpoint rule with ``samples`` points.

        Subclasses with an analytic integral override this. A scene whose own
        :meth:`illuminance_lux_many` draws several instants at once (a described scene's renderer)
        is asked for them in batches of :data:`MEAN_BATCH_PIXELS` (32 MiB of frames); the sum runs in the
        same order.
        """
        if not t1_s >= t0_s:
            raise ViformError(f"window end t1_s={t1_s!r} must be ≥ start t0_s={t0_s!r}")
        if t1_s == t0_s:
            return self.illuminance_lux(t0_s)
        samples = check_int("samples", samples, 1)
        times = _midpoints(t0_s, t1_s, samples)
        acc = np.zeros(self.shape)
        if self._draws_many_at_once():
            batch = max(1, MEAN_BATCH_PIXELS // (self.height * self.width))
            for i in range(0, samples, batch):
                for frame in self.illuminance_lux_many(times[i:i + batch]):
                    acc += frame
        else:
            for t in times:
                acc += self.illuminance_lux(float(t))
        return acc / samples

    def _draws_many_at_once(self) -> bool:
        """Whether :meth:`illuminance_lux_many` is the scene's own, beside its :meth:`illuminance_lux` (so the
        same light), rather than the default loop over instants."""
        mro = type(self).__mro__
        many = next(c for c in mro if "illuminance_lux_many" in c.__dict__)
        return many is next(c for c in mro if "illuminance_lux" in c.__dict__) and not self._light_patched()

    def rolling_mean_illuminance_lux(self, t0_s: float, exposure_s: float, row_offset_s: float) -> np.ndarray:
        """Mean light of each row over its own window, as a rolling shutter exposes it (lux, (H, W)):
        row r over [t0_s + r·row_offset_s, t0_s + r·row_offset_s + exposure_s].

        Row r of :meth:`mean_illuminance_lux` over that window. With the default midpoint rule each
        sample is drawn for every row at once, each row at its own instant
        (:meth:`illuminance_lux_row_times`); scenes with their own mean (or a faster way to draw a
        row's window) give the rows one by one, or override this with the same values.
        """
        if type(self).mean_illuminance_lux is not Scene.mean_illuminance_lux or "mean_illuminance_lux" in vars(self):
            out = np.empty(self.shape)  # (row by row: one frame held at a time)
            for r in range(self.height):
                start = t0_s + r * row_offset_s
                out[r] = self.mean_illuminance_lux(start, start + exposure_s)[r]
            return out
        # the midpoint rule of mean_illuminance_lux, row by row: the same instants, sums and order
        samples = 32
        start = t0_s + np.arange(self.height) * row_offset_s
        end = start + exposure_s
        bad = np.flatnonzero(~(end >= start))
        if bad.size:
            r = int(bad[0])
            raise ViformError(f"window end t1_s={float(end[r])!r} must be ≥ start t0_s={float(start[r])!r}")
        still = end == start  # a window of no length: the light at its instant
        if still.all():
            return self.illuminance_lux_row_times(start)
        acc = np.zeros(self.shape)
        for times in _midpoints(start, end, samples):  # (samples, H): each row's instants, as mean_illuminance_lux's
            acc += self.illuminance_lux_row_times(times)
        out = acc / samples
        if still.any():
            out[still] = self.illuminance_lux_row_times(start)[still]
        return out

    def illuminance_lux_row_times(self, times_s) -> np.ndarray:
        """The light with each row at its own instant (lux, (H, W)): row r of
        :meth:`illuminance_lux` at ``times_s[r]``.

        The default draws a frame per distinct instant; scenes whose light is a function of the
        pixel and the instant (the pattern and described scenes) draw every row at once, with the
        same values.
        """
        out = np.empty(self.shape)
        distinct, which = np.unique(self._row_times(times_s), return_inverse=True)
        for k, t in enumerate(distinct):
            rows = which == k
            out[rows] = self.illuminance_lux(float(t))[rows]
        return out

    def _row_times(self, times_s) -> np.ndarray:
        """``times_s`` as one instant per row, (H,) float64 (for :meth:`illuminance_lux_row_times`)."""
        times = np.asarray(times_s, dtype=np.float64).ravel()
        if times.size != self.height:
            raise ViformError(f"times_s has {times.size} instants; {self.height} are needed, one per row")
        return times

    def compiled_light(self):
        """A :class:`~viform.light.compiled.CompiledLight` the simulator evaluates in compiled
        code, or None (the default: the simulator calls :meth:`illuminance_lux_many`).

        Scenes that implement it return None when a subclass overrides their light.
        """
        return None

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """Ticks per light sample the simulator uses when asked for "auto": 1 (the light of every tick
        at its middle). Scenes whose light is sampled (described scenes) choose from their motion."""
        return 1

    def _own_light(self, cls) -> bool:
        """True when ``illuminance_lux`` is ``cls``'s own (a subclass, or a patch on this scene, may have
        changed the light)."""
        return type(self).illuminance_lux is cls.illuminance_lux and \
            type(self).illuminance_lux_many is Scene.illuminance_lux_many and not self._light_patched()

    def _light_patched(self) -> bool:
        """True when this scene's light functions were replaced on the scene itself (not its class)."""
        return "illuminance_lux" in vars(self) or "illuminance_lux_many" in vars(self)

    def describe(self) -> dict:
        """Metadata saved with captures (with ``builtin``: how to remake a built-in scene, see
        :func:`viform.light.catalog.scene_from_description`)."""
        d = {"name": self.name, "height": self.height, "width": self.width, "duration_s": self.duration_s}
        spec = getattr(self, "builtin_spec", None)
        if spec is not None:
            d["builtin"] = spec
        return d

    # ------------------------------------------------------------------ ground truth
    # Conventions (coordinates, flow direction, boxes): viform.light.truth. Scenes that know
    # their geometry override these; the defaults say that this scene has no such truth.

    def truth_kinds(self) -> tuple[str, ...]:
        """Which truths this scene gives: a subset of ``("motion", "depth", "objects")``."""
        return ()

    def _no_truth(self, kind: str):
        raise TruthUnavailable(
            f"scene {self.name!r} has no {kind} truth: "
            + ("image and video files carry only light, no motion, depth or objects"
               if isinstance(self, (StillScene, VideoScene)) and not self.truth_kinds()
               else f"it gives {', '.join(self.truth_kinds()) or 'none'}"))

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        """Image-plane velocity of every pixel at ``t_s``: shape (2, H, W), (vx, vy) in px/s, NaN where undefined."""
        self._no_truth("motion")

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        """Forward optical flow from ``t0_s`` to ``t1_s`` (px) with its validity mask."""
        self._no_truth("motion")

    def depth_m(self, t_s: float) -> np.ndarray:
        """Distance (m) from the camera of the surface seen at every pixel at ``t_s``, shape (H, W)."""
        self._no_truth("depth")

    def objects(self, t_s: float) -> list[ObjectTruth]:
        """The labelled objects at ``t_s`` (ids stable over time); [] when none is in the field."""
        self._no_truth("objects")

    def object_labels(self, t_s: float) -> np.ndarray:
        """Visible object id per pixel at ``t_s`` (int32, 0 = background), shape (H, W)."""
        self._no_truth("objects")


class StaticTruth:
    """Truth of a synthetic scene that does not move: zero motion everywhere, no objects, no range."""

    def truth_kinds(self) -> tuple[str, ...]:
        return ("motion", "objects")

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        return static_motion(self.shape)

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        return FlowTruth(np.zeros((2, *self.shape)), np.ones(self.shape, bool), float(t0_s), float(t1_s))

    def objects(self, t_s: float) -> list[ObjectTruth]:
        return []

    def object_labels(self, t_s: float) -> np.ndarray:
        return np.zeros(self.shape, np.int32)


# --------------------------------------------------------------------------- images

def image_to_lux(image, max_lux: float | None) -> np.ndarray:
    """Map stored pixel values to lux, explicitly.

    Integer images (uint8, uint16, …) map linearly: 0 → 0 lux, the dtype's full scale →
    ``max_lux``. Float images (TIFF, EXR, NumPy) are lux already: ``max_lux`` does not
    apply to them. Colour images are reduced to luminance with the Rec. 709 weights.

    Parameters
    ----------
    image : array_like (H, W) or (H, W, 3)
        Stored pixel values: integers of any width, or floats already in lux.
    max_lux : float or None
        Illuminance, lux, of an integer image's full scale; needed for integer images, ignored
        for float ones.

    Returns
    -------
    ndarray of float64 (H, W)
        Illuminance per pixel, lux.
    """
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[-1] in (3, 4):
        weights = np.array([0.2126, 0.7152, 0.0722])
        rgb = arr[..., :3]
        dtype = arr.dtype
        arr = (rgb.astype(np.float64) @ weights)
        if np.issubdtype(dtype, np.integer):
            arr = arr / np.iinfo(dtype).max
            if max_lux is None:
                raise ViformError("max_lux is required for integer images: give the lux of full scale")
            return check_lux(arr * check_positive("max_lux", max_lux), "image")
    if arr.ndim != 2:
        raise ViformError(f"image must be 2-D (H, W) or colour (H, W, 3|4); got shape {arr.shape}")
    if np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool:
        if max_lux is None:
            raise ViformError("max_lux is required for integer images: give the lux of full scale")
        full = 1 if arr.dtype == bool else np.iinfo(arr.dtype).max
        return check_lux(arr.astype(np.float64) / full * check_positive("max_lux", max_lux), "image")
    return check_lux(arr.astype(np.float64), "image")


def _resize(image: np.ndarray, shape: tuple[int, int] | None) -> np.ndarray:
    if shape is None or tuple(shape) == image.shape:
        return image
    from skimage.transform import resize

    return resize(image, shape, order=1, anti_aliasing=True, preserve_range=True)


class StillScene(Scene):
    """A still image; the light does not change with time."""

    name = "still"

    def __init__(self, lux_image, duration_s: float | None = None):
        lux_image = check_lux(lux_image, "lux_image")
        if lux_image.ndim != 2:
            raise ViformError(f"lux_image must be 2-D (H, W); got shape {lux_image.shape}")
        super().__init__(*lux_image.shape, duration_s=duration_s)
        self._lux = np.ascontiguousarray(lux_image, dtype=np.float64)

    @classmethod
    def from_file(cls, path, max_lux: float | None = 1000.0, shape=None, **kw) -> StillScene:
        """Load an image file (anything imageio reads); pixel values map to lux by :func:`image_to_lux`."""
        import imageio.v3 as iio

        try:
            image = iio.imread(path)
        except Exception as exc:  # imageio raises many types
            raise ViformError(f"image file {str(path)!r} could not be read: {one_line(exc)}") from None
        return cls(_resize(image_to_lux(image, max_lux), shape), **kw)

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        return self._lux

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        return self._lux

    def compiled_light(self):
        if not self._own_light(StillScene):
            return None
        from viform.light.compiled import CompiledLight

        return CompiledLight("frames", self.height, self.width, frames=self._lux[None],
                             frame_index=lambda times: np.zeros(np.shape(times), np.int64))


class VideoScene(Scene):
    """An image sequence at a declared frame rate.

    Frame k is the light at instant k / frame_rate_hz. Between frames the light is held
    (``interpolation="hold"``: frame k stands for [k/f, (k+1)/f)) or interpolated linearly
    (``"linear"``). Past the last frame the last frame is held.
    """

    name = "video"

    def __init__(self, lux_frames, frame_rate_hz: float, interpolation: str = "linear"):
        frames = check_lux(lux_frames, "lux_frames")
        if frames.ndim != 3 or frames.shape[0] < 1:
            raise ViformError(f"lux_frames must have shape (N, H, W) with N ≥ 1; got {frames.shape}")
        self.frame_rate_hz = check_positive("frame_rate_hz", frame_rate_hz)
        self.interpolation = check_choice("interpolation", interpolation, ("hold", "linear"))
        super().__init__(frames.shape[1], frames.shape[2], duration_s=frames.shape[0] / self.frame_rate_hz)
        self._frames = frames

    @classmethod
    def from_file(cls, path, frame_rate_hz: float | None = None, max_lux: float = 1000.0,
                  interpolation: str = "linear", shape=None, max_frames: int | None = None) -> VideoScene:
        """Load a video file or a folder of images (sorted by name).

        ``frame_rate_hz`` defaults to the file's own rate when it declares one.
        """
        import imageio.v3 as iio

        path = Path(path)
        frames = []
        declared = None
        try:
            if path.is_dir():
                files = sorted(p for p in path.iterdir() if p.suffix.lower() in
                               (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"))
                if not files:
                    raise ViformError(f"image folder {str(path)!r} holds no images")
                for f in files[:max_frames]:
                    frames.append(_resize(image_to_lux(iio.imread(f), max_lux), shape))
            else:
                try:
                    declared = iio.immeta(path).get("fps")
                except Exception:
                    declared = None
                for i, frame in enumerate(iio.imiter(path)):
                    if max_frames is not None and i >= max_frames:
                        break
                    frames.append(_resize(image_to_lux(frame, max_lux), shape))
        except ViformError:
            raise
        except Exception as exc:
            raise ViformError(f"video {str(path)!r} could not be read: {one_line(exc)}") from None
        if not frames:
            raise ViformError(f"video {str(path)!r} holds no frames")
        if declared is not None and not (isinstance(declared, (int, float)) and 0 < declared < 1e7):
            declared = None  # some files declare 0 or garbage: treat as not declared
        rate = frame_rate_hz if frame_rate_hz is not None else declared
        if rate is None:
            # the command line turns frame_rate_hz into its flag (--frame-rate-hz, highspeed's --scene-fps)
            raise ViformError(f"{str(path)!r} declares no usable frame rate: give it with frame_rate_hz")
        return cls(np.stack(frames), rate, interpolation)

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        position = max(0.0, t_s * self.frame_rate_hz)
        last = self._frames.shape[0] - 1
        k = min(int(math.floor(position)), last)
        if self.interpolation == "hold" or k == last:
            return self._frames[k]
        w = position - k
        return (1 - w) * self._frames[k] + w * self._frames[k + 1]

    def _frame_index(self, times) -> np.ndarray:
        # the frame illuminance_lux holds at each instant (same arithmetic, elementwise)
        position = np.maximum(0.0, np.asarray(times, dtype=np.float64) * self.frame_rate_hz)
        return np.minimum(np.floor(position), self._frames.shape[0] - 1).astype(np.int64)

    def compiled_light(self):
        if not self._own_light(VideoScene):
            return None
        from viform.light.compiled import CompiledLight

        if self.interpolation == "hold" or self._frames.shape[0] == 1:
            return CompiledLight("frames", self.height, self.width, frames=self._frames,
                                 frame_index=self._frame_index)
        return CompiledLight("video-linear", self.height, self.width, frames=self._frames,
                             frame_rate_hz=self.frame_rate_hz)


# ----------------------------------------------------------------- synthetic scenes

def texture(x, y, period_px: float = 48.0) -> np.ndarray:
    """An analytic test texture in [0, 1] defined on the whole plane.

    A checkerboard with sharp edges (period ``period_px``) mixed with two oblique
    gratings, so both edges and smooth gradients move with the pattern.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    checker = ((np.floor(x / period_px) + np.floor(y / period_px)) % 2.0)
    g1 = 0.5 + 0.5 * np.sin(2 * np.pi * (0.8 * x + 0.6 * y) / (0.7 * period_px))
    g2 = 0.5 + 0.5 * np.cos(2 * np.pi * (-0.5 * x + 0.87 * y) / (1.9 * period_px))
    return 0.55 * checker + 0.25 * g1 + 0.20 * g2


def edge(x, y, period_px: float = 48.0) -> np.ndarray:
    """A single vertical step edge at x = 0 (bright for x ≥ 0), in [0, 1]."""
    return (np.asarray(x, dtype=np.float64) >= 0).astype(np.float64) + 0 * np.asarray(y)


def bars(x, y, period_px: float = 48.0) -> np.ndarray:
    """Vertical square-wave bars of period ``period_px``, in [0, 1]."""
    return ((np.floor(np.asarray(x, dtype=np.float64) / (period_px / 2)) % 2.0)
            + 0 * np.asarray(y))


PATTERNS = {"texture": texture, "edge": edge, "bars": bars}


class _PatternScene(Scene):
    def __init__(self, height, width, pattern, min_lux, max_lux, period_px, duration_s):
        super().__init__(height, width, duration_s)
        self.pattern = check_choice("pattern", pattern, tuple(PATTERNS))
        self.min_lux = check_non_negative("min_lux", min_lux)
        self.max_lux = check_positive("max_lux", max_lux)
        if self.max_lux <= self.min_lux:
            raise ViformError(f"max_lux = {max_lux!r} must exceed min_lux = {min_lux!r}")
        self.period_px = check_positive("period_px", period_px)
        self._y, self._x = np.mgrid[0:height, 0:width].astype(np.float64)

    def _lux(self, u, v):
        value = PATTERNS[self.pattern](u, v, self.period_px)
        return self.min_lux + (self.max_lux - self.min_lux) * value

    @abstractmethod
    def _motion(self) -> tuple:
        """The pattern's motion for the compiled kernel; each moving subclass (translating, rotating) defines it."""

    def _pattern_light(self, modulation=("none",)):
        """The compiled form of this pattern scene (None when a subclass changed the light)."""
        cls = getattr(type(self), "_light_class", None)
        if cls is None or not self._own_light(cls):
            return None
        from viform.light.compiled import CompiledLight

        return CompiledLight("pattern", self.height, self.width, pattern=self.pattern, min_lux=self.min_lux,
                             max_lux=self.max_lux, period_px=self.period_px, motion=self._motion(),
                             modulation=modulation)

    def compiled_light(self):
        return self._pattern_light()

    @abstractmethod
    def max_speed_px_per_s(self) -> float:
        """The fastest image speed of the pattern anywhere in the field, px/s."""

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """The longest hold (ticks) that misplaces the pattern by at most
        :data:`~viform.light.sampled.LIGHT_ERROR_PX` anywhere in the field
        (:func:`~viform.light.sampled.auto_light_sample_ticks`); 1 when a subclass changed the light."""
        if self.compiled_light() is None:
            return 1
        from viform.light.sampled import auto_light_sample_ticks

        return auto_light_sample_ticks(self.max_speed_px_per_s(), clock_hz)

    # truth: the whole field is one rigid surface (no objects, no range)
    def truth_kinds(self) -> tuple[str, ...]:
        return ("motion", "objects")

    def objects(self, t_s: float) -> list[ObjectTruth]:
        return []

    def object_labels(self, t_s: float) -> np.ndarray:
        return np.zeros(self.shape, np.int32)

    def optical_flow_px(self, t0_s: float, t1_s: float) -> FlowTruth:
        # each moving subclass defines _field_move: where a surface point seen at t0 is at t1
        labels = np.zeros(self.shape, np.int32)
        return flow_from_layers(labels, labels, None, {0: self._field_move(t0_s, t1_s)}, {}, t0_s, t1_s)


class TranslatingScene(_PatternScene):
    """A pattern translating at a constant velocity (pixels per second).

    Ground truth at t: L(x, y, t) = P(x − x0 − vx·t, y − y0 − vy·t), pixel centres at
    integer coordinates. ``x0`` defaults to the image centre for the ``edge`` pattern.
    """

    name = "translating"
    _light_class = None  # set below: the class whose illuminance_lux the compiled form mirrors

    def __init__(self, height=250, width=400, velocity_px_per_s=(2000.0, 0.0), pattern="texture",
                 min_lux=0.2, max_lux=4.0, period_px=48.0, origin_px=None, duration_s=None):
        super().__init__(height, width, pattern, min_lux, max_lux, period_px, duration_s)
        vx, vy = velocity_px_per_s
        self.velocity_px_per_s = (float(vx), float(vy))
        if not all(math.isfinite(v) for v in self.velocity_px_per_s):
            raise ViformError(f"velocity_px_per_s = {velocity_px_per_s!r} must be finite")
        if origin_px is None:
            origin_px = (width / 2.0, height / 2.0) if pattern == "edge" else (0.0, 0.0)
        self.origin_px = (float(origin_px[0]), float(origin_px[1]))

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        vx, vy = self.velocity_px_per_s
        return self._lux(self._x - self.origin_px[0] - vx * t_s, self._y - self.origin_px[1] - vy * t_s)

    def illuminance_lux_row_times(self, times_s) -> np.ndarray:
        if not self._own_light(TranslatingScene):
            return super().illuminance_lux_row_times(times_s)
        t = self._row_times(times_s)[:, None]
        vx, vy = self.velocity_px_per_s  # (illuminance_lux's arithmetic, each row at its instant)
        return self._lux(self._x - self.origin_px[0] - vx * t, self._y - self.origin_px[1] - vy * t)

    def _motion(self) -> tuple:
        return ("translate", *self.origin_px, *self.velocity_px_per_s)

    def max_speed_px_per_s(self) -> float:
        return math.hypot(*self.velocity_px_per_s)

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        """Constant velocity (vx, vy) at every pixel, px/s."""
        return np.broadcast_to(np.asarray(self.velocity_px_per_s)[:, None, None], (2, *self.shape)).copy()

    def _field_move(self, t0_s, t1_s):
        vx, vy = self.velocity_px_per_s
        return translate_by(vx * (t1_s - t0_s), vy * (t1_s - t0_s))


class RotatingScene(_PatternScene):
    """A pattern rotating about the image centre at ``angular_speed_rad_per_s``."""

    name = "rotating"

    def __init__(self, height=250, width=400, angular_speed_rad_per_s=2 * np.pi * 5, pattern="texture",
                 min_lux=0.2, max_lux=4.0, period_px=48.0, duration_s=None):
        super().__init__(height, width, pattern, min_lux, max_lux, period_px, duration_s)
        self.angular_speed_rad_per_s = float(angular_speed_rad_per_s)
        self._cx, self._cy = (width - 1) / 2.0, (height - 1) / 2.0

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        a = -self.angular_speed_rad_per_s * t_s
        dx, dy = self._x - self._cx, self._y - self._cy
        u = math.cos(a) * dx - math.sin(a) * dy
        v = math.sin(a) * dx + math.cos(a) * dy
        return self._lux(u, v)

    def illuminance_lux_row_times(self, times_s) -> np.ndarray:
        if not self._own_light(RotatingScene):
            return super().illuminance_lux_row_times(times_s)
        # illuminance_lux's arithmetic, each row at its instant (its cosine and sine from math, as there)
        a = [-self.angular_speed_rad_per_s * float(t) for t in self._row_times(times_s)]
        cos = np.array([math.cos(x) for x in a])[:, None]
        sin = np.array([math.sin(x) for x in a])[:, None]
        dx, dy = self._x - self._cx, self._y - self._cy
        return self._lux(cos * dx - sin * dy, sin * dx + cos * dy)

    def _motion(self) -> tuple:
        return ("rotate", self._cx, self._cy, self.angular_speed_rad_per_s)

    def max_speed_px_per_s(self) -> float:
        """|ω| times the distance from the centre to the farthest pixel edge, px/s."""
        return abs(self.angular_speed_rad_per_s) * math.hypot(self._cx + 0.5, self._cy + 0.5)

    def motion_px_per_s(self, t_s: float) -> np.ndarray:
        """ω × r about the image centre: (vx, vy) = ω·(−(y − cy), x − cx), px/s (y down, ω > 0 turns x towards y)."""
        w = self.angular_speed_rad_per_s
        return np.stack([-w * (self._y - self._cy), w * (self._x - self._cx)])

    def _field_move(self, t0_s, t1_s):
        return rotate_about(self._cx, self._cy, self.angular_speed_rad_per_s * (t1_s - t0_s))


TranslatingScene._light_class = TranslatingScene
RotatingScene._light_class = RotatingScene


class HDRScene(StaticTruth, StillScene):
    """A static scene spanning ``decades`` decades of illuminance.

    A horizontal logarithmic ramp from ``min_lux`` to ``min_lux·10^decades`` in the upper
    half and a row of uniform patches, one per decade, in the lower half.
    """

    name = "hdr"

    def __init__(self, height=250, width=400, min_lux=0.1, decades=6.0, duration_s=None):
        check_positive("min_lux", min_lux)
        decades = check_positive("decades", decades)
        height = check_int("height", height, 2)
        width = check_int("width", width, 2)
        x = np.linspace(0.0, 1.0, width)
        ramp = min_lux * 10.0 ** (decades * x)
        patches = min_lux * 10.0 ** np.floor(x * (math.floor(decades) + 1) - 1e-9).clip(0, math.floor(decades))
        lux = np.empty((height, width))
        lux[: height // 2] = ramp
        lux[height // 2:] = patches
        super().__init__(lux, duration_s)
        self.min_lux, self.decades = float(min_lux), decades


class _UniformScene(StaticTruth, StillScene):
    """A uniform, still light (the default base of the step and flicker scenes)."""


def _delegate_truth(cls):
    """Truth of a scene that only modulates its base's light: the base's motion and objects."""
    for method in ("truth_kinds", "motion_px_per_s", "optical_flow_px", "depth_m", "objects", "object_labels"):
        def call(self, *args, _method=method):
            return getattr(self.base, _method)(*args)

        call.__name__ = method
        call.__doc__ = f"The base scene's {method} (modulating light moves nothing)."
        setattr(cls, method, call)
    return cls


@_delegate_truth
class StepScene(Scene):
    """A base image whose illuminance jumps by ``factor`` at ``step_time_s``.

    L(t) = base for t < step_time_s, base·factor after. The window mean is exact.
    """

    name = "step"

    def __init__(self, base: Scene | None = None, step_time_s=0.01, factor=10.0, height=64, width=64,
                 lux=1.0):
        if base is None:
            base = _UniformScene(np.full((height, width), check_non_negative("lux", lux)))
        super().__init__(base.height, base.width, base.duration_s)
        self.base = base
        self.step_time_s = float(step_time_s)
        self.factor = check_non_negative("factor", factor)

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        lux = self.base.illuminance_lux(t_s)
        return lux * self.factor if t_s >= self.step_time_s else lux

    def compiled_light(self):
        if not self._own_light(StepScene):
            return None
        base = self.base.compiled_light()
        if base is None:
            return None
        if base.kind == "frames" and base.frames.shape[0] == 1:
            step = self.step_time_s
            frames = np.stack([base.frames[0], base.frames[0] * self.factor])
            return replace(base, frames=frames,
                           frame_index=lambda times: (np.asarray(times) >= step).astype(np.int64))
        if base.kind == "pattern" and base.modulation[0] == "none":
            return replace(base, modulation=("step", self.step_time_s, self.factor))
        return None

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        if t1_s <= self.step_time_s or t0_s >= self.step_time_s or t1_s == t0_s:
            return super().mean_illuminance_lux(t0_s, t1_s, samples)
        before = (self.step_time_s - t0_s) / (t1_s - t0_s)
        return (self.base.mean_illuminance_lux(t0_s, t1_s, samples)
                * (before + (1 - before) * self.factor))


@_delegate_truth
class FlickerScene(Scene):
    """A source modulated periodically: L(t) = base·(1 + depth·w(2π f t)).

    ``waveform`` is ``"sine"`` (w = sin) or ``"square"`` (w = sign of sin). With a
    still base the window mean is exact.
    """

    name = "flicker"

    def __init__(self, base: Scene | None = None, frequency_hz=100.0, depth=1.0, waveform="sine",
                 height=64, width=64, lux=1.0):
        if base is None:
            base = _UniformScene(np.full((height, width), check_non_negative("lux", lux)))
        super().__init__(base.height, base.width, base.duration_s)
        self.base = base
        self.frequency_hz = check_positive("frequency_hz", frequency_hz)
        if not 0 <= depth <= 1:
            raise ViformError(f"depth = {depth!r} is not allowed: it must lie in [0, 1]")
        self.depth = float(depth)
        self.waveform = check_choice("waveform", waveform, ("sine", "square"))

    def modulation(self, t_s: float) -> float:
        phase = 2 * math.pi * self.frequency_hz * t_s
        w = math.sin(phase)
        if self.waveform == "square":
            w = 1.0 if w >= 0 else -1.0
        return 1.0 + self.depth * w

    def _mean_modulation(self, t0, t1):
        if t1 == t0:
            return self.modulation(t0)
        w = 2 * math.pi * self.frequency_hz
        if self.waveform == "sine":
            return 1.0 + self.depth * (math.cos(w * t0) - math.cos(w * t1)) / (w * (t1 - t0))

        def square_integral(t):  # ∫0^t sign(sin(w s)) ds: whole periods add 0
            period = 1.0 / self.frequency_hz
            r = t % period
            return r if r <= period / 2 else period - r

        return 1.0 + self.depth * (square_integral(t1) - square_integral(t0)) / (t1 - t0)

    def illuminance_lux(self, t_s: float) -> np.ndarray:
        return self.base.illuminance_lux(t_s) * self.modulation(t_s)

    def compiled_light(self):
        if not self._own_light(FlickerScene) or type(self).modulation is not FlickerScene.modulation:
            return None
        base = self.base.compiled_light()
        if base is None:
            return None
        modulation = (self.waveform, self.frequency_hz, self.depth)
        if base.kind == "frames" and base.frames.shape[0] == 1:
            return replace(base, kind="frames-modulated", modulation=modulation, frame_index=None)
        if base.kind == "pattern" and base.modulation[0] == "none":
            return replace(base, modulation=modulation)
        return None

    def auto_light_sample_ticks(self, clock_hz: float, duration_s: float | None = None) -> int:
        """The base scene's choice, and at most a 32nd of the modulation's period (1 when the light is not
        compiled)."""
        if self.compiled_light() is None:
            return 1
        ticks = self.base.auto_light_sample_ticks(clock_hz, duration_s)
        if isinstance(self.base, StillScene):
            from viform.light.sampled import MAX_AUTO_SAMPLE_TICKS

            ticks = MAX_AUTO_SAMPLE_TICKS
        return int(max(1, min(ticks, math.floor(clock_hz / (self.frequency_hz * 32)))))

    def mean_illuminance_lux(self, t0_s, t1_s, samples=32):
        if isinstance(self.base, StillScene):
            return self.base.illuminance_lux(t0_s) * self._mean_modulation(t0_s, t1_s)
        return super().mean_illuminance_lux(t0_s, t1_s, samples)
