"""The one error type for bad user input, and the warnings skinfit emits."""

__all__ = ["InputError", "ConvergenceWarning", "SupportWarning", "IntegrityWarning", "MissingDependency",
           "require_optional"]


class InputError(ValueError):
    """A user file or argument is invalid.

    The message names the file, the field or column, the row (1-based data row, header
    excluded) when there is one, and what was expected, e.g.
    ``datasets/x/data.csv: column 'normal_force', row 7: expected a force >= 0 (got -0.3 mN)``.
    """

    def __init__(self, where, what, *, field=None, row=None):
        self.where = str(where)
        self.field = field
        self.row = row
        self.what = what
        loc = self.where
        if field is not None:
            loc += f": {field}"
        if row is not None:
            loc += f", row {row}"
        super().__init__(f"{loc}: {what}")

    def __reduce__(self):
        # keyword-only field/row: the default reduction (cls, self.args) cannot rebuild it, so a
        # campaign worker's error would not cross the process boundary (and its message be lost)
        return (_rebuild, (type(self), self.where, self.what, self.field, self.row))


def _rebuild(cls, where, what, field, row):
    return cls(where, what, field=field, row=row)


class ConvergenceWarning(UserWarning):
    """A fit did not meet its convergence criteria."""


class SupportWarning(UserWarning):
    """A prediction was requested at a parameter point outside the model's physical support."""


class IntegrityWarning(UserWarning):
    """A saved result read without a check for damage: written before skinfit recorded checksums
    (:mod:`skinfit.integrity`)."""


class MissingDependency(ImportError):
    """An optional dependency is not installed; the message names the extra that brings it."""

    def __init__(self, package, extra):
        self.package, self.extra = package, extra
        super().__init__(f"{package} is not installed: install skinfit[{extra}] "
                         f"(pip install 'skinfit[{extra}]')")


def require_optional(module, extra):
    """Import an optional dependency, or raise MissingDependency naming the extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingDependency(module.split(".")[0], extra) from None
