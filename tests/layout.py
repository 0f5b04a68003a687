"""Layout checks measured on a drawn figure at its saved size: every piece of text inside the
canvas, no two pieces of text overlapping, none smaller than 8 pt (matplotlib's renderer,
``Text.get_window_extent``)."""

import itertools
import re

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg


def drawn_texts(fig):
    """(description, Text) of every non-empty text the figure draws."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    out = []

    def add(what, text):
        if text is not None and text.get_visible() and text.get_text().strip():
            out.append((what, text))

    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            lo, hi = sorted(axis.get_view_interval())
            span = (hi - lo) * 1e-6 if np.isfinite(hi - lo) else 0
            locs = axis.get_majorticklocs()
            for tick, loc in zip(axis.get_major_ticks(len(locs)), locs):
                if lo - span <= loc <= hi + span:
                    add(f"{name} tick {tick.label1.get_text()}", tick.label1)
                    add(f"{name} tick {tick.label2.get_text()}", tick.label2)
            add(f"{name} label", axis.label)
            add(f"{name} offset", axis.get_offset_text())
        for title in (ax.title, ax._left_title, ax._right_title):
            add("axes title", title)
        if ax.get_legend() is not None:
            for text in ax.get_legend().get_texts():
                add("legend", text)
    for legend in fig.legends:
        for text in legend.get_texts():
            add("legend", text)
    add("suptitle", fig._suptitle)
    for text in fig.texts:
        if text is not fig._suptitle:
            add("figure text", text)
    return out


def layout_problems(fig, min_font=8.0):
    """Texts outside the canvas, overlapping pairs and too-small fonts, as readable lines."""
    texts = drawn_texts(fig)
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    boxes = [(what, t, t.get_window_extent(renderer)) for what, t in texts]
    problems = []
    for what, t, box in boxes:
        if box.x0 < canvas.x0 - 1 or box.y0 < canvas.y0 - 1 or box.x1 > canvas.x1 + 1 or box.y1 > canvas.y1 + 1:
            problems.append(f"outside the canvas: {what!r} {t.get_text()!r}")
        if t.get_fontsize() < min_font:
            problems.append(f"{t.get_fontsize():.1f} pt < {min_font} pt: {what!r} {t.get_text()!r}")
    for (wa, ta, a), (wb, tb, b) in itertools.combinations(boxes, 2):
        w = min(a.x1, b.x1) - max(a.x0, b.x0)
        h = min(a.y1, b.y1) - max(a.y0, b.y0)
        if w > 1 and h > 1:  # more than a pixel each way
            problems.append(f"overlap: {wa!r} {ta.get_text()!r} and {wb!r} {tb.get_text()!r}")
    return problems


def unplain_ticks(fig):
    """Tick labels a reader has to decode: ``1e-05``, ``2×10⁻⁷``, or an offset/power text
    beside an axis (the power belongs in the unit, plots.style.plain_scale)."""
    fig.draw_without_rendering()
    bad = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for axis in (ax.xaxis, ax.yaxis):
            where = ax.get_xlabel() if axis is ax.xaxis else ax.get_ylabel()
            bad += [(where, t.get_text()) for t in axis.get_ticklabels(which="both")
                    if re.search(r"\de[-+]?\d|^[-+]?1e|\\times|×|10\^", t.get_text())]
            if axis.get_offset_text().get_text():
                bad.append((where, "offset " + axis.get_offset_text().get_text()))
    return bad
