"""Units read without pint (coherent SI products, and such products with one SI prefix) agree
with pint exactly: same factor to the last bit (data converted with it give the same numbers,
so fits with the same seed the same draws) and the same dimension."""

import itertools
import random

import pytest

from skinfit.io import units
from skinfit.io.units import parse_unit

POWERS = (-3, -2, -1, 1, 2, 3)


def _pint(text):
    """(factor, dims) of ``text`` by pint: the independent reading."""
    ureg = units.registry()
    q = ureg.Quantity(1.0, ureg.parse_units(text.replace("μ", "µ"))).to_base_units()
    return q.magnitude, frozenset((str(k), int(v)) for k, v in q.dimensionality.items() if v != 0)


def _term(prefix, sym, power):
    return prefix + sym + (f"^{power}" if power != 1 else "")


@pytest.mark.parametrize("prefix", list(units._PREFIXES))
def test_every_prefixed_si_symbol_at_every_power_reads_as_pint_reads_it(prefix):
    for sym, power in itertools.product(sorted(units._PREFIXABLE), POWERS):
        text = _term(prefix, sym, power)
        fast = units._product(text, prefixed=True)
        assert fast is not None, text  # read by the grammar, not by pint
        assert fast == _pint(text), text


def test_products_with_one_prefixed_term_read_as_pint_reads_them():
    """Seeded random products of up to 3 terms (``mN*s/m``, ``N/mm^2``, ``s^-1*kPa``...): pint
    multiplies each term's factor ** power in turn, so one prefixed term among factor-1 SI
    terms gives exactly ``prefix ** power``."""
    rng = random.Random(20261126)
    symbols = sorted(units._PREFIXABLE) + ["kg"]
    for _ in range(400):
        terms, prefixed = [], rng.randrange(3)
        for i in range(rng.randint(1, 3)):
            sym = rng.choice(symbols)
            prefix = rng.choice(list(units._PREFIXES)) if i == prefixed and sym != "kg" else ""
            terms.append(("" if i == 0 else rng.choice("*/")) + _term(prefix, sym, rng.choice(POWERS)))
        text = "".join(terms)
        assert units._product(text, prefixed=True) == _pint(text), text
        assert (parse_unit(text).factor, parse_unit(text).dims) == _pint(text), text


@pytest.mark.parametrize("text", ["deg", " deg "])
def test_degrees_alone_are_read_without_pint_as_pint_reads_them(text, monkeypatch):
    expected = _pint(text.strip())  # pi / 180, dimensionless
    parse_unit.cache_clear()

    def no_pint():
        raise AssertionError("pint's registry used")

    monkeypatch.setattr(units, "registry", no_pint)
    try:
        assert (parse_unit(text).factor, parse_unit(text).dims) == expected
    finally:
        parse_unit.cache_clear()  # nothing read without pint here is kept for the other tests


@pytest.mark.parametrize("text", ["mm^2/mC^3", "mN/mm^2", "kN*mm", "deg/s", "deg^2", "min", "mmHg", "mg", "ft", "Gy",
                                  "pc", "cd"])
def test_two_prefixes_and_other_units_are_left_to_pint(text):
    """pint rounds a product of several prefixed factors in its own way (mm^2/mC^3: 1000 there,
    999.9999999999999 as 1e-3**2 * 1e-3**-3); names that only look like a prefixed symbol
    (min, mmHg, pc, cd) are pint's units."""
    assert units._product(text, prefixed=True) is None
    assert (parse_unit(text).factor, parse_unit(text).dims) == _pint(text)


@pytest.mark.parametrize("text", ["mkg", "kkm", "mN^", "mN*", "mmm", "xN", "kmN"])
def test_what_neither_grammar_nor_pint_reads_is_an_unknown_unit(text):
    assert units._product(text, prefixed=True) is None
    with pytest.raises(ValueError, match="unknown unit"):
        parse_unit(text)


def test_model_cards_still_refuse_prefixed_units():
    """The prefix grammar serves data units only: a model card states coherent SI units."""
    assert units.check_model_unit("mN") is not None and units.check_model_unit("N*s/mm") is not None
    assert units.check_model_unit("N*s/m") is None
    assert units.si_unit("mN*s/m") == "N*s/m" and units.si_unit("kPa") == "Pa" and units.si_unit("mm^2") == "m^2"


@pytest.mark.parametrize("text", ["N^1.5", "Mx", "m^0.5"])
def test_a_fractional_power_of_a_dimension_is_refused(text):
    """pint reads these (maxwell is cm^1.5 g^0.5 / s); the dimension exponents a Unit holds are
    integers, and truncating 1.5 to 1 would let a wrong unit pass the dimension check."""
    with pytest.raises(ValueError, match="not a whole power"):
        parse_unit(text)
