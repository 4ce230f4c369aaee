"""Shared check for the report figures: every piece of text inside the figure, none on another."""

import pytest


def _drawn_texts(fig):
    """(text, window box) of every visible, non-empty text the figure draws: titles, axis labels,
    tick labels within their axes' span, annotations, legend entries, colour-bar labels."""
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    out = []
    every_axes = [*fig.axes, *(c for a in fig.axes for c in a.child_axes)]  # inset colour bars too
    for ax in every_axes:
        if not ax.get_visible():
            continue
        span = ax.get_window_extent(renderer)
        ticks = [(t, "x") for t in ax.xaxis.get_ticklabels()] + [(t, "y") for t in ax.yaxis.get_ticklabels()]
        ticks = ticks if ax.axison else []  # axis("off"): its ticks are not drawn
        for t, axis in ticks:
            if not (t.get_visible() and t.get_text().strip()):
                continue
            box = t.get_window_extent(renderer)
            centre = (box.x0 + box.x1) / 2 if axis == "x" else (box.y0 + box.y1) / 2
            lo, hi = (span.x0, span.x1) if axis == "x" else (span.y0, span.y1)
            if lo - 1 <= centre <= hi + 1:  # ticks outside the view are never drawn
                out.append((t.get_text(), box))
        labels = [ax.xaxis.label, ax.yaxis.label] if ax.axison else []
        for t in [ax.title, ax._left_title, ax._right_title, *labels, *ax.texts]:
            if t.get_visible() and t.get_text().strip():
                out.append((t.get_text(), Text.get_window_extent(t, renderer)))  # text, not its arrow
    legends = [a.get_legend() for a in fig.axes if a.get_legend()] + list(fig.legends)
    for leg in legends:
        out += [(t.get_text(), t.get_window_extent(renderer)) for t in leg.get_texts() if t.get_text().strip()]
    figure_texts = [*fig.texts, *([fig._suptitle] if fig._suptitle is not None else [])]
    out += [(t.get_text(), t.get_window_extent(renderer)) for t in dict.fromkeys(figure_texts)
            if isinstance(t, Text) and t.get_visible() and t.get_text().strip()]
    return out


def layout_problems(fig, tolerance_px: float = 1.0) -> list[str]:
    """Texts cut off at the figure's edge, and pairs of texts drawn over each other."""
    texts = _drawn_texts(fig)
    w, h = fig.bbox.width, fig.bbox.height
    problems = [f"{s!r} cut off at the edge ({b.x0:.0f}, {b.y0:.0f})–({b.x1:.0f}, {b.y1:.0f}) of {w:.0f}×{h:.0f}"
                for s, b in texts
                if b.x0 < -tolerance_px or b.y0 < -tolerance_px or b.x1 > w + tolerance_px or b.y1 > h + tolerance_px]
    problems += _texts_on_markers(fig, tolerance_px)
    for i, (s1, b1) in enumerate(texts):
        for s2, b2 in texts[i + 1:]:
            dx = min(b1.x1, b2.x1) - max(b1.x0, b2.x0)
            dy = min(b1.y1, b2.y1) - max(b1.y0, b2.y0)
            if dx > tolerance_px and dy > tolerance_px:
                problems.append(f"{s1!r} overlaps {s2!r} by {dx:.0f}×{dy:.0f} px")
    return problems


def _texts_on_markers(fig, tolerance_px: float) -> list[str]:
    """Texts written in an axes over one of its line's markers (a number on its neighbour's circle)."""
    import numpy as np
    from matplotlib.text import Text

    renderer = fig.canvas.get_renderer()
    out = []
    for ax in fig.axes:
        # the text's own box: an annotation's arrow is meant to reach its marker
        boxes = [(t.get_text(), Text.get_window_extent(t, renderer)) for t in ax.texts if t.get_text().strip()]
        for line in ax.lines:
            if line.get_marker() in (None, "None", "", " ") or not boxes:
                continue
            half = line.get_markersize() * fig.dpi / 72 / 2
            xy = ax.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
            for s, b in boxes:
                hit = ((xy[:, 0] + half > b.x0 + tolerance_px) & (xy[:, 0] - half < b.x1 - tolerance_px)
                       & (xy[:, 1] + half > b.y0 + tolerance_px) & (xy[:, 1] - half < b.y1 - tolerance_px))
                if hit.any():
                    out.append(f"{s!r} drawn on a marker of {line.get_label()!r}")
    return out


@pytest.fixture
def check_layout():
    """Assert a figure has no text cut off at its edges and no two texts on each other; close it."""

    def check(fig):
        import matplotlib.pyplot as plt

        try:
            problems = layout_problems(fig)
        finally:
            plt.close(fig)
        assert not problems, "\n".join(problems)

    return check
