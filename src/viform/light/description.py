"""Scene descriptions: a scene as data (YAML or JSON), checked against a JSON Schema.

A description gives, in sensor-plane lux, pixels and seconds, a canvas, a background and
layers, each with a light source, a shape, a motion, a modulation and a depth, and an
optional camera motion. :func:`load_description` reads one, substitutes its named
parameters, validates it (unknown keys are refused, so typos are caught) and returns plain
data that :class:`~viform.light.layered.DescribedScene` renders. Every error is one line that
names the file, the key path (``layers[2].motion.keyframes[1].t_s``), the value and what is
allowed.

Validation uses ``jsonschema`` (the reference implementation of JSON Schema for Python), so
the format is the schema :data:`SCHEMA` and the documentation (``docs/scenes.md``) is made from
it. Checks the schema cannot state (finite numbers, keyframe times in order, image files that
exist) follow it, with the same message form.

Named parameters: ``parameters: {speed_px_per_s: {default: 800, minimum: 0}}`` declares a
setting; the string ``"$speed_px_per_s"`` anywhere in the description stands for its value.
Two settings exist in every description: ``brightness`` (a factor on every illuminance) and
``speed`` (a factor on every motion and on time-dependent modulation of position), and
``peak_lux`` (the brightness factor that makes the brightest nominal level that many lux).
"""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path

from viform._validate import ViformError, one_line

#: Format version written as ``viform_scene``.
FORMAT_VERSION = 1
#: Largest canvas a description may ask for (pixels, each side and in all).
MAX_SIDE_PX = 16384
MAX_PIXELS = 1 << 26
#: Image files a source or mask may name.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".npy", ".exr", ".hdr")
#: Images that ship with scikit-image (public domain or CC0), named ``skimage:NAME`` in a description.
BUNDLED_PREFIX = "skimage:"
BUNDLED_IMAGES = ("astronaut", "camera", "coffee", "chelsea", "rocket", "grass", "gravel", "brick", "coins",
                  "moon", "page", "text", "horse")
#: Settings every description has (besides its own named parameters).
UNIVERSAL_SETTINGS = {
    "brightness": "factor on every illuminance of the scene (1 = as described)",
    "peak_lux": "set the brightness factor so that the brightest nominal level is this many lux",
    "speed": "factor on every motion (positions, angles, scales and their keyframe times)",
}

_NUMBER = {"type": "number"}
_NONNEG = {"type": "number", "minimum": 0}
_POS = {"type": "number", "exclusiveMinimum": 0}
_LUX = {"type": "number", "minimum": 0, "maximum": 1e9, "description": "illuminance on the sensor plane, lux"}
_POINT = {"type": "array", "items": _NUMBER, "minItems": 2, "maxItems": 2}
_SCALE = {"oneOf": [_POS, {"type": "array", "items": _POS, "minItems": 2, "maxItems": 2}]}


def _obj(properties: dict, required=(), description: str = "") -> dict:
    out = {"type": "object", "properties": properties, "additionalProperties": False}
    if required:
        out["required"] = list(required)
    if description:
        out["description"] = description
    return out


def _one_of(description: str, **forms) -> dict:
    """An object with exactly one of ``forms`` as its key."""
    return {"description": description, "oneOf": [_obj({k: v}, [k]) for k, v in forms.items()]}


_LUX_RANGE = {"description": "lux of the source's 0 and full scale: [low, high]",
              "type": "array", "items": _LUX, "minItems": 2, "maxItems": 2}

SOURCE = _one_of(
    "where the layer's light comes from (lux at every point of the layer's own plane)",
    solid=_obj({"lux": _LUX}, ["lux"], "one level everywhere"),
    pattern=_obj({
        "name": {"enum": ["texture", "edge", "bars", "noise", "sines"],
                 "description": "texture: checkerboard and two gratings; edge: a step at u = 0; bars: square "
                                "wave along u; noise: smooth value noise; sines: 1 + depth·sin(2πu/p)·sin(2πv/p) "
                                "from the top-left corner of the layer's rectangle"},
        "period_px": _POS,
        "lux": {"description": "[low, high] (texture, edge, bars, noise) or the mean (sines)",
                "oneOf": [_LUX_RANGE, _LUX]},
        "depth": {"type": "number", "minimum": 0, "maximum": 1, "description": "sines: modulation depth"},
        "seed": {"type": "integer", "minimum": 0, "description": "noise: the lattice's seed"},
        "scale": {"type": "array", "items": _POS, "minItems": 2, "maxItems": 2,
                  "description": "the pattern is evaluated at (u / sx, v / sy)"},
    }, ["name", "lux"], "a built-in procedural pattern in the layer's coordinates (px)"),
    image=_obj({
        "path": {"type": "string", "minLength": 1,
                 "description": "image file, relative to the description's folder (8/16-bit: PNG, JPEG, TIFF, "
                                "BMP; float lux: .npy, .exr, .hdr), or skimage:NAME for an image that ships with "
                                "scikit-image (astronaut, camera, coffee, chelsea, rocket, grass, gravel, brick, …)"},
        "transfer": {"enum": ["srgb", "linear"], "description": "8/16-bit values: sRGB-encoded or linear"},
        "lux": {"description": "8/16-bit images: lux of value 0 and of full scale", **_LUX_RANGE},
        "map": {"enum": ["linear", "log"],
                "description": "value v in [0, 1] → lux: low + (high − low)·v, or low·(high/low)^v"},
        "gain": {"type": "number", "exclusiveMinimum": 0, "description": "float images: factor on the stored lux"},
        "size_px": {"type": "array", "items": _POS, "minItems": 2, "maxItems": 2,
                    "description": "[width, height] of the image on the layer's plane (default: its pixels)"},
        "centre_px": {**_POINT, "description": "where the image's centre lies in the layer's coordinates"},
    }, ["path"], "an image file, centred on the layer's origin"),
    gaussian=_obj({"lux": _LUX, "sigma_px": _POS},
                  ["lux", "sigma_px"], "a Gaussian spot: lux·exp(−r²/2σ²) about the layer's origin"),
)

SHAPE = _one_of(
    "the layer's outline in its own coordinates; pixels at its edge are covered by their exact area",
    rectangle=_obj({"width_px": _POS, "height_px": _POS, "centre_px": _POINT}, ["width_px", "height_px"]),
    ellipse=_obj({"width_px": _POS, "height_px": _POS, "centre_px": _POINT}, ["width_px", "height_px"]),
    polygon=_obj({"points_px": {"type": "array", "items": _POINT, "minItems": 3, "maxItems": 4096}},
                 ["points_px"], "vertices in order (any simple polygon)"),
    alpha=_obj({}, description="the image source's alpha channel"),
    mask=_obj({"path": {"type": "string", "minLength": 1}}, ["path"],
              "a mask image (grey 0 = out, full scale = in), placed as the source image"),
)

_KEYFRAME = _obj({
    "t_s": {"type": "number", "minimum": 0, "description": "instant, s"},
    "position_px": {**_POINT, "description": "where the layer's origin is (x right, y down), px"},
    "angle_rad": {**_NUMBER, "description": "rotation (positive turns x towards y), rad"},
    "scale": _SCALE,
}, ["t_s"])

MOTION = _one_of(
    "how the layer moves: its origin's position, rotation and scale over time",
    velocity=_obj({"px_per_s": _POINT, "rad_per_s": _NUMBER, "scale_per_s": _NUMBER},
                  description="constant velocity through the layer's pose at canvas.time_reference_s"),
    circle=_obj({"centre_px": _POINT, "radius_px": _POS, "rad_per_s": _NUMBER, "phase_rad": _NUMBER},
                ["centre_px", "radius_px", "rad_per_s"],
                "the origin runs on a circle (phase_rad: its angle at canvas.time_reference_s)"),
    keyframes=_obj({"keys": {"type": "array", "items": _KEYFRAME, "minItems": 1, "maxItems": 100000},
                    "interpolation": {"enum": ["linear", "spline"]}}, ["keys"],
                   "poses at instants, interpolated (held before the first and after the last)"),
)

MODULATION = _one_of(
    "a factor m(t) on the layer's light",
    pwm=_obj({"frequency_hz": _POS, "duty": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1},
              "low": _NONNEG, "phase_s": _NUMBER}, ["frequency_hz", "duty"],
             "1 during the first `duty` of each period, `low` otherwise"),
    sine=_obj({"frequency_hz": _POS, "depth": {"type": "number", "minimum": 0, "maximum": 1},
               "phase_rad": _NUMBER}, ["frequency_hz", "depth"], "1 + depth·sin(2πft + phase)"),
    square=_obj({"frequency_hz": _POS, "depth": {"type": "number", "minimum": 0, "maximum": 1}},
                ["frequency_hz", "depth"], "1 + depth·sign(sin 2πft)"),
    step=_obj({"t_s": _NONNEG, "factor": _NONNEG}, ["t_s", "factor"], "1 before t_s, factor after"),
)

DEPTH = {"description": "distance of the layer's plane from the camera, m (occlusion follows it)",
         "oneOf": [_POS, _obj({"depth_m": _POS, "slope_m_per_px": _POINT}, ["depth_m"],
                              "a tilted plane: depth_m + sx·u + sy·v at layer point (u, v)")]}

_POSE = {
    "position_px": {**_POINT, "description": "the layer's origin at canvas.time_reference_s (default 0 s), px"},
    "angle_rad": {**_NUMBER, "description": "rotation at that instant, rad"},
    "scale": {**_SCALE, "description": "scale at that instant"},
}

LAYER = _obj({
    "name": {"type": "string"},
    "object": _obj({"id": {"type": "integer", "minimum": 1, "maximum": 1 << 30}, "class": {"type": "string"}},
                   ["id"], "an object for detection and tracking truth"),
    "source": SOURCE,
    "shape": SHAPE,
    **_POSE,
    "motion": MOTION,
    "modulation": MODULATION,
    "depth_m": DEPTH,
    "blend": {"enum": ["over", "add"], "description": "over: covers what is behind; add: light adds (glows)"},
}, ["source"], "one layer of the scene")

BACKGROUND = _obj({"source": SOURCE, **_POSE, "motion": MOTION, "modulation": MODULATION, "depth_m": DEPTH},
                  ["source"], "the layer behind everything; it fills the field")

CAMERA = _obj({
    "motion": {**MOTION, "description": "pan (position_px), roll (angle_rad) and zoom (scale) of the whole view "
                                        "about the canvas centre"},
    "shake": _obj({"amplitude_px": _NONNEG, "frequency_hz": _POS, "seed": {"type": "integer", "minimum": 0}},
                  ["amplitude_px", "frequency_hz"], "a hand-held shake: three sines per axis, seeded phases"),
}, description="motion of the whole view")

_PARAMETER = _obj({"default": {}, "minimum": _NUMBER, "maximum": _NUMBER, "unit": {"type": "string"},
                   "doc": {"type": "string"}}, ["default"])

SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "viform scene description",
    **_obj({
        "viform_scene": {"const": FORMAT_VERSION, "description": "format version"},
        "name": {"type": "string", "minLength": 1},
        "summary": {"type": "string"},
        "canvas": _obj({
            "width_px": {"type": "integer", "minimum": 1, "maximum": MAX_SIDE_PX},
            "height_px": {"type": "integer", "minimum": 1, "maximum": MAX_SIDE_PX},
            "duration_s": {"type": "number", "exclusiveMinimum": 0, "maximum": 1e6},
            "time_reference_s": {"type": "number", "minimum": 0, "maximum": 1e6,
                                 "description": "the speed setting scales motion about this instant, s (paths "
                                                "written about it keep their meeting there)"},
        }, ["width_px", "height_px"], "the field in pixels; --height/--width scale every position and size"),
        "parameters": {"type": "object", "additionalProperties": _PARAMETER,
                       "propertyNames": {"pattern": "^[a-z][a-z0-9_]*$"},
                       "description": "named settings; \"$name\" in a value stands for the setting"},
        "background": BACKGROUND,
        "layers": {"type": "array", "items": LAYER, "maxItems": 1024},
        "camera": CAMERA,
    }, ["viform_scene", "name", "canvas", "background"]),
}

_REF = re.compile(r"^\$([a-z][a-z0-9_]*)$")


class DescriptionError(ViformError):
    """A scene description that cannot be used; the message names the file and the key path."""


def key_path(parts) -> str:
    """``("layers", 2, "motion")`` → ``"layers[2].motion"``."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def _short(value, limit: int = 60) -> str:
    text = json.dumps(value, default=str) if not isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _fail(origin: str, path, value, allowed: str):
    where = key_path(path)
    shown = "" if value is _MISSING else f" = {_short(value)}"
    raise DescriptionError(f"{origin}: {where}{shown} is not allowed: {allowed}")


_MISSING = object()


def _schema_message(error) -> tuple[list, object, str]:
    """(key path, value, what is allowed) of a jsonschema error."""
    path = list(error.absolute_path)
    v, s = error.validator, error.validator_value
    value = error.instance
    if v == "additionalProperties":
        extra = sorted(set(error.instance) - set(error.schema.get("properties", {})))
        allowed = ", ".join(sorted(error.schema.get("properties", {}))) or "none"
        return path + [extra[0]], _MISSING, f"unknown key (allowed here: {allowed})"
    if v == "required":
        missing = [k for k in s if k not in error.instance]
        return path + [missing[0]], _MISSING, "this key is required"
    if v == "oneOf":
        forms = []
        for sub in s:
            forms.extend(sub.get("required", []))
        if isinstance(value, dict) and forms:
            given = [k for k in value if k in forms]
            if len(given) != 1:
                return path, value, f"give exactly one of: {', '.join(forms)}"
            # the one form given is wrong inside: report the error under it
            inner = [e for e in error.context if list(e.absolute_path)[len(path):len(path) + 1] == [given[0]]]
            if inner:
                from jsonschema.exceptions import best_match

                return _schema_message(best_match(inner))
        types = [sub.get("type") for sub in s if "type" in sub]
        if types:
            return path, value, f"it must be {' or '.join(map(str, types))} of the allowed form"
        return path, value, "it matches none of the allowed forms"
    text = {
        "minimum": lambda: f"it must be ≥ {s:g}",
        "maximum": lambda: f"it must be ≤ {s:g}",
        "exclusiveMinimum": lambda: f"it must be > {s:g}",
        "exclusiveMaximum": lambda: f"it must be < {s:g}",
        "type": lambda: f"it must be of type {s if isinstance(s, str) else ' or '.join(s)}",
        "enum": lambda: f"choose one of {', '.join(map(str, s))}",
        "const": lambda: f"it must be {s!r}",
        "minItems": lambda: f"it needs at least {s} items",
        "maxItems": lambda: f"it may hold at most {s} items",
        "minLength": lambda: "it must not be empty",
        "pattern": lambda: f"it must match {s}",
    }.get(v)
    if v == "propertyNames":
        return path, value, "parameter names are lower case letters, digits and _ , starting with a letter"
    return path, value, text() if text else one_line(error)


def _check_numbers(node, path, origin):
    """Refuse NaN and infinities anywhere (the schema's bounds do not catch NaN)."""
    if isinstance(node, float) and not math.isfinite(node):
        _fail(origin, path, node, "it must be a finite number")
    if isinstance(node, dict):
        for k, v in node.items():
            _check_numbers(v, path + [k], origin)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            _check_numbers(v, path + [i], origin)


def _substitute(node, values, path, origin, used):
    if isinstance(node, str):
        m = _REF.match(node)
        if m:
            name = m.group(1)
            if name not in values:
                _fail(origin, path, node, f"no parameter {name!r} is declared under parameters "
                                          f"(declared: {', '.join(sorted(values)) or 'none'})")
            used.add(name)
            return copy.deepcopy(values[name])
        return node
    if isinstance(node, dict):
        return {k: _substitute(v, values, path + [k], origin, used) for k, v in node.items()}
    if isinstance(node, list):
        return [_substitute(v, values, path + [i], origin, used) for i, v in enumerate(node)]
    return node


def read_document(path) -> dict:
    """The raw mapping in a YAML or JSON file; a file that cannot be read or parsed is named."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DescriptionError(f"scene description {str(path)!r} could not be read: {one_line(exc)}") from None
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import yaml

            data = yaml.safe_load(text)
    except Exception as exc:  # yaml and json raise their own types
        raise DescriptionError(f"scene description {str(path)!r} is not valid "
                               f"{'JSON' if path.suffix.lower() == '.json' else 'YAML'}: {one_line(exc)}") from None
    if not isinstance(data, dict):
        raise DescriptionError(f"scene description {str(path)!r} must hold a mapping (keys and values); "
                               f"it holds {type(data).__name__}")
    return data


def parameter_values(document: dict, settings: dict | None = None, origin: str = "description") -> dict:
    """The named parameters' values: defaults, then ``settings`` (checked against their bounds)."""
    declared = document.get("parameters") or {}
    values = {}
    for name, spec in declared.items():
        values[name] = spec.get("default") if isinstance(spec, dict) else None
    for name, value in (settings or {}).items():
        if name in UNIVERSAL_SETTINGS:
            continue
        if name not in declared:
            raise DescriptionError(f"{origin}: setting {name}={_short(value)} is not allowed: the scene's settings "
                                   f"are {', '.join(sorted(set(declared) | set(UNIVERSAL_SETTINGS)))}")
        spec = declared[name]
        if isinstance(spec.get("default"), (int, float)) and not isinstance(spec.get("default"), bool):
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise DescriptionError(f"{origin}: setting {name}={_short(value)} is not allowed: "
                                       "it must be a number") from None
            if not math.isfinite(value):
                raise DescriptionError(f"{origin}: setting {name}={value!r} is not allowed: it must be finite")
            lo, hi = spec.get("minimum"), spec.get("maximum")
            if (lo is not None and value < lo) or (hi is not None and value > hi):
                raise DescriptionError(f"{origin}: setting {name}={value:g} is not allowed: it must lie in "
                                       f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]")
        values[name] = value
    return values


def validate(document: dict, origin: str = "description", settings: dict | None = None,
             base_dir=None) -> dict:
    """Substitute the named parameters, validate against :data:`SCHEMA` and the checks it cannot
    state; return the resolved description (a new dict, image paths made absolute)."""
    import jsonschema

    if not isinstance(document, dict):
        raise DescriptionError(f"{origin}: a scene description is a mapping; got {type(document).__name__}")
    params = document.get("parameters")
    if params is not None:
        validator = jsonschema.Draft202012Validator({"type": "object", "additionalProperties": _PARAMETER,
                                                     "propertyNames": SCHEMA["properties"]["parameters"][
                                                         "propertyNames"]})
        for error in validator.iter_errors(params):
            path, value, allowed = _schema_message(error)
            _fail(origin, ["parameters"] + path, value, allowed)
    values = parameter_values(document, settings, origin)
    used: set = set()
    resolved = {k: (_substitute(v, values, [k], origin, used) if k != "parameters" else copy.deepcopy(v))
                for k, v in document.items()}
    _check_numbers({k: v for k, v in resolved.items() if k != "parameters"}, [], origin)
    validator = jsonschema.Draft202012Validator(SCHEMA)
    errors = sorted(validator.iter_errors(resolved), key=lambda e: (len(list(e.absolute_path)), str(e.path)))
    if errors:
        from jsonschema.exceptions import best_match

        path, value, allowed = _schema_message(best_match(errors))
        _fail(origin, path, value, allowed)
    canvas = resolved["canvas"]
    if canvas["width_px"] * canvas["height_px"] > MAX_PIXELS:
        _fail(origin, ["canvas"], [canvas["width_px"], canvas["height_px"]],
              f"at most {MAX_PIXELS:,} pixels in all")
    layers = resolved.get("layers", [])
    with_depth = [i for i, layer in enumerate(layers) if "depth_m" in layer]
    if with_depth and len(with_depth) != len(layers):
        i = next(i for i in range(len(layers)) if i not in with_depth)
        _fail(origin, ["layers", i, "depth_m"], _MISSING,
              f"required when another layer has a depth (layers[{with_depth[0]}] does)")
    ids = {}
    for i, layer in enumerate(layers):
        if "object" in layer:
            oid = layer["object"]["id"]
            if oid in ids:
                _fail(origin, ["layers", i, "object", "id"], oid, f"ids are unique; layers[{ids[oid]}] has it")
            ids[oid] = i
        shape = layer.get("shape", {})
        if "alpha" in shape and "image" not in layer["source"]:
            _fail(origin, ["layers", i, "shape", "alpha"], {}, "an alpha shape needs an image source")
        if "mask" in shape and "image" not in layer["source"]:
            _fail(origin, ["layers", i, "shape", "mask"], shape["mask"], "a mask is placed as the source image: "
                                                                         "give an image source")
    for where, node in _with_motion(resolved):
        keys = node.get("motion", {}).get("keyframes", {}).get("keys")
        if keys:
            for j in range(1, len(keys)):
                if not keys[j]["t_s"] > keys[j - 1]["t_s"]:
                    _fail(origin, where + ["motion", "keyframes", "keys", j, "t_s"], keys[j]["t_s"],
                          f"keyframe instants must increase (the one before is {keys[j - 1]['t_s']:g} s)")
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    for where, source_path, node in _files(resolved):
        if str(node[source_path[-1]]).startswith(BUNDLED_PREFIX):
            name = str(node[source_path[-1]])[len(BUNDLED_PREFIX):]
            if name not in BUNDLED_IMAGES:
                _fail(origin, where, node[source_path[-1]], f"bundled images: {', '.join(BUNDLED_IMAGES)}")
            continue
        file = Path(node[source_path[-1]])
        if not file.is_absolute():
            file = base / file
        if file.suffix.lower() not in IMAGE_SUFFIXES:
            _fail(origin, where, str(node[source_path[-1]]),
                  f"an image file ({', '.join(IMAGE_SUFFIXES)})")
        if not file.is_file():
            _fail(origin, where, str(node[source_path[-1]]), f"no such image file ({file})")
        node[source_path[-1]] = str(file.resolve())
    resolved["parameters"] = {k: {**(document.get("parameters") or {})[k], "value": values[k]} for k in values}
    return resolved


def _with_motion(doc):
    if "background" in doc:
        yield ["background"], doc["background"]
    for i, layer in enumerate(doc.get("layers", [])):
        yield ["layers", i], layer
    if "camera" in doc:
        yield ["camera"], doc["camera"]


def _files(doc):
    for where, node in _with_motion(doc):
        image = node.get("source", {}).get("image") if isinstance(node.get("source"), dict) else None
        if image is not None:
            yield where + ["source", "image", "path"], ["path"], image
        mask = node.get("shape", {}).get("mask") if isinstance(node.get("shape"), dict) else None
        if mask is not None:
            yield where + ["shape", "mask", "path"], ["path"], mask


def load_description(spec, settings: dict | None = None) -> dict:
    """A validated description from a file path (YAML/JSON) or a mapping (image paths relative to
    the current folder).

    Parameters
    ----------
    spec : str, path or dict
        A YAML/JSON description file or the description itself.
    settings : dict, optional
        Values of the description's named parameters and the universal settings
        (:data:`UNIVERSAL_SETTINGS`).

    Returns
    -------
    dict
        The validated description, settings applied and defaults filled in.
    """
    if isinstance(spec, dict):
        return validate(spec, "description", settings)
    path = Path(spec)
    return validate(read_document(path), str(path), settings, base_dir=path.parent)


def is_description_file(spec) -> bool:
    """Whether ``spec`` names a scene description (by its suffix: .yaml, .yml, .json)."""
    return isinstance(spec, (str, Path)) and Path(spec).suffix.lower() in (".yaml", ".yml", ".json")


def parse_settings(text: str | None, flag: str = "--scene-set") -> dict:
    """``"brightness=300,speed=0.5"`` → {"brightness": 300.0, "speed": 0.5}; numbers where they parse."""
    out: dict = {}
    if not text:
        return out
    for item in re.split(r",(?![^\[]*\])", text):
        item = item.strip()
        if not item:
            continue
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ViformError(f"{flag} = {text!r} is not allowed: give NAME=VALUE pairs separated by commas "
                              "(e.g. brightness=2,speed=0.5)")
        value = value.strip()
        try:
            parsed = json.loads(value)
        except ValueError:
            parsed = value
        if isinstance(parsed, float) and not math.isfinite(parsed) or value.lower() in ("nan", "inf", "-inf"):
            raise ViformError(f"{flag}: {name}={value} is not allowed: it must be a finite number")
        out[name] = parsed
    return out


def schema_reference() -> str:
    """The format's keys as a Markdown list, made from :data:`SCHEMA` (docs/scenes.md includes it)."""
    lines: list[str] = []

    def kind(node) -> str:
        if "enum" in node:
            return " | ".join(map(str, node["enum"]))
        if "const" in node:
            return repr(node["const"])
        t = node.get("type")
        if t == "array":
            item = node.get("items", {})
            more = "" if node.get("maxItems") == node.get("minItems") else "…"
            return f"[{kind(item)} × {node.get('minItems', '')}{more}]"
        if "oneOf" in node:
            forms = [next(iter(sub.get("required", [])), kind(sub)) for sub in node["oneOf"]]
            return "one of: " + ", ".join(forms)
        bounds = []
        for key, sym in (("minimum", "≥"), ("exclusiveMinimum", ">"), ("maximum", "≤"), ("exclusiveMaximum", "<")):
            if key in node:
                bounds.append(f"{sym} {node[key]:g}")
        return (t or "any") + (f" ({', '.join(bounds)})" if bounds else "")

    def walk(node, path, depth):
        if "oneOf" in node and all(sub.get("type") == "object" for sub in node["oneOf"]):
            for sub in node["oneOf"]:
                name = sub["required"][0]
                inner = sub["properties"][name]
                lines.append(f"{'  ' * depth}- `{path}.{name}`: {inner.get('description', '')}")
                walk(inner, f"{path}.{name}", depth + 1)
            return
        for name, child in node.get("properties", {}).items():
            req = " (required)" if name in node.get("required", []) else ""
            here = f"{path}.{name}" if path else name
            desc = child.get("description", "")
            lines.append(f"{'  ' * depth}- `{here}`{req}: {kind(child)}{' — ' + desc if desc else ''}")
            target = child.get("items", child) if child.get("type") == "array" else child
            walk(target, here + ("[i]" if child.get("type") == "array" else ""), depth + 1)

    walk(SCHEMA, "", 0)
    return "\n".join(lines) + "\n"
