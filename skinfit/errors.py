"""The one error type for bad user input, and the warnings skinfit emits.

Every exception class skinfit defines must cross a process boundary intact (a campaign's or the
demo's worker raises it, the parent unpickles it): one whose ``__init__`` takes other arguments
than it passes to ``Exception.__init__`` inherits :class:`Portable`, and
:func:`portable` replaces, in a worker, an exception that would still not survive the crossing.
"""

import pickle

__all__ = ["InputError", "InputTypeError", "ForwardError", "ConvergenceWarning", "SupportWarning", "IntegrityWarning",
           "MissingDependency", "require_optional", "Portable", "WorkerError", "portable", "error_line"]


class Portable:
    """Mixin of an exception class whose instances pickle whatever its ``__init__`` takes.

    The default reduction calls ``cls(*self.args)``: an ``__init__`` with other or keyword-only
    arguments (``MAPError(message, result)``) then fails in the process that unpickles it, where
    a ``concurrent.futures`` pool takes the failure for a dead worker (``BrokenProcessPool`` for
    every fit).  This one rebuilds the instance without calling ``__init__``: its ``args`` and
    its attributes (``__dict__``) as they were.  List it before the builtin base class.
    """

    def __reduce__(self):
        return _restore, (type(self), self.args, dict(self.__dict__))


def _restore(cls, args, state):
    exc = cls.__new__(cls, *args)
    exc.args = args
    exc.__dict__.update(state)
    return exc


class InputError(Portable, ValueError):
    """A user file or argument is invalid.

    The message names the file, the field or column, the row when there is one (1-based data
    row, header excluded; in a lab's file read through a card's ``[read]`` options, the row as
    the user sees the file: the line of a text file with header and comment lines counted, the
    row of a sheet, the element of a MATLAB or HDF5 vector), and what was expected, e.g.
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


class InputTypeError(InputError, TypeError):
    """An argument of the wrong type (a dict or an array where a path or a Fit is expected, a
    bool or a float where a count is): an InputError (one line, naming the argument) that is
    also the TypeError Python's convention expects."""


class ForwardError(InputError):
    """A model's forward function broke its contract (skinfit.io.registry.ROLES): it raised,
    returned something other than ``(dict of (k, n) real arrays, bool (k, n) ok)``, returned
    NaN or inf at a point it marks valid, or is not vectorised over parameter draws.  ``where``
    is the model card, ``field`` its ``forward`` key."""


class ConvergenceWarning(UserWarning):
    """A fit did not meet its convergence criteria."""


class SupportWarning(UserWarning):
    """A prediction was requested at a parameter point outside the model's physical support."""


class IntegrityWarning(UserWarning):
    """A saved result read without a check for damage: written before skinfit recorded checksums
    (:mod:`skinfit.io.integrity`)."""


class MissingDependency(Portable, ImportError):
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


class WorkerError(Portable, RuntimeError):
    """An exception raised in a worker process that could not be sent back as itself (it, or
    an attribute of it, does not pickle): its class name (``kind``) and message."""

    def __init__(self, kind, message):
        super().__init__(message)
        self.kind = kind


def portable(exc):
    """``exc`` when it survives pickling and unpickling (as it must to leave a worker), else a
    :class:`WorkerError` holding its class name and message."""
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # whatever pickling raises (TypeError, AttributeError, PicklingError, ...)
        return WorkerError(type(exc).__name__, str(exc))
    return exc


def error_line(exc):
    """``"Class: message"`` on one line, for an index or a log (a :class:`WorkerError` named by
    the class of the exception it stands for)."""
    kind = exc.kind if isinstance(exc, WorkerError) else type(exc).__name__
    return f"{kind}: " + " ".join(str(exc).split())
