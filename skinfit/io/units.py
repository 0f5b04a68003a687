"""Units: parsed, dimension-checked and converted to SI at the data boundary.

One closed grammar, no unit library: a unit is a product of symbols with integer powers
(``N*s/m``, ``mm^2``, ``mN/mm``, ``m/s^2``), each symbol an SI symbol of :data:`SYMBOLS`
(``m s kg g A K N Pa J W C V F ohm Hz rad``) with at most one SI prefix of :data:`PREFIXES`
(``u``, ``µ`` and ``μ`` all micro), or one of the non-SI units of :data:`OTHER` (``deg``,
``min``, ``h``, ``count``: an encoder count, dimensionless, for a rig's ``mm/count`` gain).
Anything else is refused, naming what is accepted.  Model cards state coherent
SI units (no prefix), where a power may also be a symbol of the model: :func:`check_model_unit`.
"""

import math
import re
from dataclasses import dataclass
from functools import lru_cache

__all__ = ["Unit", "parse_unit", "to_si", "si_unit", "dimension", "check_model_unit", "same_dimension", "UNITS",
           "NONNEGATIVE", "SYMBOLS", "PREFIXES", "OTHER", "pretty_unit", "unit_mathtext"]

_L, _M, _T, _I, _K = "[length]", "[mass]", "[time]", "[current]", "[temperature]"
#: SI symbols -> (factor to the coherent SI unit, dimension exponents)
SYMBOLS = {
    "m": (1.0, {_L: 1}), "s": (1.0, {_T: 1}), "kg": (1.0, {_M: 1}), "g": (1e-3, {_M: 1}), "A": (1.0, {_I: 1}),
    "K": (1.0, {_K: 1}), "N": (1.0, {_M: 1, _L: 1, _T: -2}), "Pa": (1.0, {_M: 1, _L: -1, _T: -2}),
    "J": (1.0, {_M: 1, _L: 2, _T: -2}), "W": (1.0, {_M: 1, _L: 2, _T: -3}), "C": (1.0, {_I: 1, _T: 1}),
    "V": (1.0, {_M: 1, _L: 2, _T: -3, _I: -1}), "F": (1.0, {_M: -1, _L: -2, _T: 4, _I: 2}),
    "ohm": (1.0, {_M: 1, _L: 2, _T: -3, _I: -2}), "Hz": (1.0, {_T: -1}), "rad": (1.0, {}),
    "1": (1.0, {}), "-": (1.0, {}),
}
#: Non-SI units accepted as symbols (no prefix): degree of angle, minute and hour of time, an
#: encoder count (a raw position channel; its gain is in mm/count)
OTHER = {"deg": (math.pi / 180, {}), "min": (60.0, {_T: 1}), "h": (3600.0, {_T: 1}), "count": (1.0, {})}
#: SI prefixes, longest first so that ``da`` is tried before ``d``
PREFIXES = {"da": 1e1, "T": 1e12, "G": 1e9, "M": 1e6, "k": 1e3, "h": 1e2, "d": 1e-1, "c": 1e-2, "m": 1e-3,
            "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "n": 1e-9, "p": 1e-12, "f": 1e-15}
_PREFIXABLE = set(SYMBOLS) - {"kg", "1", "-"}
#: dimension exponents -> the name used in messages (and for the sign rule below)
_NAMES = {
    frozenset(): "dimensionless quantity", frozenset({_M: 1, _L: 1, _T: -2}.items()): "force",
    frozenset({_M: 1, _L: 2, _T: -3, _I: -1}.items()): "voltage", frozenset({_L: 1}.items()): "length",
    frozenset({_L: 2}.items()): "area", frozenset({_M: 1, _L: -1, _T: -2}.items()): "pressure",
    frozenset({_L: 1, _T: -1}.items()): "velocity", frozenset({_T: -1}.items()): "frequency",
    frozenset({_T: 1}.items()): "time", frozenset({_M: 1, _T: -1}.items()): "impedance",
}
# Quantities that are physically non-negative unless a column is declared `signed = true`.
NONNEGATIVE = {"force", "length", "area", "pressure", "frequency", "voltage", "impedance", "time"}

#: The common units (every unit of the grammar above is accepted).
UNITS = ("1", "N", "mN", "uN", "V", "kV", "m", "mm", "um", "µm", "nm", "m^2", "mm^2", "Pa", "kPa", "MPa",
         "m/s", "mm/s", "Hz", "kHz", "rad", "deg", "s", "ms", "N*s/m")

_TOKEN = re.compile(r"\s*(?:(?P<sym>[A-Za-zµμ]+|1|-)(?:\^(?P<pow>-?\d+|\(-?\d+\)))?)\s*")


@dataclass(frozen=True)
class Unit:
    """A parsed unit: ``factor`` converts a value in it to SI; ``dims`` its dimension exponents."""

    text: str
    factor: float
    dims: frozenset

    @property
    def name(self):
        return _NAMES.get(self.dims) or _dims_text(self.dims)


def _dims_text(dims):
    return " ".join(f"{k}^{v}" if v != 1 else k for k, v in sorted(dims)) or "dimensionless"


def _coherent(text):
    """Dimension exponents of a product of coherent SI symbols (``N*s/m``, ``m^2/N^2``), or None."""
    product = _product(text, prefixed=False)
    return None if product is None or product[0] != 1.0 else product[1]


def _symbol(sym, prefixed):
    """(factor, dims) of one symbol, or None: an SI symbol, with one SI prefix if ``prefixed``,
    or (if ``prefixed``) a unit of :data:`OTHER`."""
    if sym in SYMBOLS:
        return SYMBOLS[sym]
    if not prefixed:
        return None
    if sym in OTHER:
        return OTHER[sym]
    for prefix, scale in PREFIXES.items():
        if sym.startswith(prefix) and sym[len(prefix):] in _PREFIXABLE:
            factor, dims = SYMBOLS[sym[len(prefix):]]
            return scale * factor, dims
    return None


def _product(text, prefixed=True):
    """(factor to SI, dimension exponents) of a product of symbols with integer powers
    (``a/b*c`` is ``a * c / b``), or None when ``text`` is not one."""
    dims, sign, pos, factor = {}, 1, 0, 1.0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            return None
        power = int(m.group("pow").strip("()")) if m.group("pow") else 1
        found = _symbol(m.group("sym"), prefixed)
        if found is None:
            return None
        factor *= found[0] ** (sign * power)
        for k, v in found[1].items():
            dims[k] = dims.get(k, 0) + sign * power * v
        pos = m.end()
        if pos < len(text):
            if text[pos] not in "*/":
                return None
            sign = -1 if text[pos] == "/" else 1
            pos += 1
            if pos == len(text):
                return None
    return factor, frozenset((k, v) for k, v in dims.items() if v != 0)


@lru_cache(maxsize=256)
def parse_unit(text):
    """Parse ``text`` into a :class:`Unit`; ValueError naming the text for a unit outside the grammar."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"unknown unit {text!r}: expected a unit such as N, mN, um, mm^2, mm/s, kPa")
    text = text.strip()
    product = _product(text)
    if product is None:
        raise ValueError(f"unknown unit {text!r}: expected a product of SI units with at most one prefix each "
                         f"and integer powers, or deg, min, h, count (e.g. {', '.join(UNITS[1:12])})")
    return Unit(text, *product)


def to_si(unit):
    """Factor that converts a value in ``unit`` to SI (ValueError for an unknown unit)."""
    return parse_unit(unit).factor


def dimension(unit):
    """Name of the dimension of ``unit`` (``force``, ``length``...), for messages."""
    return parse_unit(unit).name


def same_dimension(a, b):
    return parse_unit(a).dims == parse_unit(b).dims


_POWER_NAME = re.compile(r"\^(\((?:[A-Za-z_][A-Za-z0-9_]*|\d+(?:\.\d+)?|[-+*/ ])+\)|[A-Za-z_][A-Za-z0-9_]*)")


def check_model_unit(text):
    """None if ``text`` is a coherent SI unit, where a power may also be a symbol of the model
    (``N^n_z``, ``m^2/N^m``, ``N^(1-c)``: exponents that are parameters or derived from them);
    else the reason it is refused."""
    if not isinstance(text, str) or not text.strip():
        return "expected a unit (\"1\" for a dimensionless quantity)"
    if _coherent(_POWER_NAME.sub("^1", text)) is None:
        return ("not a coherent SI unit (a model card states SI units: products of "
                f"{', '.join(s for s in SYMBOLS if s not in ('1', '-', 'g'))} with integer powers, "
                "e.g. N*s/m, m^2/N^2)")
    return None


_SI_NAMES = {"force": "N", "voltage": "V", "length": "m", "area": "m^2", "pressure": "Pa", "velocity": "m/s",
             "frequency": "Hz", "time": "s", "impedance": "N*s/m", "dimensionless quantity": "1"}


def si_unit(unit):
    """The SI unit values in ``unit`` are stored in after conversion (``mN`` -> ``N``)."""
    u = parse_unit(unit)
    if not u.dims and u.text in ("deg", "degree", "degrees", "°", "arcmin", "arcsec"):
        return "rad"
    if u.factor == 1.0 and _coherent(u.text) is not None:
        return u.text
    if u.name in _SI_NAMES:
        return _SI_NAMES[u.name]
    return "*".join(f"{_BASE[k]}^{v}" if v != 1 else _BASE[k] for k, v in sorted(u.dims)) or "1"


_BASE = {_L: "m", _M: "kg", _T: "s", _I: "A", _K: "K"}


_SUPERSCRIPT = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")
_LETTERS = dict(zip("abcdefghijklmnoprstuvwxyz", "ᵃᵇᶜᵈᵉᶠᵍʰⁱʲᵏˡᵐⁿᵒᵖʳˢᵗᵘᵛʷˣʸᶻ"))
_POWER = re.compile(r"\^(\([^)]*\)|-?\d+|[A-Za-z_][A-Za-z0-9_]*)")
_MICRO = re.compile(r"(?<![A-Za-z])u(?=(?:m|N|s|V|A|g|Pa|J|W|C|F|Hz|rad)\b)")


def _power_html(power):
    """A power of a unit as HTML: ``n_z`` -> ``n<sub>z</sub>``, ``(1-c)`` -> ``1−c``."""
    power = power.strip("()").replace("-", "\u2212")
    name, _, sub = power.partition("_")
    return f"<sup>{name}{f'<sub>{sub}</sub>' if sub else ''}</sup>"


def pretty_unit(text, html=False):
    """A unit of the grammar above as a physicist writes it: ``N*s/m`` -> ``N·s/m``,
    ``m^2`` -> ``m²``, ``um`` -> ``µm``, ``ohm`` -> ``Ω``; a power that is a symbol of the model
    (``m^2/N^m_a``) as a superscript in ``html`` (``m²/N<sup>m<sub>a</sub></sup>``), in plain
    text in superscript letters where Unicode has them (``m²/Nᵐ``), else kept as ``^m_a``;
    ``1`` (dimensionless) stays ``1``."""
    if not isinstance(text, str) or text.strip() in ("", "1", "-"):
        return text

    def power(m):
        p = m.group(1)
        if re.fullmatch(r"-?\d+", p):
            return p.translate(_SUPERSCRIPT)
        if not html and all(c in _LETTERS for c in p):  # N^m -> Nᵐ
            return "".join(_LETTERS[c] for c in p)
        if html:
            return _power_html(p)
        return m.group(0)

    out = text.strip().replace("ohm", "\u03a9")
    out = _MICRO.sub("\u00b5", out)
    if html:  # the text around the powers escaped; the powers are markup
        parts, pos = [], 0
        for m in _POWER.finditer(out):
            parts += [_escape(out[pos:m.start()]), power(m)]
            pos = m.end()
        out = "".join(parts) + _escape(out[pos:])
    else:
        out = _POWER.sub(power, out)
    return out.replace("*", "\u00b7")


def _escape(text):
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def unit_mathtext(text):
    r"""A unit as matplotlib mathtext for axis labels (``m^2/N^m_a`` -> ``$\mathrm{m}^{2}/\mathrm{N}^{m_{a}}$``):
    every power a superscript, ``*`` a centred dot; ``1`` (dimensionless) stays ``1``."""
    if not isinstance(text, str) or text.strip() in ("", "1", "-"):
        return text
    out = _MICRO.sub("\u00b5", text.strip().replace("ohm", r"\Omega"))

    def power(m):
        p = m.group(1).strip("()")
        name, _, sub = p.partition("_")
        return "^{" + name + ("_{" + sub + "}" if sub else "") + "}"

    tokens = re.split(r"(\^(?:\([^)]*\)|-?\d+|[A-Za-z_][A-Za-z0-9_]*)|[*/])", out)
    parts = []
    for t in tokens:
        if not t:
            continue
        if t.startswith("^"):
            parts.append(power(_POWER.match(t)))
        elif t == "*":
            parts.append(r"\cdot ")
        elif t == "/":
            parts.append("/")
        else:
            parts.append(r"\mathrm{" + t + "}")
    return "$" + "".join(parts) + "$"
