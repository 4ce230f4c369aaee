"""PyTorch entry points (optional extra ``viform[torch]``): :class:`SpikeDataset` and its ``collate``.

torch is imported only when ``viform.torch.SpikeDataset`` is first used, so ``import viform``
never needs it. The implementation lives in :mod:`viform.torch_dataset`.
"""

from __future__ import annotations

__all__ = ["SpikeDataset", "collate"]  # noqa: F822 (provided lazily by __getattr__)


def __getattr__(name: str):
    if name in ("SpikeDataset", "collate"):
        import viform.torch_dataset as implementation

        return getattr(implementation, name)
    raise AttributeError(f"module 'viform.torch' has no attribute {name!r}")
