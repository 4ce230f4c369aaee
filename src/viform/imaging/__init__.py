"""Images at any instant from a spike stream (seed 000 §3.3): accumulation, interval,
multi-interval and motion-compensated imaging, at one instant or over a whole stream."""

from viform.imaging.accumulation import (
    ALIGNMENTS,
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
from viform.imaging.motion import motion_compensated_image
from viform.imaging.multi_interval import multi_interval_image
from viform.imaging.sequence import METHODS, reconstruct_ticks
from viform.imaging.support import SpikeSupport, imaging_need, spike_support, support_from_rates
from viform.imaging.units import LightImage

__all__ = [
    "ALIGNMENTS", "LightImage", "METHODS", "accumulation_8bit", "accumulation_image", "interval_8bit",
    "interval_frames", "interval_image", "interval_ticks", "inverse_tau_display_8bit", "motion_compensated_image",
    "multi_interval_image", "reconstruct_ticks", "sliding_accumulation", "spike_counts", "tau_display_8bit",
    "SpikeSupport", "imaging_need", "spike_support", "support_from_rates",
]
