"""Sensor models, one module per architecture, behind :class:`~viform.sensors.base.Sensor`.

Every camera is a :class:`Sensor` whose ``capture(scene, duration_s, *, seed)`` returns its native output
(a :class:`FrameStack` or a :class:`~viform.stream.SpikeStream`). The catalogue (:data:`SENSORS`,
:func:`make_sensor`, :func:`sensor_names`) names every sensor the commands know; the models are:

* spike cameras: :class:`SpikeSensor` (:class:`SpikeSensorParameters`; chip presets
  :func:`load_spike_preset`), :class:`SubthresholdSpikeSensor`;
* frame cameras: :class:`FrameSensor` (:class:`FramePixelParameters`), the segmented-exposure HDR CMOS
  :class:`SegmentedExposureSensor`, the overflow-capacitor HDR pixel :class:`OverflowSensor`, the
  1,666 fps :class:`HighSpeedCamera` and the range-gated :class:`GatedInterlineCCD`.

The names are imported on first use (:mod:`viform._lazy`): ``import viform.sensors`` costs nothing.
"""

from viform import _lazy

__all__ = [
    "Sensor", "FrameStack",
    "SENSORS", "SensorEntry", "make_sensor", "sensor_names", "register",
    "SpikeSensor", "SpikeSensorParameters",
    "SpikePreset", "load_spike_preset", "save_spike_preset",
    "SubthresholdSpikeSensor",
    "FrameSensor", "FramePixelParameters",
    "SegmentedExposureSensor", "RpdBarrier",
    "OverflowSensor", "PhotodiodeJunction",
    "HighSpeedCamera", "AutoExposure",
    "GatedInterlineCCD", "InterlineCCDParameters", "GateTiming",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "base": ["Sensor", "FrameStack"],
    "catalog": ["SENSORS", "SensorEntry", "make_sensor", "sensor_names", "register"],
    "spike": ["SpikeSensor", "SpikeSensorParameters"],
    "spike_presets": ["SpikePreset", "load_spike_preset", "save_spike_preset"],
    "subthreshold": ["SubthresholdSpikeSensor"],
    "frame": ["FrameSensor", "FramePixelParameters"],
    "segmented": ["SegmentedExposureSensor", "RpdBarrier"],
    "overflow": ["OverflowSensor", "PhotodiodeJunction"],
    "highspeed": ["HighSpeedCamera"],
    "auto_exposure": ["AutoExposure"],
    "gated_ccd": ["GatedInterlineCCD", "InterlineCCDParameters"],
    "gate_timing": ["GateTiming"],
})
