"""Random layered scenes: natural images cut into objects, moving by random affine motions, with exact truth.

:func:`random_layers_description` draws one scene — a background image and foreground objects cut
from images by ellipses or polygons, each moving at a random constant velocity, rotation rate and
scale rate, each at random lux levels across a chosen dynamic range, some flickering, the camera
sometimes panning — and returns it as a plain scene description (:mod:`viform.light.description`),
validated by its schema. Every drawn scene is therefore an ordinary described scene
(:class:`~viform.light.layered.DescribedScene`) with its exact truth: flow with its valid mask,
depth, labels, boxes (the FlyingChairs / FlyingThings idea of real textures moving by known
transforms, here with physical light levels).

The draw is a pure function of the seed, the canvas, the duration, the image list and the ranges,
so a dataset that seeds each clip from its own name gets the same scenes whatever its worker count
or order. Images are a folder's PNG/JPEG/TIFF/BMP files (sorted by name) or, by default, photographs
that ship with scikit-image (public domain or CC0: :data:`BUNDLED_NATURAL`), so no download is needed.

Ranges (:data:`RANGES`; a range is ``[low, high]``) are named with their units. Their defaults are set
to cover the built-in scenes' ranges (speeds 100–10,000 px/s — the dataset draws the built-in scenes at
100–8,000 —, rotations up to 40 rad/s — the rotating scene turns at 31 rad/s —, two decades of light
below the peak — the span of the brightness factors drawn for the built-in scenes, 0.1–10 —, mains and
LED flicker frequencies), not tuned on any result.

How each quantity is drawn (u: uniform, log-u: log-uniform):

* objects: a count u in ``n_objects``; each an image (u), cut by an ellipse or a star-shaped polygon
  of 5–9 vertices (u), its longer side u in ``object_size_fraction`` of the canvas' shorter side,
  showing a random part of its image (the image is 1–2× the outline); its centre u over the canvas
  at the clip's middle instant, angle u in [−π, π), depth log-u in 1–20 m (occlusion follows depth);
* motion: speed log-u in ``speed_px_per_s`` in a direction u; rotation rate u in
  ``rotation_rad_per_s`` and scale rate u in ``scale_per_s``, each with a random sign (the scale rate
  is capped at 1 / duration, so the scale stays within [0.5, 1.5] over the clip); the motion is
  written about the clip's middle instant (``canvas.time_reference_s``);
* light: each layer's full-scale level log-u in [peak_lux·10^−D, peak_lux] (D =
  ``dynamic_range_decades``), its image mapped linearly (sRGB decoded) from full scale / 10^c to full
  scale, c u in ``contrast_decades``;
* flicker: each layer (background included) flickers with probability ``flicker_probability``: a
  sine, square or PWM modulation (u) at a frequency log-u in ``flicker_hz``;
* camera: with probability ``camera_motion_probability`` the view pans at a speed log-u in
  ``camera_speed_px_per_s`` in a direction u; the background image is placed large enough to cover
  the field for the whole clip.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from viform._validate import ViformError, one_line
from viform.light.description import BUNDLED_PREFIX, load_description

#: Photographs that ship with scikit-image used by default (grey or colour natural content).
BUNDLED_NATURAL = ("astronaut", "camera", "coffee", "chelsea", "rocket", "grass", "gravel", "brick", "coins", "moon")
#: Image files taken from a folder.
FOLDER_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")

#: Range name → (default, unit, what it is, (smallest, largest) allowed value, integer).
RANGES = {
    "n_objects": ((1, 4), "objects", "number of foreground objects", (0, 64), True),
    "speed_px_per_s": ((100.0, 10000.0), "px/s", "object speed (log-uniform)", (0.0, 1e7), False),
    "rotation_rad_per_s": ((0.0, 40.0), "rad/s", "object rotation rate, either sign", (0.0, 1e5), False),
    "scale_per_s": ((0.0, 4.0), "1/s", "object scale rate, either sign (capped at 1 / duration)", (0.0, 1e4), False),
    "object_size_fraction": ((0.2, 0.6), "of the shorter side", "object size", (1e-3, 4.0), False),
    "contrast_decades": ((0.5, 2.0), "decades", "each layer's full scale over its black level", (0.0, 9.0), False),
    "flicker_hz": ((50.0, 2000.0), "Hz", "flicker frequency (log-uniform)", (1e-3, 1e7), False),
    "camera_speed_px_per_s": ((50.0, 2000.0), "px/s", "camera pan speed (log-uniform)", (0.0, 1e7), False),
}
#: Scalar settings → (default, unit, what it is, (smallest, largest)).
SCALARS = {
    "peak_lux": (1000.0, "lux", "top of the range of full-scale levels", (1e-6, 1e8)),
    "dynamic_range_decades": (2.0, "decades", "full-scale levels span peak_lux·10^−D … peak_lux", (0.0, 12.0)),
    "flicker_probability": (0.25, "", "chance that a layer flickers", (0.0, 1.0)),
    "camera_motion_probability": (0.5, "", "chance that the camera pans (0: never, 1: always)", (0.0, 1.0)),
}


def default_ranges() -> dict:
    """Every range and scalar setting at its default (JSON values)."""
    return {**{k: list(v[0]) for k, v in RANGES.items()}, **{k: v[0] for k, v in SCALARS.items()}}


def check_ranges(ranges: dict | None, where: str = "random-layers") -> dict:
    """The ranges with defaults filled in, checked: ``[low, high]`` with low ≤ high, within their bounds.

    Errors name the setting (``speed_px_per_s = [5, 1]``), its value and what is allowed.
    """
    out = default_ranges()
    for name, value in (ranges or {}).items():
        if name in RANGES:
            default, unit, what, (lo, hi), integer = RANGES[name]
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                value = [value, value]
            ok = isinstance(value, (list, tuple)) and len(value) == 2 and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
            if ok and integer:
                ok = all(float(v).is_integer() for v in value)
            if not ok or not (lo <= value[0] <= value[1] <= hi):
                raise ViformError(f"{where} setting {name} = {value!r} is not allowed: give [low, high] "
                                  f"{'whole numbers ' if integer else ''}with {lo:g} ≤ low ≤ high ≤ {hi:g} ({unit}: "
                                  f"{what})")
            out[name] = [int(v) for v in value] if integer else [float(v) for v in value]
        elif name in SCALARS:
            default, unit, what, (lo, hi) = SCALARS[name]
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            if not ok or not (lo <= value <= hi):
                raise ViformError(f"{where} setting {name} = {value!r} is not allowed: it must lie in "
                                  f"[{lo:g}, {hi:g}] ({unit + ': ' if unit else ''}{what})")
            out[name] = float(value)
        else:
            raise ViformError(f"{where} setting {name} = {value!r} is not allowed: the settings are "
                              f"{', '.join(list(RANGES) + list(SCALARS))}")
    return out


def image_files(folder, what: str = "images") -> list[str]:
    """The image files (:data:`FOLDER_SUFFIXES`) of ``folder``, sorted by name, as absolute paths."""
    path = Path(folder)
    if not path.is_dir():
        raise ViformError(f"{what} = {str(folder)!r} is not allowed: no such folder")
    files = sorted(str(p.resolve()) for p in path.iterdir()
                   if p.is_file() and p.suffix.lower() in FOLDER_SUFFIXES and not p.name.startswith("."))
    if not files:
        raise ViformError(f"{what} = {str(folder)!r} is not allowed: the folder holds no image files "
                          f"({', '.join(FOLDER_SUFFIXES)})")
    return files


def image_pool(images=None, what: str = "images") -> list[str]:
    """Image sources for a draw: ``None`` → the bundled photographs (``skimage:NAME``); a folder → its
    image files; a list → those paths or ``skimage:NAME`` names."""
    if images is None:
        return [BUNDLED_PREFIX + n for n in BUNDLED_NATURAL]
    if isinstance(images, (str, Path)):
        return image_files(images, what)
    pool = [str(p) if str(p).startswith(BUNDLED_PREFIX) else str(Path(p).resolve()) for p in images]
    if not pool:
        raise ViformError(f"{what} is empty: give at least one image")
    return pool


@lru_cache(maxsize=256)
def image_size(source: str) -> tuple[int, int]:
    """(width, height) of an image file or ``skimage:NAME``, in texels."""
    try:
        if source.startswith(BUNDLED_PREFIX):
            import skimage.data

            shape = getattr(skimage.data, source[len(BUNDLED_PREFIX):])().shape
        else:
            import warnings

            import imageio.v3 as iio

            with warnings.catch_warnings():  # imageio warns while it tries plugins on a damaged file
                warnings.simplefilter("ignore")
                shape = iio.improps(source).shape
    except Exception as exc:
        raise ViformError(f"image {source!r} could not be read: {one_line(exc)}") from None
    if len(shape) < 2 or shape[0] < 1 or shape[1] < 1:
        raise ViformError(f"image {source!r} has no pixels (shape {shape})")
    return int(shape[1]), int(shape[0])


def _log_uniform(rng, lo: float, hi: float) -> float:
    if lo <= 0:
        return float(rng.uniform(lo, hi))
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _signed(rng, lo: float, hi: float) -> float:
    return float((1.0 if rng.random() < 0.5 else -1.0) * rng.uniform(lo, hi))


def _levels(rng, r: dict) -> list[float]:
    """[black, full scale] lux of one layer."""
    peak = r["peak_lux"]
    high = _log_uniform(rng, peak * 10.0 ** -r["dynamic_range_decades"], peak)
    c = float(rng.uniform(*r["contrast_decades"]))
    return [high * 10.0 ** -c, high]


def _flicker(rng, r: dict) -> dict | None:
    if not rng.random() < r["flicker_probability"]:
        return None
    kind = ("sine", "square", "pwm")[int(rng.integers(3))]
    f = _log_uniform(rng, *r["flicker_hz"])
    if kind == "pwm":
        return {"pwm": {"frequency_hz": f, "duty": float(rng.uniform(0.1, 0.9)), "low": float(rng.uniform(0.0, 0.5))}}
    return {kind: {"frequency_hz": f, "depth": float(rng.uniform(0.3, 1.0))}}


def _outline(rng, w: float, h: float) -> tuple[str, dict]:
    if rng.random() < 0.5:
        return "ellipse", {"ellipse": {"width_px": w, "height_px": h}}
    n = int(rng.integers(5, 10))
    step = 2 * math.pi / n
    angles = np.arange(n) * step + rng.uniform(-0.3, 0.3, n) * step  # increasing: a star-shaped polygon
    radii = rng.uniform(0.55, 1.0, n)
    points = [[float(r * w / 2 * math.cos(a)), float(r * h / 2 * math.sin(a))]
              for a, r in zip(angles, radii, strict=True)]
    return "polygon", {"polygon": {"points_px": points}}


def _short_name(source: str) -> str:
    return source if source.startswith(BUNDLED_PREFIX) else Path(source).name


def random_layers(seed, height: int, width: int, duration_s: float, images=None, **ranges) -> tuple[dict, dict]:
    """Draw one random layered scene: (its validated description, the drawn parameters).

    Parameters
    ----------
    seed : int or numpy.random.Generator
        Source of every random choice (the same seed and inputs give the same scene).
    height, width : int
        Canvas in px.
    duration_s : float
        Length of the clip, s; motions are written about its middle instant.
    images : folder, list of paths, or None
        Image sources (see :func:`image_pool`); None: the bundled photographs.
    **ranges
        Any of :data:`RANGES` (``[low, high]``) and :data:`SCALARS` (see the module notes).

    Returns
    -------
    description : dict
        A scene description validated by :func:`~viform.light.description.load_description`.
    drawn : dict
        What was drawn, layer by layer (images, outlines, levels in lux, speeds in px/s, rates in
        rad/s and 1/s, flicker, depth in m, camera pan in px/s), and the ranges used.
    """
    if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or height < 1:
        raise ViformError(f"height = {height!r} is not allowed: it must be a whole number of px ≥ 1")
    if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
        raise ViformError(f"width = {width!r} is not allowed: it must be a whole number of px ≥ 1")
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and 0 < duration_s <= 1e6):
        raise ViformError(f"duration_s = {duration_s!r} is not allowed: it must be a finite time > 0 s")
    r = check_ranges(ranges)
    pool = image_pool(images)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    h, w, T = int(height), int(width), float(duration_s)
    short = min(h, w)

    # camera first: the background must cover the field wherever the view goes
    camera = None
    travel = 0.0
    if rng.random() < r["camera_motion_probability"]:
        speed = _log_uniform(rng, *r["camera_speed_px_per_s"])
        angle = rng.uniform(0, 2 * math.pi)
        camera = [speed * math.cos(angle), speed * math.sin(angle)]
        travel = speed * T  # the view moves ±travel/2 about the middle instant

    def pick() -> str:
        return pool[int(rng.integers(len(pool)))]

    source = pick()
    iw, ih = image_size(source)
    need_w, need_h = w + travel + 2.0, h + travel + 2.0
    f = max(need_w / iw, need_h / ih) * float(rng.uniform(1.0, 1.5))
    size = [iw * f, ih * f]
    centre = [w / 2 + float(rng.uniform(-1, 1)) * (size[0] - need_w) / 2,
              h / 2 + float(rng.uniform(-1, 1)) * (size[1] - need_h) / 2]
    lux = _levels(rng, r)
    flicker = _flicker(rng, r)
    depth = _log_uniform(rng, 30.0, 300.0)
    background = {"source": {"image": {"path": source, "lux": lux, "transfer": "srgb", "map": "linear",
                                       "size_px": size}},
                  "position_px": centre, "depth_m": depth}
    if flicker:
        background["modulation"] = flicker
    drawn = {"background": {"image": _short_name(source), "size_px": size, "centre_px": centre, "lux": lux,
                            "flicker": flicker, "depth_m": depth},
             "objects": [], "camera_pan_px_per_s": camera}

    layers = []
    n = int(rng.integers(r["n_objects"][0], r["n_objects"][1] + 1))
    scale_cap = 1.0 / T  # |rate|·T/2 ≤ 0.5: the scale stays in [0.5, 1.5] over the clip
    for k in range(n):
        source = pick()
        iw, ih = image_size(source)
        long_side = float(rng.uniform(*r["object_size_fraction"])) * short
        bw, bh = (long_side, long_side * ih / iw) if iw >= ih else (long_side * iw / ih, long_side)
        kind, shape = _outline(rng, bw, bh)
        zoom = float(rng.uniform(1.0, 2.0))
        isize = [bw * zoom, bh * zoom]
        icentre = [float(rng.uniform(-1, 1)) * (isize[0] - bw) / 2, float(rng.uniform(-1, 1)) * (isize[1] - bh) / 2]
        position = [float(rng.uniform(0, w)), float(rng.uniform(0, h))]
        angle = float(rng.uniform(-math.pi, math.pi))
        speed = _log_uniform(rng, *r["speed_px_per_s"])
        direction = float(rng.uniform(0, 2 * math.pi))
        velocity = [speed * math.cos(direction), speed * math.sin(direction)]
        spin = _signed(rng, *r["rotation_rad_per_s"])
        lo, hi = r["scale_per_s"]
        grow = _signed(rng, min(lo, scale_cap), min(hi, scale_cap))
        lux = _levels(rng, r)
        flicker = _flicker(rng, r)
        depth = _log_uniform(rng, 1.0, 20.0)
        layer = {"name": f"object-{k + 1}", "object": {"id": k + 1, "class": "object"},
                 "source": {"image": {"path": source, "lux": lux, "transfer": "srgb", "map": "linear",
                                      "size_px": isize, "centre_px": icentre}},
                 "shape": shape, "position_px": position, "angle_rad": angle,
                 "motion": {"velocity": {"px_per_s": velocity, "rad_per_s": spin, "scale_per_s": grow}},
                 "depth_m": depth}
        if flicker:
            layer["modulation"] = flicker
        layers.append(layer)
        drawn["objects"].append({"id": k + 1, "image": _short_name(source), "outline": kind,
                                 "size_px": [bw, bh], "position_px": position, "angle_rad": angle,
                                 "speed_px_per_s": speed, "direction_rad": direction, "rotation_rad_per_s": spin,
                                 "scale_per_s": grow, "lux": lux, "flicker": flicker, "depth_m": depth})

    document = {"viform_scene": 1, "name": "random-layers",
                "summary": f"{n} image object{'s' if n != 1 else ''} over an image background, random affine "
                           "motions" + (", camera pan" if camera else ""),
                "canvas": {"width_px": w, "height_px": h, "duration_s": T, "time_reference_s": T / 2},
                "background": background, "layers": layers}
    if camera:
        document["camera"] = {"motion": {"velocity": {"px_per_s": camera}}}
    description = load_description(document)
    drawn["ranges"] = r
    return description, drawn


def random_layers_description(seed, height: int, width: int, duration_s: float, images=None, **ranges) -> dict:
    """A random layered scene as a validated description (see :func:`random_layers`)."""
    return random_layers(seed, height, width, duration_s, images, **ranges)[0]
