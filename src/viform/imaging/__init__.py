"""Images at any instant from a viform (seed 000 §3.3): accumulation and interval imaging."""

from viform.imaging.accumulation import (
    accumulation_8bit,
    accumulation_image,
    sliding_accumulation,
    spike_counts,
)
from viform.imaging.interval import (
    interval_8bit,
    interval_frames,
    interval_image,
    interval_ticks,
    inverse_tau_display_8bit,
    tau_display_8bit,
)
from viform.imaging.units import LightImage

__all__ = [
    "LightImage", "accumulation_8bit", "accumulation_image", "interval_8bit", "interval_frames",
    "interval_image", "interval_ticks", "inverse_tau_display_8bit", "sliding_accumulation", "spike_counts",
    "tau_display_8bit",
]
