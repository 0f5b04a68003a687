"""Lab tables as their software exports them, read into one shape: a :class:`Table` of text
cells with each data row's number as the user sees the file.

CSV is read with Python's :mod:`csv` module: its dialect (separator ``,`` ``;`` or tab, the
decimal mark, full-line comments starting with ``#`` or ``%``, the encoding utf-8, utf-8-sig,
latin-1 or cp1252) is detected from the file or given, and what was detected is reported.
Excel ``.xlsx`` is read with openpyxl (the optional extra ``excel``); MATLAB ``.mat`` and HDF5
files with scipy.io and h5py (:mod:`skinfit.io.vectors`).  The format is told by the file's
first bytes, so a binary file is never read as text.  Nothing ambiguous is guessed: two
separators that both split the file evenly, numbers written with both decimal marks, several
sheets with data, numbers whose comma may be a decimal or a thousands mark (``1,234`` with no
number in the file that settles it) are errors naming the file, column and row, with the option
that settles it.

Row numbers are those the user sees: the line of a text file (header and comment lines
counted), the row of a sheet, the 1-based element of a MATLAB or HDF5 vector.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
import pandas as pd

from skinfit.errors import InputError, require_optional
from skinfit.io.units import parse_unit
from skinfit.io.vectors import read_hdf5, read_mat

__all__ = ["Table", "READ_KEYS", "FORMATS", "SEPARATORS", "ENCODINGS", "read_lab_table", "detect_format",
           "check_read", "format_read", "quote_headers", "split_unit",
           "split_csv", "split_header"]

#: The reading options a dataset card's ``[read]`` table may hold.
READ_KEYS = ("format", "sep", "decimal", "comment", "encoding", "sheet", "variable")
FORMATS = ("csv", "xlsx", "mat", "hdf5")
SEPARATORS = {",": ",", ";": ";", "\t": "\t", "tab": "\t", "\\t": "\t"}
ENCODINGS = ("utf-8", "utf-8-sig", "latin-1", "cp1252")
COMMENTS = "#%"

_HDF5 = b"\x89HDF\r\n\x1a\n"


@dataclass(frozen=True)
class Table:
    """A lab table as read: ``headers`` as the file has them, ``cells`` (one object column of
    text per header, ``""`` for an empty cell), ``rows`` ((n,) int: each data row's number as the
    user sees the file), ``units`` (header -> unit stated by the file beside its header text, an
    HDF5 ``unit`` attribute), ``read`` (every option as used: given or detected), ``detected``
    (the options found from the file), ``header_row`` (the header's row; None for named vectors)
    and ``skipped`` (what of the file is not a column, with why)."""

    where: str
    headers: tuple
    cells: pd.DataFrame
    rows: np.ndarray
    read: MappingProxyType
    detected: tuple = ()
    units: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    header_row: int | None = None
    skipped: tuple = ()


def quote_headers(headers):
    """Header cells as they may appear in a message: names only (never a line of some other file)."""
    ok = [h for h in headers if re.fullmatch(r"[\w .,+\-/*^()\[\]%µμ°]{1,48}", h)]
    return [repr(h) for h in ok] if len(ok) == len(headers) else [f"{len(headers)} header fields"]


def detect_format(raw, where):
    """``csv``, ``xlsx``, ``mat`` or ``hdf5`` from the first bytes of a file (its name is not
    trusted: a ``.csv`` saved by Excel as a workbook is a workbook)."""
    if raw.startswith(b"PK\x03\x04"):
        return "xlsx"
    if raw.startswith(b"\xd0\xcf\x11\xe0"):
        raise InputError(where, "a legacy Excel .xls workbook: save it as .xlsx (or CSV) and read that")
    if raw.startswith(b"MATLAB"):
        return "mat"
    if raw.startswith(_HDF5):
        return "hdf5"
    if b"\0" in raw[:4096]:
        raise InputError(where, "a binary file that is none of the formats skinfit reads (CSV, Excel .xlsx, "
                                "MATLAB .mat v5 or v7.3, HDF5 .h5)")
    return "csv"


def check_read(read, where, prefix="read."):
    """The ``[read]`` options of a card (or given on the command line) checked: known keys,
    values skinfit understands; returns a plain dict of the options given."""
    if not isinstance(read, Mapping):
        raise InputError(where, "expected a table of reading options", field=prefix.rstrip("."))
    out = {}
    for key, value in read.items():
        if key not in READ_KEYS:
            raise InputError(where, f"unknown reading option (expected {', '.join(READ_KEYS)})", field=prefix + key)
        if not isinstance(value, str):
            raise InputError(where, f"expected a string (got {value!r})", field=prefix + key)
        if key == "format" and value not in FORMATS:
            raise InputError(where, f"expected one of {', '.join(FORMATS)} (got {value!r})", field=prefix + key)
        if key == "sep":
            if value not in SEPARATORS:
                raise InputError(where, f"expected ',', ';' or tab (got {value!r})", field=prefix + key)
            value = SEPARATORS[value]
        if key == "decimal" and value not in (".", ","):
            raise InputError(where, f"expected '.' or ',' (got {value!r})", field=prefix + key)
        if key == "comment" and not set(value) <= set(COMMENTS):
            raise InputError(where, f"expected '#', '%', both or '' (got {value!r})", field=prefix + key)
        if key == "encoding" and value.lower() not in ENCODINGS:
            raise InputError(where, f"expected one of {', '.join(ENCODINGS)} (got {value!r})", field=prefix + key)
        out[key] = value.lower() if key == "encoding" else value
    return out


def format_read(table):
    """One line saying how a table was read, marking the options detected from the file."""
    shown = {"\t": "tab"}
    parts = []
    for key in READ_KEYS:
        if key in table.read and key != "format":
            value = table.read[key]
            text = repr(shown.get(value, value)) if key != "comment" or value else "none"
            parts.append(f"{key} {text}{' (detected)' if key in table.detected else ''}")
    return f"{table.read['format']}: " + ", ".join(parts)


def read_lab_table(raw, where, read=None):
    """A :class:`Table` from the bytes of a lab file, with the options ``read`` (see
    :func:`check_read`) given and the others detected."""
    read = dict(read or {})
    fmt = detect_format(raw, where)
    if read.get("format", fmt) != fmt:
        raise InputError(where, f"is a {fmt} file by its content, the reading options say {read['format']!r}",
                         field="format")
    for key in ("sheet",) if fmt != "xlsx" else ():
        if key in read:
            raise InputError(where, f"--{key}/{key} applies to an Excel file, this is a {fmt} file", field=key)
    if fmt != "csv":
        for key in ("sep", "decimal", "encoding"):
            if key in read:
                raise InputError(where, f"--{key}/{key} applies to a CSV file, this is a {fmt} file", field=key)
    if fmt == "csv":
        if "variable" in read:
            raise InputError(where, "--variable/variable applies to a MATLAB or HDF5 file, this is a CSV file",
                             field="variable")
        return _read_csv(raw, where, read)
    if fmt == "xlsx":
        return _read_xlsx(raw, where, read)
    if "comment" in read:
        raise InputError(where, f"--comment/comment applies to a CSV or Excel file, this is a {fmt} file",
                         field="comment")
    reader = read_mat if fmt == "mat" else read_hdf5
    variable, columns, units, skipped = reader(raw, where, read.get("variable"))
    n = len(next(iter(columns.values())))
    cells = pd.DataFrame({h: pd.Series(v, dtype=object) for h, v in columns.items()})
    detected = () if "variable" in read else ("variable",)
    return Table(where, tuple(columns), cells, np.arange(1, n + 1), MappingProxyType({"format": fmt,
                 "variable": variable}), detected, MappingProxyType(units), None, tuple(skipped))


def _decode(raw, where, encoding):
    if encoding is not None:
        try:
            return raw.decode(encoding), encoding
        except UnicodeDecodeError as exc:
            raise InputError(where, f"not {encoding} text (byte {exc.start}): give the file's encoding "
                             f"({', '.join(ENCODINGS)})", field="encoding") from None
    if raw.startswith(b"\xef\xbb\xbf"):
        return raw[3:].decode("utf-8", errors="strict"), "utf-8-sig"
    try:
        return raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        pass
    if any(0x80 <= b <= 0x9F for b in raw):  # printable in cp1252 (Windows), control codes in latin-1
        try:
            return raw.decode("cp1252"), "cp1252"
        except UnicodeDecodeError:
            pass
    return raw.decode("latin-1"), "latin-1"


def _lines(text, comment):
    """(line number, line) of the lines that are neither blank nor comments, and the comment
    characters seen at the start of a line."""
    kept, seen = [], set()
    for no, line in enumerate(text.splitlines(keepends=True), start=1):
        first = line.lstrip()[:1]
        if not first:
            continue
        if first in (COMMENTS if comment is None else comment):
            seen.add(first)
            continue
        kept.append((no, line))
    return kept, "".join(c for c in COMMENTS if c in seen)


def _records(lines, sep, where, limit=None):
    """(line number, fields) of each CSV record, its line the first it spans."""
    consumed = []

    def feed():
        for no, line in lines:
            consumed.append(no)
            yield line

    reader = csv.reader(feed(), delimiter=sep, skipinitialspace=True)
    out = []
    while limit is None or len(out) < limit:
        k = len(consumed)
        try:
            fields = next(reader)
        except StopIteration:
            break
        except csv.Error as exc:
            raise InputError(where, f"not a readable CSV file ({exc})", row=consumed[-1] if consumed else None) \
                from None
        out.append((consumed[k], [f.strip() for f in fields]))
    return out


def _detect_sep(lines, where):
    """The one separator that splits the header into >= 2 fields and every sampled row into as
    many; with none such, the one giving the header most fields (rows are then checked)."""
    even, widest = [], (0, ",")
    for sep in (",", ";", "\t"):
        records = _records(lines, sep, where, limit=200)
        if not records:
            return ","
        n = len(records[0][1])
        widest = max(widest, (n, sep), key=lambda t: t[0])
        if n >= 2 and all(len(f) == n for _, f in records):
            even.append((sep, n))
    if len(even) > 1:
        shown = " or ".join(f"{'tab' if s == chr(9) else repr(s)} ({n} columns)" for s, n in even)
        raise InputError(where, f"the separator could be {shown}: give it (--sep, or sep in [read])",
                         field="sep", row=lines[0][0])
    if not even and widest[0] == 1:  # the first line is one field whatever the separator: a title?
        for sep in (",", ";", "\t"):
            below = [len(f) for _, f in _records(lines[1:], sep, where, limit=200)]
            if below and min(below) == max(below) >= 2:
                raise InputError(where, f"the first line has one field and the lines below {below[0]} (separated by "
                                 f"{'tab' if sep == chr(9) else repr(sep)}): a title line above the header? start it "
                                 "with '#' or delete it", field="header", row=lines[0][0])
    return even[0][0] if even else widest[1]


def _read_csv(raw, where, read):
    text, encoding = _decode(raw, where, read.get("encoding"))
    detected = [k for k in ("encoding",) if "encoding" not in read]
    lines, seen = _lines(text, read.get("comment"))
    comment = read.get("comment", seen)
    if "comment" not in read:
        detected.append("comment")
    if not lines:
        raise InputError(where, "the file is empty (expected a header row and data rows)")
    sep = read.get("sep") or _detect_sep(lines, where)
    if "sep" not in read:
        detected.append("sep")
    records = _records(lines, sep, where)
    header_row, header = records[0]
    width = len(header)
    while width > 1 and not header[width - 1] and all(len(f) == width and not f[-1] for _, f in records[1:]):
        width -= 1  # a trailing separator on every line (spreadsheet exports): an empty last column dropped
    header = header[:width]
    body = [(no, f[:width] if len(f) > width and not any(f[width:]) else f) for no, f in records[1:]]
    _check_header(header, where, header_row)
    for no, fields in body:
        if len(fields) != width:
            extra = (f"; field {width + 1} on is beyond the header (a decimal comma in a file separated by "
                     f"{sep!r}? give the separator and decimal mark)" if len(fields) > width else "")
            if width == 1 and len(fields) > 1:
                extra = f" (line {header_row}, read as the header, has one field: a title line? mark it a comment)"
            raise InputError(where, f"{len(fields)} fields where the header has {width}{extra}", row=no,
                             field=f"column {width + 1}" if len(fields) > width else f"column {len(fields) + 1}")
    if not body:
        raise InputError(where, "no data rows (expected at least one row below the header)", row=header_row)
    columns = list(zip(*(f for _, f in body)))
    rows = np.array([no for no, _ in body])
    decimal = read.get("decimal") or _detect_decimal(header, columns, rows, where)
    if "decimal" not in read:
        detected.append("decimal")
    if decimal == ",":
        columns = [_comma_to_dot(h, col, rows, where) for h, col in zip(header, columns)]
    cells = pd.DataFrame({h: pd.Series(col, dtype=object) for h, col in zip(header, columns)})
    options = {"format": "csv", "sep": sep, "decimal": decimal, "comment": comment, "encoding": encoding}
    return Table(where, tuple(header), cells, rows, MappingProxyType(options), tuple(detected),
                 header_row=header_row)


def _check_header(header, where, row):
    for j, h in enumerate(header):
        if not h:
            raise InputError(where, f"header field {j + 1} is empty (every column needs a name)", field="header",
                             row=row)
        if header.index(h) != j:
            raise InputError(where, f"the header names this column twice (fields {header.index(h) + 1} and "
                             f"{j + 1}): which one is meant is ambiguous", field=f"column {h!r}", row=row)


def _marks(column):
    """Masks of a column's cells that are finite numbers written with a decimal point (``1.5``),
    and with a decimal comma (``-0,25``, ``1,5e-3``); vectorised (numpy.strings, pandas)."""
    arr = np.asarray(column, dtype=str)
    dots, commas = np.strings.count(arr, "."), np.strings.count(arr, ",")
    point, comma = (dots == 1) & (commas == 0), (commas == 1) & (dots == 0)
    swapped = np.where(comma, np.strings.replace(arr, ",", "."), arr)
    numeric = np.isfinite(pd.to_numeric(pd.Series(swapped, dtype=object), errors="coerce").to_numpy(dtype=float))
    return point & numeric, comma & numeric


def _detect_decimal(header, columns, rows, where):
    """``,`` when numbers are written only with a decimal comma, else ``.``; both in one file is
    ambiguous (``1.500`` may be a thousands mark): an error at the first cell breaking the mark
    of the cells above it, naming a cell of the other mark too."""
    first = {}
    for h, col in zip(header, columns):
        for mark, mask in zip(".,", _marks(col)):
            if mask.any() and (mark not in first or int(np.argmax(mask)) < first[mark][0]):
                first[mark] = (int(np.argmax(mask)), h, col[int(np.argmax(mask))])
    if len(first) == 2:
        (i1, h1, c1), (i2, h2, c2) = sorted(first.values(), key=lambda t: t[0])
        raise InputError(where, f"{c2!r} is written with the other decimal mark than {c1!r} (column {h1!r}, row "
                         f"{rows[i1]}): give the decimal mark (--decimal, or decimal in [read])",
                         field=f"column {h2!r}", row=int(rows[i2]))
    if "," in first:
        _check_not_thousands(header, columns, rows, where)
    return "," if "," in first else "."


# A number a thousands separator may have written: 1-3 digits, not starting with 0, then ",ddd".
_THOUSANDS = re.compile(r"[+-]?[1-9][0-9]{0,2},[0-9]{3}")


def _check_not_thousands(header, columns, rows, where):
    """InputError when every number written with a comma would also read with ``,`` as a
    thousands separator (``1,234``: 1.234 or 1234?) and none with a decimal point settles it: the
    first such cell named.  One cell not of that form (``0,5``, ``12,25``, ``1,5e-3``) settles it."""
    cells = []
    for h, col in zip(header, columns):
        comma = _marks(col)[1]
        for i in np.flatnonzero(comma):
            if not _THOUSANDS.fullmatch(col[i]):
                return
            cells.append((int(i), h, col[i]))
    i, h, text = min(cells, key=lambda t: t[0])
    whole = text.replace(",", "")
    raise InputError(where, f"{text!r} reads as {text.replace(',', '.')} with a decimal comma or as {whole} with a "
                     "thousands separator, and no number in the file settles which (every comma has three digits "
                     "after it, no number has a decimal point): give the decimal mark (--decimal ',' or decimal = "
                     "\",\" in [read]; thousands separators are not read: export without them)",
                     field=f"column {h!r}", row=int(rows[i]))


def _comma_to_dot(header, column, rows, where):
    point, comma = _marks(column)
    if point.any():
        i = int(np.argmax(point))
        raise InputError(where, f"{column[i]!r} has a decimal point in a file read with a decimal comma (a thousands "
                         "mark?): write the number as the others are", field=f"column {header!r}", row=int(rows[i]))
    return [c.replace(",", ".") if m else c for c, m in zip(column, comma)]


def _cell_text(value):
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, (int, float)):
        return repr(float(value))
    if hasattr(value, "isoformat"):
        return value.isoformat()
    return str(value).strip()


def _read_xlsx(raw, where, read):
    # openpyxl is an optional extra (skinfit[excel]): imported only when a workbook is read
    openpyxl = require_optional("openpyxl", "excel")
    try:
        book = openpyxl.load_workbook(io.BytesIO(raw), data_only=True)
    except Exception as exc:  # openpyxl raises many kinds (zipfile.BadZipFile, KeyError, InvalidFileException)
        raise InputError(where, f"not a readable Excel workbook ({type(exc).__name__}: {exc})") from None
    names = book.sheetnames
    sheet = read.get("sheet")
    if sheet is not None and sheet not in names:
        raise InputError(where, f"no sheet {sheet!r} (the workbook has {', '.join(map(repr, names))})",
                         field="sheet")
    grids = {}
    for name in [sheet] if sheet else names:
        ws = book[name]
        grid = [[_cell_text(v) for v in row] for row in ws.iter_rows(min_row=1, min_col=1, max_row=ws.max_row,
                                                                      max_col=ws.max_column, values_only=True)]
        if any(any(row) for row in grid):
            grids[name] = grid
    if not grids:
        raise InputError(where, f"sheet {sheet!r} is empty" if sheet else "every sheet is empty",
                         field="sheet" if sheet else None)
    if len(grids) > 1:
        raise InputError(where, f"{len(grids)} sheets hold data ({', '.join(map(repr, grids))}): name one "
                                "(--sheet, or sheet in [read])", field="sheet")
    sheet, grid = next(iter(grids.items()))
    comment = read.get("comment")
    kept = [(no, row) for no, row in enumerate(grid, start=1) if any(row)]
    seen = {row[0][:1] for _, row in kept if row[0][:1] in COMMENTS}
    comment = "".join(c for c in COMMENTS if c in seen) if comment is None else comment
    kept = [(no, row) for no, row in kept if not (comment and row[0][:1] and row[0][:1] in comment)]
    header_row, header = kept[0]
    width = max(j + 1 for j, h in enumerate(header) if h)
    if any(len(row) > width and any(row[width:]) for _, row in kept):
        raise InputError(where, f"values right of the last header cell (column {width + 1} of sheet {sheet!r}; "
                                "every column needs a name)", field="header", row=header_row)
    header = header[:width]
    _check_header(header, where, header_row)
    body = kept[1:]
    if not body:
        raise InputError(where, "no data rows (expected at least one row below the header)", row=header_row)
    cells = pd.DataFrame({h: pd.Series([row[j] for _, row in body], dtype=object) for j, h in enumerate(header)})
    detected = tuple(k for k in ("sheet", "comment") if k not in read)
    return Table(where, tuple(header), cells, np.array([no for no, _ in body]),
                 MappingProxyType({"format": "xlsx", "sheet": sheet, "comment": comment}), detected,
                 header_row=header_row)


_HEADER = re.compile(r"^(?P<name>[^\[\]]*?)\s*\[(?P<unit>[^\[\]]*)\]\s*$")


def split_header(header):
    """``"normal_force [mN]"`` -> ``("normal_force", "mN")``; ``"subject"`` -> ``("subject", None)``."""
    m = _HEADER.match(header)
    return (m.group("name").strip(), m.group("unit").strip()) if m else (header.strip(), None)


_UNIT_PART = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\[\]()]*)[\])]\s*$")


def split_unit(header):
    """``"Normal force (mN)"`` or ``"normal_force [mN]"`` -> ``("Normal force", "mN")``: the name
    and the unit a header states, the unit only when it is one skinfit reads (``"Force (left)"``
    -> ``("Force (left)", None)``)."""
    m = _UNIT_PART.match(header.strip())
    if m and m.group("name"):
        try:
            parse_unit(m.group("unit").strip())
        except ValueError:
            return header.strip(), None
        return m.group("name").strip(), m.group("unit").strip()
    return header.strip(), None


def split_csv(raw, where):
    """Header and rows of a plain CSV (UTF-8, comma-separated, no comments: the shipped datasets
    and files written with ``name [unit]`` headers); every row must have exactly the header's
    fields, numbered as data rows (header excluded)."""
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(where, f"not UTF-8 text (invalid byte at offset {exc.start}): write its card with skinfit "
                         "dataset init FILE --model MODEL, which reads other encodings") from None
    if "\0" in text:
        raise InputError(where, "holds NUL bytes: not a text (CSV) file")
    try:
        rows = [r for r in csv.reader(io.StringIO(text, newline=""), skipinitialspace=True) if r]
    except csv.Error as exc:
        raise InputError(where, f"not a readable CSV file ({exc})") from None
    if not rows:
        raise InputError(where, "the file is empty (expected a header row and data rows)")
    header = [h.strip() for h in rows[0]]
    for j, h in enumerate(header):
        if not h:
            raise InputError(where, f"header field {j + 1} is empty (every column needs a name)", field="header")
        if header.index(h) != j:
            raise InputError(where, f"the header names this column twice (fields {header.index(h) + 1} and "
                             f"{j + 1}): which one is meant is ambiguous", field=f"column {h!r}")
    names = [split_header(h)[0] for h in header]
    for j, h in enumerate(names):
        if names.index(h) != j:
            raise InputError(where, f"two header fields name column {h!r} ({header[names.index(h)]!r} and "
                             f"{header[j]!r}): which one is meant is ambiguous", field=f"column {h!r}")
    n = len(header)
    for i, r in enumerate(rows[1:]):
        if len(r) != n:
            extra = (f"; field {n + 1} on is beyond the header (a decimal comma in a comma-separated file? "
                     "write 0.5, not 0,5, or quote the value)" if len(r) > n else "")
            raise InputError(where, f"{len(r)} fields where the header has {n}{extra}", row=i + 1,
                             field=f"column {n + 1}" if len(r) > n else f"column {len(r) + 1}")
    return header, rows[1:]
