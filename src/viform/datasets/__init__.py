"""Spike datasets: convert video clips at scale (dask.distributed) and read the layouts the field uses.

* :func:`build_dataset` / ``viform dataset``: a folder of videos or frame folders → the
  Spike-Zoo / SpikeCV layout (``spike/<clip>.dat``, ``gt/<clip>_<frame>.png``, ``config.yaml``),
  with a JSON sidecar per ``.dat`` and a manifest (:mod:`viform.datasets.build`).
* :func:`open_dataset`: that layout and Spike-Zoo / SpikeCV ones (``.dat`` + ``config.yaml``,
  ``.npz`` with key ``spk``) as ground-truth-aligned samples and tonic-style events
  (:mod:`viform.datasets.loaders`). The PyTorch wrapper is :class:`viform.torch.SpikeDataset`.
"""

from viform.datasets.build import DatasetSettings, build_dataset, convert_serially, make_settings
from viform.datasets.layout import clip_seed, read_config
from viform.datasets.loaders import SpikeFolder, open_dataset

__all__ = ["DatasetSettings", "build_dataset", "convert_serially", "make_settings", "clip_seed", "read_config",
           "SpikeFolder", "open_dataset"]
