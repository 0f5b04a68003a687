"""Units accepted in dataset cards, converted to SI at the data boundary."""

import math

__all__ = ["UNITS", "to_si", "dimension"]

# unit -> (factor to SI, dimension)
UNITS = {
    "1": (1.0, "dimensionless"),
    "-": (1.0, "dimensionless"),
    "N": (1.0, "force"),
    "mN": (1e-3, "force"),
    "uN": (1e-6, "force"),
    "kN": (1e3, "force"),
    "V": (1.0, "voltage"),
    "kV": (1e3, "voltage"),
    "m": (1.0, "length"),
    "cm": (1e-2, "length"),
    "mm": (1e-3, "length"),
    "um": (1e-6, "length"),
    "nm": (1e-9, "length"),
    "m^2": (1.0, "area"),
    "cm^2": (1e-4, "area"),
    "mm^2": (1e-6, "area"),
    "um^2": (1e-12, "area"),
    "Pa": (1.0, "pressure"),
    "kPa": (1e3, "pressure"),
    "MPa": (1e6, "pressure"),
    "GPa": (1e9, "pressure"),
    "m/s": (1.0, "velocity"),
    "mm/s": (1e-3, "velocity"),
    "um/s": (1e-6, "velocity"),
    "Hz": (1.0, "frequency"),
    "kHz": (1e3, "frequency"),
    "rad": (1.0, "angle"),
    "deg": (math.pi / 180.0, "angle"),
    "s": (1.0, "time"),
    "ms": (1e-3, "time"),
    "N*s/m": (1.0, "impedance"),
    "kg/s": (1.0, "impedance"),
}

# Quantities that are physically non-negative unless a column is declared `signed = true`.
NONNEGATIVE = {"force", "length", "area", "pressure", "frequency", "voltage", "impedance", "time"}


def to_si(unit):
    """Factor that converts a value in ``unit`` to SI. Raises KeyError for unknown units."""
    return UNITS[unit][0]


def dimension(unit):
    return UNITS[unit][1]
