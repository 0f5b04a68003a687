"""skinfit's closed unit grammar against pint, an independent unit library: every unit the
grammar reads has pint's factor and dimension (bit for bit where one prefix is involved, so
data converted with it give the numbers pint would), and everything outside it is refused."""

import itertools
import random

import pytest

from skinfit.io import units
from skinfit.io.units import parse_unit

pint = pytest.importorskip("pint")  # a test dependency only: skinfit itself reads units without it
UREG = pint.UnitRegistry()
POWERS = (-3, -2, -1, 1, 2, 3)
PREFIXABLE = sorted(set(units.SYMBOLS) - {"kg", "1", "-"})


def _pint(text):
    """(factor, dims) of ``text`` by pint: the independent reading."""
    q = UREG.Quantity(1.0, UREG.parse_units(text.replace("μ", "µ"))).to_base_units()
    return q.magnitude, frozenset((str(k), int(v)) for k, v in q.dimensionality.items() if v != 0)


def _term(prefix, sym, power):
    return prefix + sym + (f"^{power}" if power != 1 else "")


@pytest.mark.parametrize("prefix", list(units.PREFIXES))
def test_every_prefixed_si_symbol_at_every_power_reads_as_pint_reads_it(prefix):
    for sym, power in itertools.product(PREFIXABLE, POWERS):
        if sym == "g":
            continue  # gram: its own factor 1e-3 times the prefix's, compared to rounding below
        text = _term(prefix, sym, power)
        assert (parse_unit(text).factor, parse_unit(text).dims) == _pint(text), text


def test_products_with_one_prefixed_term_read_as_pint_reads_them():
    """Seeded random products of up to 3 terms (``mN*s/m``, ``N/mm^2``, ``s^-1*kPa``...): one
    prefixed term among factor-1 SI terms gives exactly ``prefix ** power``, as in pint."""
    rng = random.Random(20261126)
    symbols = [s for s in PREFIXABLE if s != "g"] + ["kg"]
    for _ in range(400):
        terms, prefixed = [], rng.randrange(3)
        for i in range(rng.randint(1, 3)):
            sym = rng.choice(symbols)
            prefix = rng.choice(list(units.PREFIXES)) if i == prefixed and sym != "kg" else ""
            terms.append(("" if i == 0 else rng.choice("*/")) + _term(prefix, sym, rng.choice(POWERS)))
        text = "".join(terms)
        assert (parse_unit(text).factor, parse_unit(text).dims) == _pint(text), text


@pytest.mark.parametrize("text", ["mm^2/mC^3", "mN/mm^2", "kN*mm", "deg", " deg ", "deg/s", "deg^2", "min",
                                  "mm/min", "h", "mm/h", "g", "mg", "ug*m/s^2", "kg/mm^3"])
def test_several_prefixes_and_the_other_units_agree_with_pint(text):
    factor, dims = parse_unit(text).factor, parse_unit(text).dims
    expected_factor, expected_dims = _pint(text.strip())
    assert dims == expected_dims and factor == pytest.approx(expected_factor, rel=4e-16), text


@pytest.mark.parametrize("text", ["mkg", "kkm", "mN^", "mN*", "mmm", "xN", "kmN", "mmHg", "ft", "inch", "Gy", "pc",
                                  "cd", "Mx", "N^1.5", "m^0.5", "degC", "", " "])
def test_units_outside_the_grammar_are_refused_naming_what_is_accepted(text):
    with pytest.raises(ValueError, match=r"unknown unit .*(expected a product of SI units|expected a unit such as)"):
        parse_unit(text)


def test_model_cards_refuse_prefixed_units():
    """The prefixes serve data units only: a model card states coherent SI units."""
    assert units.check_model_unit("mN") is not None and units.check_model_unit("N*s/mm") is not None
    assert units.check_model_unit("g") is not None and units.check_model_unit("min") is not None
    assert units.check_model_unit("N*s/m") is None and units.check_model_unit("N^n_z") is None
    assert units.si_unit("mN*s/m") == "N*s/m" and units.si_unit("kPa") == "Pa" and units.si_unit("mm^2") == "m^2"
    assert units.si_unit("deg") == "rad" and units.si_unit("mm/h") == "m/s"
