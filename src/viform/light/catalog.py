"""The scene catalogue: every scene viform knows by name, and loading a scene from a name or a file.

A scene is asked for by a name (:data:`BUILTIN_SCENES`), an image or video file, or a folder
of images (:func:`load_scene`); a capture records how to remake a built-in scene
(:meth:`~viform.light.scenes.Scene.describe`) and :func:`scene_from_description` remakes it,
with its exact truth, from a file's metadata. The scene classes live in their own modules
(:mod:`viform.light.scenes`, :mod:`~viform.light.dilemma`, :mod:`~viform.light.articulated`,
:mod:`~viform.light.multi_object`); this module imports them all and none of them imports it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from viform._validate import ViformError, check_choice, check_positive, one_line
from viform.light import dilemma
from viform.light.articulated import WavingHandScene
from viform.light.multi_object import MultiObjectScene
from viform.light.scenes import (
    FlickerScene,
    HDRScene,
    RotatingScene,
    Scene,
    StepScene,
    StillScene,
    TranslatingScene,
    VideoScene,
    _resize,
)
from viform.light.truth import TruthUnavailable

#: Built-in scenes: name → constructor ``(height, width, **parameters) -> Scene``.
BUILTIN_SCENES = {
    "translating": lambda height, width, **kw: TranslatingScene(height, width, **kw),
    "moving-edge": lambda height, width, **kw: TranslatingScene(height, width, pattern="edge", **kw),
    "rotating": lambda height, width, **kw: RotatingScene(height, width, **kw),
    "hdr": lambda height, width, **kw: HDRScene(height, width, **kw),
    "step": lambda height, width, **kw: StepScene(height=height, width=width, **kw),
    "flicker": lambda height, width, **kw: FlickerScene(height=height, width=width, **kw),
    **dilemma.BUILTIN,
    "waving-hand": lambda height, width, **kw: WavingHandScene(height, width, **kw),
    "multi-object": lambda height, width, **kw: MultiObjectScene(height=height, width=width, **kw),
}


def builtin_scene(name: str, height: int = 250, width: int = 400, **kw) -> Scene:
    """A built-in synthetic scene by name (see :data:`BUILTIN_SCENES`)."""
    check_choice("scene", name, tuple(BUILTIN_SCENES))
    scene = BUILTIN_SCENES[name](height=height, width=width, **kw)
    scene.name = name  # metadata records the name the user gave ("moving-edge", not its class's "translating")
    # enough to remake the scene, and so its exact truth, from a file's metadata
    scene.builtin_spec = {"name": name, "height": int(height), "width": int(width), "parameters": _plain(kw)}
    return scene


def _plain(parameters: dict) -> dict:
    """Keyword arguments as JSON values (tuples → lists); refuses what JSON cannot carry."""
    import json

    try:
        return json.loads(json.dumps(parameters))
    except TypeError:
        return {"unrecordable": True}


def scene_from_description(described: dict | None) -> Scene:
    """Remake a built-in scene from the ``scene`` metadata a capture recorded (its truth included).

    Raises :class:`~viform.light.truth.TruthUnavailable` for scenes that were not built-in
    (an image or a video) or whose parameters were not recorded.
    """
    spec = (described or {}).get("builtin") if isinstance(described, dict) else None
    name = (described or {}).get("name", "unknown") if isinstance(described, dict) else "unknown"
    if not isinstance(spec, dict) or spec.get("name") not in BUILTIN_SCENES or \
            not isinstance(spec.get("parameters"), dict) or spec["parameters"].get("unrecordable"):
        raise TruthUnavailable(f"the stream's scene {name!r} is not a built-in scene viform can remake, so it "
                               "carries no truth (image and video files have none)")
    try:
        parameters = {k: tuple(v) if isinstance(v, list) else v for k, v in spec["parameters"].items()}
        return builtin_scene(spec["name"], int(spec["height"]), int(spec["width"]), **parameters)
    except (TypeError, ValueError, KeyError) as exc:
        raise TruthUnavailable(f"the stream's scene description cannot be remade: {one_line(exc)}") from None


_VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".gif", ".webm")


def fit_shape(native: tuple[int, int], height: int | None, width: int | None,
              names: tuple[str, str] = ("--height", "--width")) -> tuple[int, int]:
    """The size to resize an image of shape ``native`` to, keeping its aspect ratio.

    Give ``height``, ``width`` or both; with both, they must keep the image's aspect ratio
    (within one pixel), else the request is refused rather than stretching the picture.
    """
    h0, w0 = native
    if height is None and width is None:
        return native
    if height is not None and width is not None:
        if abs(height * w0 - width * h0) > max(h0, w0):
            raise ViformError(f"{names[0]} {height} {names[1]} {width} would stretch the {h0}×{w0} image "
                              f"(height × width); give only {names[0]} or only {names[1]} to keep its aspect ratio")
        return int(height), int(width)
    if height is not None:
        return int(height), max(1, int(round(w0 * height / h0)))
    return max(1, int(round(h0 * width / w0))), int(width)


def load_scene(spec: str, height: int = 250, width: int = 400, max_lux: float = 4.0,
               frame_rate_hz: float | None = None, interpolation: str = "linear",
               resize: bool = False, fit: tuple[int | None, int | None] | None = None) -> Scene:
    """A scene from a built-in name, an image file, a video file or a folder of images.

    Integer image and video pixel values map linearly to [0, ``max_lux``] lux; float images
    are lux already. Built-in scenes are made at ``height`` × ``width``; files keep their own
    size unless ``resize`` (to exactly ``height`` × ``width``) or ``fit`` = (height or None,
    width or None), which resizes keeping the aspect ratio (see :func:`fit_shape`).
    ``max_lux`` and ``frame_rate_hz`` are checked for every scene (a built-in one ignores them,
    but a negative full scale or frame rate is a mistake worth saying).
    """
    if max_lux is not None:
        check_positive("max_lux", max_lux)
    if frame_rate_hz is not None:
        check_positive("frame_rate_hz", frame_rate_hz)
    if spec in BUILTIN_SCENES:
        return builtin_scene(spec, height, width)
    path = Path(spec)
    if not path.exists():
        raise ViformError(f"scene {spec!r} is neither a built-in scene ({', '.join(BUILTIN_SCENES)}) "
                          "nor an existing file or folder")
    shape = (height, width) if resize else None
    if path.is_dir() or path.suffix.lower() in _VIDEO_SUFFIXES:
        scene = VideoScene.from_file(path, frame_rate_hz=frame_rate_hz, max_lux=max_lux,
                                     interpolation=interpolation, shape=shape)
        if fit is not None and shape is None and fit != (None, None):
            target = fit_shape(scene.shape, *fit)
            if target != scene.shape:
                scene = VideoScene(np.stack([_resize(f, target) for f in scene._frames]), scene.frame_rate_hz,
                                   scene.interpolation)
        return scene
    scene = StillScene.from_file(path, max_lux=max_lux, shape=shape)
    if fit is not None and shape is None and fit != (None, None):
        target = fit_shape(scene.shape, *fit)
        if target != scene.shape:
            scene = StillScene(_resize(scene.illuminance_lux(0.0), target))
    return scene
