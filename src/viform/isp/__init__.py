"""Image signal processing of the high-frame-rate camera (seed 002): equalization, links, the whole pipeline.

* :func:`run_highspeed` shoots a scene with the 1,666 fps camera and runs its FPGA pipeline
  (:class:`HighSpeedConfig` → :class:`HighSpeedResult`); :func:`process_frames` runs the pipeline on
  frames already captured.
* Histogram equalization as the FPGA computes it: :func:`histogram_counter`,
  :func:`equalization_lut_float`, :func:`equalization_lut_shift`, :func:`equalize`, and
  :class:`StreamEqualizer` (the table of the previous frame applied to the next).
* Links and the DDR ring: :func:`link_plan`, :func:`choose_decimation`, :data:`INTERFACES`,
  :class:`RingBuffer`, :class:`DDRBuffer`.

The names are imported on first use (:mod:`viform._lazy`): ``import viform.isp`` costs nothing.
"""

from viform import _lazy

__all__ = [
    "run_highspeed", "process_frames", "HighSpeedConfig", "HighSpeedResult",
    "histogram_counter", "equalization_lut_float", "equalization_lut_shift", "equalize", "StreamEqualizer",
    "link_plan", "choose_decimation", "INTERFACES", "RingBuffer", "DDRBuffer",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "highspeed_pipeline": ["run_highspeed", "process_frames", "HighSpeedConfig", "HighSpeedResult"],
    "histogram": ["histogram_counter", "equalization_lut_float", "equalization_lut_shift", "equalize",
                  "StreamEqualizer"],
    "link": ["link_plan", "choose_decimation", "INTERFACES", "RingBuffer", "DDRBuffer"],
})
