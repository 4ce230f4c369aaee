"""The scene catalogue: every scene viform knows by name, and loading a scene from a name or a file.

A scene is asked for by a name (:data:`SCENES`, :data:`BUILTIN_SCENES`), a scene description
(YAML or JSON, :mod:`viform.light.description`), an image or video file, or a folder of images
(:func:`load_scene`). A capture records how to remake its scene
(:meth:`~viform.light.scenes.Scene.describe`) and :func:`scene_from_description` remakes it, with
its exact truth, from a file's metadata. The scene classes live in their own modules
(:mod:`viform.light.scenes`, :mod:`~viform.light.dilemma`, :mod:`~viform.light.articulated`,
:mod:`~viform.light.multi_object`, :mod:`~viform.light.layered`); this module imports them all and
none of them imports it.

Each entry (:class:`SceneEntry`) says what the scene is, its parameters with their defaults,
and whether a shipped description of it exists (``viform scenes show NAME`` prints it, a
starting point for one's own) or why it stays code. Every entry takes the settings every
described scene takes — ``brightness`` (a factor on its light) and ``speed`` (a factor on its
motion) — through :func:`entry_settings`.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viform._validate import ViformError, check_choice, check_positive, one_line
from viform.light import dilemma
from viform.light.articulated import WavingHandScene
from viform.light.description import UNIVERSAL_SETTINGS, is_description_file, load_description
from viform.light.layered import DescribedScene
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

#: Folder of the shipped descriptions (``<name>.yaml``).
DESCRIPTIONS_DIR = Path(__file__).with_name("descriptions")

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



@dataclass(frozen=True)
class SceneEntry:
    """One scene of the catalogue.

    Attributes
    ----------
    name, summary : str
    build : callable
        ``(height, width, **parameters) -> Scene``.
    parameters : dict
        Parameter name → default (the keyword arguments ``build`` takes).
    description : str or None
        File name of its shipped description under :data:`DESCRIPTIONS_DIR`, or None.
    described_as : str
        How the description's rendering relates to the code that runs the name.
    code_reason : str
        Why the scene stays code (empty when a description reproduces it).
    brightness, speed : callable
        ``(factor, defaults) -> keyword arguments``: how the universal settings reach its parameters.
    """

    name: str
    summary: str
    build: object
    parameters: dict = field(default_factory=dict)
    description: str | None = None
    described_as: str = ""
    code_reason: str = ""
    brightness: object = None
    speed: object = None

    def description_path(self) -> Path | None:
        return None if self.description is None else DESCRIPTIONS_DIR / self.description


def _defaults(cls, skip=("self", "height", "width", "base", "duration_s")) -> dict:
    out = {}
    for name, p in inspect.signature(cls.__init__).parameters.items():
        if name in skip or p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
            continue
        out[name] = p.default
    return out


def _scale(*names):
    """Settings → the named parameters, each times the factor."""
    def apply(factor, defaults):
        out = {}
        for n in names:
            value = defaults[n]
            out[n] = [factor * v for v in value] if isinstance(value, (tuple, list)) else factor * value
        return out

    return apply


def _native(name):
    return lambda factor, defaults: {name: factor * defaults.get(name, 1.0)}


_CODE = "its light is drawn by code: "
_SAME = ("the description renders the same light (equal to rounding, ≤ 1e-15 relative) and the same truth; "
         "the name runs the code, whose compiled light gives the same bits")
SCENES: dict[str, SceneEntry] = {e.name: e for e in (
    SceneEntry("translating", "the test texture (checkerboard and two gratings) translating at 2,000 px/s",
               BUILTIN_SCENES["translating"], _defaults(TranslatingScene),
               description="translating.yaml", described_as=_SAME,
               brightness=_scale("min_lux", "max_lux"), speed=_scale("velocity_px_per_s")),
    SceneEntry("moving-edge", "a vertical step edge translating at 2,000 px/s (the motion-blur target)",
               BUILTIN_SCENES["moving-edge"], {k: v for k, v in _defaults(TranslatingScene).items() if k != "pattern"},
               description="moving-edge.yaml", described_as=_SAME,
               brightness=_scale("min_lux", "max_lux"), speed=_scale("velocity_px_per_s")),
    SceneEntry("rotating", "the test texture rotating about the image centre at 5 rev/s",
               BUILTIN_SCENES["rotating"], _defaults(RotatingScene),
               description="rotating.yaml", described_as=_SAME,
               brightness=_scale("min_lux", "max_lux"), speed=_scale("angular_speed_rad_per_s")),
    SceneEntry("hdr", "a still logarithmic ramp and decade patches spanning 6 decades of illuminance",
               BUILTIN_SCENES["hdr"], _defaults(HDRScene), code_reason=_CODE + "a still image computed once",
               brightness=_scale("min_lux")),
    SceneEntry("step", "uniform light that jumps by a factor at an instant", BUILTIN_SCENES["step"],
               _defaults(StepScene, skip=("self", "base", "height", "width")) | {},
               description="step.yaml", described_as=_SAME,
               brightness=_scale("lux")),
    SceneEntry("flicker", "uniform light modulated by a sine or square wave", BUILTIN_SCENES["flicker"],
               _defaults(FlickerScene, skip=("self", "base", "height", "width")),
               description="flicker.yaml", described_as=_SAME,
               brightness=_scale("lux")),
    SceneEntry("dilemma", "the high-speed / high-dynamic-range dilemma: 6.4 decades, a propeller, a vehicle, "
                          "a PWM LED, a small fast object", BUILTIN_SCENES["dilemma"],
               _defaults(dilemma.DilemmaScene),
               code_reason=_CODE + "propeller blades (angular sectors of a disc) and an additive Gaussian "
                                   "blob on a procedural wall, with the comparison's regions and demands",
               brightness=_native("brightness"), speed=_native("speed")),
    SceneEntry("night-road-fog", "a night road in fog, with range for the gated camera",
               BUILTIN_SCENES["night-road-fog"], _defaults(dilemma.NightRoadFogScene),
               code_reason="active range-gated light: the gated camera images its range, reflectance and "
                           "fog (an ActiveScene), which a description of passive light does not carry",
               brightness=_native("brightness"), speed=_native("speed")),
    SceneEntry("waving-hand", "a person waving a hand (seed 000 §6): an articulated arm of capsules",
               BUILTIN_SCENES["waving-hand"], _defaults(WavingHandScene),
               code_reason=_CODE + "an articulated arm (the forearm turns about the moving elbow) with a "
                                   "one-pixel soft edge",
               brightness=_scale("wall_lux", "shirt_lux", "skin_lux"), speed=_scale("wave_hz")),
    SceneEntry("multi-object", "seven textured objects crossing a textured background, for detection and "
                               "tracking", BUILTIN_SCENES["multi-object"], _defaults(MultiObjectScene),
               description="multi-object.yaml",
               described_as="the description renders the same light (to 2e-15 relative at 400×250; at other "
                            "sizes it samples pixel centres where the code samples corners) and the same "
                            "labels, boxes, visible fractions and velocities; its flow also marks mixed edge "
                            "pixels invalid",
               brightness=_native("brightness"), speed=_native("speed")),
)}


def entry_settings(name: str, settings: dict | None, where: str = "scene setting", base: dict | None = None) -> dict:
    """Keyword arguments of built-in scene ``name`` from settings: its own parameters by name, and the
    universal ``brightness`` and ``speed`` factors mapped onto them (see :class:`SceneEntry`).

    ``base`` (keyword arguments, e.g. drawn ones) is the starting point: settings replace its values
    by name, and the factors scale its values (the scene's defaults where it has none)."""
    entry = SCENES[name]
    out: dict = dict(base or {})
    for key, value in (settings or {}).items():
        if key in ("brightness", "speed"):
            check_positive(f"{where} {key}", value) if key == "brightness" else None
            if key == "speed" and not (isinstance(value, (int, float)) and value >= 0):
                raise ViformError(f"{where} speed={value!r} is not allowed: it must be a factor ≥ 0")
            mapping = getattr(entry, key)
            if mapping is not None:
                out.update(mapping(float(value), {**entry.parameters, **out}))
            continue
        if key == "peak_lux":
            continue
        if key not in entry.parameters:
            allowed = sorted(set(entry.parameters) | set(UNIVERSAL_SETTINGS))
            raise ViformError(f"{where} {key}={value!r} is not allowed: scene {name!r} takes "
                              f"{', '.join(allowed)}")
        out[key] = tuple(value) if isinstance(value, list) else value
    if "peak_lux" in (settings or {}):
        peak = check_positive(f"{where} peak_lux", settings["peak_lux"])
        probe = BUILTIN_SCENES[name](height=48, width=64, **out)
        nominal = max(float(probe.illuminance_lux(t).max()) for t in (0.0, 0.002, 0.01))
        if entry.brightness is None:
            raise ViformError(f"{where} peak_lux: scene {name!r} has no brightness to set")
        out.update(entry.brightness(peak / nominal, {**entry.parameters, **out}))
    return out


def builtin_scene(name: str, height: int = 250, width: int = 400, **kw) -> Scene:
    """A built-in synthetic scene by name (see :data:`BUILTIN_SCENES`).

    Parameters
    ----------
    name : str
        One of :data:`BUILTIN_SCENES` (``"dilemma"``, ``"moving-edge"``, ``"multi-object"`` ...).
    height, width : int
        Size of the scene, pixels.
    **kw
        The scene's own parameters (see :func:`entry_settings`), e.g. ``velocity_px_per_s``.

    Returns
    -------
    Scene
        The scene, with ``name`` and ``builtin_spec`` recorded so that a capture's metadata can remake
        it (:func:`scene_from_description`).

    Examples
    --------
    >>> scene = builtin_scene("dilemma", height=32, width=48)
    >>> type(scene).__name__, scene.shape, scene.name
    ('DilemmaScene', (32, 48), 'dilemma')
    """
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


def described_scene(spec, height: int | None = None, width: int | None = None, settings: dict | None = None,
                    fit: tuple[int | None, int | None] | None = None) -> DescribedScene:
    """A :class:`~viform.light.layered.DescribedScene` from a description file, a mapping or the name of
    a shipped description; at its canvas size, at ``height`` × ``width``, or fitted (aspect kept).

    Parameters
    ----------
    spec : str, path or dict
        A description file (.yaml, .yml, .json), a mapping, or the name of a shipped description.
    height, width : int, optional
        Size to render at, pixels (default: the description's canvas).
    settings : dict, optional
        Values of the description's named parameters (``brightness``, ``speed`` ...).
    fit : tuple of (int or None, int or None), optional
        (height, width) to fit into keeping the aspect ratio.

    Returns
    -------
    DescribedScene
        The layered scene with its exact truth.
    """
    if isinstance(spec, str) and spec in SCENES and SCENES[spec].description:
        spec = str(SCENES[spec].description_path())
    if isinstance(spec, (str, Path)) and not Path(spec).is_file():
        raise ViformError(f"scene description {str(spec)!r}: no such file")
    description = load_description(spec, settings)
    canvas = description["canvas"]
    native = (canvas["height_px"], canvas["width_px"])
    if height is None and width is None and fit is not None and fit != (None, None):
        height, width = fit_shape(native, *fit)
    universal = {k: v for k, v in (settings or {}).items() if k in UNIVERSAL_SETTINGS}
    return DescribedScene(description, height, width,
                          source=str(Path(spec).resolve()) if isinstance(spec, (str, Path)) else None,
                          settings={**universal, **{k: v for k, v in (settings or {}).items()
                                                     if k not in UNIVERSAL_SETTINGS}})


def scene_from_description(described: dict | None) -> Scene:
    """Remake a capture's scene from the ``scene`` metadata it recorded (its truth included): a
    built-in scene from its name and parameters, a described scene from the description it embeds.

    Raises :class:`~viform.light.truth.TruthUnavailable` for scenes that were neither (an image or
    a video) or whose parameters were not recorded.

    Parameters
    ----------
    described : dict or None
        The ``scene`` metadata of a capture (a sidecar's or a result's).

    Returns
    -------
    Scene
        The scene the capture was made of.
    """
    if isinstance(described, dict) and isinstance(described.get("described"), dict):
        record = described["described"]
        try:
            universal = {k: v for k, v in (record.get("settings") or {}).items() if k in UNIVERSAL_SETTINGS}
            return DescribedScene(record["description"], int(record["height"]), int(record["width"]),
                                  source=record.get("source"), settings=universal)
        except (TypeError, ValueError, KeyError) as exc:
            raise TruthUnavailable(f"the stream's described scene cannot be remade: {one_line(exc)}") from None
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
            raise ViformError(f"{names[0]} {height} {names[1]} {width} would stretch the {w0}×{h0} image "
                              f"(width × height); give only {names[0]} or only {names[1]} to keep its aspect ratio")
        return int(height), int(width)
    if height is not None:
        return int(height), max(1, int(round(w0 * height / h0)))
    return max(1, int(round(h0 * width / w0))), int(width)


def load_scene(spec: str, height: int = 250, width: int = 400, max_lux: float = 4.0,
               frame_rate_hz: float | None = None, interpolation: str = "linear",
               resize: bool = False, fit: tuple[int | None, int | None] | None = None,
               settings: dict | None = None) -> Scene:
    """A scene from a built-in name, a scene description (.yaml, .yml, .json), an image file, a
    video file or a folder of images.

    ``settings`` (name → value) set a built-in scene's parameters (:func:`entry_settings`) or a
    description's (its named parameters, ``brightness``, ``peak_lux``, ``speed``); image and
    video files take none. A description is rendered at its canvas size unless ``resize`` (exactly
    ``height`` × ``width``) or ``fit`` asks for another.

    Integer image and video pixel values map linearly to [0, ``max_lux``] lux; float images
    are lux already. Built-in scenes are made at ``height`` × ``width``; files keep their own
    size unless ``resize`` (to exactly ``height`` × ``width``) or ``fit`` = (height or None,
    width or None), which resizes keeping the aspect ratio (see :func:`fit_shape`).
    ``max_lux`` and ``frame_rate_hz`` are checked for every scene (a built-in one ignores them,
    but a negative full scale or frame rate is a mistake worth saying).

    Parameters
    ----------
    spec : str
        A built-in scene's name, or the path of a description, an image, a video or a folder of images.
    height, width : int
        Size, pixels, of a built-in scene, or of a file's scene when ``resize`` is set.
    max_lux : float
        Illuminance, lux, of an integer image's or video's full scale.
    frame_rate_hz : float or None
        Frame rate of a video or a folder of images, Hz (None: a video file's own).
    interpolation : str
        How a video or image sequence is interpolated between frames (``"linear"`` or ``"hold"``).
    resize : bool
        Resize a file's scene to exactly ``height`` × ``width``.
    fit : tuple of (int or None, int or None), optional
        (height, width) to fit into keeping the aspect ratio (:func:`fit_shape`).
    settings : dict, optional
        Parameter name → value of a built-in scene or a description.

    Returns
    -------
    Scene
        The scene, illuminance in lux on each pixel over time.
    """
    if max_lux is not None:
        check_positive("max_lux", max_lux)
    if frame_rate_hz is not None:
        check_positive("frame_rate_hz", frame_rate_hz)
    if spec in BUILTIN_SCENES:
        return builtin_scene(spec, height, width, **entry_settings(spec, settings))
    if is_description_file(spec):
        return described_scene(spec, height if resize else None, width if resize else None, settings,
                               fit=None if resize else fit)
    if settings:
        raise ViformError(f"scene settings ({', '.join(settings)}) apply to built-in scenes and scene "
                          f"descriptions; {spec!r} is an image or video file")
    path = Path(spec)
    if not path.exists():
        raise ViformError(f"scene {spec!r} is neither a built-in scene ({', '.join(BUILTIN_SCENES)}) "
                          "nor an existing file or folder (a scene description ends in .yaml, .yml or .json)")
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
