"""The interface every sensor model shares.

A sensor captures a :class:`~viform.light.scenes.Scene` over a time span and returns its
output: a :class:`~viform.stream.container.SpikeStream` for the spike camera, a
:class:`FrameStack` for frame cameras. ``describe()`` gives the parameters as plain data,
saved with every capture so results can be traced to the model that made them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from viform._validate import ViformError
from viform.light.scenes import Scene


class Sensor(ABC):
    """A sensor model: pixel physics plus readout."""

    #: Short name used in reports and presets.
    name: str = "sensor"

    @abstractmethod
    def capture(self, scene: Scene, duration_s: float, *, seed: int = 0):
        """Capture ``scene`` from t = 0 for ``duration_s`` seconds."""

    @abstractmethod
    def describe(self) -> dict:
        """The model's parameters as JSON-serialisable data (units in the keys)."""

    def check_scene(self, scene: Scene, height: int | None, width: int | None) -> tuple[int, int]:
        """Resolution to capture at: the sensor's if set, which must match the scene's."""
        if height is None and width is None:
            return scene.shape
        if (height, width) != scene.shape:
            raise ViformError(f"sensor resolution {height}x{width} (HxW) differs from the scene's "
                              f"{scene.height}x{scene.width}; build the scene at the sensor's resolution")
        return height, width


@dataclass
class FrameStack:
    """Frames from a frame camera.

    Attributes
    ----------
    frames_dn : ndarray, shape (N, H, W)
        Digital numbers after the ADC (unsigned integers).
    start_times_s : ndarray, shape (N,)
        Start of each frame's exposure, seconds.
    exposure_s : ndarray, shape (N,)
        Exposure time of each frame, seconds.
    metadata : dict
        The sensor's ``describe()`` and anything the capture adds.
    """

    frames_dn: np.ndarray
    start_times_s: np.ndarray
    exposure_s: np.ndarray
    metadata: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.frames_dn.shape[0])
