"""Camera links, frame decimation and the DDR ring buffer (seed 002 §3.2.5, §3.3).

Seed 002 §3.3, Table 3 compares the usual machine-vision links; the camera uses CameraLink
*Full* (80 MHz, 8 pixels per clock at 8 bit, 40-cycle gaps between lines and between frames):

    link_cycles_per_frame = H · (ceil(W / taps) + line_gap) + frame_gap               (L1)

which gives 80 MHz / (720 · (160 + 40) + 40) = 555.4 fps at 1280 × 720 × 8 bit (seed: 555 fps).
Serial links (CoaXPress, CameraLink HS, USB 3.0, GigE Vision) are modelled by their payload
bandwidth: lanes × line rate × line-code efficiency × protocol efficiency (the last is our
assumption, stated per link below), so

    link_frame_rate_hz = payload_bps / (H · W · bits)                                (L2)

Seed 002 §3.2.5: every frame from the sensor is written to a 2 GB DDR4 ring
(2 GiB / (1280 · 720 · 8 bit) ≈ 2 330 frames); every third frame is read out and sent
(3:1 decimation); when the ring is full writing wraps to the start. :class:`RingBuffer`
replays that schedule frame by frame and counts what is sent, what is still buffered and
what is lost.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from viform._validate import ViformError, check_choice, check_int, check_positive, check_range


@dataclass(frozen=True)
class CameraLinkTiming:
    """A parallel-tap link with line and frame gaps (CameraLink, seed 002 §3.3, eq. (L1)).

    Attributes
    ----------
    name : str
    clock_hz : float
        Pixel clock of the link, Hz (80 MHz for CameraLink Full, seed 002 §3.3).
    data_bits_per_clock : int
        Payload bits per clock (64 for Full: 8 taps × 8 bit, or 6 × 10 bit).
    line_gap_cycles, frame_gap_cycles : int
        Idle clocks after each line and each frame (40 and 40 in the seed).
    max_distance_m : float
    realtime_trigger : bool
    """

    name: str = "cameralink"
    clock_hz: float = 80e6
    data_bits_per_clock: int = 64
    line_gap_cycles: int = 40
    frame_gap_cycles: int = 40
    max_distance_m: float = 10.0
    realtime_trigger: bool = True

    def pixels_per_clock(self, bits_per_pixel: int) -> int:
        return self.data_bits_per_clock // bits_per_pixel

    def cycles_per_frame(self, height: int, width: int, bits_per_pixel: int = 8) -> int:
        """(L1): H · (ceil(W / taps) + line_gap) + frame_gap."""
        taps = self.pixels_per_clock(_check_bits(bits_per_pixel))
        if taps < 1:
            raise ViformError(f"bits_per_pixel = {bits_per_pixel} does not fit the link's "
                              f"{self.data_bits_per_clock}-bit word")
        return height * (math.ceil(width / taps) + self.line_gap_cycles) + self.frame_gap_cycles

    def max_frame_rate_hz(self, height: int, width: int, bits_per_pixel: int = 8) -> float:
        """Highest real-time frame rate (555.4 fps for 1280 × 720 × 8 bit)."""
        return self.clock_hz / self.cycles_per_frame(height, width, bits_per_pixel)

    @property
    def payload_bps(self) -> float:
        return self.clock_hz * self.data_bits_per_clock

    def describe(self) -> dict:
        return {"kind": "parallel", **asdict(self), "payload_bps": self.payload_bps}


@dataclass(frozen=True)
class SerialLink:
    """A serial link rated by bandwidth (seed 002, Table 3, eq. (L2)).

    Attributes
    ----------
    name : str
    lanes : int
    lane_rate_bps : float
        Line rate of one lane, bit/s (Table 3).
    line_code_efficiency : float
        Payload fraction after line coding (8b/10b → 0.8).
    protocol_efficiency : float
        Payload fraction after packet headers, our assumption (not in the seed).
    max_distance_m : float
    realtime_trigger : bool
    """

    name: str
    lanes: int
    lane_rate_bps: float
    line_code_efficiency: float = 0.8
    protocol_efficiency: float = 0.95
    max_distance_m: float = 100.0
    realtime_trigger: bool = False

    @property
    def payload_bps(self) -> float:
        return (self.lanes * self.lane_rate_bps * self.line_code_efficiency
                * self.protocol_efficiency)

    def max_frame_rate_hz(self, height: int, width: int, bits_per_pixel: int = 8) -> float:
        """(L2): payload_bps / (H · W · bits)."""
        return self.payload_bps / (height * width * _check_bits(bits_per_pixel))

    def describe(self) -> dict:
        return {"kind": "serial", **asdict(self), "payload_bps": self.payload_bps}


def _check_bits(bits):
    return check_int("bits_per_pixel", bits, 1, 16)


#: The links of seed 002 Table 3. Line rates are the table's; lane counts and efficiencies
#: are ours: CoaXPress CXP-6 × 4 lanes (8b/10b), CameraLink HS M-protocol 2N × 3.125 Gbit/s
#: with N = 4 (8b/10b), USB 3.0 5 Gbit/s (8b/10b, ~85 % after USB3 Vision packets),
#: GigE Vision 1 Gbit/s (~95 % after UDP/GVSP headers with jumbo frames).
INTERFACES = {
    "coaxpress": SerialLink("coaxpress", lanes=4, lane_rate_bps=6.25e9, line_code_efficiency=0.8,
                            protocol_efficiency=0.95, max_distance_m=100.0, realtime_trigger=True),
    "cameralink-hs": SerialLink("cameralink-hs", lanes=8, lane_rate_bps=3.125e9,
                                line_code_efficiency=0.8, protocol_efficiency=0.95,
                                max_distance_m=15.0),
    "cameralink": CameraLinkTiming(),
    "usb3": SerialLink("usb3", lanes=1, lane_rate_bps=5e9, line_code_efficiency=0.8,
                       protocol_efficiency=0.85, max_distance_m=3.0),
    "gige": SerialLink("gige", lanes=1, lane_rate_bps=1e9, line_code_efficiency=1.0,
                       protocol_efficiency=0.95, max_distance_m=100.0),
}


def get_interface(name: str):
    """A link from :data:`INTERFACES` by name (error names ``interface``)."""
    return INTERFACES[check_choice("interface", name, tuple(INTERFACES))]


# ---------------------------------------------------------------------- decimation

def choose_decimation(sensor_rate_hz: float, link_rate_hz: float, *, max_decimation: int = 64,
                      buffer_frames: int | None = None, sustain_s: float | None = None,
                      interface: str = "link") -> int:
    """Smallest N so that 1 frame in N fits the link (seed 002 §3.2.5, the 3:1 sampling).

    Without a buffer the condition is strict: sensor_rate / N ≤ link_rate. With a ring of
    ``buffer_frames`` and a recording of ``sustain_s`` seconds, a small excess is allowed as
    long as the backlog of frames waiting for the link stays inside the ring for the whole
    recording (see :func:`overrun_time_s`). This is how the seed sends every 3rd frame of
    1 666.7 fps over a 555.4 fps link: strictly 1 666.7 / 3 = 555.6 fps is 0.03 % too fast,
    and the ring absorbs the difference for ≈ 83 minutes.

    Parameters
    ----------
    sensor_rate_hz : float
        Sensor frame rate, Hz.
    link_rate_hz : float
        Frames per second the link carries, Hz.
    max_decimation : int
        Largest N tried.
    buffer_frames : int, optional
        Frames the ring holds (none: the strict condition).
    sustain_s : float, optional
        Recording length the ring must absorb, s.
    interface : str
        The link's name, for the error message.

    Returns
    -------
    int
        N: 1 frame in N is sent.

    Raises
    ------
    ViformError
        When even ``max_decimation`` does not fit (the message names ``interface``).

    Examples
    --------
    The seed's camera: 1 666.7 fps over CameraLink Full (555.4 fps), with and without the 2 GB ring
    (2 330 frames) over an hour:

    >>> choose_decimation(1666.7, 555.4)
    4
    >>> choose_decimation(1666.7, 555.4, buffer_frames=2330, sustain_s=3600.0)
    3
    """
    sensor_rate_hz = check_positive("sensor_rate_hz", sensor_rate_hz)
    link_rate_hz = check_positive("link_rate_hz", link_rate_hz)
    max_decimation = check_int("max_decimation", max_decimation, 1)
    for n in range(1, max_decimation + 1):
        if sensor_rate_hz / n <= link_rate_hz * (1 + 1e-12):
            return n
        if buffer_frames is not None and sustain_s is not None:
            if overrun_time_s(sensor_rate_hz, link_rate_hz, n, buffer_frames) >= sustain_s:
                return n
    need = math.ceil(sensor_rate_hz / link_rate_hz)
    raise ViformError(
        f"interface = {interface!r} is too slow: it carries at most {link_rate_hz:.1f} fps but the "
        f"sensor makes {sensor_rate_hz:.1f} fps, which needs {need}:1 decimation > "
        f"max_decimation = {max_decimation}; choose a faster interface, a smaller roi or a "
        f"larger max_decimation")


def overrun_time_s(sensor_rate_hz: float, link_rate_hz: float, decimation: int,
                   buffer_frames: int) -> float:
    """Time until the ring overwrites a selected frame not yet sent (inf if the link keeps up).

    Selected frames arrive at r_s = sensor/N and leave at r_l, so the backlog grows as
    B(t) = (r_s − r_l)·t. The oldest waiting frame was written B / r_s ago; its slot is
    rewritten C / sensor after it was written, and its transfer takes 1 / r_l, so the first
    loss comes when B / r_s + 1 / r_l = C / sensor:

        t_loss = (C / N − r_s / r_l) / (r_s − r_l)
    """
    selected = sensor_rate_hz / decimation
    excess = selected - link_rate_hz
    if excess <= 0:
        return math.inf
    return max(0.0, buffer_frames / decimation - selected / link_rate_hz) / excess


# ---------------------------------------------------------------------- DDR ring

@dataclass(frozen=True)
class DDRBuffer:
    """The frame store (seed 002 §3.2: DDR4, 64 bit, 2 GB, up to 3 200 MT/s).

    Attributes
    ----------
    capacity_bytes : int
        2 GiB = 2 147 483 648 bytes (the seed's 2 330 frames follow from binary gigabytes).
    bus_bits : int
    transfer_rate_per_s : float
        Transfers per second (3.2e9).
    efficiency : float
        Usable fraction of the peak bandwidth (refresh, bank turns); our assumption.
    """

    capacity_bytes: int = 2 * 1024 ** 3
    bus_bits: int = 64
    transfer_rate_per_s: float = 3.2e9
    efficiency: float = 0.7

    def frame_bytes(self, height: int, width: int, bits_per_pixel: int = 8) -> int:
        return math.ceil(height * width * _check_bits(bits_per_pixel) / 8)

    def capacity_frames(self, height: int, width: int, bits_per_pixel: int = 8) -> int:
        """Whole frames that fit: 2 330 for 1280 × 720 × 8 bit."""
        return self.capacity_bytes // self.frame_bytes(height, width, bits_per_pixel)

    def record_duration_s(self, frame_rate_hz: float, height: int, width: int,
                          bits_per_pixel: int = 8) -> float:
        """Length of the history the ring holds at the sensor's frame rate (1.40 s in the seed)."""
        return self.capacity_frames(height, width, bits_per_pixel) / check_positive("frame_rate_hz",
                                                                                    frame_rate_hz)

    @property
    def peak_bandwidth_bytes_per_s(self) -> float:
        return self.bus_bits / 8 * self.transfer_rate_per_s

    def check_bandwidth(self, write_rate_hz: float, read_rate_hz: float, height: int, width: int,
                        bits_per_pixel: int = 8) -> float:
        """Fraction of the usable bandwidth needed to write every frame and read the sent ones."""
        need = (write_rate_hz + read_rate_hz) * self.frame_bytes(height, width, bits_per_pixel)
        load = need / (self.peak_bandwidth_bytes_per_s * self.efficiency)
        if load > 1:
            raise ViformError(f"DDR bandwidth exceeded: writing {write_rate_hz:.0f} fps and "
                              f"reading "
                              f"{read_rate_hz:.0f} fps needs {need / 1e9:.2f} GB/s, more than "
                              f"{self.peak_bandwidth_bytes_per_s * self.efficiency / 1e9:.2f} GB/s")
        return load


@dataclass
class StreamAccount:
    """What happened to every captured frame (see :meth:`RingBuffer.run`)."""

    captured: int
    buffered: int
    transmitted: int
    dropped: int
    decimation: int
    transmitted_indices: np.ndarray
    overrun_indices: np.ndarray
    send_end_times_s: np.ndarray

    def to_dict(self) -> dict:
        return {"frames_captured": self.captured, "frames_buffered_at_end": self.buffered,
                "frames_transmitted": self.transmitted, "frames_dropped": self.dropped,
                "selected_but_overwritten": int(self.overrun_indices.size),
                "decimation": self.decimation}


class RingBuffer:
    """Replay of the seed's DDR4 write/read arbitration (seed 002 §3.2.5).

    Every sensor frame i is written to slot i mod C when its readout ends, at
    (i + 1) / sensor_rate. Frames with i mod N = 0 are queued for the link, which sends one
    at a time at ``link_rate_hz``. A queued frame whose slot would be rewritten (frame
    i + C written) before its transmission ends is skipped: it is lost.

    *Transmitted* frames are those whose transfer ends within the recording (n frames). At
    the end the ring still holds the last min(n, C) frames, which can be read out afterwards;
    a frame is *dropped* when it was neither sent nor is still in the ring.
    """

    def __init__(self, capacity_frames: int, sensor_rate_hz: float, link_rate_hz: float,
                 decimation: int):
        self.capacity_frames = check_int("capacity_frames", capacity_frames, 1)
        self.sensor_rate_hz = check_positive("sensor_rate_hz", sensor_rate_hz)
        self.link_rate_hz = check_positive("link_rate_hz", link_rate_hz)
        self.decimation = check_int("decimation", decimation, 1)

    def run(self, n_frames: int) -> StreamAccount:
        n = check_int("n_frames", n_frames, 0)
        c, d = self.capacity_frames, self.decimation
        written = (np.arange(n) + 1) / self.sensor_rate_hz
        send_time = 1.0 / self.link_rate_hz
        link_free = 0.0
        sent, lost, ends = [], [], []
        t_end = n / self.sensor_rate_hz
        for i in range(0, n, d):
            start = max(written[i], link_free)
            if start + send_time > t_end:
                break  # the recording is over: the rest stays in the ring (read out later)
            # Slot i is rewritten when frame i + C is written; that may lie beyond the record.
            overwrite = (i + c + 1) / self.sensor_rate_hz
            if start + send_time > overwrite:
                lost.append(i)
                continue
            link_free = start + send_time
            sent.append(i)
            ends.append(link_free)
        sent_arr = np.asarray(sent, dtype=np.int64)
        buffered = min(n, c)
        kept = set(range(n - buffered, n)) | set(sent)
        return StreamAccount(captured=n, buffered=buffered, transmitted=len(sent),
                             dropped=n - len(kept), decimation=d, transmitted_indices=sent_arr,
                             overrun_indices=np.asarray(lost, dtype=np.int64),
                             send_end_times_s=np.asarray(ends))


def link_plan(sensor_rate_hz: float, height: int, width: int, interface: str = "cameralink",
              bits_per_pixel: int = 8, decimation: int | None = None, max_decimation: int = 64,
              buffer: DDRBuffer | None = None, sustain_s: float = 3600.0) -> dict:
    """Link rate, decimation, ring size and the overrun time for one configuration.

    Parameters
    ----------
    sensor_rate_hz : float
        Sensor frame rate, Hz.
    height, width : int
        Frame size, pixels.
    interface : str
        A link of :data:`INTERFACES` (``"cameralink"``, ``"usb3"``, ``"gige"`` ...).
    bits_per_pixel : int
        Bits per pixel sent.
    decimation : int, optional
        1 frame in N sent (default: the smallest that fits, :func:`choose_decimation`).
    max_decimation : int
        Largest N tried.
    buffer : DDRBuffer, optional
        The frame ring (default: the seed's 2 GB DDR4).
    sustain_s : float
        Recording length the ring must absorb, s.

    Returns
    -------
    dict
        ``link_max_frame_rate_hz``, ``decimation`` (strict and with the buffer),
        ``transmitted_frame_rate_hz``, ``buffer_capacity_frames``, ``buffer_record_s``, the overrun
        time and the link's description.
    """
    link = get_interface(interface)
    buffer = buffer or DDRBuffer()
    link_rate = link.max_frame_rate_hz(height, width, bits_per_pixel)
    capacity = buffer.capacity_frames(height, width, bits_per_pixel)
    if capacity < 1:
        raise ViformError(f"a {width}x{height} frame does not fit in the "
                          f"{buffer.capacity_bytes} B buffer")
    strict = choose_decimation(sensor_rate_hz, link_rate, max_decimation=max_decimation,
                               interface=interface)
    buffered = choose_decimation(sensor_rate_hz, link_rate, max_decimation=max_decimation,
                                 buffer_frames=capacity, sustain_s=sustain_s, interface=interface)
    if decimation is None:
        decimation = buffered
    decimation = check_int("decimation", decimation, 1, max_decimation)
    sustain = overrun_time_s(sensor_rate_hz, link_rate, decimation, capacity)
    load = buffer.check_bandwidth(sensor_rate_hz, min(link_rate, sensor_rate_hz / decimation),
                                  height, width, bits_per_pixel)
    return {"interface": interface, "link": link.describe(), "link_max_frame_rate_hz": link_rate,
            "sensor_frame_rate_hz": sensor_rate_hz, "decimation": decimation,
            "decimation_strict": strict, "decimation_with_buffer": buffered,
            "sustain_target_s": check_range("sustain_s", sustain_s, 0, math.inf, low_open=True),
            "transmitted_frame_rate_hz": min(link_rate, sensor_rate_hz / decimation),
            "buffer_capacity_frames": capacity,
            "buffer_record_s": buffer.record_duration_s(sensor_rate_hz, height, width,
                                                        bits_per_pixel),
            "time_to_first_overrun_s": sustain, "ddr_bandwidth_load": load}
