"""PyTorch dataset of spike windows and ground truth (optional extra: ``pip install 'viform[torch]'``).

Use it as ``viform.torch.SpikeDataset``. Each item is a Spike-Zoo-style sample::

    {"spike": float32 tensor (T, H, W) of 0/1, "gt_img": float32 tensor (1, H, W) in [0, 1],
     "rate": float, "clip": str, "tick": int}

and, for datasets made from built-in scenes (``viform dataset --scenes``), the exact truth:
``flow`` (2, H, W) px and ``flow_valid`` (H, W), ``depth`` (H, W) m, ``boxes`` (N, 4) x, y, w, h
px, ``ids``, ``classes`` and ``visibility`` (N,). ``boxes`` and friends differ in length from
frame to frame: batch them with :func:`collate` (lists for those, stacks for the rest).

``T`` ticks are centred on a ground-truth frame (see :mod:`viform.datasets.loaders`), and
``spike.mean(0) / rate`` estimates ``gt_img`` (seed 000 §3.2: the firing rate is proportional
to the light below saturation).
"""

from __future__ import annotations

try:
    import torch
    from torch.utils.data import Dataset
except ImportError as exc:  # pragma: no cover - exercised only without torch
    raise ImportError("viform's PyTorch dataset needs PyTorch: pip install 'viform[torch]'") from exc

from viform.datasets.loaders import DEFAULT_WINDOW_TICKS, SpikeFolder


class SpikeDataset(Dataset):
    """A spike dataset folder (viform, Spike-Zoo or SpikeCV layout) as a map-style torch dataset.

    Parameters
    ----------
    root : path
        The dataset folder.
    window_ticks : int
        Ticks per sample (41 by default).
    transform : callable, optional
        Applied to each sample dict before it is returned (augmentation, cropping).
    **kwargs
        Passed to :class:`viform.datasets.loaders.SpikeFolder` (``height``, ``width``,
        ``rate``, ``split``, ``npz_key``, ``npz_axes``, ``flip``).
    """

    def __init__(self, root, *, window_ticks: int = DEFAULT_WINDOW_TICKS, transform=None, **kwargs):
        self.folder = SpikeFolder(root, window_ticks=window_ticks, **kwargs)
        self.transform = transform

    def __len__(self) -> int:
        return len(self.folder)

    def __getitem__(self, index: int) -> dict:
        sample = self.folder[index]
        item = {"spike": torch.from_numpy(sample["spike"]).to(torch.float32),
                "gt_img": torch.from_numpy(sample["gt_img"]),
                "rate": float(sample["rate"]), "clip": sample["clip"], "tick": int(sample["tick"])}
        for key in TRUTH_KEYS:
            if key in sample:
                item[key] = torch.from_numpy(sample[key])
        return self.transform(item) if self.transform is not None else item


#: Truth keys of scene datasets; the last four vary in length per frame.
TRUTH_KEYS = ("flow", "flow_valid", "depth", "boxes", "ids", "classes", "visibility")
_PER_OBJECT = ("boxes", "ids", "classes", "visibility")


def collate(samples: list[dict]) -> dict:
    """Batch samples for a ``DataLoader(collate_fn=collate)``: per-object truth as lists, the rest stacked."""
    from torch.utils.data import default_collate

    fixed = [{k: v for k, v in s.items() if k not in _PER_OBJECT} for s in samples]
    batch = default_collate(fixed)
    for key in _PER_OBJECT:
        if key in samples[0]:
            batch[key] = [s[key] for s in samples]
    return batch
