"""PyTorch entry points (optional extra ``viform[torch]``): :class:`SpikeDataset`.

torch is imported only when ``viform.torch.SpikeDataset`` is first used, so ``import viform``
never needs it. The implementation lives in :mod:`viform.torch_dataset`.
"""

from __future__ import annotations

__all__ = ["SpikeDataset"]  # noqa: F822 (provided lazily by __getattr__)


def __getattr__(name: str):
    if name == "SpikeDataset":
        from viform.torch_dataset import SpikeDataset

        return SpikeDataset
    raise AttributeError(f"module 'viform.torch' has no attribute {name!r}")
