"""viform.torch.SpikeDataset: Spike-Zoo-style samples through a DataLoader (skipped without torch)."""

from __future__ import annotations

import pytest


def test_import_viform_torch_does_not_need_torch():
    import viform.torch

    assert "SpikeDataset" in viform.torch.__all__


def test_dataloader_batches(spike_zoo_layout):
    torch = pytest.importorskip("torch")
    from viform.torch import SpikeDataset

    dataset = SpikeDataset(spike_zoo_layout, window_ticks=21)
    assert len(dataset) == 2
    loader = torch.utils.data.DataLoader(dataset, batch_size=2, shuffle=False, num_workers=0)
    batch = next(iter(loader))
    assert batch["spike"].shape == (2, 21, 250, 400) and batch["spike"].dtype == torch.float32
    assert batch["gt_img"].shape == (2, 1, 250, 400)
    assert set(torch.unique(batch["spike"]).tolist()) <= {0.0, 1.0}
    assert torch.allclose(batch["rate"].float(), torch.tensor([0.6, 0.6]))
    # the spike-rate image tracks the ground truth: correlation well above chance
    est = batch["spike"].mean(1) / batch["rate"].view(-1, 1, 1)
    corr = torch.corrcoef(torch.stack([est[0].flatten(), batch["gt_img"][0, 0].flatten()]))[0, 1]
    assert corr > 0.8, corr
