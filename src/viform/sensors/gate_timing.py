"""The timing of one gate of a range-gated interline CCD (seed 004, Fig. 3).

:class:`GateTiming` is the one timing model from which both the physics
(:class:`~viform.sensors.gated_ccd.GatedInterlineCCD`) and the drawn drive
(:func:`~viform.sensors.gated_waveforms.drive_waveforms`) are derived.
"""

from __future__ import annotations

from dataclasses import dataclass

from viform._validate import ViformError, check_non_negative, check_positive
from viform.light.laser import PulsedLaser, range_from_delay_m, round_trip_time_s


@dataclass(frozen=True)
class GateTiming:
    """The one timing model of a gate (seed 004, Fig. 3), from which both the physics
    (:class:`~viform.sensors.gated_ccd.GatedInterlineCCD`) and the drawn drive
    (:func:`~viform.sensors.gated_waveforms.drive_waveforms`) are derived.

    Instants after the laser pulse starts:

    * ``open_s`` = 2R/c: SUB falls, the photodiodes start to integrate;
    * ``transfer_start_s`` = open + τ + t_min: V2/V3 rise to +15 V (the seed's t_нак = τ + t_min
      ends here, and its t_экспозиции = X·t_нак counts only this);
    * ``close_s`` = transfer_start + ``readout_pulse_s``: V2/V3 fall and SUB rises again.

    While the readout pulse is high the photodiode is connected to the vertical register, so
    the charge it collects during the pulse is moved too (the seed itself says charge
    accumulates again only "as soon as the positive potential stops being applied"); SUB
    cannot rise earlier without draining the packet being transferred. The light is therefore
    collected over [open_s, close_s] = τ + t_min + t_readout — 2.135 µs with the assumed 1 µs
    pulse, not the seed's 1.135 µs. The seed's figure (only its caption survives in the text)
    gives no pulse width; its text supports t_нак = τ + t_min as the *drawn* SUB→V2/V3 interval.

    Raises :class:`ViformError` if the gate is not inside one pulse period (range beyond
    the unambiguous range c/(2 f_rep)).
    """

    gate_range_m: float
    laser: PulsedLaser
    min_transfer_time_s: float
    readout_pulse_s: float = 1.0e-6

    def __post_init__(self):
        r = self.gate_range_m
        if isinstance(r, (int, float)) and r < 0:
            raise ViformError(f"gate_range_m = {r!r} is not allowed: the gate range must be ≥ 0 m")
        check_non_negative("gate_range_m", r)
        check_positive("min_transfer_time_s", self.min_transfer_time_s)
        check_positive("readout_pulse_s", self.readout_pulse_s)
        if self.close_s >= self.laser.period_s:
            raise ViformError(
                f"gate_range_m = {r:g} m is beyond the unambiguous range: the gate would close "
                f"{self.close_s * 1e6:.2f} µs after the pulse, after the next pulse "
                f"({self.laser.period_s * 1e6:.1f} µs at {self.laser.repetition_hz:g} Hz); the largest "
                f"gate range is "
                f"{self.max_gate_range_m(self.laser, self.min_transfer_time_s, self.readout_pulse_s):.0f} m"
            )

    @staticmethod
    def max_gate_range_m(laser: PulsedLaser, min_transfer_time_s: float, readout_pulse_s: float = 1.0e-6) -> float:
        return range_from_delay_m(laser.period_s - laser.pulse_width_s - min_transfer_time_s - readout_pulse_s)

    @property
    def open_s(self) -> float:
        """Gate delay t_откл = 2R/c (end of SUB), s."""
        return round_trip_time_s(self.gate_range_m)

    @property
    def accumulation_s(self) -> float:
        """The seed's t_нак = pulse width + minimum SUB → V2/V3 time, s (drawn, not collected)."""
        return self.laser.pulse_width_s + self.min_transfer_time_s

    @property
    def transfer_start_s(self) -> float:
        """Rising edge of the V2/V3 readout pulse, s after the pulse start."""
        return self.open_s + self.accumulation_s

    @property
    def close_s(self) -> float:
        """End of the readout pulse (SUB rises), s after the pulse start: light stops counting here."""
        return self.transfer_start_s + self.readout_pulse_s

    @property
    def width_s(self) -> float:
        """Collection window per pulse, s: t_нак + the readout pulse."""
        return self.close_s - self.open_s

    @property
    def range_window_m(self) -> tuple[float, float]:
        """Ranges with some return inside the gate: (R − cτ/2, R + c·width/2)."""
        c_half = range_from_delay_m(1.0)
        return (
            max(0.0, self.gate_range_m - c_half * self.laser.pulse_width_s),
            self.gate_range_m + c_half * self.width_s,
        )

    @property
    def full_range_window_m(self) -> tuple[float, float]:
        """Ranges whose whole return lies inside the gate: [R, R + c·(width − τ)/2]."""
        return (self.gate_range_m, self.gate_range_m + range_from_delay_m(self.width_s - self.laser.pulse_width_s))

    def to_dict(self) -> dict:
        return {
            "gate_range_m": self.gate_range_m,
            "open_s": self.open_s,
            "accumulation_s": self.accumulation_s,
            "transfer_start_s": self.transfer_start_s,
            "readout_pulse_s": self.readout_pulse_s,
            "width_s": self.width_s,
            "close_s": self.close_s,
            "range_window_m": list(self.range_window_m),
            "full_range_window_m": list(self.full_range_window_m),
        }
