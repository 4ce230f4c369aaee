"""Source clips of a dataset: a folder of videos, or of frame folders (REDS, GoPro style).

Each entry of the source folder is one clip, named by its stem: ``clips/000/`` (a folder of
images, sorted by name) or ``clips/walk.mp4`` (a video). Frame k is the light at the instant
k / frame_rate_hz; pixel values map linearly to lux (0 → 0 lux, full scale → ``max_lux``) and
colour is reduced to luminance (Rec. 709), as :func:`viform.light.scenes.image_to_lux` does.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viform._validate import ViformError, one_line

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".gif", ".webm")
#: Clip names become file names (spike/<clip>.dat, gt/<clip>_<frame>.png).
_CLIP_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


@dataclass(frozen=True)
class SourceClip:
    """One clip of the source folder: its name, path and kind (``"frames"`` or ``"video"``)."""

    name: str
    path: str
    kind: str


def find_clips(src) -> list[SourceClip]:
    """The clips of a source folder, sorted by name; refuses an empty folder and unusable names."""
    src = Path(src)
    if not src.is_dir():
        raise ViformError(f"SRC {str(src)!r} is not a folder: give a folder of videos or of frame folders")
    clips = []
    for entry in sorted(src.iterdir()):
        if entry.name.startswith("."):
            continue
        if entry.is_dir():
            if any(p.suffix.lower() in IMAGE_SUFFIXES for p in entry.iterdir()):
                clips.append(SourceClip(entry.name, str(entry), "frames"))
        elif entry.suffix.lower() in VIDEO_SUFFIXES:
            clips.append(SourceClip(entry.stem, str(entry), "video"))
    if not clips:
        raise ViformError(f"SRC {str(src)!r} holds no videos ({', '.join(VIDEO_SUFFIXES)}) "
                          f"and no folders of images ({', '.join(IMAGE_SUFFIXES)})")
    names = [c.name for c in clips]
    bad = [n for n in names if not _CLIP_NAME.match(n)]
    if bad:
        raise ViformError(f"SRC: clip name {bad[0]!r} cannot be a file name in the dataset: "
                          "use letters, digits and . _ + - (not starting with a symbol)")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ViformError(f"SRC: two clips are both named {dupes[0]!r} (a video and a folder, or two "
                          "videos with different suffixes); rename one")
    return clips


def read_clip(clip: SourceClip, height: int, width: int,
              max_lux: float) -> tuple[np.ndarray, float | None, dict]:
    """Frames of a clip as lux at the sensor's size, shape (N, H, W) float64, its declared frame rate and its fit.

    Frames are scaled by one factor (bilinear, anti-aliased) until they cover ``height`` ×
    ``width``, then centre-cropped to it, as they are read: the aspect ratio is kept (a disc
    stays a disc in the spikes and the ground truth) and only sensor-sized frames are held.
    The third value describes that fit (:func:`fit_to_sensor`). A frame file that cannot be
    read is named in the error.
    """
    import imageio.v3 as iio

    from viform.light.scenes import image_to_lux

    path = Path(clip.path)
    frames = []
    declared = None
    fit = None
    try:
        if clip.kind == "frames":
            files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            for f in files:
                try:
                    image = iio.imread(f)
                except Exception as exc:
                    raise ViformError(f"frame file {str(f)!r} is not a readable image ({_read_error(exc)})") from None
                lux = image_to_lux(image, max_lux)
                fit = fit if fit is not None else fit_to_sensor(lux.shape, (height, width))
                frames.append(_fit(lux, fit))
        else:
            try:
                declared = iio.immeta(path).get("fps")
            except Exception:
                declared = None
            for frame in iio.imiter(path):
                lux = image_to_lux(frame, max_lux)
                fit = fit if fit is not None else fit_to_sensor(lux.shape, (height, width))
                frames.append(_fit(lux, fit))
    except ViformError as exc:
        raise ViformError(f"clip {clip.name!r}: {exc}") from None
    except Exception as exc:
        raise ViformError(f"clip {clip.name!r}: {str(path)!r} could not be read: {_read_error(exc)}") from None
    if not frames:
        raise ViformError(f"clip {clip.name!r}: {str(path)!r} holds no frames")
    if any(f.shape != frames[0].shape for f in frames):
        raise ViformError(f"clip {clip.name!r}: its frames do not all have the same size")
    return np.stack(frames), (float(declared) if declared else None), fit


def _read_error(exc: Exception) -> str:
    """What a reader's failure means, in one line (imageio lists plugins to install when no reader knows the bytes)."""
    text = str(exc)
    if "backend" in text.lower() or "plugin" in text.lower():
        return "no image or video reader recognises its contents: damaged, or not the format its suffix says"
    return one_line(exc)


def fit_to_sensor(native: tuple[int, int], shape: tuple[int, int]) -> dict:
    """How a ``native`` (rows, columns) frame is fitted to the sensor ``shape`` without stretching.

    One scale factor, the smallest that covers the sensor in both directions, then a centred
    crop of the excess rows or columns. Returns ``source_shape``, ``scale``, ``scaled_shape``
    and ``crop`` (``(row0, col0)``, the first kept row and column of the scaled frame).
    """
    h0, w0 = (int(n) for n in native[:2])
    h, w = (int(n) for n in shape)
    scale = max(h / h0, w / w0)
    scaled = (max(h, int(round(h0 * scale))), max(w, int(round(w0 * scale))))
    crop = ((scaled[0] - h) // 2, (scaled[1] - w) // 2)
    return {"source_shape": [h0, w0], "scale": float(scale), "scaled_shape": list(scaled), "crop": list(crop),
            "sensor_shape": [h, w]}


def describe_fit(fit: dict) -> str:
    """One line for a user: how the source frames became sensor frames."""
    (h0, w0), (hs, ws), (h, w) = fit["source_shape"], fit["scaled_shape"], fit["sensor_shape"]
    text = f"{w0}×{h0} source frames scaled ×{fit['scale']:.3g} to {ws}×{hs}"
    if (hs, ws) == (h, w):
        return text + " (aspect ratio kept, nothing cropped)"
    cut = f"{hs - h} rows" if hs != h else f"{ws - w} columns"
    return text + f", {cut} cropped (centred) to the sensor's {w}×{h}; aspect ratio kept"


def _fit(image: np.ndarray, fit: dict) -> np.ndarray:
    if list(image.shape) != fit["source_shape"]:
        raise ViformError(f"a frame is {image.shape[1]}×{image.shape[0]}, the clip's first "
                          f"{fit['source_shape'][1]}×{fit['source_shape'][0]}: frames of one clip must share a size")
    (hs, ws), (r0, c0), (h, w) = fit["scaled_shape"], fit["crop"], fit["sensor_shape"]
    return _resize(image, (hs, ws))[r0:r0 + h, c0:c0 + w]


def _resize(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if image.shape == tuple(shape):
        return image
    from skimage.transform import resize

    return resize(image, shape, order=1, anti_aliasing=True, preserve_range=True)


def lux_to_gt_image(lux: np.ndarray, max_lux: float) -> np.ndarray:
    """8-bit ground truth of a lux frame: round(255 · lux / max_lux), clipped to [0, 255]."""
    return np.clip(np.rint(lux * (255.0 / max_lux)), 0, 255).astype(np.uint8)
