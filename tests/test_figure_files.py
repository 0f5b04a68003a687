"""The report's figure files (:func:`skinfit.report.figure_files.write_png`): the PDF drawn by
matplotlib, the PNG that PDF rendered by PDFium. Checked against matplotlib's own Agg rendering
of the same figure."""

import io

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from skinfit.plots import figures as plots
from skinfit.report.figure_files import write_png


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


def _blocks(image, size=6):
    h, w = image.shape[0] // size * size, image.shape[1] // size * size
    return image[:h, :w].reshape(h // size, size, w // size, size, -1).mean(axis=(1, 3))


def test_png_and_pdf_show_the_figure_agg_would_draw(tmp_path):
    fig = _figure()
    write_png(fig, tmp_path / "f.png")
    png = np.asarray(Image.open(tmp_path / "f.png").convert("RGB"), dtype=float)
    # matplotlib's raster of the same figure, at the same size and laid out the same way
    FigureCanvasAgg(fig).draw()
    agg = np.asarray(fig.canvas.buffer_rgba(), dtype=float)[..., :3]
    assert abs(png.shape[0] - agg.shape[0]) <= 1 and abs(png.shape[1] - agg.shape[1]) <= 1
    assert png.shape[1] == round(5.0 * plots._DPI)
    h, w = min(png.shape[0], agg.shape[0]), min(png.shape[1], agg.shape[1])
    png, agg = png[:h, :w], agg[:h, :w]
    # the same picture: anti-aliasing and glyph rasterisation differ only at edges, so 6 x 6 px
    # block means agree (2.0 grey levels on average; the Agg image moved by 3 px: 6.4)
    assert np.mean(np.abs(_blocks(png) - _blocks(agg))) < 3.5
    # the black square where the axes put it, in both
    (x0, y0), (x1, y1) = fig.axes[0].transData.transform([(2, 4), (4, 2)])  # top-left, bottom-right (px, y up)
    rows, cols = slice(int(agg.shape[0] - y0) + 3, int(agg.shape[0] - y1) - 3), slice(int(x0) + 3, int(x1) - 3)
    assert png[rows, cols].max() < 30 and agg[rows, cols].max() < 30
    red = (png[..., 0] > 200) & (png[..., 1] < 80) & (png[..., 2] < 80)
    assert red[:, w // 2:].sum() > 200 and not red[:, : w // 2].any()
    # the PDF: one page of the figure's size in points
    pdf = (tmp_path / "f.pdf").read_bytes()
    assert pdf.startswith(b"%PDF-")
    import pypdfium2

    document = pypdfium2.PdfDocument(io.BytesIO(pdf))
    page = document[0]
    try:
        assert len(document) == 1
        assert np.allclose(page.get_size(), (5.0 * 72, 2.5 * 72), atol=0.5)
    finally:
        page.close()
        document.close()


def test_the_same_figure_gives_the_same_files(tmp_path):
    """No time stamp in the PDF and font-subset tags independent of Python's per-process hash
    salt: drawn in two processes (PYTHONHASHSEED 1 and 2), the PNG and PDF are byte for byte
    the same (a regenerated report changes only the files whose figures changed), and the PDF
    still opens as one page."""
    import os
    import subprocess
    import sys

    draw = ("import sys\nfrom matplotlib.figure import Figure\nfrom skinfit.report.figure_files import write_png\n"
            "fig = Figure(figsize=(4, 2), layout='constrained')\nax = fig.subplots()\n"
            "ax.plot([0, 1], [0, 1]); ax.set(xlabel='normal force [N]', title='a title')\n"
            "write_png(fig, sys.argv[1])\n")
    for seed, name in (("1", "a.png"), ("2", "b.png")):
        subprocess.run([sys.executable, "-c", draw, str(tmp_path / name)], check=True,
                       env={**os.environ, "PYTHONHASHSEED": seed, "MPLBACKEND": "Agg"})
    a, b = (tmp_path / "a.pdf").read_bytes(), (tmp_path / "b.pdf").read_bytes()
    assert a == b and b"/CreationDate" not in a and b"/BaseFont /AAAAAA+DejaVuSans" in a
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    import pypdfium2

    document = pypdfium2.PdfDocument(a)
    try:
        assert len(document) == 1
    finally:
        document.close()


def _font_subtypes(pdf):
    """The /Subtype of every font dictionary in ``pdf`` and whether a TrueType program is
    embedded (``/FontFile2``), read from the file's bytes (matplotlib writes its objects
    uncompressed, only the streams are deflated)."""
    import re

    text = pdf.decode("latin-1")
    return set(re.findall(r"/Subtype\s*/(Type3|Type1|TrueType|CIDFontType2|CIDFontType0|Type0)\b", text)), \
        "/FontFile2" in text


def test_saved_pdfs_embed_truetype_fonts_not_type3(tmp_path):
    """A figure's PDF, written by the report or by a plot function given a ``.pdf`` path, embeds
    its text's font as a TrueType subset (Type 42 in matplotlib): IEEE's and ScholarOne's
    manuscript checks refuse Type 3 fonts, matplotlib's default. PDFium still finds the
    title's text in it."""
    import pypdfium2

    write_png(_figure(), tmp_path / "f.png")
    plots._finish(_figure(), tmp_path / "g.pdf")
    for name in ("f.pdf", "g.pdf"):
        pdf = (tmp_path / name).read_bytes()
        subtypes, embedded = _font_subtypes(pdf)
        assert "Type3" not in subtypes and "CIDFontType2" in subtypes and embedded, (name, subtypes)
        document = pypdfium2.PdfDocument(pdf)
        page = document[0]
        textpage = page.get_textpage()
        try:
            text = textpage.get_text_range()
        finally:  # children first: pypdfium2 4.0 crashes closing a page after its document
            textpage.close()
            page.close()
            document.close()
        assert "a title" in text and "normal force [N]" in text
    import matplotlib

    assert matplotlib.rcParams["pdf.fonttype"] == 3  # the user's own setting left as it was
