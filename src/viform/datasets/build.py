"""Convert a folder of video clips into a spike dataset, clip by clip, on dask.distributed.

Each clip is an independent task (:func:`convert_clip`): its frames become a
:class:`~viform.light.scenes.VideoScene` (frame k is the light at k / frame_rate_hz, linear
in between), the spike camera (seed 000 §3.2, exact Poisson photon statistics, seed 000 §5.1)
reads it on its clock, and the bits are packed and written block by block into
``spike/<clip>.dat`` while their SHA-256 and spike count are accumulated — the clip's spike
stream is never held whole. Ground-truth PNGs are the source frames at the sensor's size.

Determinism: the clip's seed is :func:`~viform.datasets.layout.clip_seed` (dataset seed,
clip name), and the simulator gives the same bits whatever its block size, so the dataset's
bits do not depend on the number of workers or the order in which they finish.

Resuming: a clip is finished when its sidecar (written last) names the run's settings and
the ``.dat`` on disk has the SHA-256 and every ground-truth PNG the hash the sidecar records;
such clips are skipped, anything else is redone from scratch. Every file is written under a
temporary name and renamed (:mod:`viform._io`), so a killed worker leaves at most a stale
temporary file, which the next attempt removes.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from viform._io import atomic_open, check_output_folder, save_image, write_json
from viform._parallel import (
    DEFAULT_CONNECT_TIMEOUT_S,
    SchedulerLost,
    completed,
    one_line_warnings,
    open_client,
    parse_memory,
)
from viform._validate import ViformError, check_choice, check_int, check_positive, one_line
from viform.datasets.layout import (
    CONFIG_NAME,
    GT_DIR,
    LAYOUT_FORMAT,
    MANIFEST_NAME,
    SPIKE_DIR,
    clip_seed,
    gt_name,
    read_config,
    sha256_file,
    write_config,
)
from viform.datasets.sources import SourceClip, describe_fit, find_clips, lux_to_gt_image, read_clip

#: Preset used when none is given: the 400×250, 40 kHz chip of seed 000 §6.
DEFAULT_PRESET = "spikeone"
#: Spikes per tick of a full-scale source pixel when --max-lux is not given (Spike-Zoo's REDS rate).
FULL_SCALE_RATE = 0.6


@dataclass(frozen=True)
class DatasetSettings:
    """Everything that decides a clip's bits (compared on resume)."""

    preset: str
    parameters: object  # SpikeSensorParameters
    height: int
    width: int
    max_lux: float
    seed: int = 0
    gt_every: int = 1
    frame_rate_hz: float | None = None
    interpolation: str = "linear"
    light_sample_ticks: int = 1
    truth_every_ticks: int | None = None  # scene clips: ticks per truth step (None: video datasets)

    def describe(self) -> dict:
        """JSON-able description (sensor parameters in full)."""
        d = {k: v for k, v in asdict(self).items() if k != "parameters"}
        if d["truth_every_ticks"] is None:  # video datasets keep the fingerprint they had before
            del d["truth_every_ticks"]
        d["sensor"] = json.loads(json.dumps(self.parameters.to_dict(), default=_jsonable))
        return d

    def fingerprint(self) -> str:
        """SHA-256 of :meth:`describe`: two runs with the same fingerprint write the same bits."""
        return hashlib.sha256(json.dumps(self.describe(), sort_keys=True).encode()).hexdigest()


@dataclass(frozen=True)
class ClipTask:
    """One unit of work sent to a worker."""

    clip: SourceClip
    out: str
    settings: DatasetSettings
    provenance: dict = field(default_factory=dict)
    block_ticks: int = 4096
    # testing aid: after this many blocks of this clip the worker process exits abruptly,
    # once per output folder (a marker file remembers it), as a killed worker would
    crash_after_blocks: int | None = None
    device: str = "cpu"  # where the spike kernels run: "cpu" or "cuda" (viform.sensors.spike_cuda)


def _jsonable(value):
    from viform._io import _jsonable as convert

    return convert(value)


# ---------------------------------------------------------------------- settings

def resolve_preset(spec: str | None, height: int | None = None, width: int | None = None, **overrides):
    """Sensor parameters and resolution from a spike camera of the sensor catalogue or a preset JSON file.

    ``spec``: a name of :mod:`viform.sensors.catalog` of the spike family (default
    :data:`DEFAULT_PRESET`), or a ``.json`` preset (:func:`viform.sensors.spike_presets.load_spike_preset`).
    ``height``/``width`` override its resolution (the catalogue's ``scene_shape`` for a name) and
    ``overrides`` its parameters (any of ``viform sensors show spike``, e.g. ``threshold_level``).
    """
    from viform.sensors.catalog import SENSORS, sensor_names, spike_sensor
    from viform.sensors.spike_presets import load_spike_preset

    spec = spec or DEFAULT_PRESET
    if spec in SENSORS:
        entry = SENSORS[spec]
        if entry.family != "spike":
            raise ViformError(f"--preset = {spec!r} is not allowed: a dataset is recorded by a spike camera: "
                              f"{', '.join(sensor_names('spike'))}, or a preset .json file")
        params, (h, w) = entry.build(height=None, width=None, **overrides).parameters, entry.scene_shape
    else:
        preset = load_spike_preset(spec)
        params, h, w = preset.parameters, preset.height, preset.width
        if overrides:
            params = spike_sensor(params, **overrides).parameters
    h = check_int("--height", h if height is None else height, 1)
    w = check_int("--width", w if width is None else width, 1)
    if (h * w) % 8:
        raise ViformError(f"width × height = {w}×{h} is not a multiple of 8 pixels: the .dat layout "
                          "packs each frame into whole bytes")
    return params, h, w


def full_scale_lux(parameters, rate_per_tick: float = FULL_SCALE_RATE) -> float:
    """Illuminance (lux) at which a pixel fires ``rate_per_tick`` spikes per tick on average.

    Seed 000 §3.2: a steady pixel fires (λ_signal + λ_dark)·Δt / Q spikes per tick, so the
    signal electrons per second needed are rate·Q·clock_hz − dark current.
    """
    electrons_per_s = rate_per_tick * round(parameters.threshold_electrons) * parameters.clock_hz \
        - parameters.dark_current_e_per_s
    if electrons_per_s <= 0:
        raise ViformError("the preset's dark current alone exceeds the full-scale firing rate: give --max-lux")
    return float(parameters.optics.lux_from_electrons_per_s(electrons_per_s))


def make_settings(preset: str | None = None, *, height: int | None = None, width: int | None = None,
                  seed: int = 0, gt_every: int = 1, frame_rate_hz: float | None = None,
                  max_lux: float | None = None, interpolation: str = "linear", light_sample_ticks: int = 1,
                  truth_every_ticks: int | None = None, **overrides) -> DatasetSettings:
    """Validated :class:`DatasetSettings` (errors name the command-line option).

    ``max_lux`` (the illuminance of a full-scale source pixel) defaults to the light at which
    the sensor fires :data:`FULL_SCALE_RATE` spikes per tick (Spike-Zoo's REDS rate).
    """
    params, h, w = resolve_preset(preset, height, width, **overrides)
    max_lux = full_scale_lux(params) if max_lux is None else max_lux
    return DatasetSettings(
        preset=preset or DEFAULT_PRESET, parameters=params, height=h, width=w,
        seed=check_int("--seed", seed, 0, (1 << 63) - 1),
        gt_every=check_int("--gt-every", gt_every, 1),
        frame_rate_hz=None if frame_rate_hz is None else check_positive("--frame-rate-hz", frame_rate_hz),
        max_lux=check_positive("--max-lux", max_lux),
        interpolation=check_choice("--interpolation", interpolation, ("hold", "linear")),
        light_sample_ticks=check_int("--light-sample-ticks", light_sample_ticks, 1),
        truth_every_ticks=None if truth_every_ticks is None else check_int("--truth-every-ticks", truth_every_ticks,
                                                                           1, 1 << 24))


def scene_clips(scenes, clips_per_scene: int, duration_s: float, settings: DatasetSettings,
                pairs: bool = False, images=None, scene_settings: dict | None = None) -> list:
    """Clips drawn from built-in scenes and random layered scenes (:mod:`viform.datasets.scene_clips`):
    ``clips_per_scene`` of each, named ``<scene>-<k>``, and with ``pairs`` each one's clean twin
    ``<scene>-<k>-clean``.

    ``images`` (a folder, or None for the bundled photographs) feeds ``random-layers``;
    ``scene_settings`` (``--scene-set``) apply to every scene named: a built-in scene's parameters and
    brightness/speed factors on its drawn ones, the random-layers generator's ranges.
    """
    from viform.datasets.scene_clips import (
        CLEAN_SUFFIX,
        RANDOM_LAYERS,
        parse_scene_list,
        random_layers_clip,
        random_layers_ranges,
        scene_parameters,
    )
    from viform.datasets.sources import SourceClip

    names = parse_scene_list(scenes) if isinstance(scenes, str) else list(scenes)
    clips_per_scene = check_int("--clips", clips_per_scene, 1, 100_000)
    duration_s = check_positive("--duration", duration_s)
    if settings.truth_every_ticks is None:
        raise ViformError("scene clips need a truth step: give truth_every_ticks (--truth-every-ticks)")
    if duration_s * settings.parameters.clock_hz < settings.truth_every_ticks:
        raise ViformError(f"--duration {duration_s:g} s is shorter than one truth step "
                          f"({settings.truth_every_ticks} ticks at {settings.parameters.clock_hz:g} Hz)")
    if images is not None and RANDOM_LAYERS not in names:
        raise ViformError(f"--images applies to --scenes {RANDOM_LAYERS} only (it is not among "
                          f"{', '.join(names)})")
    pool = ranges = None
    if RANDOM_LAYERS in names:
        from viform.light.random_layers import image_pool

        pool = image_pool(images, "--images")
        ranges = random_layers_ranges(scene_settings, settings.max_lux)
    out = []
    for scene in names:
        for k in range(clips_per_scene):
            name = f"{scene}-{k:04d}"
            spec = {"scene": scene, "height": settings.height, "width": settings.width,
                    "duration_s": duration_s, "clean": False}
            if scene == RANDOM_LAYERS:
                try:
                    description, drawn = random_layers_clip(name, settings.seed, settings.height, settings.width,
                                                            duration_s, ranges, pool)
                except ViformError as exc:
                    raise ViformError(f"--images {str(images)!r}: {exc}" if images is not None else str(exc)) \
                        from None
                spec.update(parameters=drawn, description=description)
            else:
                spec["parameters"] = scene_parameters(scene, name, settings.seed, settings.max_lux, scene_settings)
            if scene_settings:
                spec["settings"] = scene_settings
            out.append(SourceClip(name, json.dumps(spec, sort_keys=True), "scene"))
            if pairs:
                # the twin draws the same light and photon seed: its spec differs only in "clean"
                twin = {**spec, "clean": True, "twin_of": name}
                out.append(SourceClip(name + CLEAN_SUFFIX, json.dumps(twin, sort_keys=True), "scene"))
    return out


# ---------------------------------------------------------------------- one clip

def _sidecar_tools():
    try:
        from viform.stream.sidecar import read_sidecar, sidecar_path, stream_header, write_sidecar
        return read_sidecar, sidecar_path, stream_header, write_sidecar
    except ImportError:  # fallback: plain JSON beside the .dat
        def sidecar_path(p):
            return Path(p).with_name(Path(p).name + ".json")

        def read_sidecar(p):
            path = sidecar_path(p)
            return json.loads(path.read_text()) if path.is_file() else None

        def write_sidecar(p, metadata):
            write_json(sidecar_path(p), metadata)

        return read_sidecar, sidecar_path, None, write_sidecar


def _finished(task: ClipTask, dat: Path) -> dict | None:
    """The recorded result of a clip already converted with these settings and intact on disk, else None."""
    read_sidecar, sidecar_path, _, _ = _sidecar_tools()
    if not dat.is_file() or not sidecar_path(dat).is_file():
        return None
    try:
        side = read_sidecar(dat)
    except (ViformError, ValueError, OSError):
        return None
    record = (side or {}).get("dataset")
    if not isinstance(record, dict) or record.get("settings_sha256") != task.settings.fingerprint():
        return None
    if record.get("source") != task.clip.path or dat.stat().st_size != record.get("bytes"):
        return None
    if sha256_file(dat) != record.get("sha256"):
        return None
    gt_dir = Path(task.out) / GT_DIR
    for gt in record.get("gt_frames", []):
        path = gt_dir / gt["file"]
        if not path.is_file() or sha256_file(path) != gt.get("sha256"):
            return None
    if task.clip.kind == "scene":
        from viform.datasets.scene_clips import truth_intact

        if not truth_intact(task.out, record):
            return None
    return {**record, "status": "skipped"}


def _remove_stale(out: Path, clip: str) -> None:
    """Temporary files a killed attempt left behind (atomic writes name them ``.<target>.*``)."""
    from viform.datasets.scene_clips import DEPTH_DIR, DESCRIPTION_DIR, FLOW_DIR, MOT_DIR

    for folder, prefix in ((out / SPIKE_DIR, f".{clip}.dat"), (out / GT_DIR, f".{clip}_"),
                           (out / DESCRIPTION_DIR, f".{clip}.yaml"),
                           (out / FLOW_DIR, f".{clip}_"), (out / DEPTH_DIR, f".{clip}_")):
        if folder.is_dir():
            for p in folder.iterdir():
                if p.name.startswith(prefix):
                    p.unlink(missing_ok=True)
    mot = out / MOT_DIR / clip
    if mot.is_dir():
        for p in mot.rglob(".*"):
            if p.is_file():
                p.unlink(missing_ok=True)


def convert_clip(task: ClipTask) -> dict:
    """Convert one clip (runs on a worker); returns its manifest row plus ``status`` and ``seconds``.

    Memory: the clip's frames at sensor size (N·H·W·8 bytes) and one block of ticks; the
    stream goes straight to disk.
    """
    from numba import get_num_threads, set_num_threads

    started = time.perf_counter()
    cpu_started = time.thread_time()  # this worker thread's CPU time: a rate that other load does not skew
    clip, out = task.clip, Path(task.out)
    dat = out / SPIKE_DIR / f"{clip.name}.dat"
    _remove_stale(out, clip.name)
    done = _finished(task, dat)
    if done is not None:
        return {**done, "seconds": time.perf_counter() - started}
    threads = get_num_threads()
    set_num_threads(1)  # one clip per worker thread: parallelism comes from the workers
    try:
        result = _convert(task, dat, started)
        result["cpu_seconds"] = time.thread_time() - cpu_started
        return result
    finally:
        set_num_threads(threads)


def _convert_or_report(task: ClipTask) -> dict:
    """:func:`convert_clip` on a worker, a clip's bad input returned as ``{"status": "failed", "error"}``.

    Returned rather than raised, so that the worker does not log a "Compute Failed" block with a
    traceback for what is the user's data (the summary names the clip, the file and the fault).
    """
    try:
        return convert_clip(task)
    except ViformError as exc:
        return {"status": "failed", "error": str(exc)}


def _clean_parameters(parameters):
    """The clean twin's sensor: photon noise and every fixed pattern off (same light, same seed)."""
    from dataclasses import replace

    return replace(parameters, photon_noise=False, threshold_spread_fraction=0.0, gain_spread_fraction=0.0,
                   dark_current_spread_fraction=0.0, hot_pixel_fraction=0.0)


def _convert_scene(task: ClipTask, dat: Path, started: float) -> dict:
    """A scene clip: the drawn scene, its spikes and its exact truth (flow, depth, objects)."""
    from viform.datasets.scene_clips import make_scene, write_truth
    from viform.sensors.spike import SpikeSensor

    s, clip, out = task.settings, task.clip, Path(task.out)
    _sidecar_tools()[1](dat).unlink(missing_ok=True)
    spec = json.loads(clip.path)
    scene = make_scene(clip)
    parameters = _clean_parameters(s.parameters) if spec["clean"] else s.parameters
    sensor = SpikeSensor(parameters, s.height, s.width)
    # a clean twin uses its noisy clip's seed, so the two differ by the noise alone
    seed = clip_seed(s.seed, spec.get("twin_of", clip.name))
    source = sensor.stream(scene, spec["duration_s"], seed=seed, light_sample_ticks=s.light_sample_ticks,
                           reuse_buffer=True)
    from viform.vision.detectability import SpikeDetectability

    detect = SpikeDetectability(parameters.threshold_electrons, parameters.optics.electrons_per_lux_second)
    truth = write_truth(out, clip.name, scene, source.n_ticks, s.truth_every_ticks, source.clock_hz, s.max_lux,
                        detectability=detect)
    described = None
    if "description" in spec:  # a drawn description: written beside the truth, to remake the clip's scene
        from viform.datasets.scene_clips import write_description

        described = write_description(out, clip.name, spec["description"])
    spikes, digest = _write_dat(task, dat, source)
    from viform.datasets.scene_clips import too_dark

    darkness = too_dark(spikes, source.n_ticks, s.height * s.width, s.truth_every_ticks)
    full_scale_rate = float(sensor.expected_firing_rate_per_tick(np.array(s.max_lux)))
    record = {
        "clip": clip.name, "source": clip.path, "seed": seed, "ticks": source.n_ticks,
        "spikes": spikes, "sha256": digest, "bytes": dat.stat().st_size,
        "height": s.height, "width": s.width, "clock_hz": source.clock_hz, "n_frames": len(truth["frames"]),
        "frame_rate_hz": source.clock_hz / s.truth_every_ticks, "rate": full_scale_rate,
        "gt_frames": truth["frames"], "settings_sha256": s.fingerprint(),
        "scene": spec["scene"], "scene_parameters": spec["parameters"], "clean": spec["clean"], **darkness,
        **({"scene_settings": spec["settings"]} if "settings" in spec else {}),
        **({"scene_description": spec["description"], "description_file": described} if described else {}),
        "truth": {"kinds": truth["kinds"], "step_ticks": s.truth_every_ticks, "mot": truth["mot"],
                  "frame_time": "frame k: the end of step k, t = k·step_ticks / clock_hz (s)",
                  "flow": "forward flow from frame k to frame k + 1, px, Middlebury .flo (unknown = 1e10)",
                  "depth": "range along the line of sight, m, float32 .npy (inf: no surface)"},
    }
    if truth["mot"]:
        record["mot"] = truth["mot"]
    _write_clip_sidecar(dat, source, sensor, task, record)
    return {**record, "status": "converted", "seconds": time.perf_counter() - started}


def _write_dat(task: ClipTask, dat: Path, source) -> tuple[int, str]:
    """Pack and write the stream block by block (bounded memory); returns (spikes, SHA-256)."""
    from viform.stream.dat import pack_frames

    out, clip = Path(task.out), task.clip
    digest = hashlib.sha256()
    spikes = 0
    crash_marker = out / f".crash-{clip.name}"
    crash = task.crash_after_blocks is not None and not crash_marker.exists()
    with atomic_open(dat, "wb") as f:
        for i, (_, block) in enumerate(source.iter_blocks(task.block_ticks)):
            packed = pack_frames(block, flip=True)  # bottom-up rows, as the cameras write
            f.write(packed)
            digest.update(packed)
            spikes += int(np.count_nonzero(block))
            if crash and i + 1 >= task.crash_after_blocks:
                crash_marker.touch()
                f.flush()
                os._exit(70)
        f.flush()
        os.fsync(f.fileno())
    return spikes, digest.hexdigest()


def _convert(task: ClipTask, dat: Path, started: float) -> dict:
    from viform.light.scenes import VideoScene
    from viform.sensors.spike import SpikeSensor

    s, clip, out = task.settings, task.clip, Path(task.out)
    if clip.kind == "scene":
        return _convert_scene(task, dat, started)
    _sidecar_tools()[1](dat).unlink(missing_ok=True)  # a redone clip is unfinished until its new sidecar

    frames, declared_hz, fit = read_clip(clip, s.height, s.width, s.max_lux)
    frame_rate_hz = s.frame_rate_hz or declared_hz
    if frame_rate_hz is None:
        raise ViformError(f"clip {clip.name!r} declares no frame rate: give --frame-rate-hz")
    n_frames = frames.shape[0]
    seed = clip_seed(s.seed, clip.name)
    sensor = SpikeSensor(s.parameters, s.height, s.width)
    scene = VideoScene(frames, frame_rate_hz, s.interpolation)
    source = sensor.stream(scene, n_frames / frame_rate_hz, seed=seed,
                           light_sample_ticks=s.light_sample_ticks, reuse_buffer=True, device=task.device)
    clock_hz = source.clock_hz

    # ground truth first: the sidecar, written last, is what marks the clip finished
    gt_frames = []
    for k in range(0, n_frames, s.gt_every):
        name = gt_name(clip.name, k)
        image = lux_to_gt_image(frames[k], s.max_lux)
        save_image(out / GT_DIR / name, image)
        tick = min(int(math.floor(k / frame_rate_hz * clock_hz + 1e-9)), source.n_ticks - 1)
        gt_frames.append({"frame": k, "time_s": k / frame_rate_hz, "tick": tick, "file": name,
                          "sha256": sha256_file(out / GT_DIR / name)})
    del frames  # the scene keeps its own copy

    spikes, digest = _write_dat(task, dat, source)
    full_scale_rate = float(sensor.expected_firing_rate_per_tick(np.array(s.max_lux)))
    record = {
        "clip": clip.name, "source": clip.path, "seed": seed, "ticks": source.n_ticks,
        "spikes": spikes, "sha256": digest, "bytes": dat.stat().st_size,
        "height": s.height, "width": s.width, "clock_hz": clock_hz, "n_frames": n_frames,
        "frame_rate_hz": frame_rate_hz, "rate": full_scale_rate, "gt_frames": gt_frames,
        "settings_sha256": s.fingerprint(), "fit": fit,
    }
    _write_clip_sidecar(dat, source, sensor, task, record)
    return {**record, "status": "converted", "seconds": time.perf_counter() - started}


def _write_clip_sidecar(dat: Path, source, sensor, task: ClipTask, record: dict) -> None:
    _, _, stream_header, write_sidecar = _sidecar_tools()
    extra = {"source_clip": task.clip.path, "preset": task.settings.preset, "dataset": record,
             "dataset_settings": task.settings.describe(), **task.provenance}
    if stream_header is not None:
        header = stream_header(source, rows="bottom-up", extra=extra)
    else:
        header = {"height": source.height, "width": source.width, "n_ticks": source.n_ticks,
                  "clock_hz": source.clock_hz, "threshold_electrons": source.threshold_electrons,
                  "start_time_s": 0.0, "rows": "bottom-up", "bit_order": "little",
                  "seed": record["seed"], "metadata": {"sensor": sensor.describe()}, **extra}
    write_sidecar(dat, json.loads(json.dumps(header, default=_jsonable)))


# ---------------------------------------------------------------------- the dataset

def _provenance() -> dict:
    try:
        from viform.stream.sidecar import provenance
        return provenance()
    except ImportError:
        import datetime as dt
        import shlex
        import sys

        from viform import __version__

        return {"viform_version": __version__, "command_line": shlex.join(sys.argv),
                "utc_date": dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")}


def _label_types(clips) -> list:
    """SpikeCV's label-type ids present: 1 reconstruction, 2 optical flow, 3.1 depth, 5 tracking."""
    types = [1]
    scenes = [c for c in clips if c.kind == "scene"]
    if scenes:
        from viform.light.catalog import builtin_scene
        from viform.light.layered import DescribedScene

        kinds = set()
        firsts = {}
        for c in scenes:
            firsts.setdefault(json.loads(c.path)["scene"], json.loads(c.path))
        for name, spec in firsts.items():
            if "description" in spec:  # a drawn description: every one has the truth kinds of its layers
                kinds.update(DescribedScene(spec["description"]).truth_kinds())
            else:
                kinds.update(builtin_scene(name, 64, 96).truth_kinds())
        types += [t for kind, t in (("motion", 2), ("depth", 3.1), ("objects", 5)) if kind in kinds]
    return types


def _config(out: Path, settings: DatasetSettings, clips=()) -> dict:
    p = settings.parameters
    return {
        "filename": out.resolve().name,
        "spike_h": settings.height,
        "spike_w": settings.width,
        "is_labeled": True,
        "labeled_data_type": _label_types(clips),  # SpikeCV's ids; 1: ground-truth images
        "labeled_data_suffix": "png",
        "clock_hz": float(p.clock_hz),
        "threshold_electrons": float(p.threshold_electrons),
        "format": LAYOUT_FORMAT,
        "settings_sha256": settings.fingerprint(),
        "settings": settings.describe(),
    }


def _check_existing_config(out: Path, config: dict) -> None:
    path = out / CONFIG_NAME
    if not path.exists():
        return
    old = read_config(path)
    if old.get("settings_sha256") == config["settings_sha256"]:
        return
    old_s, new_s = old.get("settings") or {}, config["settings"]
    diff = next((k for k in new_s if old_s.get(k) != new_s.get(k)), None)
    what = f"{diff}: {old_s.get(diff)!r} there, {new_s.get(diff)!r} now" if diff else "not a viform dataset"
    raise ViformError(f"--out {str(out)!r} already holds a dataset made with other settings ({what}); "
                      "use a new --out folder, or the same options to resume it")


#: The modules a clip's task imports, imported once by the fork server a local cluster's workers are
#: forked from (:data:`viform._parallel.WORKER_START`), not again by each worker (the spike sensor
#: imports its compiled kernels only when it simulates: they are listed too).
WORKER_MODULES = ("viform.datasets.build", "viform.datasets.scene_clips", "viform.sensors.spike",
                  "viform.sensors._spike_kernels", "viform.light.scenes", "viform.stream.dat", "viform.stream.sidecar")


def build_dataset(src, out, settings: DatasetSettings, *, workers: int | None = None, scheduler: str | None = None,
                  client=None, memory_limit="auto", block_ticks: int = 4096, progress: bool = True,
                  crash: tuple[str, int] | None = None, device: str = "cpu",
                  connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S, on_connect=None) -> dict:
    """Convert every clip of ``src`` into the spike dataset ``out``; returns a summary.

    Parameters
    ----------
    src : path
        A folder of videos or of frame folders (see :mod:`viform.datasets.sources`).
    out : path
        The dataset folder (created; an existing one made with the same settings is resumed).
    settings : DatasetSettings
        From :func:`make_settings`.
    workers : int, optional
        Local worker processes (default: the CPU count, at most one per clip).
    scheduler : str, optional
        Address of an existing dask scheduler (``tcp://host:8786``) instead of a local cluster.
    client : distributed.Client, optional
        An open client to use as is (tests, notebooks).
    memory_limit : str or int
        Per-worker memory limit of the local cluster (``"auto"``: the machine's memory / workers).
    block_ticks : int
        Ticks simulated, packed and written at a time (bounds a worker's memory; no effect on bits).
    progress : bool
        One tqdm progress bar (stderr) for the whole dataset.
    device : {"cpu", "cuda", "auto"}
        Where each clip's spike kernels run (a GPU: same bits, see :mod:`viform.sensors.spike_cuda`).
    connect_timeout_s : float
        Seconds to keep trying to reach the scheduler, at the start and after losing it.
    on_connect : callable (scheduler, connect_timeout_s), optional
        Called once the inputs are checked, just before a ``scheduler`` is reached (the CLI says so).

    Faults: a worker that dies mid-clip is replaced and the clip converted again from the start
    (its partial files removed first; the bits are the same). A lost scheduler (or one without a
    worker for ``connect_timeout_s``) stops the run with one line saying how many clips are done;
    each finished clip is whole on disk, and running the command again converts only the others.

    Returns
    -------
    dict
        ``clips``, ``converted``, ``skipped``, ``failed`` (list of {clip, error}), ``ticks``,
        ``spikes``, ``bytes``, ``pixel_ticks``, ``seconds``, ``clips_per_s``,
        ``pixel_ticks_per_s``, ``workers``, ``manifest``.
    """
    out = Path(out)
    clips = list(src) if isinstance(src, (list, tuple)) else find_clips(src)
    if settings.frame_rate_hz is None:
        folders = [c.name for c in clips if c.kind == "frames"]
        if folders:
            raise ViformError(f"--frame-rate-hz is required: clip {folders[0]!r} is a folder of images, "
                              "which declares no frame rate")
    block_ticks = check_int("block_ticks", block_ticks, 1)
    if scheduler is not None and workers is not None:
        raise ViformError("--workers and --scheduler exclude each other: a scheduler brings its own workers")
    if workers is None:
        workers = max(1, min(os.cpu_count() or 1, len(clips)))
    workers = check_int("--workers", workers, 1, 1024)
    memory_limit = parse_memory(memory_limit)
    check_output_folder("--out", out)
    if out.exists() and not out.is_dir():
        raise ViformError(f"--out {str(out)!r} is a file, not a folder")
    config = _config(out, settings, clips)
    _check_existing_config(out, config)
    # reach the scheduler (or start the workers) before anything is written: a wrong
    # --scheduler must leave no half-made dataset behind
    own_client = client is None
    own_cluster = None
    if own_client:
        if scheduler is not None and on_connect is not None:
            on_connect(scheduler, connect_timeout_s)
        client, own_cluster = open_client(workers, scheduler, memory_limit, connect_timeout_s, preload=WORKER_MODULES)
    try:
        (out / SPIKE_DIR).mkdir(parents=True, exist_ok=True)
        (out / GT_DIR).mkdir(parents=True, exist_ok=True)
        write_config(out / CONFIG_NAME, config)
    except BaseException:
        if own_client:
            client.close()
        if own_cluster is not None:
            own_cluster.close()
        raise

    prov = _provenance()
    from viform.sensors.spike_cuda import resolve_device

    device = resolve_device(device, "--device")
    tasks = [ClipTask(c, str(out), settings, prov, block_ticks,
                      crash[1] if crash is not None and crash[0] == c.name else None, device) for c in clips]
    rows: dict[str, dict] = {}
    failed: dict[str, str] = {}
    opened = time.perf_counter()

    def record(task: ClipTask, result: dict | None, error: str | None) -> None:
        if error is None:
            rows[task.clip.name] = result
        else:
            failed[task.clip.name] = error
        _write_manifest(out, settings, rows, failed)

    bar = None
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
        started = time.perf_counter()  # rates count conversion, not the cluster's start-up
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), unit="clip", desc="dataset", disable=not progress, leave=True)
        token = uuid.uuid4().hex[:8]
        futures = {client.submit(one_line_warnings(_convert_or_report), t, key=f"viform-clip-{t.clip.name}-{token}",
                                 pure=False): t for t in tasks}
        try:
            for fut, result in completed(client, futures, connect_timeout_s):
                task = futures[fut]
                if isinstance(result, ViformError):
                    record(task, None, str(result))
                elif isinstance(result, BaseException):  # a worker lost too often, an unexpected failure
                    record(task, None, f"{type(result).__name__}: {one_line(result)}")
                elif result.get("status") == "failed":
                    record(task, None, result["error"])
                else:
                    record(task, result, None)
                bar.update(1)
                if failed:
                    bar.set_postfix(failed=len(failed))
        except SchedulerLost as exc:
            raise ViformError(f"{exc}: {len(rows)} of {len(tasks)} clips are done and listed in "
                              f"{str(out / MANIFEST_NAME)!r} (every clip file written is whole); run the same command "
                              "again: it keeps the finished clips and converts the others") from None
    finally:
        if bar is not None:
            bar.close()
        if own_client:
            client.close()
        if own_cluster is not None:
            own_cluster.close()
    summary = _summary(out, clips, rows, failed, time.perf_counter() - started, n_workers)
    summary["startup_s"] = started - opened
    return summary


#: Manifest keys of scene clips: what was drawn, and where the truth is.
_SCENE_KEYS = ("scene", "scene_parameters", "scene_settings", "scene_description", "description_file", "clean",
               "truth", "too_dark", "spikes_per_pixel_per_truth_step")


def _write_manifest(out: Path, settings: DatasetSettings, rows: dict, failed: dict) -> None:
    """manifest.json: clips sorted by name, without timings (same bits, same manifest)."""
    keep = ("clip", "source", "seed", "ticks", "spikes", "sha256", "bytes", "n_frames", "frame_rate_hz",
            "rate", "gt_frames", "fit")
    write_json(out / MANIFEST_NAME, {
        "format": LAYOUT_FORMAT, "spike_h": settings.height, "spike_w": settings.width,
        "clock_hz": float(settings.parameters.clock_hz), "settings_sha256": settings.fingerprint(),
        "clips": [{k: rows[c][k] for k in keep + _SCENE_KEYS if k in rows[c]} for c in sorted(rows)],
        "failed": [{"clip": c, "error": failed[c]} for c in sorted(failed)],
    })


def _summary(out, clips, rows, failed, seconds, workers) -> dict:
    converted = [r for r in rows.values() if r["status"] == "converted"]
    pixel_ticks = sum(r["ticks"] * r["height"] * r["width"] for r in converted)
    return {
        "out": str(out), "clips": len(clips), "converted": len(converted),
        "skipped": sum(r["status"] == "skipped" for r in rows.values()),
        "failed": [{"clip": c, "error": failed[c]} for c in sorted(failed)],
        "ticks": sum(r["ticks"] for r in rows.values()),
        "spikes": sum(r["spikes"] for r in rows.values()),
        "bytes": sum(r["bytes"] for r in rows.values()),
        "pixel_ticks_converted": pixel_ticks,
        "seconds": seconds,
        "cpu_seconds": sum(r.get("cpu_seconds", 0.0) for r in converted),
        # clip-seconds per second: how many clips were being converted at once, on average
        "clips_in_flight": sum(r["seconds"] for r in converted) / seconds if seconds > 0 else 0.0,
        "clips_per_s": len(converted) / seconds if seconds > 0 else 0.0,
        "pixel_ticks_per_s": pixel_ticks / seconds if seconds > 0 else 0.0,
        "workers": workers,
        "manifest": str(Path(out) / MANIFEST_NAME),
        "too_dark": sorted(c for c, r in rows.items() if r.get("too_dark")),
        # how the source frames were fitted to the sensor (scaled, centre-cropped: never stretched)
        "fits": sorted({describe_fit(r["fit"]) for r in rows.values() if r.get("fit")}),
    }


def convert_serially(src, out, settings: DatasetSettings, block_ticks: int = 4096,
                     crash: tuple[str, int] | None = None) -> dict:
    """Reference path without dask: every clip in this process, one after the other (benchmarks).

    ``crash`` (testing aid, as in :func:`build_dataset`) ends this whole process mid-clip.
    """
    out = Path(out)
    clips = list(src) if isinstance(src, (list, tuple)) else find_clips(src)
    (out / SPIKE_DIR).mkdir(parents=True, exist_ok=True)
    (out / GT_DIR).mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows, failed = {}, {}
    for c in clips:
        try:
            rows[c.name] = convert_clip(ClipTask(c, str(out), settings, _provenance(), block_ticks,
                                                 crash[1] if crash is not None and crash[0] == c.name else None))
        except ViformError as exc:
            failed[c.name] = str(exc)
    _write_manifest(out, settings, rows, failed)
    return _summary(out, clips, rows, failed, time.perf_counter() - started, 0)
