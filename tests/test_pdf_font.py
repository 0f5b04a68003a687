"""The saved figures' font cut (skinfit.plots._pdf_font): the same text as DejaVu Sans, in the same
places, quicker to embed; the original font wherever that could not be promised."""

import io
import os
import re
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from fontTools.ttLib import TTFont  # noqa: E402
from matplotlib.ft2font import FT2Font, LoadFlags  # noqa: E402

from skinfit.plots import figures as plots  # noqa: E402

from skinfit.plots import _pdf_font

pytestmark = pytest.mark.skipif(_pdf_font.derived() is None, reason="no DejaVu Sans cut here (see its log)")

# printable ASCII, Latin-1 letters and signs, Greek, and the signs of units and labels
CORPUS = ("".join(chr(c) for c in range(0x20, 0x7F)) + "ÀÄÅÇÉÖØÜßàäåçéñöøüµ°²³·×±÷"
          + "ΑΒΓΔΘΛΞΠΣΦΨΩαβγδεζηθικλμνξπρστυφχψω" + "ЖЯжя" + "−–—‘’“”…⁰¹⁻₀₁→≤≥≈∞√∝∂")


def _laid_out(path, text, flags):
    """(glyph name, x, y) of each glyph of ``text`` as matplotlib lays it out with the font at
    ``path`` and FreeType load ``flags`` (HarfBuzz through libraqm from matplotlib 3.11,
    FreeType's kerning before)."""
    font = FT2Font(os.fspath(path))
    font.set_size(10, 72)
    if hasattr(font, "_layout"):
        return [(item.ft_object.get_glyph_name(item.glyph_index), item.x, item.y)
                for item in font._layout(text, flags)]
    xys = font.set_text(text, 0.0, flags=flags)  # matplotlib < 3.11: one position per character, kerned
    names = [font.get_glyph_name(font.get_char_index(ord(ch))) for ch in text]
    return list(zip(names, *np.asarray(xys).reshape(-1, 2).T.tolist()))


def test_the_cut_sets_every_pair_of_characters_as_dejavu_sans_does():
    """Every ordered pair of the corpus' 180-odd characters (kerning pairs, ligatures such as
    "ffi") gets the same glyphs at the same positions from the cut as from the DejaVu Sans it
    was cut from, unhinted as in a PDF and hinted as text is measured for the layout (by
    default from matplotlib 3.11; the cut is not used with the auto-hinter forced): the legacy
    kern table kerns as GPOS did, GSUB is kept."""
    cut = _pdf_font.derived()
    assert set(CORPUS) <= cut.drawn
    for flags in (LoadFlags.NO_HINTING, LoadFlags.DEFAULT):
        for first in CORPUS:
            text = "".join(first + second for second in CORPUS)
            assert _laid_out(cut.path, text, flags) == _laid_out(cut.source, text, flags), (flags, first)
    ligatures = _laid_out(cut.path, "office fluff", LoadFlags.NO_HINTING)
    if hasattr(FT2Font, "_layout"):  # matplotlib >= 3.11 sets ligatures: kept by the cut
        assert any(name.startswith("f_") or name in ("fi", "fl") for name, _, _ in ligatures)


@pytest.mark.parametrize("flags", [LoadFlags.DEFAULT, LoadFlags.NO_AUTOHINT, LoadFlags.NO_HINTING])
def test_every_glyph_the_cut_draws_has_dejavu_sans_metrics(flags):
    """Each of the ~2 450 characters the cut sets has the source glyph's advance, size and
    bearings under the hinting modes the cut is used with (with the auto-hinter forced, a few
    superscripts differ: such figures keep DejaVu Sans, tested below)."""
    cut = _pdf_font.derived()
    a, b = FT2Font(cut.path), FT2Font(cut.source)
    for font in (a, b):
        font.set_size(10, 72)
    keys = ("linearHoriAdvance", "horiAdvance", "width", "height", "horiBearingX", "horiBearingY")
    differ = []
    for ch in sorted(cut.drawn):
        if ord(ch) >= 32:
            ga, gb = a.load_char(ord(ch), flags=flags), b.load_char(ord(ch), flags=flags)
            if [getattr(ga, k) for k in keys] != [getattr(gb, k) for k in keys]:
                differ.append(ch)
    assert len(cut.drawn) > 2000 and not differ


def _font_programs(pdf):
    """The TrueType programs (fontTools TTFont) embedded in ``pdf`` (its /FontFile2 streams)."""
    fonts = []
    for ref in sorted(set(re.findall(rb"/FontFile2 (\d+) 0 R", pdf))):
        start = pdf.index(b"stream\n", pdf.index(b"\n" + ref + b" 0 obj")) + len(b"stream\n")
        fonts.append(TTFont(io.BytesIO(zlib.decompressobj().decompress(pdf[start:]))))
    return fonts


def _families(pdf):
    """The family names of the fonts embedded in ``pdf`` (mathtext, as in tick labels, embeds its own subset)."""
    return {f["name"].getDebugName(1) for f in _font_programs(pdf)}


def _picture(pdf):
    import pypdfium2

    document = pypdfium2.PdfDocument(pdf)
    page = document[0]
    try:
        return np.asarray(page.render(scale=2).to_pil().convert("RGB"))
    finally:
        page.close()
        document.close()


def _figure(title):
    fig, ax = plt.subplots(figsize=(4, 3), layout="constrained")
    ax.plot([0.1, 1, 2], [1, 3, 2])
    ax.set_title(title)
    ax.set_xlabel("normal force [N]")
    ax.set_ylabel("friction coefficient µ [-]")
    return fig


def _saved(fig):
    buffer = io.BytesIO()
    plots.save_figure(fig, buffer, format="pdf", metadata={"CreationDate": None})
    return buffer.getvalue()


def test_a_saved_pdf_embeds_the_cut_and_shows_the_same_picture(monkeypatch):
    """A figure's PDF embeds the cut (no GPOS table; the PDF names it DejaVuSans) and PDFium
    draws it pixel for pixel as the same figure saved with DejaVu Sans itself."""
    title = "AVATAR To Wa: office coefficient, τ₀ = 5 µm² ± 2 (Ω, −3 °C)"
    monkeypatch.setitem(matplotlib.rcParams, "text.hinting", "default")  # matplotlib < 3.11 forces the auto-hinter
    with_cut = _saved(_figure(title))
    fonts = _font_programs(with_cut)
    assert fonts and all(f["name"].getDebugName(1) == _pdf_font.FAMILY and "GPOS" not in f for f in fonts)
    assert b"+DejaVuSans" in with_cut
    monkeypatch.setattr(_pdf_font, "rc_for", lambda fig: {})
    original = _saved(_figure(title))
    assert _families(original) == {"DejaVu Sans"}
    assert np.array_equal(_picture(with_cut), _picture(original))
    plt.close("all")


@pytest.mark.parametrize("title", ["x\u0304 = 3 N",  # a combining mark, which GPOS places
                                   "subject שרה"])  # a DejaVu Sans alphabet the cut leaves out
def test_text_the_cut_would_not_set_as_dejavu_sans_keeps_dejavu_sans(title):
    fig = _figure(title)
    assert _pdf_font.rc_for(fig) == {}
    assert _families(_saved(fig)) == {"DejaVu Sans"}
    plt.close(fig)


def test_text_measured_with_the_autohinter_forced_keeps_dejavu_sans():
    with matplotlib.rc_context({"text.hinting": "force_autohint"}):
        fig = _figure("a title")
        assert _pdf_font.rc_for(fig) == {}
        assert _families(_saved(fig)) == {"DejaVu Sans"}
    plt.close(fig)


def test_the_users_own_font_choice_is_kept():
    """Sans-serif text that the user's rcParams make another font is not turned into the cut."""
    with matplotlib.rc_context({"font.sans-serif": ["DejaVu Serif"]}):
        fig = _figure("a title")
        assert _pdf_font.rc_for(fig) == {}
        assert _families(_saved(fig)) == {"DejaVu Serif"}
    assert _pdf_font.FAMILY not in matplotlib.rcParams["font.sans-serif"]  # the rcParams left as they were
    plt.close(fig)


_CACHE_SCRIPT = textwrap.dedent("""
    import sys
    from pathlib import Path
    import matplotlib
    matplotlib.use("Agg")
    matplotlib.rcParams["text.hinting"] = "default"  # matplotlib < 3.11 forces the auto-hinter: no cut
    import matplotlib.pyplot as plt
    from skinfit.plots import _pdf_font
    from skinfit.plots import figures as plots
    _pdf_font.cache_dir = lambda: Path(sys.argv[1])
    cut = _pdf_font.derived()
    fig, ax = plt.subplots()
    ax.set_title("a title")
    plots.save_figure(fig, sys.argv[2])
    print("none" if cut is None else cut.path)
""")


def _derive_in_new_process(folder, pdf):
    """(the cut's path or "none", the families embedded in a figure saved) in a new interpreter
    whose cache folder is ``folder``."""
    out = subprocess.run([sys.executable, "-c", _CACHE_SCRIPT, str(folder), str(pdf)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip(), _families(pdf.read_bytes())


def _dead_pid():
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_the_cut_is_made_once_atomically_and_again_when_damaged(tmp_path):
    """The cut is written into the cache folder named by its source's sha256 (no temporary file
    of its own left; a killed derivation's removed, a live one's left to its process), the same
    bytes by every derivation; a damaged file there is cut again; where the folder cannot be
    written, figures are saved with DejaVu Sans."""
    from skinfit.inference.checkpoint import temp_file

    folder = tmp_path / "fonts"
    folder.mkdir()
    target = folder / "DejaVuSans.ttf"
    killed = Path(temp_file(target))  # named as a writer's temporary file: host, pid, random part
    killed.rename(killed.with_name(killed.name.replace(f".{os.getpid()}-", f".{_dead_pid()}-")))
    running = Path(temp_file(target))  # this (live) process'
    first, families = _derive_in_new_process(folder, tmp_path / "a.pdf")
    assert families == {_pdf_font.FAMILY}
    assert sorted(p.name for p in folder.iterdir()) == sorted([running.name, os.path.basename(first)])
    data = open(_pdf_font.derived().source, "rb").read()
    assert _pdf_font.derive(data) == _pdf_font.derive(data) == open(first, "rb").read()
    with open(first, "r+b") as fh:  # cut short, as by a disk that filled
        fh.truncate(5000)
    assert _derive_in_new_process(folder, tmp_path / "b.pdf") == (first, {_pdf_font.FAMILY})
    assert open(first, "rb").read() == _pdf_font.derive(data)
    blocked = tmp_path / "a file"
    blocked.write_text("not a folder")
    assert _derive_in_new_process(blocked / "fonts", tmp_path / "c.pdf") == ("none", {"DejaVu Sans"})
