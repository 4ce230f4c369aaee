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


def read_clip(clip: SourceClip, height: int, width: int, max_lux: float) -> tuple[np.ndarray, float | None]:
    """Frames of a clip as lux at the sensor's size, shape (N, H, W) float64, and its declared frame rate.

    Frames are resized (bilinear, anti-aliased) to ``height`` × ``width`` as they are read, so
    only the sensor-sized frames are held.
    """
    import imageio.v3 as iio

    from viform.light.scenes import image_to_lux

    path = Path(clip.path)
    frames = []
    declared = None
    try:
        if clip.kind == "frames":
            files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            for f in files:
                frames.append(_resize(image_to_lux(iio.imread(f), max_lux), (height, width)))
        else:
            try:
                declared = iio.immeta(path).get("fps")
            except Exception:
                declared = None
            for frame in iio.imiter(path):
                frames.append(_resize(image_to_lux(frame, max_lux), (height, width)))
    except ViformError as exc:
        raise ViformError(f"clip {clip.name!r} ({str(path)!r}): {exc}") from None
    except Exception as exc:
        raise ViformError(f"clip {clip.name!r}: {str(path)!r} could not be read: {one_line(exc)}") from None
    if not frames:
        raise ViformError(f"clip {clip.name!r}: {str(path)!r} holds no frames")
    return np.stack(frames), (float(declared) if declared else None)


def _resize(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if image.shape == tuple(shape):
        return image
    from skimage.transform import resize

    return resize(image, shape, order=1, anti_aliasing=True, preserve_range=True)


def lux_to_gt_image(lux: np.ndarray, max_lux: float) -> np.ndarray:
    """8-bit ground truth of a lux frame: round(255 · lux / max_lux), clipped to [0, 255]."""
    return np.clip(np.rint(lux * (255.0 / max_lux)), 0, 255).astype(np.uint8)
