"""Units: parsed, dimension-checked and converted to SI at the data boundary.

A unit is a string such as ``mN``, ``um`` / ``µm``, ``mm^2``, ``mm/s``, ``kPa``, ``N*s/m``.
Coherent SI units (``N``, ``m^2/J``, ``N*s/m``: a product of SI symbols with integer powers,
factor 1) are read by a small grammar here, and so are such products with one SI prefix
(``mN``, ``mm^2``, ``mm/s``, ``kPa``: the factor computed as pint computes it, bit for bit,
which tests/test_units.py checks against pint), and so is ``deg`` alone; anything else (``deg/s``,
``min``, ``inch``, two prefixes...) by pint, imported on first need (its import and registry cost ~1 s)
through one application-level UnitRegistry.  Model cards state SI units and may also write a power
as a symbol of the model (``N^n_z``, ``N^(1-c)``): :func:`check_model_unit`.
"""

import math
import re
from dataclasses import dataclass
from functools import lru_cache

__all__ = ["Unit", "parse_unit", "to_si", "si_unit", "dimension", "check_model_unit", "same_dimension", "UNITS",
           "NONNEGATIVE"]

_L, _M, _T, _I, _K = "[length]", "[mass]", "[time]", "[current]", "[temperature]"
#: coherent SI symbols -> dimension exponents (as pint names them)
_SI = {
    "m": {_L: 1}, "s": {_T: 1}, "kg": {_M: 1}, "A": {_I: 1}, "K": {_K: 1},
    "N": {_M: 1, _L: 1, _T: -2}, "Pa": {_M: 1, _L: -1, _T: -2}, "J": {_M: 1, _L: 2, _T: -2},
    "W": {_M: 1, _L: 2, _T: -3}, "C": {_I: 1, _T: 1}, "V": {_M: 1, _L: 2, _T: -3, _I: -1},
    "F": {_M: -1, _L: -2, _T: 4, _I: 2}, "ohm": {_M: 1, _L: 2, _T: -3, _I: -2},
    "Hz": {_T: -1}, "rad": {}, "1": {}, "-": {},
}
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

#: Examples of accepted units (any unit pint reads is accepted; these are the common ones).
UNITS = ("1", "N", "mN", "uN", "V", "kV", "m", "mm", "um", "µm", "nm", "m^2", "mm^2", "Pa", "kPa", "MPa",
         "m/s", "mm/s", "Hz", "kHz", "rad", "deg", "s", "ms", "N*s/m")

#: SI prefixes the grammar reads (``u``, ``µ`` and ``μ``: micro), longest first; each checked
#: against pint on every symbol of :data:`_SI` it may precede (tests/test_units.py)
_PREFIXES = {"da": 1e1, "T": 1e12, "G": 1e9, "M": 1e6, "k": 1e3, "h": 1e2, "d": 1e-1, "c": 1e-2, "m": 1e-3,
             "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "n": 1e-9, "p": 1e-12, "f": 1e-15}
_PREFIXABLE = set(_SI) - {"kg", "1", "-"}
#: Units outside SI read without pint when they are the whole unit text, with pint's factor
#: (degree = pi / 180 radian) and dimension, checked in tests/test_units.py
_WHOLE = {"deg": (math.pi / 180, frozenset())}

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
    """Dimension exponents of a product of SI symbols (``N*s/m``, ``m^2/N^2``), or None."""
    product = _product(text)
    return None if product is None else product[1]


def _split_prefix(sym):
    """(prefix, SI symbol) of a symbol with one SI prefix (``mN`` -> ``m``, ``N``), or None."""
    for prefix in _PREFIXES:
        if sym.startswith(prefix) and sym[len(prefix):] in _PREFIXABLE:
            return prefix, sym[len(prefix):]
    return None


def _product(text, prefixed=False):
    """(factor to SI, dimension exponents) of a product of SI symbols with integer powers, or
    None; with ``prefixed``, one of the symbols may carry an SI prefix (``mN*s/m``, ``mm^2``),
    its factor ``prefix ** power`` as pint computes it (a second prefix: None, for pint, whose
    products of several factors round differently)."""
    dims, sign, pos, factor = {}, 1, 0, None
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            return None
        sym = m.group("sym")
        power = int(m.group("pow").strip("()")) if m.group("pow") else 1
        if sym not in _SI:
            split = _split_prefix(sym) if prefixed and factor is None else None
            if split is None:
                return None
            factor, sym = _PREFIXES[split[0]] ** (sign * power), split[1]
        for k, v in _SI[sym].items():
            dims[k] = dims.get(k, 0) + sign * power * v
        pos = m.end()
        if pos < len(text):
            if text[pos] not in "*/":
                return None
            sign = -1 if text[pos] == "/" else 1  # "a/b*c" = a/(b) * c, as pint reads it
            pos += 1
            if pos == len(text):
                return None
    return (1.0 if factor is None else factor), frozenset((k, v) for k, v in dims.items() if v != 0)


_REGISTRY = None


def registry():
    """The one pint UnitRegistry of the application (created on first call)."""
    global _REGISTRY
    if _REGISTRY is None:
        import pint  # here, not with the module: pint (~0.3 s) only for units outside the table above

        _REGISTRY = pint.UnitRegistry()
    return _REGISTRY


@lru_cache(maxsize=256)
def parse_unit(text):
    """Parse ``text`` into a :class:`Unit`; ValueError naming the text for an unknown unit."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"unknown unit {text!r}: expected a unit such as N, mN, um, mm^2, mm/s, kPa")
    text = text.strip()
    if text in _WHOLE:
        return Unit(text, *_WHOLE[text])
    product = _product(text, prefixed=True)
    if product is not None:
        return Unit(text, *product)
    ureg = registry()
    try:
        q = ureg.Quantity(1.0, ureg.parse_units(text.replace("μ", "µ")))
        base = q.to_base_units()
    except Exception:  # pint raises several unrelated classes (UndefinedUnitError, DefinitionSyntaxError,
        #  TokenError, AttributeError ...) for text that is not a unit
        raise ValueError(f"unknown unit {text!r}: expected a unit such as {', '.join(UNITS[1:12])}") from None
    factor = float(base.magnitude)
    if not math.isfinite(factor) or factor <= 0 or not getattr(q, "_is_multiplicative", True):
        raise ValueError(f"unit {text!r} is not a multiple of an SI unit (an offset scale such as degC?)")
    if any(v != int(v) for v in base.dimensionality.values()):
        raise ValueError(f"unit {text!r} is not a whole power of SI base units ({base.units})")
    dims = frozenset((str(k), int(v)) for k, v in base.dimensionality.items() if v != 0)
    return Unit(text, factor, dims)


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
                f"{', '.join(s for s in _SI if s not in ('1', '-'))} with integer powers, e.g. N*s/m, m^2/N^2)")
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
