"""Checks of the arguments of skinfit's public functions, made before any work starts.

Each check returns the value (numpy integers as ``int``, paths as :class:`~pathlib.Path`) or
raises a one-line :class:`~skinfit.errors.InputError` naming the function, the argument, what
was expected and what was given; a value of the wrong type raises
:class:`~skinfit.errors.InputTypeError` (an InputError that is also a TypeError).  Sizes that
would exhaust memory are refused with an estimate (:func:`check_memory`).
"""

import math
import numbers
import os
import re
import stat
import sys
from collections.abc import Mapping
from pathlib import Path

from skinfit.errors import InputError, InputTypeError

__all__ = ["file_kind", "check_count", "check_number", "check_flag", "check_seed", "as_generator", "check_path",
           "check_input_file", "check_output_file", "check_output_folder", "check_memory", "check_mapping",
           "available_memory", "size_text", "frame_type_error", "check_id"]


def shown(value, limit=60):
    """``value`` for a message: its type and a repr cut to ``limit`` characters."""
    text = " ".join(repr(value).split())  # one line: an array's repr spans several
    text = text if len(text) <= limit else text[:limit - 3] + "..."
    return text if type(value) in (bool, int, float, str, type(None)) else f"{type(value).__name__} {text}"


# numpy is not imported here (``skinfit --help`` does without it): its scalars are numbers.Integral
# and numbers.Real, and a numpy bool or Generator can exist only once numpy is imported.
def _numpy_bool(value):
    np = sys.modules.get("numpy")
    return np is not None and isinstance(value, np.bool_)


def _is_int(value):
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def check_count(value, where, name, *, lo=1, hi=None, optional=False):
    """A whole number ``lo <= value <= hi`` (a bool, a float such as 2.0, a string refused)."""
    if value is None and optional:
        return None
    bound = f">= {lo}" + (f" and <= {hi:,}" if hi is not None else "")
    if not _is_int(value):
        raise InputTypeError(where, f"expected a whole number {bound} (got {shown(value)})", field=name)
    value = int(value)
    if value < lo or (hi is not None and value > hi):
        raise InputError(where, f"expected a whole number {bound} (got {value:,})", field=name)
    return value


def check_number(value, where, name, *, lo=0.0, lo_open=True, hi=math.inf, hi_open=True):
    """A finite real number in the interval (``lo``, ``hi``) (ends closed when not ``*_open``)."""
    interval = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if not isinstance(value, numbers.Real) or isinstance(value, bool) or _numpy_bool(value):
        raise InputTypeError(where, f"expected a number in {interval} (got {shown(value)})", field=name)
    value = float(value)
    inside = ((value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
              and math.isfinite(value))
    if not inside:
        raise InputError(where, f"expected a finite number in {interval} (got {value!r})", field=name)
    return value


def check_flag(value, where, name):
    """True or False (or 1, 0); anything else, such as the string ``"no"`` (truthy), is refused."""
    if not (isinstance(value, bool) or _numpy_bool(value) or (_is_int(value) and value in (0, 1))):
        raise InputTypeError(where, f"expected True or False (got {shown(value)})", field=name)
    return bool(value)


def check_seed(rng, where, name="rng", *, recorded=False):
    """A seed numpy accepts (a whole number >= 0, below 2**63 when the result ``recorded`` it
    as a 64-bit integer), None or a numpy Generator, as given."""
    np = sys.modules.get("numpy")
    if rng is None or (np is not None and isinstance(rng, np.random.Generator)):
        return rng
    if not _is_int(rng):
        raise InputTypeError(where, f"rng must be an int seed >= 0, None or numpy.random.Generator "
                                    f"(got {shown(rng)})", field=name)
    if rng < 0 or (recorded and rng >= 2**63):
        raise InputError(where, f"expected a seed{' 0 .. 2**63-1' if recorded else ', a whole number >= 0'} "
                                f"(got {int(rng)})", field=name)
    return rng


def as_generator(rng, where="rng"):
    """SPEC 7: an int seed >= 0, None or a numpy Generator -> a numpy Generator (InputTypeError,
    a TypeError, for anything else: a float, a bool, a string)."""
    import numpy as np  # here, not with the module: see _numpy_bool (``skinfit --help`` does without numpy)

    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(check_seed(rng, where, None))


def check_path(value, where, name, what):
    """A str or os.PathLike naming ``what``, not blank (``""`` would be the current folder):
    the value as given."""
    if not isinstance(value, (str, os.PathLike)) or isinstance(os.fspath(value), bytes):
        raise InputTypeError(where, f"expected {what} (got {shown(value)})", field=name)
    if not os.fspath(value).strip():
        raise InputError(where, f"expected {what} (got {shown(value)})", field=name)
    return value


def file_kind(mode):
    """What a file of st_mode ``mode`` is, for messages: "a directory", "a FIFO", "a device"..."""
    return ("a directory" if stat.S_ISDIR(mode) else "a file" if stat.S_ISREG(mode) else "a FIFO" if stat.S_ISFIFO(mode)
            else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket or other special file")


def _kind_of(path):
    try:
        return file_kind(os.stat(path).st_mode)
    except OSError:
        return "a broken link"


def check_input_file(path, what):
    """``path`` if it is an existing regular file (a directory, FIFO or device such as
    ``/dev/zero`` is refused before it is opened: reading one would block or never end)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(path, f"no such {what}") from None
    except OSError as exc:
        raise InputError(path, f"cannot read the {what} ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(path, f"is {file_kind(st.st_mode)}: expected the {what} (skinfit reads only regular files)")
    return Path(path)


def _existing_ancestor(path):
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def check_output_file(path, where, name, what):
    """``path`` as a Path if a file may be written there: absent, or a regular file (replaced);
    never a directory, a FIFO or a device such as ``/dev/null`` (which an atomic rename would
    replace), and below folders (or places for them) only."""
    path = Path(check_path(path, where, name, f"the path of the {what} file"))
    if os.path.lexists(path):
        if not path.is_file():
            kind = _kind_of(path)
            raise InputError(path, f"is {kind}: give the path of the {what} file to write"
                             + (f", e.g. {path / 'fit.nc'}" if kind == "a directory" and what == "fit" else ""))
        return path
    top = _existing_ancestor(path.parent)
    if not top.is_dir():
        raise InputError(path, f"cannot write the {what} here: {top} is {_kind_of(top)}, not a folder")
    return path


def check_output_folder(path, where, name, purpose="expected a folder"):
    """``path`` as a Path if it is a folder or can become one (its nearest existing ancestor is
    a folder); an empty name (which would be the current folder) is refused.  The error reads
    ``PATH: is a file: PURPOSE`` (or ``is inside FILE, which is a file: PURPOSE``)."""
    path = Path(check_path(path, where, name, "the path of a folder"))
    top = _existing_ancestor(path)
    if not top.is_dir():
        what = "is" if top == Path(os.path.abspath(path)) else f"is inside {top}, which is"
        raise InputError(path, f"{what} {_kind_of(top)}: {purpose}")
    return path


def check_mapping(value, where, name, what, *, optional=True):
    """A mapping (or None when ``optional``): the value as given."""
    if value is None and optional:
        return None
    if not isinstance(value, Mapping):
        raise InputTypeError(where, f"expected {what} (got {shown(value)})", field=name)
    return value


def available_memory():
    """Bytes of memory available now (psutil if installed, else the free physical pages)."""
    try:
        import psutil  # optional: not a dependency of skinfit
    except ImportError:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return int(psutil.virtual_memory().available)


def size_text(nbytes):
    """Bytes as MiB, GiB, TiB or PiB, one decimal."""
    for unit, power in (("PiB", 50), ("TiB", 40), ("GiB", 30)):
        if nbytes >= 2**power:
            return f"{nbytes / 2**power:.1f} {unit}"
    return f"{nbytes / 2**20:.1f} MiB"


def check_memory(nbytes, where, name, what, *, fix, available=None):
    """Refuse, before the work starts, arrays of ``nbytes`` in all when they exceed the memory
    available now: the message gives the estimate, ``what`` it is made of and ``fix``."""
    available = available_memory() if available is None else available
    if nbytes > available:
        raise InputError(where, f"{what} would need {size_text(nbytes)}, more than the {size_text(available)} of "
                                f"memory available: {fix}", field=name)


def frame_type_error(value, where, name=None):
    """The InputTypeError for a table given as something other than a DataFrame, saying what to
    pass instead (a dict, a numpy array, an xarray Dataset are common)."""
    kind = type(value)
    if kind.__module__.startswith("xarray") and hasattr(value, "to_dataframe"):
        hint = "pass a pandas DataFrame: ds.to_dataframe().reset_index()"
    elif isinstance(value, Mapping):
        hint = "pass a pandas DataFrame: pd.DataFrame(d)"
    elif kind.__module__ == "numpy" and kind.__name__ == "ndarray":
        hint = "pass a pandas DataFrame with named columns: pd.DataFrame(a, columns=[...])"
    else:
        hint = "pass a pandas DataFrame"
    shown = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__.split('.')[0]}.{kind.__name__}"
    return InputTypeError(where, f"got a {shown}: {hint}", field=name)


_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+-]{0,127}")


def check_id(value, where, field="id"):
    """An id is a name (it becomes a folder or file name): letters, digits, ``_ . + -``, no path."""
    if not isinstance(value, str) or not _ID.fullmatch(value) or ".." in value:
        raise InputError(where, f"expected a name of letters, digits, '_', '.', '+', '-' (no '/', '..' or "
                         f"spaces; it names files and folders) (got {value!r})", field=field)
    return value
