"""What every figure shares: palette, sizes, the figure and its title, log-axis ticks, saving.

Figures are made without pyplot (nothing is ever shown) and saved through :func:`save_figure`,
so that every PDF embeds TrueType fonts. The report writes each figure as a PNG for the page
and a PDF for papers (:func:`write_figure_files`).
"""

import math
import os
import re
import textwrap
from pathlib import Path

import matplotlib
import matplotlib.layout_engine
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter, NullLocator
from PIL import Image

from skinfit.io.units import to_si

__all__ = ["COLOURS", "MAP_COLOUR", "DPI", "MAX_WIDTH", "MIN_FONT", "SAVE_RC", "ensure_backend", "new_figure",
           "suptitle", "wrap_title", "log_ticks", "save_figure", "finish_figure", "fix_layout",
           "write_figure_files", "plain_scale", "tick_text"]

#: Okabe & Ito's colour-blind-safe palette (Color Universal Design, 2008; yellow left out: too
#: pale on white), then two darker greys.
COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#666666")
#: The MAP's colour in the corner plot.
MAP_COLOUR = "#D55E00"
#: Resolution of saved raster figures [dots per inch].
DPI = 120
#: Widest figure [in]: the report shows figures at their pixel size up to its 1136 px column
#: (1200 px less padding), so 8 pt text stays >= 8 pt (13 px at 120 dpi) as displayed.
MAX_WIDTH = 9.4
#: Smallest font size [pt] of any text in a figure.
MIN_FONT = 8
#: Fonts of a saved PDF or PostScript figure embedded as TrueType (Type 42) subsets, not as
#: matplotlib's default Type 3 fonts, which IEEE's and ScholarOne's manuscript checks refuse.
SAVE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42}


def ensure_backend():
    """Agg unless the user chose a backend (MPLBACKEND or matplotlib.use): for the figures
    ArviZ draws through pyplot."""
    if os.environ.get("MPLBACKEND") is None and matplotlib.get_backend(auto_select=False) is None:
        matplotlib.use("Agg")


def new_figure(width, height):
    """A figure of ``width`` x ``height`` inches (the width capped at :data:`MAX_WIDTH`), laid
    out by matplotlib's constrained layout."""
    return Figure(figsize=(min(width, MAX_WIDTH), height), layout="constrained")


def suptitle(fig, text, fontsize=10):
    """A figure title wrapped at word boundaries (also after ``:`` and ``[``) to the figure's
    width, so that a long model or dataset name is never cut at the canvas edge."""
    per_line = max(20, int(fig.get_figwidth() * 72 / (0.6 * fontsize)))  # ~0.6 em per character
    spaced = text.replace("[", " [").replace(",", ", ").replace(",  ", ", ")
    lines = textwrap.wrap(spaced, per_line, break_long_words=True, break_on_hyphens=False)
    return fig.suptitle("\n".join(lines).replace(" [", "["), fontsize=fontsize)


def wrap_title(text, ax, fontsize=MIN_FONT + 1):
    """Panel title wrapped to its axes' width (at ~0.6 em a character), line by line. Under
    constrained layout the width is the axes' share of the figure less ~0.8 in of outer
    margins and 0.1 in between panels (the default subplot margins it has before the layout
    runs are wider, and wrapped "angle = 0 deg" as "angle = 0" / "deg"); a number is never
    parted from the words on either side ("= 0 deg", "contraction 1.00"), and a mathtext unit
    (``$...$``) is never broken: a piece of one would be drawn as its source text."""
    fig, spec = ax.figure, ax.get_subplotspec()
    if spec is not None and isinstance(fig.get_layout_engine(), matplotlib.layout_engine.ConstrainedLayoutEngine):
        width_in = (fig.get_figwidth() - 0.8) * len(spec.colspan) / spec.get_gridspec().ncols - 0.1
    else:
        width_in = ax.get_position().width * fig.get_figwidth()
    per_line = max(12, int(width_in * 72 / (0.6 * fontsize)))
    bound = re.sub(r"(?<=\S) (?=[-+]?\.?\d)|(?<=\d) (?=\S)", "\u00a0", text)  # a number stays with its neighbours
    bound = re.sub(r"\$[^$]*\$", lambda m: m.group(0).replace(" ", "\u00a0"), bound)  # mathtext: one piece
    return "\n".join(w for line in bound.split("\n")
                     for w in textwrap.wrap(line, per_line, break_long_words="$" not in line)).replace("\u00a0", " ")


def log_ticks(ax, which="x", numticks=5, sparse=False):
    """Readable ticks on a log axis (call after its limits are set): decades, or 1, 2, 5 x 10^k
    on a range of less than 1.5 decades or holding fewer than two decades (``sparse``: at most
    ``numticks`` evenly spaced values away from the ends, for small panels), labelled as plain
    numbers. Minor ticks stay unlabelled, and are left out between 1, 2, 5 x 10^k labels, where
    they add nothing to the labels and the grid."""
    axis = ax.xaxis if which == "x" else ax.yaxis
    lo, hi = ax.get_xlim() if which == "x" else ax.get_ylim()
    # 1, 2, 5 x 10^k also where fewer than two decades fall inside (0.02 .. 0.9 shows only 0.1)
    short = math.log10(hi / lo) < 1.5 or math.floor(math.log10(hi)) - math.ceil(math.log10(lo)) < 1
    if short and sparse:
        axis.set_major_locator(MaxNLocator(numticks, prune="both"))
        axis.set_major_formatter(FuncFormatter(lambda v, _: tick_text(v)))
    else:
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0) if short else (1.0,),
                                          numticks=3 * numticks if short else numticks))
        # decades beyond 0.001 .. 99 999 on the axis: all of them as 10ⁿ, not 10000 beside 10⁵
        powers = not short and (lo < 1e-3 or hi >= 1e5)
        axis.set_major_formatter(FuncFormatter(lambda v, _: tick_text(v, powers)))
    if short and not sparse:
        axis.set_minor_locator(NullLocator())
    axis.set_minor_formatter(NullFormatter())


def tick_text(value, powers=False):
    """A tick's value as a reader reads it, never ``1e+06``: plain digits to 3 significant
    figures (``0.002``, ``7500``), a power of ten below 0.001 or from 100 000 on as ``10⁻⁴``, ``10⁶``
    (a log axis over many decades, e.g. a wide prior); ``powers``: every power of ten so."""
    if value == 0 or not math.isfinite(value):
        return "0" if value == 0 else ""
    power = round(math.log10(abs(value)))
    if (powers or not 1e-3 <= abs(value) < 1e5) and math.isclose(abs(value), 10.0 ** power, rel_tol=1e-9):
        return ("−" if value < 0 else "") + "10" + str(power).translate(_SUPERSCRIPT)
    text = np.format_float_positional(value, precision=3, unique=True, fractional=False, trim="-")
    return text.replace("-", "\u2212")  # the minus sign, as matplotlib's own tick labels write it


def save_figure(fig, target, **kwargs):
    """``fig.savefig(target, **kwargs)`` with :data:`SAVE_RC`: what every saved figure goes through."""
    with matplotlib.rc_context(SAVE_RC):
        fig.savefig(target, **kwargs)


def finish_figure(fig, path):
    """``fig``, first written to ``path`` (its format from the suffix, raster at :data:`DPI`)
    when a path is given: the end of every plot function."""
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        save_figure(fig, path, dpi=DPI)
    return fig


def fix_layout(fig):
    """Run the figure's layout engine once and keep its result (no engine left), so that the
    PNG and the PDF saved after it show the same layout, computed once. Minor ticks carry no
    labels and so do not move the layout: their locators are set aside while it is measured
    (on a many-panel figure, making and placing them is half of constrained layout's work)."""
    engine = fig.get_layout_engine()
    if engine is None or not fig.axes:
        return
    saved = [(axis, axis.get_minor_locator()) for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)]
    for axis, _ in saved:
        axis.set_minor_locator(NullLocator())
    try:
        engine.execute(fig)
    finally:
        for axis, locator in reversed(saved):  # shared axes share one locator: the first saved is the original
            axis.set_minor_locator(locator)
    fig.set_layout_engine(None)


def write_figure_files(fig, path):
    """The report's files of a figure: ``path``, a PNG at :data:`DPI` for the page, and beside
    it the same figure as a vector PDF for papers (TrueType fonts, dense scatters rasterised at
    :data:`DPI`, no time stamp: the same figure gives the same bytes), laid out once
    (:func:`fix_layout`)."""
    path = Path(path)
    fig.set_dpi(DPI)
    fix_layout(fig)
    canvas = FigureCanvasAgg(fig)  # the PNG: Agg's pixels reduced to a 256-colour palette (a quarter of the bytes)
    with matplotlib.rc_context(SAVE_RC):
        canvas.draw()
    rgba = Image.frombuffer("RGBA", canvas.get_width_height(physical=True), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    rgba.convert("RGB").quantize(256).save(path, format="png", optimize=True, dpi=(DPI, DPI))
    save_figure(fig, path.with_suffix(".pdf"), format="pdf", metadata={"CreationDate": None})


def plain_scale(values, unit, display=None):
    """(factor, unit text) that put ``values`` (SI) in plain numbers: the model card's
    ``display`` unit where it names one (kPa for a modulus, as the tables show it), else an SI
    prefix on a simple unit (``Pa`` -> ``kPa``), else a power of ten written in the unit
    (``10⁻⁹ m^2/N^m``); values are divided by the factor. (1, unit) where plain numbers already
    read well."""
    if display:
        return to_si(display), display
    top = np.nanmax(np.abs(values)) if np.size(values) else 1.0
    if not np.isfinite(top) or top == 0 or 0.1 <= top < 10000:
        return 1.0, unit
    power = int(np.floor(np.log10(top) / 3) * 3)
    if unit and re.fullmatch(r"[A-Za-z]+", unit) and power in _PREFIX:
        return 10.0 ** power, _PREFIX[power] + unit
    shown = "" if unit in (None, "", "1", "-") else f" {unit}"
    return 10.0 ** power, f"10{str(power).translate(_SUPERSCRIPT)}{shown}"


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


_PREFIX = {-12: "p", -9: "n", -6: "\u00b5", -3: "m", 3: "k", 6: "M", 9: "G"}
