"""A figure's files: the vector PDF for papers and the PNG the page shows.

The PNG is rasterised from the PDF by PDFium (pypdfium2); the PDF's font-subset tags are made
independent of the process (:func:`stable_font_tags`).
"""

import io
import re
from pathlib import Path

import matplotlib.backends.backend_pdf  # noqa: F401  imported once, before the figure workers fork
import PIL.PngImagePlugin  # noqa: F401  likewise
import pypdfium2
from PIL import Image

from skinfit.plots import figures as plots

__all__ = ["write_png", "stable_font_tags"]


def write_png(fig, path):
    """The figure as a vector PDF (dense scatter rasterised; TrueType fonts, :data:`plots.SAVE_RC`),
    for papers, and as a PNG of that PDF rendered by PDFium at :data:`plots._DPI`, quantised to
    256 colours (a third of the size, no visible change for line art). The layout is computed
    once (:func:`plots._fix_layout`) and the figure drawn once, into the PDF, which PDFium
    rasterises (bench/results/report.md)."""
    fig.set_dpi(plots._DPI)
    plots._fix_layout(fig)
    buffer = io.BytesIO()
    plots.save_figure(fig, buffer, format="pdf", metadata={"CreationDate": None})  # the same figure, the same bytes
    pdf = stable_font_tags(buffer.getvalue())
    document = pypdfium2.PdfDocument(pdf)
    page = document[0]
    try:  # in RGB byte order, no alpha (the page is filled white): no conversion of PDFium's BGRA
        image = page.render(scale=plots._DPI / 72, rev_byteorder=True, prefer_bgrx=True).to_pil()
        image = image.convert("RGB")  # a copy, independent of PDFium's bitmap (RGBX from pypdfium2 4)
    finally:
        page.close()
        document.close()
    image.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE).save(
        path, format="PNG", compress_level=6)
    Path(path).with_suffix(".pdf").write_bytes(pdf)


_SUBSET_TAG = re.compile(rb"(/(?:BaseFont|FontName|Name) /)([A-Z]{6})(?=\+)")


def stable_font_tags(pdf):
    """``pdf`` with its font-subset tags (``/BaseFont /GXDUII+DejaVuSans``) made independent of
    the process: matplotlib derives them from ``hash()`` of the subset's glyphs, which Python
    salts per process, so the same figure gave other bytes in each. Each distinct tag becomes,
    in order of first appearance, AAAAAA, AAAAAB, ...: the same length, so every byte offset and
    the cross-reference table stay valid (PDF reference 1.7, 5.5.3: the tag is arbitrary)."""
    tags = {}

    def fixed(match):
        if match.group(2) not in tags:
            n, letters = len(tags), []
            for _ in range(6):
                n, r = divmod(n, 26)
                letters.append(chr(65 + r))
            tags[match.group(2)] = "".join(reversed(letters)).encode()
        return match.group(1) + tags[match.group(2)]

    return _SUBSET_TAG.sub(fixed, pdf)
