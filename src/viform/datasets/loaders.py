"""Read spike datasets as ground-truth-aligned samples and as events.

Layouts read by :func:`open_dataset`:

* viform's (``viform dataset``): ``manifest.json`` names the clips, their ticks and the tick of
  every ground-truth frame; ``spike/<clip>.dat`` + sidecar; ``gt/<clip>_<frame>.png``.
* Spike-Zoo / SpikeCV: ``config.yaml`` with ``spike_h``/``spike_w`` (in the folder or one or
  two levels up), spike files in ``spike/`` (or the folder itself): ``.dat`` (packed bits, rows
  bottom-up) or ``.npz`` (array ``spk``, shape (T, H, W)); one ground truth per spike file,
  ``gt/<stem>.png`` or ``<stem>_gt.png`` beside it, for the middle tick (Spike-Zoo's
  convention: ``spike[T//2 - L//2 : T//2 - L//2 + L]`` pairs with the image).

A sample is a window of ``window_ticks`` ticks centred on the ground-truth tick
(start = tick − L//2), with ``rate``: the mean spikes per tick of a full-scale (gt = 1) pixel,
so mean(spike) / rate estimates the image (Spike-Zoo's convention; viform's manifest gives it
per clip from the sensor, seed 000 §3.2: rate = min(λ_full·Δt / Q, 1)). Ground-truth frames
whose window does not fit inside the stream are left out (no padding is invented).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from viform._validate import ViformError, check_int, check_positive
from viform.datasets.layout import CONFIG_NAME, GT_DIR, LAYOUT_FORMAT, MANIFEST_NAME, SPIKE_DIR, read_config

#: Spike-Zoo's default rate (its REDS-based "base" set): full-scale pixels fire 0.6 spikes/tick.
SPIKE_ZOO_RATE = 0.6
#: Spike-Zoo's usual window (41 ticks around the ground-truth instant).
DEFAULT_WINDOW_TICKS = 41
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")

#: Events as tonic expects them: x = column, y = row (0 at the top), t in µs, p = polarity index.
TONIC_EVENT_DTYPE = np.dtype([("x", np.int16), ("y", np.int16), ("t", np.int64), ("p", np.int8)])


@dataclass
class GroundTruth:
    frame: int
    tick: int
    path: Path
    flow: Path | None = None  # .flo: forward flow to the next truth frame (scene clips)
    depth: Path | None = None  # .npy: range, m (scenes with range)


@dataclass
class ClipRecord:
    """One spike file of a dataset and its ground-truth frames."""

    name: str
    path: Path
    height: int | None
    width: int | None
    rate: float
    gt: list[GroundTruth] = field(default_factory=list)
    n_ticks: int | None = None
    mot: Path | None = None  # MOTChallenge gt.txt of the clip's objects (scene clips)
    truth_kinds: tuple = ()


class SpikeFolder:
    """A spike dataset on disk: samples ``{spike, gt_img, rate, ...}`` around each ground-truth frame.

    Parameters
    ----------
    root : path
        The dataset folder (see the module notes for the layouts).
    window_ticks : int
        Ticks per sample (41, Spike-Zoo's usual length).
    height, width : int, optional
        Frame size of ``.dat`` files when neither a ``config.yaml`` nor a sidecar gives it.
    rate : float, optional
        Full-scale spikes per tick, for layouts that do not record it (default 0.6).
    flip : bool
        ``.dat`` rows stored bottom-up (True: the cameras' and SpikeCV's layout).
    split : str, optional
        Sub-folder to read (Spike-Zoo's ``train`` / ``test``).
    npz_key, npz_axes : str, optional
        Array name and axis order (e.g. ``"HWT"``) of ``.npz`` files, passed to the reader.
    """

    def __init__(self, root, *, window_ticks: int = DEFAULT_WINDOW_TICKS, height: int | None = None,
                 width: int | None = None, rate: float | None = None, flip: bool = True, split: str | None = None,
                 npz_key: str | None = None, npz_axes: str | None = None):
        root = Path(root)
        if split is not None:
            root = root / split
        if not root.is_dir():
            raise ViformError(f"dataset folder {str(root)!r} does not exist")
        self.root = root
        self.truth_kinds: tuple = ()
        self._mot_rows: dict[int, np.ndarray] = {}
        self.window_ticks = check_int("window_ticks", window_ticks, 1)
        self.flip = flip
        self._npz = {k: v for k, v in (("key", npz_key), ("axes", npz_axes)) if v is not None}
        self._sources: dict[int, object] = {}
        default_rate = SPIKE_ZOO_RATE if rate is None else check_positive("rate", rate)
        manifest = root / MANIFEST_NAME
        if manifest.is_file():
            self.layout = "viform"
            self.clips = self._from_manifest(manifest, rate)
        else:
            self.layout = "spike-zoo"
            self.clips = self._from_folder(root, height, width, default_rate)
        if not self.clips:
            raise ViformError(f"dataset folder {str(root)!r} holds no .dat or .npz spike files")
        self.samples: list[tuple[int, int]] = []
        half = self.window_ticks // 2
        for ci, clip in enumerate(self.clips):
            n_ticks = self._n_ticks(ci)
            for gi, gt in enumerate(clip.gt):
                if gt.tick - half >= 0 and gt.tick - half + self.window_ticks <= n_ticks:
                    self.samples.append((ci, gi))

    # ------------------------------------------------------------------ discovery
    def _from_manifest(self, path: Path, rate: float | None) -> list[ClipRecord]:
        try:
            manifest = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ViformError(f"{str(path)!r} is not a readable manifest: {exc}") from None
        if not isinstance(manifest, dict) or manifest.get("format") != LAYOUT_FORMAT:
            raise ViformError(f"{str(path)!r} is not a viform dataset manifest (format {LAYOUT_FORMAT!r})")
        from viform.datasets.scene_clips import DEPTH_DIR, FLOW_DIR

        h, w = manifest.get("spike_h"), manifest.get("spike_w")
        clips = []
        for row in manifest.get("clips", []):
            name = str(row["clip"])
            gts = [GroundTruth(int(g["frame"]), int(g["tick"]), self.root / GT_DIR / g["file"],
                               self.root / FLOW_DIR / g["flow"] if g.get("flow") else None,
                               self.root / DEPTH_DIR / g["depth"] if g.get("depth") else None)
                   for g in row.get("gt_frames", [])]
            truth = row.get("truth") or {}
            mot = (truth.get("mot") or {}).get("gt")
            clips.append(ClipRecord(name, self.root / SPIKE_DIR / f"{name}.dat", h, w,
                                    float(row.get("rate", SPIKE_ZOO_RATE)) if rate is None else rate,
                                    gts, int(row["ticks"]), self.root / mot if mot else None,
                                    tuple(truth.get("kinds", ()))))
        # every sample carries the same keys: the truth kinds any clip of the set has
        self.truth_kinds = tuple(k for k in ("motion", "depth", "objects") if any(k in c.truth_kinds for c in clips))
        return clips

    def _from_folder(self, root: Path, height, width, rate: float) -> list[ClipRecord]:
        config = None
        for folder in (root, root.parent, root.parent.parent):
            if (folder / CONFIG_NAME).is_file():
                config = read_config(folder / CONFIG_NAME)
                break
        if config is not None:
            height = config["spike_h"] if height is None else height
            width = config["spike_w"] if width is None else width
        spike_dir = root / SPIKE_DIR if (root / SPIKE_DIR).is_dir() else root
        gt_dir = root / GT_DIR
        files = sorted(p for p in spike_dir.rglob("*") if p.suffix.lower() in (".dat", ".npz") and p.is_file())
        clips = []
        for p in files:
            name = p.stem
            candidates = [gt_dir / f"{name}{s}" for s in _IMAGE_SUFFIXES] + \
                         [p.with_name(f"{name}_gt{s}") for s in _IMAGE_SUFFIXES]
            gt = next((c for c in candidates if c.is_file()), None)
            clip = ClipRecord(name, p, height, width, rate)
            if gt is not None:
                clip.gt.append(GroundTruth(0, -1, gt))  # tick: the middle one, set once the length is known
            clips.append(clip)
        self.clips = clips
        for ci, clip in enumerate(clips):
            for g in clip.gt:
                g.tick = self._n_ticks(ci) // 2
        return clips

    def __getstate__(self):  # DataLoader workers reopen the files instead of copying memory maps
        state = dict(self.__dict__)
        state["_sources"] = {}
        return state

    # ------------------------------------------------------------------ access
    def source(self, clip):
        """The :class:`~viform.stream.container.SpikeSource` of a clip (index or name), opened once."""
        ci = self._clip_index(clip)
        if ci not in self._sources:
            from viform.stream.io import open_spikes

            c = self.clips[ci]
            if c.path.suffix.lower() == ".npz":
                src = open_spikes(c.path, **self._npz)
            else:
                src = open_spikes(c.path, c.height, c.width, flip=self.flip)
            self._sources[ci] = src
        return self._sources[ci]

    def _n_ticks(self, ci: int) -> int:
        clip = self.clips[ci]
        if clip.n_ticks is None:
            clip.n_ticks = int(self.source(ci).n_ticks)
        return clip.n_ticks

    def _clip_index(self, clip) -> int:
        if isinstance(clip, str):
            names = [c.name for c in self.clips]
            if clip not in names:
                raise ViformError(f"clip {clip!r} is not in {str(self.root)!r} (it has {len(names)} clips)")
            return names.index(clip)
        return check_int("clip", clip, 0, len(self.clips) - 1)

    def __len__(self) -> int:
        return len(self.samples)

    def window(self, index: int) -> tuple[int, int, int]:
        """(clip index, first tick, stop tick) of sample ``index``."""
        index = check_int("index", index, -len(self.samples), len(self.samples) - 1)
        ci, gi = self.samples[index]
        start = self.clips[ci].gt[gi].tick - self.window_ticks // 2
        return ci, start, start + self.window_ticks

    def __getitem__(self, index: int) -> dict:
        """``{spike: uint8 (T, H, W), gt_img: float32 (1, H, W) in [0, 1], rate, clip, frame, tick, start_tick}``,
        plus the truth of scene datasets (the same keys for every sample of a set):

        * ``flow`` float32 (2, H, W), px, forward to the next truth frame (0 where unknown) and
          ``flow_valid`` bool (H, W) — False where occluded, leaving, or the clip has no flow;
        * ``depth`` float32 (H, W), m (NaN where the clip has no range; inf: no surface);
        * ``boxes`` float32 (N, 4) x, y, w, h in px (0-based), ``ids`` int64 (N,), ``classes``
          int64 (N,), ``visibility`` float32 (N,): the objects of this frame (MOTChallenge truth).
        """
        if isinstance(index, (int, np.integer)) and not -len(self) <= index < len(self):
            raise IndexError(f"sample {index} of {len(self)}")
        ci, start, stop = self.window(int(index))
        ci_, gi = self.samples[int(index)]
        clip, gt = self.clips[ci], self.clips[ci].gt[gi]
        spike = np.asarray(self.source(ci).read_ticks(start, stop), dtype=np.uint8)
        sample = {"spike": spike, "gt_img": read_gt(gt.path)[None], "rate": clip.rate, "clip": clip.name,
                  "frame": gt.frame, "tick": gt.tick, "start_tick": start}
        sample.update(self._truth(ci, gt, spike.shape[1:]))
        return sample

    def _truth(self, ci: int, gt: GroundTruth, shape) -> dict:
        out = {}
        if "motion" in self.truth_kinds:
            from viform.vision.flow import read_flo

            if gt.flow is not None:
                flow, valid = read_flo(gt.flow)
                out["flow"], out["flow_valid"] = np.nan_to_num(flow, nan=0.0), valid
            else:
                out["flow"], out["flow_valid"] = np.zeros((2, *shape), np.float32), np.zeros(shape, bool)
        if "depth" in self.truth_kinds:
            out["depth"] = np.load(gt.depth) if gt.depth is not None else np.full(shape, np.nan, np.float32)
        if "objects" in self.truth_kinds:
            rows = self._objects(ci)
            rows = rows[rows[:, 0] == gt.frame]
            out.update(boxes=rows[:, 2:6].astype(np.float32), ids=rows[:, 1].astype(np.int64),
                       classes=rows[:, 7].astype(np.int64), visibility=rows[:, 8].astype(np.float32))
        return out

    def _objects(self, ci: int) -> np.ndarray:
        """A clip's MOTChallenge rows (read once), 0-based boxes; empty when it has no objects."""
        if ci not in self._mot_rows:
            from viform.vision.motchallenge import read_gt as read_mot_gt

            path = self.clips[ci].mot
            self._mot_rows[ci] = read_mot_gt(path) if path is not None else np.zeros((0, 9))
        return self._mot_rows[ci]

    def events(self, index: int) -> tuple[np.ndarray, tuple[int, int, int]]:
        """Spikes of sample ``index`` as tonic expects them, and its ``sensor_size``.

        A structured array (x = column, y = row from the top, t = µs at the end of the tick in
        which the spike was read, p = 0) sorted by time, and ``sensor_size = (W, H, 1)``: a
        spike camera has one polarity, tonic's index 0 (what its ``MergePolarities`` gives).
        """
        ci, start, stop = self.window(index)
        return spikes_to_tonic(self.source(ci), start, stop)


def spikes_to_tonic(source, start: int = 0, stop: int | None = None,
                    block_ticks: int = 4096) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Ticks [start, stop) of a spike source as tonic events and ``sensor_size`` (W, H, 1)."""
    stop = source.n_ticks if stop is None else min(stop, source.n_ticks)
    parts = []
    for first, block in source.iter_blocks(block_ticks, start, stop):
        k, y, x = np.nonzero(block)
        ev = np.empty(k.size, TONIC_EVENT_DTYPE)
        ev["x"], ev["y"], ev["p"] = x, y, 0
        ev["t"] = np.rint((source.start_time_s + (first + k + 1) / source.clock_hz) * 1e6).astype(np.int64)
        parts.append(ev)
    events = np.concatenate(parts) if parts else np.empty(0, TONIC_EVENT_DTYPE)
    return events, (int(source.width), int(source.height), 1)


def read_gt(path) -> np.ndarray:
    """A ground-truth image as float32 in [0, 1], grayscale (colour → Rec. 709 luminance)."""
    import imageio.v3 as iio

    image = np.asarray(iio.imread(path))
    full = float(np.iinfo(image.dtype).max) if np.issubdtype(image.dtype, np.integer) else 1.0
    image = image.astype(np.float32) / full
    if image.ndim == 3:
        image = image[..., :3] @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)
    return image


def open_dataset(root, **kwargs) -> SpikeFolder:
    """Open a spike dataset folder (viform, Spike-Zoo or SpikeCV layout); see :class:`SpikeFolder`."""
    return SpikeFolder(root, **kwargs)
