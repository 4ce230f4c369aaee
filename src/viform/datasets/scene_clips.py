"""Training clips made from the built-in scenes, with parameters drawn per clip, and their truth files.

Files carry no truth; the built-in scenes know theirs exactly (:mod:`viform.light.truth`). A
dataset of scene clips draws, for each clip, the scene's parameters — speeds, directions,
brightness, texture, object count and sizes where the scene has them — from a random generator
seeded by the dataset seed and the clip's name (the randomization SPCS used for the SPIFT flow
set, here with exact photon statistics), records them in the clip's sidecar, and writes the
truth beside the spikes.

Truth layout, per clip (frames count output steps from 1, as MOTChallenge does: step k covers
ticks [(k − 1)·N, k·N) and its truth is taken at the end of the step, t_k = k·N / clock):

::

    gt/<clip>_<k>.png        the light at t_k for a person to look at: sRGB-encoded, white = the clip's
                             display scale (its 99.5th percentile of lux, recorded as display_white_lux)
    gt_lux/<clip>_<k>.npy    the light at t_k in lux, float32 (the truth itself)
    flow/<clip>_<k>.flo      forward flow t_k → t_{k+1}, px, Middlebury .flo (what SCFlow/SpikeCV
                             read); occluded or leaving pixels stored as unknown (1e10)
    depth/<clip>_<k>.npy     range (m) per pixel, float32, inf where no surface (scenes with range)
    mot/<clip>/gt/gt.txt     MOTChallenge object truth (frame, id, x, y, w, h, conf, class, visibility)
    mot/<clip>/seqinfo.ini   frame step in ticks, clock, size, class names
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from viform._io import atomic_open, save_image
from viform._validate import ViformError, check_int
from viform.datasets.layout import GT_DIR, clip_seed, sha256_file
from viform.light.catalog import BUILTIN_SCENES, builtin_scene

FLOW_DIR = "flow"
LUX_DIR = "gt_lux"
#: A clip is flagged too dark for its preset when a pixel fires, on average, less than once per truth step.
DARK_SPIKES_PER_STEP = 1.0
DEPTH_DIR = "depth"
MOT_DIR = "mot"
#: Folder of the scene descriptions of drawn described scenes (``<clip>.yaml``).
DESCRIPTION_DIR = "scenes"
#: Suffix of a clip's clean twin (same light and seed, photon noise and fixed patterns off).
CLEAN_SUFFIX = "-clean"


def _log_uniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _direction(rng, speed):
    angle = rng.uniform(0, 2 * math.pi)
    return [speed * math.cos(angle), speed * math.sin(angle)]


def _pattern_light(rng, full_scale_lux):
    top = full_scale_lux * rng.uniform(0.15, 1.0)
    return {"max_lux": top, "min_lux": top * rng.uniform(0.03, 0.4),
            "pattern": str(rng.choice(["texture", "texture", "bars", "edge"])),
            "period_px": float(rng.uniform(16.0, 64.0))}


#: Scene name → draw(rng, full-scale lux) → keyword arguments of :func:`builtin_scene`.
RANDOMIZERS = {
    "translating": lambda rng, fs: {**_pattern_light(rng, fs),
                                    "velocity_px_per_s": _direction(rng, _log_uniform(rng, 100.0, 8000.0))},
    "moving-edge": lambda rng, fs: {"max_lux": fs * rng.uniform(0.15, 1.0), "min_lux": fs * rng.uniform(0.005, 0.1),
                                    "velocity_px_per_s": _direction(rng, _log_uniform(rng, 100.0, 8000.0))},
    "rotating": lambda rng, fs: {**_pattern_light(rng, fs),
                                 "angular_speed_rad_per_s": float(rng.choice([-1, 1]) * _log_uniform(rng, 2.0, 80.0))},
    "dilemma": lambda rng, fs: {"brightness": _log_uniform(rng, 0.1, 10.0), "speed": _log_uniform(rng, 0.25, 3.0)},
    "night-road-fog": lambda rng, fs: {"visibility_m": _log_uniform(rng, 50.0, 500.0),
                                       "brightness": _log_uniform(rng, 0.3, 30.0)},
    "waving-hand": lambda rng, fs: {"wall_lux": fs * rng.uniform(0.05, 0.4), "shirt_lux": fs * rng.uniform(0.02, 0.2),
                                    "skin_lux": fs * rng.uniform(0.3, 1.0), "wave_hz": rng.uniform(1.0, 8.0),
                                    "forearm_amplitude_rad": rng.uniform(0.3, 1.0)},
    "multi-object": lambda rng, fs: {"brightness": _log_uniform(rng, 0.1, 10.0), "speed": _log_uniform(rng, 0.3, 2.0),
                                     "background": str(rng.choice(["texture", "plain"])),
                                     "background_lux": fs * _log_uniform(rng, 0.002, 0.2)},
    "hdr": lambda rng, fs: {"min_lux": fs * _log_uniform(rng, 1e-4, 1e-2), "decades": rng.uniform(3.0, 6.0)},
}


#: The scene of natural images cut into moving layers (:mod:`viform.light.random_layers`).
RANDOM_LAYERS = "random-layers"
#: Every name ``--scenes`` takes.
SCENE_CHOICES = (*RANDOMIZERS, RANDOM_LAYERS)


def _parameters_rng(clip: str, dataset_seed: int):
    return np.random.default_rng(clip_seed(dataset_seed, f"parameters/{clip}"))


def scene_parameters(scene: str, clip: str, dataset_seed: int, full_scale_lux: float,
                     settings: dict | None = None) -> dict:
    """The drawn parameters of one clip of a built-in scene: a pure function of (dataset seed, clip
    name), JSON values; ``settings`` (name → value, as ``--scene-set`` gives them) then fix named
    parameters and scale the drawn ones by the ``brightness`` and ``speed`` factors
    (:func:`viform.light.catalog.entry_settings`)."""
    if scene not in RANDOMIZERS:
        raise ViformError(f"--scenes {scene!r} is not allowed: choose among {', '.join(SCENE_CHOICES)}")
    drawn = RANDOMIZERS[scene](_parameters_rng(clip, dataset_seed), float(full_scale_lux))
    drawn = json.loads(json.dumps(drawn, default=float))
    if settings:
        from viform.light.catalog import entry_settings

        drawn = entry_settings(scene, settings, "--scene-set", base=drawn)
    return json.loads(json.dumps(drawn, default=float))


def random_layers_ranges(settings: dict | None, full_scale_lux: float) -> dict:
    """The generator's ranges for a dataset: its defaults with ``peak_lux`` at the sensor's full scale,
    then ``settings`` (``--scene-set``): any range or scalar of :mod:`viform.light.random_layers` by
    name, ``brightness`` (a factor on peak_lux) and ``speed`` (a factor on every speed and rate range)."""
    from viform.light.random_layers import check_ranges

    settings = dict(settings or {})
    factors = {k: settings.pop(k) for k in ("brightness", "speed") if k in settings}
    ranges = check_ranges({"peak_lux": float(full_scale_lux), **settings}, "--scene-set")
    for key, value in factors.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ViformError(f"--scene-set {key}={value!r} is not allowed: it must be a finite factor > 0")
    if "brightness" in factors:
        ranges["peak_lux"] *= float(factors["brightness"])
    if "speed" in factors:
        for key in ("speed_px_per_s", "rotation_rad_per_s", "scale_per_s", "camera_speed_px_per_s"):
            ranges[key] = [v * float(factors["speed"]) for v in ranges[key]]
    return check_ranges(ranges, "--scene-set")


def random_layers_clip(clip: str, dataset_seed: int, height: int, width: int, duration_s: float,
                       ranges: dict, images=None) -> tuple[dict, dict]:
    """(description, drawn parameters) of one random-layers clip, drawn from the clip's own seed
    (a pure function of the dataset seed and the clip's name)."""
    from viform.light.random_layers import random_layers

    seed = clip_seed(dataset_seed, f"parameters/{clip}")
    description, drawn = random_layers(np.random.default_rng(seed), height, width, duration_s, images, **ranges)
    drawn["seed"] = seed
    return json.loads(json.dumps(description)), json.loads(json.dumps(drawn))


def parse_scene_list(text: str) -> list[str]:
    """``--scenes a,b,c`` → names, each a built-in scene with drawn parameters."""
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    if not names:
        raise ViformError("--scenes is empty: give built-in scene names, e.g. --scenes translating,multi-object")
    for name in names:
        if name not in SCENE_CHOICES:
            known = name in BUILTIN_SCENES
            raise ViformError(f"--scenes {name!r} is not allowed: " + (
                "it has no parameters to draw; " if known else "") + f"choose among {', '.join(SCENE_CHOICES)}")
    if len(set(names)) != len(names):
        raise ViformError(f"--scenes {text!r} names a scene twice")
    return names


def truth_times(n_ticks: int, step_ticks: int, clock_hz: float) -> np.ndarray:
    """Truth instants t_k = k·N / clock for the whole steps k = 1 … ⌊T / N⌋ of a stream (s)."""
    step_ticks = check_int("--truth-every-ticks", step_ticks, 1)
    return np.arange(1, n_ticks // step_ticks + 1) * step_ticks / clock_hz


def truth_name(clip: str, frame: int, suffix: str) -> str:
    return f"{clip}_{frame:06d}{suffix}"


def write_truth(out, clip: str, scene, n_ticks: int, step_ticks: int, clock_hz: float, max_lux: float,
                detectability=None) -> dict:
    """Write a clip's truth files under ``out`` (layout in the module notes); returns their records.

    ``detectability`` (:mod:`viform.vision.detectability`) fills gt.txt's detectability column.

    Returns
    -------
    dict
        ``frames``: per step {frame, time_s, tick (the step's last tick), file, sha256, flow,
        flow_sha256, depth, depth_sha256}; ``mot``: {gt, seqinfo, sha256} or None; ``kinds``.
    """
    from viform.vision.flow import write_flo

    out = Path(out)
    kinds = scene.truth_kinds()
    times = truth_times(n_ticks, step_ticks, clock_hz)
    frames = []
    white = display_white_lux(scene, times)
    for k, t in enumerate(times, start=1):
        record = {"frame": k, "time_s": float(t), "tick": int(k * step_ticks - 1)}
        lux = scene.illuminance_lux(float(t))
        name = truth_name(clip, k, ".png")
        save_image(out / GT_DIR / name, display_image(lux, white))
        record.update(file=name, sha256=sha256_file(out / GT_DIR / name), display_white_lux=white,
                      display_transfer="srgb")
        name = truth_name(clip, k, ".npy")
        with atomic_open(out / LUX_DIR / name, "wb") as f:
            np.save(f, lux.astype(np.float32))
        record.update(lux_file=name, lux_sha256=sha256_file(out / LUX_DIR / name))
        if "motion" in kinds and k < len(times):
            flow = scene.optical_flow_px(float(t), float(times[k]))
            name = truth_name(clip, k, ".flo")
            write_flo(out / FLOW_DIR / name, flow.flow_px, flow.valid)
            record.update(flow=name, flow_sha256=sha256_file(out / FLOW_DIR / name))
        if "depth" in kinds:
            name = truth_name(clip, k, ".npy")
            with atomic_open(out / DEPTH_DIR / name, "wb") as f:
                np.save(f, scene.depth_m(float(t)).astype(np.float32))
            record.update(depth=name, depth_sha256=sha256_file(out / DEPTH_DIR / name))
        frames.append(record)
    mot = None
    if "objects" in kinds and len(times):
        from viform.vision.motchallenge import gt_rows, write_gt, write_seqinfo

        rows, classes = gt_rows(scene, times, detectability=detectability, return_class_ids=True)
        folder = out / MOT_DIR / clip
        write_gt(folder / "gt" / "gt.txt", rows)
        write_seqinfo(folder / "seqinfo.ini", name=clip, n_frames=len(times), step_ticks=step_ticks,
                      clock_hz=clock_hz, width=scene.width, height=scene.height, classes=classes)
        digest = hashlib.sha256()
        for part in ("gt/gt.txt", "seqinfo.ini"):
            digest.update((folder / part).read_bytes())
        mot = {"gt": f"{MOT_DIR}/{clip}/gt/gt.txt", "seqinfo": f"{MOT_DIR}/{clip}/seqinfo.ini",
               "sha256": digest.hexdigest(), "classes": classes}
    return {"frames": frames, "mot": mot, "kinds": list(kinds)}


def write_description(out, clip: str, description: dict) -> dict:
    """Write a clip's scene description to ``scenes/<clip>.yaml`` (``viform simulate`` remakes the scene
    from it); returns {file, sha256}."""
    import yaml

    path = Path(out) / DESCRIPTION_DIR / f"{clip}.yaml"
    first = ("viform_scene", "name", "summary", "canvas", "background", "layers", "camera")
    description = {**{k: description[k] for k in first if k in description},
                   **{k: v for k, v in description.items() if k not in first}}
    text = (f"# the scene of dataset clip {clip}: viform simulate {DESCRIPTION_DIR}/{clip}.yaml remakes it\n"
            + yaml.safe_dump(description, sort_keys=False, allow_unicode=True))
    with atomic_open(path, "wb") as f:
        f.write(text.encode("utf-8"))
    return {"file": f"{DESCRIPTION_DIR}/{clip}.yaml", "sha256": sha256_file(path)}


def display_white_lux(scene, times) -> float:
    """The lux shown as white in a clip's display PNGs: the 99.5th percentile of its light at its first,
    middle and last truth instants (one scale for the whole clip, so frames compare)."""
    if len(times) == 0:
        return 1.0
    picks = sorted({0, len(times) // 2, len(times) - 1})
    values = np.concatenate([scene.illuminance_lux(float(times[i])).ravel() for i in picks])
    white = float(np.percentile(values, 99.5))
    return white if white > 0 else max(float(values.max()), 1e-12)


def display_image(lux: np.ndarray, white_lux: float) -> np.ndarray:
    """8-bit sRGB-encoded image of a lux frame: 255·srgb(clip(lux / white_lux, 0, 1)) (IEC 61966-2-1)."""
    v = np.clip(lux / white_lux, 0.0, 1.0)
    encoded = np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)
    return np.rint(255.0 * encoded).astype(np.uint8)


def too_dark(spikes: int, ticks: int, pixels: int, step_ticks: int) -> dict:
    """Whether a clip is too dark for its preset: a pixel fires fewer than :data:`DARK_SPIKES_PER_STEP`
    times per truth step on average, so most pixels hold no spike in a truth frame."""
    per_step = spikes / max(1, ticks * pixels) * step_ticks
    return {"too_dark": bool(per_step < DARK_SPIKES_PER_STEP), "spikes_per_pixel_per_truth_step": per_step}


def truth_intact(out, record: dict) -> bool:
    """True when every truth file a finished clip's record names is on disk with its recorded hash."""
    out = Path(out)
    for frame in record.get("gt_frames", []):
        for key, folder in (("flow", FLOW_DIR), ("depth", DEPTH_DIR), ("lux", LUX_DIR)):
            if key == "lux":
                name = frame.get("lux_file")
                if name is not None and (not (out / folder / name).is_file()
                                         or sha256_file(out / folder / name) != frame.get("lux_sha256")):
                    return False
                continue
            name = frame.get(key)
            if name is not None:
                path = out / folder / name
                if not path.is_file() or sha256_file(path) != frame.get(f"{key}_sha256"):
                    return False
    described = record.get("description_file")
    if described and (not (out / described["file"]).is_file()
                      or sha256_file(out / described["file"]) != described.get("sha256")):
        return False
    mot = record.get("mot")
    if mot:
        digest = hashlib.sha256()
        for part in (mot["gt"], mot["seqinfo"]):
            path = out / part
            if not path.is_file():
                return False
            digest.update(path.read_bytes())
        if digest.hexdigest() != mot.get("sha256"):
            return False
    return True


def make_scene(clip_source) -> object:
    """The scene of a scene clip (:class:`~viform.datasets.sources.SourceClip` of kind ``"scene"``)."""
    spec = json.loads(clip_source.path)
    if "description" in spec:
        from viform.light.layered import DescribedScene

        return DescribedScene(spec["description"], spec["height"], spec["width"], source=spec["scene"])
    return builtin_scene(spec["scene"], spec["height"], spec["width"],
                         **{k: tuple(v) if isinstance(v, list) else v for k, v in spec["parameters"].items()})
