"""The report's figure files (``skinfit.plots.write_figure_files``): a PNG of the laid-out figure
at ``plots.DPI`` and a one-page PDF with its fonts embedded as TrueType, both written by
matplotlib, the same bytes for the same figure."""

import os
import re
import subprocess
import sys

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from skinfit import plots


def _figure():
    """Two panels with known marks: a black square (data 2-4 x 2-4) in the left panel, a red
    line and a title; constrained layout, as the report's figures."""
    fig = Figure(figsize=(5.0, 2.5), layout="constrained")
    left, right = fig.subplots(1, 2)
    left.fill_between([2, 4], [2, 2], [4, 4], color="black", lw=0)
    left.set(xlim=(0, 6), ylim=(0, 6), xlabel="normal force [N]", ylabel="friction [N]")
    right.plot([0, 1], [0, 1], color="red", lw=3)
    right.set_title("a title")
    return fig


def _pdf_objects(pdf):
    """The text of a PDF's objects (matplotlib writes them uncompressed; only streams are deflated)."""
    return pdf.decode("latin-1")


def test_png_shows_the_laid_out_figure_at_the_reports_resolution(tmp_path):
    fig = _figure()
    plots.write_figure_files(fig, tmp_path / "f.png")
    with Image.open(tmp_path / "f.png") as image:
        assert image.format == "PNG"
        png = np.asarray(image.convert("RGB"), dtype=float)
    assert png.shape[:2] == (round(2.5 * plots.DPI), round(5.0 * plots.DPI))
    # the black square where the laid-out axes put it (the layout is kept: no engine left)
    assert fig.get_layout_engine() is None
    (x0, y0), (x1, y1) = fig.axes[0].transData.transform([(2, 4), (4, 2)])  # top-left, bottom-right (px, y up)
    rows = slice(int(png.shape[0] - y0) + 3, int(png.shape[0] - y1) - 3)
    assert png[rows, int(x0) + 3:int(x1) - 3].max() < 30
    red = (png[..., 0] > 200) & (png[..., 1] < 80) & (png[..., 2] < 80)
    w = png.shape[1]
    assert red[:, w // 2:].sum() > 200 and not red[:, : w // 2].any()


def test_pdf_is_one_page_of_the_figures_size_with_truetype_fonts_embedded(tmp_path):
    """The PDF, written by the report or by a plot function given a ``.pdf`` path: one page of
    the figure's size in points, its text's font embedded as a TrueType subset (Type 42 in
    matplotlib): IEEE's and ScholarOne's manuscript checks refuse Type 3 fonts, matplotlib's
    default, which the user's own rcParams keep."""
    plots.write_figure_files(_figure(), tmp_path / "f.png")
    plots.style.finish_figure(_figure(), tmp_path / "g.pdf")
    for name in ("f.pdf", "g.pdf"):
        pdf = (tmp_path / name).read_bytes()
        assert pdf.startswith(b"%PDF-") and pdf.rstrip().endswith(b"%%EOF")
        text = _pdf_objects(pdf)
        assert len(re.findall(r"/Type\s*/Page\b", text)) == 1
        (box,) = re.findall(r"/MediaBox\s*\[\s*([\d.\s]+)\]", text)
        np.testing.assert_allclose([float(v) for v in box.split()], [0, 0, 5.0 * 72, 2.5 * 72], atol=0.5)
        subtypes = set(re.findall(r"/Subtype\s*/(Type3|Type1|TrueType|CIDFontType2|CIDFontType0|Type0)\b", text))
        assert "Type3" not in subtypes and "CIDFontType2" in subtypes, (name, subtypes)
        assert "/FontFile2" in text and re.search(r"/BaseFont\s*/[A-Z]{6}\+DejaVuSans\b", text), name
    assert matplotlib.rcParams["pdf.fonttype"] == 3  # the user's own setting left as it was


def test_the_same_figure_gives_the_same_files(tmp_path):
    """No time stamp in the PDF, nothing that depends on the process: drawn in two processes
    (PYTHONHASHSEED 1 and 2), the PNG and PDF are byte for byte the same (a regenerated report
    changes only the files whose figures changed)."""
    draw = ("import sys\nfrom matplotlib.figure import Figure\nfrom skinfit import plots\n"
            "fig = Figure(figsize=(4, 2), layout='constrained')\nax = fig.subplots()\n"
            "ax.plot([0, 1], [0, 1]); ax.set(xlabel='normal force [N] \u03bc', title='a title')\n"
            "plots.write_figure_files(fig, sys.argv[1])\n")
    for seed, name in (("1", "a.png"), ("2", "b.png")):
        subprocess.run([sys.executable, "-c", draw, str(tmp_path / name)], check=True,
                       env={**os.environ, "PYTHONHASHSEED": seed, "MPLBACKEND": "Agg"})
    a = (tmp_path / "a.pdf").read_bytes()
    assert a == (tmp_path / "b.pdf").read_bytes() and b"/CreationDate" not in a
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
