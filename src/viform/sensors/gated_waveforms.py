"""Drive waveforms of an interline CCD used as a range-gated receiver (seed 004, Figs. 2–3).

Seed 004, "Control in an undocumented way": a frame is taken in four stages.

1. *Preparation*: V1…V4 follow the datasheet's pattern up to the readout pulse (the
   charge packets of the vertical register sit under V2/V3 at the middle level, 0 V;
   V1, V4 at the low level, −5.5 V).
2. *Accumulation*, repeated X times: the laser fires; SUB (+20 V, photodiodes emptied)
   falls t_откл = 2R/c after the pulse; the photodiodes integrate for t_нак = τ + t_min
   (pulse width plus the datasheet's minimum SUB → V2/V3 time); V2 and V3 go to +15 V and
   move the charge into the vertical register, where it *adds* to what the previous pulses
   left; SUB rises again. The pulses follow each other every t_изл = 1/f_rep.
3. *Completion*: V1…V4 follow the datasheet's pattern after the readout pulse.
4. *Vertical transfer*: the register is shifted out line by line (four-phase V1…V4
   between −5.5 V and 0 V), one readout per frame.

Levels (seed 004, text under Fig. 2): V1…V4 −5.5 V … 0 V during vertical transfer, +15 V on
V2 and V3 during the readout, SUB 0 V … +20 V.

Differences between the parts the seed tried (seed 004, "Control in an undocumented way"
and the experimental section):

* ICX618ALA, ICX445ALA: progressive scan; readout pulse on V2 and V3.
* ICX445ALA: also needs VHLD and VST (the seed names them but gives no waveform: here they
  are clocked with the line shifts and held low otherwise — an assumption, stated in
  ``docs/range-gated.md``); run in a 1280 × 600 centre window for ≥ 25 Hz.
* ICX659ALA: interlaced; readout pulse (+15 V) on V1 and V3.
* ICX279AL-E: interlaced; the seed names no other difference; the readout pulse is assumed
  on V1 and V3 as for the ICX659.

Times that the seed does not give (readout-pulse width, vertical step, line time) are the
:class:`CCDDrive` fields, set to typical Sony ICX values and named as assumptions.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from viform._validate import ViformError, check_choice, check_int, check_positive
from viform.light.laser import PulsedLaser, round_trip_time_s
from viform.sensors.gate_timing import GateTiming

#: Levels the seed gives (seed 004, text under Fig. 2), volts.
V_LOW_V = -5.5
V_MID_V = 0.0
V_READ_V = 15.0
SUB_LOW_V = 0.0
SUB_HIGH_V = 20.0


@dataclass(frozen=True)
class CCDDrive:
    """Drive description of one interline CCD (seed 004).

    Attributes
    ----------
    name : str
    interlaced : bool
    readout_gates : tuple of str
        Vertical phases that take the +15 V readout pulse.
    extra_signals : tuple of str
        Other vertical-drive inputs the part needs (ICX445: VHLD, VST).
    rows, cols : int
        Lines shifted out per frame (per field when interlaced) and pixels per line.
    line_time_s : float
        Time per line of the vertical transfer (horizontal readout dominates), s.
    readout_pulse_s : float
        Width of the V2/V3 (+15 V) readout pulse, s (assumed; ICX parts 1–3 µs).
    min_transfer_time_s : float
        Minimum time from the SUB falling edge to the readout pulse, s (t_min; assumed 1 µs).
    vertical_step_s : float
        Duration of one of the 8 steps of a four-phase line shift, s (assumed 0.25 µs).
    note : str
        What differs from the ICX618, in words.
    """

    name: str
    interlaced: bool
    readout_gates: tuple[str, ...]
    extra_signals: tuple[str, ...] = ()
    rows: int = 494
    cols: int = 659
    line_time_s: float = 1.0 / 60.0 / 525
    readout_pulse_s: float = 1.0e-6
    min_transfer_time_s: float = 1.0e-6
    vertical_step_s: float = 0.25e-6
    note: str = ""

    def __post_init__(self):
        check_int("rows", self.rows, 1)
        check_int("cols", self.cols, 1)
        for name in ("line_time_s", "readout_pulse_s", "min_transfer_time_s", "vertical_step_s"):
            check_positive(name, getattr(self, name))
        if 8 * self.vertical_step_s > self.line_time_s:
            raise ViformError(f"vertical_step_s = {self.vertical_step_s:g} is not allowed: eight steps "
                              f"must fit in line_time_s = {self.line_time_s:g}")

    @property
    def channels(self) -> tuple[str, ...]:
        return ("LASER", "RETURN", "SUB", "V1", "V2", "V3", "V4", *self.extra_signals)


#: The parts of seed 004's experiments.
DRIVES: dict[str, CCDDrive] = {
    "icx618": CCDDrive("ICX618ALA", False, ("V2", "V3"), rows=494, cols=659,
                       note="progressive; the drive of the published timing diagram"),
    "icx445": CCDDrive("ICX445ALA", False, ("V2", "V3"), ("VHLD", "VST"), rows=600, cols=1280,
                       line_time_s=1.0 / 25.0 / 1.3 / 600,
                       note="progressive; needs VHLD and VST as well; 1280x600 centre window "
                            "for >= 25 Hz"),
    "icx279": CCDDrive("ICX279AL-E", True, ("V1", "V3"), rows=291, cols=752, line_time_s=64e-6,
                       note="interlaced (PAL field 291 lines); readout on V1 and V3 assumed "
                            "(not published)"),
    "icx659": CCDDrive("ICX659ALA", True, ("V1", "V3"), rows=247, cols=752, line_time_s=63.5e-6,
                       note="interlaced; +15 V readout on V1 and V3 (as published)"),
}


@dataclass
class DriveTrace:
    """Piecewise-constant drive signals: ``levels[name][i]`` holds from ``times_s[i]`` on.

    Attributes
    ----------
    times_s : ndarray (N,)
        Event times, s, increasing; the last one ends the frame.
    levels : dict of str → ndarray (N,)
        Level of every channel after each event, V (LASER and RETURN in W: emitted and
        received-at-target-range optical power, RETURN normalised to 1).
    stages : list of (name, start_s, end_s)
    drive : CCDDrive
    info : dict
        The timing the trace was built from (t_откл, t_нак, t_изл, X, …).
    """

    times_s: np.ndarray
    levels: dict
    stages: list
    drive: CCDDrive
    info: dict

    def level_at(self, name: str, t_s: float) -> float:
        """Level of ``name`` at time ``t_s`` (right-continuous step)."""
        i = int(np.searchsorted(self.times_s, t_s, side="right")) - 1
        return float(self.levels[name][max(i, 0)])

    def edges(self, name: str, level: float) -> np.ndarray:
        """Times at which ``name`` switches *to* ``level``."""
        v = self.levels[name]
        hit = (v == level) & np.concatenate([[True], v[1:] != v[:-1]])
        return self.times_s[hit]

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])


class _Builder:
    def __init__(self, channels, initial):
        self.channels = channels
        self.state = dict(initial)
        self.events: list[tuple[float, dict]] = [(0.0, dict(initial))]

    def set(self, t_s: float, **levels):
        last_t, last = self.events[-1]
        if t_s < last_t - 1e-15:
            raise AssertionError("events out of order")  # a bug, not user input
        self.state.update(levels)
        if abs(t_s - last_t) < 1e-15:
            last.update(levels)
        else:
            self.events.append((t_s, dict(self.state)))

    def trace(self, drive, stages, info) -> DriveTrace:
        times = np.array([t for t, _ in self.events])
        levels = {c: np.array([e[c] for _, e in self.events], dtype=float) for c in self.channels}
        return DriveTrace(times, levels, stages, drive, info)


# Four-phase line shift: which of V1..V4 sit at the middle level (the potential well) in
# each of the 8 steps; the packet moves one line in 8 steps.
_FOUR_PHASE = ((1, 2), (1, 2, 3), (2, 3), (2, 3, 4), (3, 4), (3, 4, 1), (4, 1), (4, 1, 2))


def drive_waveforms(part: str = "icx618", gate_range_m: float = 150.0, pulses: int = 4,
                    laser: PulsedLaser | None = None, lines: int | None = None,
                    target_range_m: float | None = None, timing=None) -> DriveTrace:
    """The four-stage drive of one gated frame (seed 004, Fig. 3).

    Every gate instant comes from one :class:`~viform.sensors.gate_timing.GateTiming` — the
    same object the sensor model integrates light with: SUB falls at ``open_s``, V2/V3 (V1/V3
    on the interlaced parts) rise at ``transfer_start_s`` and fall at ``close_s``, where SUB
    rises again. SUB stays low through the readout pulse (raising it would drain the packet
    being transferred), so the light is collected from ``open_s`` to ``close_s``.

    Parameters
    ----------
    part : {"icx618", "icx445", "icx279", "icx659"}
    gate_range_m : float
        R, the near edge of the gate; SUB falls 2R/c after each laser pulse.
    pulses : int
        X, laser pulses accumulated in the vertical register before the one readout.
    laser : PulsedLaser
        Pulse width τ and period t_изл = 1/f_rep (default 135 ns, 12.5 kHz).
    lines : int or None
        Lines of the vertical transfer to include (default all ``drive.rows``; a diagram
        uses a few).
    target_range_m : float or None
        Range of the reflector whose return is drawn (default: ``gate_range_m``).
    timing : GateTiming or None
        The gate to draw (e.g. ``GatedInterlineCCD(...).timing``); default: built from
        ``gate_range_m``, ``laser`` and the part's t_min and readout-pulse width.

    Returns
    -------
    DriveTrace
    """
    key = check_choice("part", str(part).lower(), tuple(DRIVES))
    drive = DRIVES[key]
    x = check_int("pulses", pulses, 1)
    n_lines = drive.rows if lines is None else check_int("lines", lines, 1, drive.rows)
    if timing is None:
        laser = laser or PulsedLaser()
        if gate_range_m is None or not np.isfinite(gate_range_m) or gate_range_m < 0:
            raise ViformError(f"gate_range_m = {gate_range_m!r} is not allowed: the gate range must be ≥ 0 m")
        timing = GateTiming(float(gate_range_m), laser, drive.min_transfer_time_s, drive.readout_pulse_s)
    laser = timing.laser
    gate_range_m = timing.gate_range_m
    t_open = timing.open_s
    tau = laser.pulse_width_s
    t_acc = timing.accumulation_s                                 # t_нак (drawn SUB → V2/V3)
    t_read_on, t_read_off = timing.transfer_start_s, timing.close_s
    period = laser.period_s                                       # t_изл
    r_target = gate_range_m if target_range_m is None else float(target_range_m)
    t_ret = round_trip_time_s(r_target)
    reads = set(drive.readout_gates)
    extras = {s: V_LOW_V for s in drive.extra_signals}
    idle = {"LASER": 0.0, "RETURN": 0.0, "SUB": SUB_HIGH_V, "V1": V_LOW_V, "V2": V_LOW_V,
            "V3": V_LOW_V, "V4": V_LOW_V, **extras}
    b = _Builder(drive.channels, idle)
    stages = []
    step = drive.vertical_step_s
    well = {f"V{k}": V_MID_V for k in (1, 2, 3, 4) if f"V{k}" in reads or k in (2, 3)}
    if drive.interlaced:
        well = {g: V_MID_V for g in reads}

    # 1. preparation: the datasheet pattern up to the readout pulse (wells under the readout gates)
    t = 0.0
    b.set(t + step, **well)
    t_prep = 4 * step
    stages.append(("1 preparation", 0.0, t_prep))

    # 2. X gated accumulations
    t0 = t_prep + step                      # first laser pulse, after the preparation
    for k in range(x):
        tp = t0 + k * period
        b.set(tp, LASER=laser.peak_power_w)
        b.set(tp + tau, LASER=0.0)
        events = sorted([(tp + t_ret, "ret_on"), (tp + t_ret + tau, "ret_off"), (tp + t_open, "sub_off"),
                         (tp + t_read_on, "read_on"), (tp + t_read_off, "read_off")])
        for te, what in events:
            if what == "ret_on":
                b.set(te, RETURN=1.0)
            elif what == "ret_off":
                b.set(te, RETURN=0.0)
            elif what == "sub_off":
                b.set(te, SUB=SUB_LOW_V)
            elif what == "read_on":
                b.set(te, **{g: V_READ_V for g in reads})
            else:  # charge moved into the register; SUB empties the photodiodes again
                b.set(te, **{g: V_MID_V for g in reads}, SUB=SUB_HIGH_V)
    t_acc_end = t0 + (x - 1) * period + t_read_off + step
    stages.append(("2 accumulation x" + str(x), t_prep, t_acc_end))

    # 3. completion: back to the line-transfer start pattern (wells under V1, V2)
    b.set(t_acc_end, **{f"V{k}": (V_MID_V if k in (1, 2) else V_LOW_V) for k in (1, 2, 3, 4)})
    t_comp = t_acc_end + 2 * step
    stages.append(("3 completion", t_acc_end, t_comp))

    # 4. vertical transfer: one four-phase line shift per line, then horizontal readout
    t = t_comp
    for _ in range(n_lines):
        for j, mids in enumerate(_FOUR_PHASE[1:] + _FOUR_PHASE[:1]):
            lv = {f"V{k}": (V_MID_V if k in mids else V_LOW_V) for k in (1, 2, 3, 4)}
            if "VST" in extras:
                lv["VST"] = V_MID_V if 1 in mids else V_LOW_V
            if "VHLD" in extras:
                lv["VHLD"] = V_MID_V if 3 in mids else V_LOW_V
            b.set(t + (j + 1) * step, **lv)
        t += drive.line_time_s
    b.set(t, **{s: V_LOW_V for s in extras})
    stages.append(("4 vertical transfer", t_comp, t))
    b.set(t + step)
    info = {"part": drive.name, "interlaced": drive.interlaced, "readout_gates": list(drive.readout_gates),
            "extra_signals": list(drive.extra_signals), "pulses": x, "gate_range_m": float(gate_range_m),
            "delay_s": t_open, "accumulation_window_s": t_acc, "pulse_period_s": period,
            "pulse_width_s": tau, "readout_pulse_s": timing.readout_pulse_s,
            "collection_window_s": timing.width_s, "exposure_s": x * t_acc,
            "collected_exposure_s": x * timing.width_s, "lines": n_lines, "frame_s": t + step,
            "levels_v": {"vertical_low": V_LOW_V, "vertical_mid": V_MID_V, "readout": V_READ_V,
                         "sub_low": SUB_LOW_V, "sub_high": SUB_HIGH_V},
            "drive": asdict(drive)}
    return b.trace(drive, stages, info)


# ----------------------------------------------------------------------------- files

def trace_csv(trace: DriveTrace) -> str:
    """Wide CSV: one row per event, ``time_s`` then every channel's level after it."""
    names = list(trace.levels)
    lines = ["time_s," + ",".join(f"{n}_{'w' if n == 'LASER' else ('rel' if n == 'RETURN' else 'v')}"
                                  for n in names)]
    for i, t in enumerate(trace.times_s):
        lines.append(f"{t:.12g}," + ",".join(f"{trace.levels[n][i]:g}" for n in names))
    return "\n".join(lines) + "\n"


def trace_vcd(trace: DriveTrace, timescale_ps: int = 1) -> str:
    """Value Change Dump (IEEE 1364 §18) with ``real`` variables, times in ``timescale_ps`` ps."""
    ids = {n: chr(33 + i) for i, n in enumerate(trace.levels)}
    head = ["$version viform gated drive waveforms $end", f"$timescale {timescale_ps} ps $end",
            f"$scope module {trace.drive.name} $end"]
    head += [f"$var real 64 {ids[n]} {n} $end" for n in trace.levels]
    head += ["$upscope $end", "$enddefinitions $end"]
    out = list(head)
    prev = {}
    for i, t in enumerate(trace.times_s):
        changes = [(n, trace.levels[n][i]) for n in trace.levels if prev.get(n) != trace.levels[n][i]]
        if not changes and i:
            continue
        out.append(f"#{int(round(t * 1e12 / timescale_ps))}")
        if i == 0:
            out.append("$dumpvars")
        out += [f"r{v:g} {ids[n]}" for n, v in changes]
        if i == 0:
            out.append("$end")
        prev.update(changes)
    return "\n".join(out) + "\n"


def plot_waveforms(path, trace: DriveTrace, cycle: DriveTrace | None = None) -> None:
    """Timing diagram: (top) the whole frame, not to scale, like seed 004 Fig. 3; (bottom)
    one accumulation cycle to scale in µs with t_откл, t_нак and the readout pulse marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform._io import save_figure

    names = list(trace.levels)
    t = trace.times_s
    # Not to scale: each gap is drawn log-compressed so short pulses and long waits both show.
    gaps = np.diff(t)
    xs = np.concatenate([[0.0], np.cumsum(np.log1p(gaps / 50e-9))])
    fig, (a, bax) = plt.subplots(2, 1, figsize=(11, 8.6), gridspec_kw={"height_ratios": [1.25, 1]})
    spacing = 1.4
    for i, n in enumerate(names):
        v = trace.levels[n]
        lo, hi = _channel_range(n)
        y0 = -i * spacing
        a.step(xs, y0 + (v - lo) / (hi - lo), where="post", color=_colour(n), lw=1.3)
        a.text(-0.01 * xs[-1], y0 + 0.3, n, ha="right", va="center", fontsize=9, color=_colour(n))
    for name, s0, s1 in trace.stages:
        x0, x1 = np.interp([s0, s1], t, xs)
        a.axvspan(x0, x1, color="0.93" if name[0] in "13" else "white", zorder=-1)
        a.text((x0 + x1) / 2, 1.25, name, ha="center", fontsize=8)
    a.set_xlim(-0.12 * xs[-1], xs[-1] * 1.01)
    a.set_ylim(-(len(names) - 1) * spacing - 0.9, 1.5)
    a.set_yticks([])
    a.set_xticks([])
    info = trace.info
    # The top panel may draw a shortened frame (``trace``) of the run (``cycle``): the title
    # gives the run's pulse count and frame time, and how much of it is drawn.
    run = cycle.info if cycle is not None else info
    a.set_title(f"{info['part']}: four-stage gated drive, X = {run['pulses']} pulses, gate {info['gate_range_m']:g} m, "
                f"frame {run['frame_s'] * 1e3:.4g} ms\n(not to scale; first {info['pulses']} of {run['pulses']} "
                f"pulses and {info['lines']} of {run['lines']} line shifts shown)", fontsize=10)
    a.text(0.0, -(len(names) - 1) * spacing - 0.75,
           "levels: SUB 0 / +20 V; V-phases −5.5 / 0 V, readout +15 V; LASER 0 / "
           f"{trace.levels['LASER'].max():g} W; RETURN = echo from the gate range", fontsize=8)

    c = cycle or trace
    tp = float(c.edges("LASER", c.levels["LASER"].max())[0])
    ci = c.info
    t_end = tp + ci["delay_s"] + ci["accumulation_window_s"] + ci["readout_pulse_s"] + 0.4e-6
    sel = (c.times_s >= tp - 0.3e-6) & (c.times_s <= t_end)
    tt = np.concatenate([[tp - 0.3e-6], c.times_s[sel], [t_end]])
    show = [n for n in names if n in ("LASER", "RETURN", "SUB", *ci["readout_gates"])]
    for i, n in enumerate(show):
        v = np.array([c.level_at(n, x) for x in tt])
        lo, hi = _channel_range(n)
        y0 = -i * spacing
        bax.step((tt - tp) * 1e6, y0 + (v - lo) / (hi - lo), where="post", color=_colour(n), lw=1.5,
                 label=n)
        bax.text(-0.33, y0 + 0.3, n, ha="right", va="center", fontsize=9, color=_colour(n))
    d, w = ci["delay_s"] * 1e6, ci["accumulation_window_s"] * 1e6
    rp = ci["readout_pulse_s"] * 1e6
    for xv in (0.0, d, d + w, d + w + rp):
        bax.axvline(xv, color="0.6", ls=":", lw=0.8)
    ylow = -(len(show) - 1) * spacing - 0.15
    bax.annotate("", xy=(d + w + rp, ylow), xytext=(d, ylow), arrowprops=dict(arrowstyle="<->", lw=0.8, color="C0"))
    bax.text(d + (w + rp) / 2, ylow + 0.08, f"light collected = t_acc + readout pulse = {(w + rp) * 1e3:.0f} ns",
             ha="center", fontsize=8, color="C0")
    ytop = 1.35
    bax.annotate("", xy=(d, ytop), xytext=(0, ytop), arrowprops=dict(arrowstyle="<->", lw=0.8))
    bax.text(d / 2, ytop + 0.08, f"t_delay = 2R/c = {d * 1e3:.0f} ns", ha="center", fontsize=8)
    bax.annotate("", xy=(d + w, ytop), xytext=(d, ytop), arrowprops=dict(arrowstyle="<->", lw=0.8))
    bax.text(d + w / 2, ytop + 0.08, f"t_acc = τ + t_min = {w * 1e3:.0f} ns", ha="center", fontsize=8)
    bax.set_xlim(-0.35, (t_end - tp) * 1e6)
    bax.set_ylim(-(len(show) - 1) * spacing - 0.4, ytop + 0.4)
    bax.set_yticks([])
    bax.set_xlabel("time after the laser pulse (µs), to scale")
    bax.set_title(f"one accumulation cycle (repeats every t_period = {ci['pulse_period_s'] * 1e6:.0f} µs; "
                  f"readout pulse {ci['readout_pulse_s'] * 1e6:g} µs on {' and '.join(ci['readout_gates'])});\n"
                  f"light is collected from SUB's fall to the readout pulse's end: "
                  f"{ci['collection_window_s'] * 1e9:.0f} ns per pulse", fontsize=10)
    fig.tight_layout()
    save_figure(path, fig)


def _channel_range(name: str) -> tuple[float, float]:
    if name == "LASER":
        return 0.0, 200.0
    if name == "RETURN":
        return 0.0, 1.0
    if name == "SUB":
        return SUB_LOW_V, SUB_HIGH_V
    return V_LOW_V, V_READ_V


def _colour(name: str) -> str:
    return {"LASER": "C3", "RETURN": "C1", "SUB": "C0"}.get(name, "C2" if name.startswith("V") and
                                                            len(name) == 2 else "C4")
