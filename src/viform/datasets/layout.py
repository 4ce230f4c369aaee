"""The on-disk layout of a spike dataset (Spike-Zoo / SpikeCV style) and its small helpers.

::

    DIR/
      config.yaml            spike_h, spike_w (SpikeCV/Spike-Zoo keys) + how the set was made
      manifest.json          one row per clip: ticks, spikes, sha256 of the .dat, ground-truth frames
      spike/<clip>.dat       headerless packed bits, rows bottom-up (the cameras' .dat layout)
      spike/<clip>.dat.json  sidecar: full sensor description, seed, source clip, provenance
      gt/<clip>_<frame>.png  8-bit ground truth: the light of source frame <frame> at sensor size

Seeds: every clip gets its own photon-noise seed, a hash of the dataset seed and the clip's
name (:func:`clip_seed`), so a clip's bits do not depend on which worker converts it, in
which order, or which other clips are in the set.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from viform._io import atomic_open
from viform._validate import ViformError, check_int

SPIKE_DIR = "spike"
GT_DIR = "gt"
CONFIG_NAME = "config.yaml"
MANIFEST_NAME = "manifest.json"
#: Format tag written in config.yaml and the manifest.
LAYOUT_FORMAT = "viform-spike-dataset/1"


def clip_seed(dataset_seed: int, clip: str) -> int:
    """Photon-noise seed of one clip: the first 63 bits of SHA-256("<dataset seed>/<clip name>").

    A pure function of the two, so results do not depend on worker count or order.
    """
    dataset_seed = check_int("seed", dataset_seed)
    digest = hashlib.sha256(f"{dataset_seed}/{clip}".encode()).digest()
    return int.from_bytes(digest[:8], "little") & ((1 << 63) - 1)


def gt_name(clip: str, frame: int) -> str:
    """File name of the ground truth of source frame ``frame`` of ``clip``."""
    return f"{clip}_{frame:06d}.png"


def spike_path(root, clip: str) -> Path:
    return Path(root) / SPIKE_DIR / f"{clip}.dat"


def sha256_file(path, chunk_bytes: int = 1 << 22) -> str:
    """Hex SHA-256 of a file, read in 4 MiB chunks (bounded memory)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(chunk_bytes):
            h.update(chunk)
    return h.hexdigest()


def read_config(path) -> dict:
    """Read a SpikeCV / Spike-Zoo ``config.yaml``; ``spike_h`` and ``spike_w`` must be whole numbers ≥ 1.

    ``path`` is the file or the folder that holds it.
    """
    import yaml

    path = Path(path)
    if path.is_dir():
        path = path / CONFIG_NAME
    if not path.is_file():
        raise ViformError(f"dataset config {str(path)!r} does not exist")
    try:
        with open(path, encoding="utf-8") as f:
            config = yaml.safe_load(f)
    except yaml.YAMLError as exc:
        raise ViformError(f"{str(path)!r} is not valid YAML: {str(exc).splitlines()[0]}") from None
    if not isinstance(config, dict):
        raise ViformError(f"{str(path)!r} must hold a mapping with spike_h and spike_w; got {type(config).__name__}")
    for key in ("spike_h", "spike_w"):
        if key not in config:
            raise ViformError(f"{str(path)!r} has no {key!r}: the .dat layout does not store the frame size")
        config[key] = check_int(f"{path.name}: {key}", config[key], 1)
    return config


def write_config(path, config: dict) -> None:
    """Write ``config.yaml`` atomically (keys in the given order)."""
    import yaml

    with atomic_open(path, "w") as f:
        yaml.safe_dump(config, f, sort_keys=False, allow_unicode=True)
