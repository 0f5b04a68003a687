"""The saved figures' font: a cut of DejaVu Sans, derived once into the user cache folder.

Every PDF matplotlib writes embeds a subset of its font (TrueType, :data:`skinfit.plots.figures.SAVE_RC`),
cut by fontTools, which decompiles the whole font's tables each time; for DejaVu Sans,
matplotlib's default, that is ~0.04 s a PDF, mostly its GPOS (kerning, mark positioning) and
MATH tables and the names and metrics of its 6 000 glyphs. The cut has neither table and only
the glyphs of the alphabets and symbols figures use (:data:`RANGES`), and sets text the same:
HarfBuzz (matplotlib >= 3.11) then kerns with the font's legacy ``kern`` table, which holds the
same pairs, and older matplotlib uses only that table; GSUB (ligatures) is kept; every glyph's
metrics are the source's under the hinting modes text is measured with by default. A figure
with a character outside the cut or a combining mark (placed by GPOS), one measured with the
auto-hinter forced, and one whose sans-serif text would not be DejaVu Sans (the user's own
font choice) keep the original font.
"""

import functools
import hashlib
import os
import unicodedata
from pathlib import Path
from typing import NamedTuple

__all__ = ["FAMILY", "RANGES", "derive", "derived", "rc_for"]

#: The cut's family name (its PostScript name stays ``DejaVuSans``, as PDFs name it).
FAMILY = "DejaVu Sans skinfit"
#: The code points the cut keeps: Latin, IPA, Greek, Cyrillic, Armenian; Latin and Greek
#: extended; punctuation, super- and subscripts, currency, letter-like symbols, number forms,
#: arrows, mathematical operators, technical symbols; geometric shapes.
RANGES = ((0x0000, 0x0530), (0x1E00, 0x2000), (0x2000, 0x2400), (0x25A0, 0x2600))
_VERSION = 1  # of the recipe: part of the file name, so a changed recipe makes a new file
_FAMILY_NAME_IDS = (1, 3, 4, 16)  # family, unique id, full name, typographic family


def cache_dir():
    """Where derived fonts are kept: ``<user cache folder>/fonts``."""
    from skinfit.io.paths import user_cache_root

    return user_cache_root() / "fonts"


def _kept(code):
    """True when the cut keeps code point ``code`` (:data:`RANGES`)."""
    return any(lo <= code < hi for lo, hi in RANGES)


def derive(source_bytes):
    """The bytes of the cut (deterministic), made from the bytes of DejaVu Sans, or None when the
    source has no legacy ``kern`` table to kern with once GPOS is gone."""
    import io
    import logging

    from fontTools import subset
    from fontTools.ttLib import TTFont

    font = TTFont(io.BytesIO(source_bytes), recalcBBoxes=False, recalcTimestamp=False)  # head and maxp as the source's
    if "kern" not in font:
        return None
    options = subset.Options(glyph_names=True, layout_features=["*"], legacy_kern=True, hinting=True,
                             notdef_outline=True, name_IDs=["*"], name_languages=["*"], name_legacy=True,
                             recalc_timestamp=False)
    options.drop_tables += ["GPOS", "MATH"]
    subsetter = subset.Subsetter(options)
    subsetter.populate(unicodes=[c for c in font.getBestCmap() if _kept(c)])
    level = logging.getLogger("fontTools.subset").level
    logging.getLogger("fontTools.subset").setLevel(logging.ERROR)  # "FFTM NOT subset ... dropped": as meant
    try:
        subsetter.subset(font)
    finally:
        logging.getLogger("fontTools.subset").setLevel(level)
    for record in font["name"].names:
        if record.nameID in _FAMILY_NAME_IDS:
            record.string = FAMILY
    out = io.BytesIO()
    font.save(out, reorderTables=False)
    return out.getvalue()


def _expected(source):
    """The code points of DejaVu Sans at ``source`` that the cut keeps."""
    from matplotlib.ft2font import FT2Font

    return {c for c in FT2Font(source).get_charmap() if _kept(c)}


def _usable(path, expected):
    """True when ``path`` is a font matplotlib reads, named :data:`FAMILY`, mapping exactly the
    ``expected`` code points."""
    from matplotlib.ft2font import FT2Font

    try:
        font = FT2Font(str(path))
        return font.family_name == FAMILY and set(font.get_charmap()) == expected
    except Exception:  # noqa: BLE001 - an unreadable file is derived again
        return False


class Cut(NamedTuple):
    """The cut's file, the DejaVu Sans it was cut from and the characters it sets as the source
    does (those it keeps, combining marks left out; control characters such as a line break,
    which are never drawn)."""

    path: str
    source: str
    drawn: frozenset

    def __repr__(self):
        return f"Cut({self.path!r}, source={self.source!r}, {len(self.drawn)} characters)"


@functools.cache
def derived():
    """The :class:`Cut` of DejaVu Sans registered with matplotlib's font manager, or None when
    it cannot be had here (DejaVu Sans not found or without a ``kern`` table, an unwritable
    cache folder): then figures keep the original font, slower to save, otherwise the same.

    The file is named by the sha256 of the DejaVu Sans it is cut from and written atomically
    (:func:`skinfit.inference.checkpoint.replace_atomic`), so processes deriving it at once write the same
    bytes and none reads a partial file; a file that is not a readable font of that family
    mapping exactly the code points the cut keeps is derived again."""
    from matplotlib import font_manager

    try:
        source = font_manager.findfont(font_manager.FontProperties(family=["DejaVu Sans"]),
                                       fallback_to_default=False)
        data = Path(source).read_bytes()
        expected = _expected(source)
        folder = cache_dir()
        path = folder / f"DejaVuSans-{hashlib.sha256(data).hexdigest()[:24]}-{_VERSION}.ttf"
        if not _usable(path, expected):
            from skinfit.inference.checkpoint import remove_stale_temps, replace_atomic

            font = derive(data)
            if font is None:
                return None
            replace_atomic(path, font)
            remove_stale_temps(folder, recursive=False)  # of derivations killed before their rename
            if not _usable(path, expected):
                return None
        font_manager.fontManager.addfont(str(path))
        found = font_manager.findfont(font_manager.FontProperties(family=[FAMILY]), fallback_to_default=False)
        if Path(found) != path:
            return None
        drawn = {chr(c) for c in expected if not unicodedata.category(chr(c)).startswith("M")}
        return Cut(str(path), os.fspath(source), frozenset(drawn | {chr(c) for c in range(32)}))
    except Exception:  # noqa: BLE001 - the original font is always a correct choice
        return None


def _autohinted():
    """True when text is measured with FreeType's auto-hinter forced (``text.hinting`` "force_autohint"
    or "auto", as in the classic style): its hinted metrics of a few superscript and modifier
    letters differ between the cut and the source (checked for every character under the other
    hinting modes by the tests), so a layout could move by a fraction of a pixel."""
    from matplotlib.backends.backend_agg import get_hinting_flag
    from matplotlib.ft2font import LoadFlags

    return get_hinting_flag() == LoadFlags.FORCE_AUTOHINT  # one of four modes, never combined


def rc_for(fig):
    """rcParams under which ``fig`` is saved with the cut: its sans-serif text drawn with it
    instead of DejaVu Sans, the same glyphs in the same places. Empty (the original font) when
    the cut is not available, when sans-serif text would not be DejaVu Sans under the current
    rcParams, when text is measured with the auto-hinter forced, or when some text of ``fig``
    holds a character the cut does not set as DejaVu Sans does (:attr:`Cut.drawn`)."""
    import matplotlib
    from matplotlib import font_manager
    from matplotlib.text import Text

    cut = derived()
    if cut is None:
        return {}
    try:
        sans = font_manager.findfont(font_manager.FontProperties(family=["sans-serif"]), fallback_to_default=False)
    except ValueError:
        return {}
    if os.fspath(sans) != cut.source or _autohinted():
        return {}
    if not set("".join(t.get_text() for t in fig.findobj(Text))) <= cut.drawn:
        return {}
    return {"font.sans-serif": [FAMILY, *matplotlib.rcParams["font.sans-serif"]]}
