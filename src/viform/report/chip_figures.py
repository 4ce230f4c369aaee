"""The spike chip's experiment figures (seed 000 §6, Figs. 1 and 3–5) from the model.

* Fig. 1: one pixel's photocurrent (mid level, then twice as strong, then half as strong),
  its spike train (integrate-and-fire to the threshold Q), each pulse drawn with width τ and
  height Q/τ (equal areas), and the *first spikes* — the pulses whose width differs from
  the current one, the rest being "repeats" (seed 000 §5.2, Fig. 1(d)).
* Fig. 3: accumulation images of the first 1, 2, 5, 50, 200 and 800 ticks of a person
  waving a hand, SpikeTwo at 20 kHz (50 µs ticks).
* Fig. 4: (a) the 800-tick accumulation, (b) the interval image at tick 800 with the seed's
  mapping: τ normalised to [0, 255] (min–max), displayed as 255 − τ.
* Fig. 5: interval images at four instants with ten marked pixels and their width
  sequences (pulse width × pulse height = Q).
"""

from __future__ import annotations

import numpy as np

from viform._io import save_figure
from viform._validate import ViformError, check_choice, check_int

#: Accumulation lengths of seed 000 Fig. 3, ticks.
FIG3_TICKS = (1, 2, 5, 50, 200, 800)


# ----------------------------------------------------------------------------- Fig. 1

def spike_train_of(current_levels, durations_ticks, threshold: float = 1.0, start_charge: float = 0.0):
    """Exact integrate-and-fire of a piecewise-constant signal (seed 000 §3, Fig. 1(a)–(b)).

    ``current_levels[i]`` (charge per tick, in units of the threshold Q when ``threshold``
    is 1) holds for ``durations_ticks[i]`` ticks. A spike fires when the accumulated charge
    reaches Q; the remainder is kept. Returns the spike times (ticks, float).
    """
    levels = np.asarray(current_levels, dtype=np.float64)
    durs = np.asarray(durations_ticks, dtype=np.float64)
    if levels.shape != durs.shape or levels.ndim != 1:
        raise ViformError("current_levels and durations_ticks must be 1-D and of equal length")
    if np.any(levels < 0) or np.any(durs <= 0):
        raise ViformError("current levels must be ≥ 0 and durations > 0")
    t0, q, out = 0.0, float(start_charge), []
    for lev, d in zip(levels, durs, strict=True):
        t, end = t0, t0 + d
        while lev > 0 and t + (threshold - q) / lev <= end + 1e-12:
            t += (threshold - q) / lev
            out.append(t)
            q = 0.0
        q += lev * (end - t)
        t0 = end
    return np.array(out)


def first_spikes(spike_times, rel_tol: float = 0.1) -> np.ndarray:
    """Indices of the first spikes (seed 000 §5.2): pulse 1, then every pulse whose width
    differs from the current width by more than ``rel_tol``; it becomes the current width."""
    t = np.asarray(spike_times, dtype=np.float64)
    if t.size == 0:
        return np.array([], dtype=int)
    widths = np.diff(np.concatenate([[0.0], t]))
    keep, cur = [0], widths[0]
    for i in range(1, t.size):
        if abs(widths[i] - cur) > rel_tol * cur:
            keep.append(i)
            cur = widths[i]
    return np.array(keep)


def plot_fig1(path, levels=(1 / 6, 1 / 3, 1 / 12), durations=(26.0, 21.0, 33.0)) -> dict:
    """Write :func:`fig1_figure` to ``path``; return its numbers."""
    fig, numbers = fig1_figure(levels, durations)
    save_figure(path, fig)
    return numbers


def fig1_figure(levels=(1 / 6, 1 / 3, 1 / 12), durations=(26.0, 21.0, 33.0)):
    """Fig. 1: photocurrent, spike train, pulses as width τ × height Q/τ, first spikes.

    The default signal reproduces the seed's example: 4 equal pulses, one shorter pulse at
    the step up, 6 pulses of half the width, a longer pulse at the step down, then pulses
    twice as wide as the first (14 pulses; first spikes 1, 5, 6, 12, 13).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = spike_train_of(levels, durations)
    widths = np.diff(np.concatenate([[0.0], t]))
    fs = first_spikes(t)
    edges = np.concatenate([[0.0], np.cumsum(durations)])
    fig, (a, b, c) = plt.subplots(3, 1, figsize=(9, 6.6), sharex=True)
    a.stairs(levels, edges, color="C0", lw=2)
    a.set_ylabel("photocurrent\n(Q per tick)")
    a.set_ylim(0, max(levels) * 1.3)
    a.set_title("(a) photocurrent   (b) spike train   (c) pulses: width τ × height Q/τ = Q;"
                " first spikes in red", fontsize=10)
    b.vlines(t, 0, 1, color="k")
    b.plot(t, np.ones_like(t), "k^", ms=5)
    for i, ti in enumerate(t):
        b.text(ti, 1.1, str(i + 1), ha="center", fontsize=7, color="C3" if i in set(fs) else "k")
    b.set_ylim(0, 1.4)
    b.set_yticks([])
    b.set_ylabel("spikes")
    for i, (ti, w) in enumerate(zip(t, widths, strict=True)):
        c.add_patch(plt.Rectangle((ti - w, 0), w, 1.0 / w, fill=True, alpha=0.5,
                                  color="C3" if i in set(fs) else "C0", ec="k", lw=0.5))
    c.stairs(levels, edges, color="C0", lw=1, ls="--", label="photocurrent")
    c.set_ylim(0, max(1.0 / widths.min(), max(levels)) * 1.2)
    c.set_ylabel("pulse height Q/τ\n(Q per tick)")
    c.set_xlabel("time (ticks)")
    c.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    return fig, {"spike_ticks": t.tolist(), "widths_ticks": widths.tolist(), "first_spikes": (fs + 1).tolist()}


# ----------------------------------------------------------------------------- Figs. 3–5

def hand_stream(size: int = 192, n_ticks: int = 800, preset: str = "spiketwo", seed: int = 0):
    """Spike stream of :class:`~viform.light.articulated.WavingHandScene` on a ``size`` ×
    ``size`` crop of the preset (SpikeTwo: 20 kHz, seed 000 §6)."""
    from viform.light.articulated import WavingHandScene
    from viform.sensors.spike_presets import load_spike_preset

    size = check_int("size", size, 16, 1000)
    n_ticks = check_int("ticks", n_ticks, 1)
    p = load_spike_preset(preset)
    sensor = p.sensor(height=size, width=size)
    # Light levels follow the sensor: the skin fires every 3 ticks, the wall every ≈ 7, the
    # clothes every ≈ 23 (the spread of the seed's 255 − τ image), whatever Q and clock are.
    par = sensor.parameters
    skin = par.threshold_electrons * par.clock_hz / 3.0 / par.optics.electrons_per_s(1.0)
    scene = WavingHandScene(size, size, wall_lux=skin * 100 / 230, shirt_lux=skin * 30 / 230, skin_lux=skin)
    stream = sensor.capture(scene, n_ticks / sensor.parameters.clock_hz, seed=seed)
    return stream, scene, p


def accumulation_counts(stream, lengths=FIG3_TICKS) -> dict:
    """Spike counts of the first n ticks for each n (seed 000 Fig. 3)."""
    n_max = stream.n_ticks
    out = {}
    bits = stream.read_ticks(0, min(max(lengths), n_max))
    csum = np.cumsum(bits, axis=0, dtype=np.int32)
    for n in lengths:
        if n > n_max:
            raise ViformError(f"accumulation of {n} ticks needs a stream of ≥ {n} ticks; it has {n_max}")
        out[int(n)] = csum[n - 1]
    return out


def plot_fig3(path, counts: dict, clock_hz: float, sensor_name: str = "SpikeTwo") -> None:
    """Write :func:`fig3_figure` to ``path``."""
    save_figure(path, fig3_figure(counts, clock_hz, sensor_name))


def fig3_figure(counts: dict, clock_hz: float, sensor_name: str = "SpikeTwo"):
    """Fig. 3: accumulation images; brightness = spikes per tick (count / n) on ONE scale, so a
    1-tick image is binary (white dots = spikes) and long windows blur the hand."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_last = max(counts)
    vmax = float(np.percentile(counts[n_last] / n_last, 99.5)) or 1.0
    ncol = (len(counts) + 1) // 2
    fig, axes = plt.subplots(2, ncol, figsize=(3.5 * ncol, 7.4), layout="constrained", squeeze=False)
    for ax in axes.ravel()[len(counts):]:
        ax.axis("off")
    for ax, (n, c) in zip(axes.ravel()[:len(counts)], counts.items(), strict=True):
        im = ax.imshow(c / n, cmap="gray", vmin=0, vmax=vmax, interpolation="nearest")
        ax.set_title(f"{n} tick{'s' if n > 1 else ''} ({n / clock_hz * 1e3:.3g} ms)", fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.7,
                 label=f"spikes per tick (count / n; one scale; white ≥ {vmax:.2f})")
    fig.suptitle(f"Accumulation images of the first n ticks: a hand waving, {sensor_name} at {clock_hz / 1e3:g} kHz",
                 fontsize=11)
    return fig


def interval_display(tau_ticks, stretch: str = "minmax") -> np.ndarray:
    """The seed's interval image: τ normalised to [0, 255], shown as 255 − τ (seed 000 §6).

    ``stretch="minmax"`` normalises between the image's min and max τ (the seed);
    ``"percentile"`` between its 1st and 99th percentiles (a few very long intervals then
    do not wash the picture out).
    """
    from viform.imaging.interval import tau_display_8bit

    check_choice("stretch", stretch, ("minmax", "percentile"))
    return tau_display_8bit(tau_ticks, (0.0, 100.0) if stretch == "minmax" else (1.0, 99.0))


def plot_fig4(path, counts800, tau800, stretch: str, n_ticks: int, clock_hz: float) -> None:
    """Write :func:`fig4_figure` to ``path``."""
    save_figure(path, fig4_figure(counts800, tau800, stretch, n_ticks, clock_hz))


def fig4_figure(counts800, tau800, stretch: str, n_ticks: int, clock_hz: float):
    """Fig. 4: (a) accumulation of all ticks (blurred hand), (b) interval image at the last tick."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    disp = interval_display(tau800, stretch)
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 5), layout="constrained")
    ia = a.imshow(counts800, cmap="gray", interpolation="nearest")
    a.set_title(f"(a) accumulation of ticks 1–{n_ticks} ({n_ticks / clock_hz * 1e3:.3g} ms)", fontsize=10)
    fig.colorbar(ia, ax=a, shrink=0.8, label="spike count")
    ib = b.imshow(disp, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    lo, hi = np.percentile(tau800, (0, 100) if stretch == "minmax" else (1, 99))
    b.set_title(f"(b) interval image at tick {n_ticks}: 255 − τ\n"
                f"(τ {lo:.0f}–{hi:.0f} ticks → 0–255, {'min–max' if stretch == 'minmax' else '1–99 %'})",
                fontsize=10)
    fig.colorbar(ib, ax=b, shrink=0.8, label="255 − normalised τ (gray level)")
    for ax in (a, b):
        ax.set_xticks([])
        ax.set_yticks([])
    return fig


def pick_pixels(scene, n: int = 10) -> list[tuple[int, int]]:
    """Ten typical pixels: along the swept arc of the hand, on the face, body and wall."""
    h, w = scene.height, scene.width
    pts = []
    for t in np.linspace(0.0, 0.04, 5):
        (_, _), (ey, ex), (wy, wx) = scene.joints(t)
        pts.append((int(wy), int(wx)))
    pts += [(int(0.44 * h), int(0.45 * w)), (int(0.85 * h), int(0.45 * w)), (int(0.15 * h), int(0.1 * w)),
            (int(0.9 * h), int(0.9 * w)), (int(0.6 * h), int(0.75 * w))]
    pts = [(min(max(r, 0), h - 1), min(max(c, 0), w - 1)) for r, c in pts]
    return pts[:n]


def plot_fig5(path, stream, instants, pixels, stretch: str = "minmax", n_ticks: int | None = None) -> dict:
    """Write :func:`fig5_figure` to ``path``; return each pixel's pulse widths (ticks)."""
    fig, seqs = fig5_figure(stream, instants, pixels, stretch, n_ticks)
    save_figure(path, fig)
    return seqs


def fig5_figure(stream, instants, pixels, stretch: str = "minmax", n_ticks: int | None = None):
    """Fig. 5: interval images at four instants with ten marked pixels, and each pixel's
    pulse-width sequence over the record (pulses drawn with width τ and height Q/τ)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from viform.imaging.interval import interval_ticks

    tau, _ = interval_ticks(stream, list(instants))
    n_ticks = stream.n_ticks if n_ticks is None else n_ticks
    bits = stream.read_ticks(0, n_ticks)
    fig = plt.figure(figsize=(13, 8.2), layout="constrained")
    gs = fig.add_gridspec(2, 4, height_ratios=[1, 1.05])
    image_axes = []
    for i, k in enumerate(instants):
        ax = fig.add_subplot(gs[0, i])
        ax.imshow(interval_display(tau[i], stretch), cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        for j, (r, c) in enumerate(pixels):
            ax.plot(c, r, "o", mfc="none", mec=f"C{j}", ms=MARKER_PT, mew=1.5)
        ax.set_title(f"tick {k + 1} ({(k + 1) / stream.clock_hz * 1e3:.1f} ms): 255 − τ", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        image_axes.append(ax)
    ax = fig.add_subplot(gs[1, :])
    seqs = {}
    trains = [np.nonzero(bits[:, r, c])[0].astype(float) + 1 for r, c in pixels]
    # one height scale for all rows: the shortest width of any of the ten pixels is full height
    hmax = 1.0 / max(1.0, min((np.diff(t).min() for t in trains if t.size > 1), default=1.0))
    for j, t in enumerate(trains):
        widths = np.diff(t)
        seqs[j + 1] = widths.astype(int).tolist()
        base = len(pixels) - 1 - j
        for t1, wdt in zip(t[1:], widths, strict=True):
            ax.add_patch(plt.Rectangle((t1 - wdt, base), wdt, 0.85 * (1.0 / wdt) / hmax, color=f"C{j}",
                                       alpha=0.6, ec="k", lw=0.3))
    for k in instants:
        ax.axvline(k + 1, color="0.3", ls=":")
    ax.set_xlim(-0.015 * n_ticks, n_ticks + 2)
    ax.set_ylim(-0.2, len(pixels))
    # the pixel numbers as tick labels: the layout keeps them inside the figure
    ax.set_yticks([len(pixels) - 1 - j + 0.3 for j in range(len(pixels))],
                  [str(j + 1) for j in range(len(pixels))], fontsize=9, fontweight="bold")
    for j, lab in enumerate(ax.get_yticklabels()):
        lab.set_color(f"C{j}")
    ax.tick_params(axis="y", length=0)
    ax.set_ylabel("pixel")
    ax.set_xlabel(f"tick ({1e6 / stream.clock_hz:g} µs at {stream.clock_hz / 1e3:g} kHz); "
                  "dotted: the four instants above")
    ax.set_title("pulse-width sequences of the ten pixels: each pulse is width τ × height ∝ 1/τ "
                 "(area = Q, one height scale); bright pixels fire short, tall pulses", fontsize=10)
    fig.get_layout_engine().execute(fig)  # fixes the axes, so the numbers can be placed in screen units
    for ax in image_axes:
        _number_markers(ax, pixels)
    return fig, seqs


#: Size of the circles marking fig. 5's pixels, points.
MARKER_PT = 7.0


def _number_markers(ax, pixels, fontsize: int = 8) -> None:
    """Number each circled pixel beside its circle, on no circle and no other number.

    Pixels along the hand's arc are a few pixels apart: numbers at a fixed offset fell on the
    neighbouring circles. Each number takes the first free spot of eight directions at growing
    distances (with a thin leader line once it is away from its circle), inside the image.
    """
    from matplotlib.text import Text
    from matplotlib.transforms import Bbox

    renderer = ax.figure.canvas.get_renderer()
    px_per_pt = ax.figure.dpi / 72
    half = (MARKER_PT / 2 + 1.0) * px_per_pt  # circle radius plus its edge, pixels
    centres = [ax.transData.transform((c, r)) for r, c in pixels]
    taken = [Bbox.from_extents(x - half, y - half, x + half, y + half) for x, y in centres]
    frame = ax.get_window_extent(renderer)
    directions = ((1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1))
    for j, (r, c) in enumerate(pixels):
        note = None
        for dist in (6.0, 11.0, 17.0, 24.0):
            for dx, dy in directions:
                ha = "left" if dx > 0 else "right" if dx < 0 else "center"
                va = "bottom" if dy > 0 else "top" if dy < 0 else "center"
                arrow = dict(arrowstyle="-", lw=0.6, color=f"C{j}", shrinkA=0, shrinkB=half / px_per_pt)
                note = ax.annotate(str(j + 1), (c, r), xytext=(dx * dist, dy * dist), textcoords="offset points",
                                   ha=ha, va=va, color=f"C{j}", fontsize=fontsize, weight="bold",
                                   arrowprops=arrow if dist > 6.0 else None)
                note.update_positions(renderer)
                b = Text.get_window_extent(note, renderer)  # the number, not its leader line
                inside = frame.x0 <= b.x0 and b.x1 <= frame.x1 and frame.y0 <= b.y0 and b.y1 <= frame.y1
                if inside and not any(b.overlaps(o) for o in taken):
                    break
                note.remove()
                note = None
            if note is not None:
                break
        if note is None:  # no free spot (a crowded tiny image): beside the circle, as before
            note = ax.annotate(str(j + 1), (c, r), xytext=(6, 0), textcoords="offset points", va="center",
                               color=f"C{j}", fontsize=fontsize, weight="bold")
        note.update_positions(renderer)
        taken.append(Text.get_window_extent(note, renderer))


def chip_figures(out_dir, size: int = 192, ticks: int = 800, stretch: str = "minmax", seed: int = 0,
                 preset: str = "spiketwo") -> dict:
    """Write fig1_spike_train.png, fig3_accumulation.png, fig4_interval_vs_accumulation.png,
    fig5_width_sequences.png into ``out_dir``; return the numbers behind them."""
    from pathlib import Path

    check_choice("stretch", stretch, ("minmax", "percentile"))
    ticks = check_int("ticks", ticks, 50)
    lengths = tuple(n for n in FIG3_TICKS if n < ticks) + (ticks,)
    # record past the last shown tick so the interval containing it is closed by its next
    # spike (the seed takes the first 800 ticks of a longer recording)
    stream, scene, p = hand_stream(size, ticks + max(128, ticks // 4), preset, seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig1 = plot_fig1(out / "fig1_spike_train.png")
    counts = accumulation_counts(stream, lengths)
    clock = stream.clock_hz
    plot_fig3(out / "fig3_accumulation.png", counts, clock, p.name)
    from viform.imaging.interval import interval_ticks

    tau_last, cens = interval_ticks(stream, [ticks - 1])
    plot_fig4(out / "fig4_interval_vs_accumulation.png", counts[ticks], tau_last[0], stretch, ticks, clock)
    instants = [int(round(f * (ticks - 1))) for f in (0.125, 0.375, 0.625, 0.875)]
    pixels = pick_pixels(scene)
    seqs = plot_fig5(out / "fig5_width_sequences.png", stream, instants, pixels, stretch, ticks)
    # blur: how far the hand moves during each accumulation window
    blur = {n: scene.hand_speed_px_per_s(0.5 * n / clock) * n / clock for n in lengths}
    return {"preset": p.name, "clock_hz": clock, "threshold_electrons": p.parameters.threshold_electrons,
            "size_px": size, "ticks": ticks, "duration_s": ticks / clock,
            "accumulation": {n: {"window_s": n / clock, "mean_spikes_per_pixel": float(c.mean()),
                                 "pixels_with_spikes": float((c > 0).mean()),
                                 "hand_travel_px": float(blur[n])} for n, c in counts.items()},
            "interval_at_last_tick": {"tau_min_ticks": int(tau_last.min()), "tau_max_ticks": int(tau_last.max()),
                                      "censored_fraction": float(cens.mean()), "stretch": stretch},
            "fig1": fig1, "fig5_instants_ticks": [k + 1 for k in instants],
            "fig5_pixels": [list(px) for px in pixels], "fig5_width_sequences": seqs,
            "files": ["fig1_spike_train.png", "fig3_accumulation.png", "fig4_interval_vs_accumulation.png",
                      "fig5_width_sequences.png"]}
