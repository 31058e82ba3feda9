"""Validated table readers and atomic writers.

Readers
-------
``read_table(path, schema)`` reads a CSV with every cell as text, checks it
against a :class:`TableSchema` and returns a :class:`pandas.DataFrame` with the
declared dtypes. Any problem raises :class:`TableError`, whose message names
the file, the 1-based *data* row (the header is not counted) and the column,
and states the expected form, e.g.::

    data/characteristics/disc.csv: row 3, column 'value': got 'abc';
    expected a finite number

Writers
-------
``write_text_atomic``, ``write_table_atomic`` and ``write_json_atomic`` write
to a temporary file in the destination directory and ``os.replace`` it onto
the target, so a reader never sees a partial file and an exception during
writing leaves the previous file (or no file) in place.
CSV output is deterministic: ``index=False``, float format ``'%.6g'``,
``'\\n'`` line endings, UTF-8. JSON output is sorted, indented by 2 and ends
with a newline; non-finite floats are rejected unless ``allow_nan=True``.
``save_figure_atomic`` writes a matplotlib figure (PNG/PDF/SVG by suffix) atomically and without
time stamps or version strings, so the same figure gives the same bytes.

This module imports nothing from the rest of ``lumbar``.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np
import pandas as pd

__all__ = [
    "Column",
    "UniqueKey",
    "TableSchema",
    "TableError",
    "OutputError",
    "read_table",
    "atomic_writer",
    "write_text_atomic",
    "write_table_atomic",
    "write_json_atomic",
    "save_figure_atomic",
    "CSV_FLOAT_FORMAT",
]

CSV_FLOAT_FORMAT = "%.6g"


class OutputError(OSError):
    """An output path cannot be written (a folder, below a file, read-only, disk full); the message names the
    path and what is expected. An ``OSError``, so existing handlers still catch it."""

    def __str__(self):
        return self.strerror


class TableError(ValueError):
    """A table does not match its schema.

    Attributes ``path``, ``row`` (1-based data row, or None for file/header
    level problems), ``column`` (or None) and ``expected`` (text).
    """

    def __init__(self, path, message: str, *, row: int | None = None,
                 column: str | None = None, expected: str | None = None):
        self.path = str(path)
        self.row = row
        self.column = column
        self.expected = expected
        self.message = message
        loc = [self.path]
        if row is not None:
            loc.append(f"row {row}")
        if column is not None:
            loc.append(f"column '{column}'")
        text = ": ".join([", ".join(loc), message])
        if expected:
            text += f"; expected {expected}"
        super().__init__(text)


@dataclass(frozen=True)
class Column:
    """Schema of one column.

    dtype: ``"float"``, ``"int"`` or ``"str"``.
    required: the column must be present in the header.
    nullable: empty cells allowed (become NaN for numbers, "" for text).
    finite: (numbers) reject nan/inf.
    min, max: inclusive numeric bounds (None = unbounded).
    allowed: for text columns, the set of permitted values.
    description: free text appended to the expected form.
    """

    dtype: str = "str"
    required: bool = True
    nullable: bool = False
    finite: bool = True
    min: float | None = None
    max: float | None = None
    allowed: frozenset[str] | None = None
    description: str = ""

    def __post_init__(self):
        if self.dtype not in ("float", "int", "str"):
            raise ValueError(f"Column dtype must be 'float', 'int' or 'str', got {self.dtype!r}")
        if self.allowed is not None and not isinstance(self.allowed, frozenset):
            object.__setattr__(self, "allowed", frozenset(self.allowed))

    def expected_form(self) -> str:
        if self.dtype == "str":
            if self.allowed is not None:
                form = "one of " + ", ".join(repr(a) for a in sorted(self.allowed))
            else:
                form = "text"
        else:
            form = "a finite number" if self.finite else "a number"
            if self.dtype == "int":
                form = "an integer"
            if self.min is not None and self.max is not None:
                form += f" in [{self.min:g}, {self.max:g}]"
            elif self.min is not None:
                form += f" >= {self.min:g}"
            elif self.max is not None:
                form += f" <= {self.max:g}"
        if self.nullable:
            form += " (or empty)"
        else:
            form += " (not empty)" if self.dtype == "str" else ""
        if self.description:
            form += f" ({self.description})"
        return form


@dataclass(frozen=True)
class UniqueKey:
    """Columns whose values identify a row: a second row with the same values is an error (a duplicated
    scenario would silently enter a fit twice). ``label`` names the key in the message ("scenario"),
    ``column`` is the column the error names, ``expected`` the expected form."""

    columns: tuple[str, ...]
    label: str
    column: str
    expected: str


@dataclass(frozen=True)
class TableSchema:
    """Column name -> :class:`Column`; ``allow_extra`` permits undeclared columns
    (they are kept as text); ``unique``: the row key (:class:`UniqueKey`), None = rows may repeat."""

    name: str
    columns: Mapping[str, Column] = field(default_factory=dict)
    allow_extra: bool = True
    unique: UniqueKey | None = None

    @property
    def required(self) -> list[str]:
        return [c for c, spec in self.columns.items() if spec.required]


def _parse_cell(raw: str, spec: Column, path, row: int, col: str):
    expected = spec.expected_form()
    s = raw.strip()
    if s == "":
        if spec.nullable:
            return float("nan") if spec.dtype in ("float", "int") else ""
        raise TableError(path, "empty cell", row=row, column=col, expected=expected)
    if spec.dtype == "str":
        if spec.allowed is not None and s not in spec.allowed:
            raise TableError(path, f"got {s!r}", row=row, column=col, expected=expected)
        return s
    try:
        val = float(s)
    except ValueError:
        raise TableError(path, f"got {s!r}, which is not a number", row=row, column=col,
                         expected=expected) from None
    if spec.finite and not math.isfinite(val):
        raise TableError(path, f"got non-finite value {s!r}", row=row, column=col, expected=expected)
    if spec.dtype == "int":
        if not math.isfinite(val) or val != int(val):
            raise TableError(path, f"got {s!r}, which is not an integer", row=row, column=col,
                             expected=expected)
        val = int(val)
    if spec.min is not None and val < spec.min:
        raise TableError(path, f"got {s!r}, below the minimum", row=row, column=col, expected=expected)
    if spec.max is not None and val > spec.max:
        raise TableError(path, f"got {s!r}, above the maximum", row=row, column=col, expected=expected)
    return val


def read_table(path, schema: TableSchema) -> pd.DataFrame:
    """Read a CSV file and validate it against ``schema``.

    Returns a DataFrame with the schema's columns converted (float64, int64 or
    object); the original row order is kept and the index is 0..n-1 (data row
    number = index + 1). Raises :class:`TableError`.
    """
    path = Path(path)
    if not path.is_file():
        raise TableError(path, "file not found", expected=f"a CSV file for table '{schema.name}'")
    try:
        raw = pd.read_csv(path, dtype=str, keep_default_na=False, na_filter=False,
                          skipinitialspace=False, encoding="utf-8")
    except pd.errors.EmptyDataError:
        raise TableError(path, "file is empty",
                         expected=f"a header with columns {schema.required}") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise TableError(path, f"malformed CSV ({exc})".replace("\n", " "),
                         expected="comma-separated UTF-8 text with one value per column") from None
    header = [str(c) for c in raw.columns]
    dup = sorted({c for c in header if header.count(c) > 1}
                 | {c[:-2] for c in header if c.endswith(".1") and c[:-2] in header})
    if dup:
        raise TableError(path, f"duplicate column(s) {dup}", column=dup[0],
                         expected="unique column names")
    for col in schema.required:
        if col not in header:
            raise TableError(path, "missing column", column=col,
                             expected=f"header containing {schema.required}")
    if not schema.allow_extra:
        extra = [c for c in header if c not in schema.columns]
        if extra:
            raise TableError(path, f"unexpected column(s) {extra}", column=extra[0],
                             expected=f"only the columns {list(schema.columns)}")
    out = {}
    for col in header:
        spec = schema.columns.get(col)
        values = raw[col].tolist()
        if spec is None:
            out[col] = pd.Series(values, dtype=object)
            continue
        parsed = [_parse_cell(v, spec, path, i + 1, col) for i, v in enumerate(values)]
        if spec.dtype == "float":
            out[col] = pd.Series(parsed, dtype="float64")
        elif spec.dtype == "int":
            if any(isinstance(p, float) for p in parsed):  # nullable ints with NaN
                out[col] = pd.Series(parsed, dtype="float64")
            else:
                out[col] = pd.Series(parsed, dtype="int64")
        else:
            out[col] = pd.Series(parsed, dtype=object)
    df = pd.DataFrame(out, columns=header)
    if schema.unique is not None and all(c in df for c in schema.unique.columns):
        _check_unique(df, schema.unique, path)
    return df


def _check_unique(df: pd.DataFrame, key: UniqueKey, path) -> None:
    """TableError at the first row whose key repeats an earlier row's."""
    seen: dict = {}
    for i, k in enumerate(zip(*(df[c].tolist() for c in key.columns))):
        k = tuple(v.item() if hasattr(v, "item") else v for v in k)
        if k in seen:
            raise TableError(path, f"duplicate {key.label} {k if len(k) > 1 else k[0]!r} (first at row {seen[k]})",
                             row=i + 1, column=key.column, expected=key.expected)
        seen[k] = i + 1


# ---------------------------------------------------------------- writers
def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_writer(path, mode: str = "w", encoding: str | None = "utf-8",
                  newline: str | None = "") -> Iterator[Any]:
    """Context manager yielding a file object on a temporary file next to
    ``path``; on normal exit it is flushed, fsynced and moved onto ``path``
    with ``os.replace``; on an exception it is removed and ``path`` is left
    untouched."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(errno.EISDIR, f"cannot write {path}: it is a folder; expected a file path")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        blocker = next((q for q in [path.parent, *path.parent.parents] if q.exists() and not q.is_dir()), path.parent)
        raise OutputError(errno.ENOTDIR, f"cannot write {path}: {blocker} is a file, not a folder; "
                                         "expected a path inside a folder") from None
    except PermissionError:
        raise OutputError(errno.EACCES, f"cannot write {path}: no permission to create the folder {path.parent}; "
                                        "expected a writable location") from None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        why = "is read-only" if isinstance(exc, PermissionError) or exc.errno == errno.EROFS else \
            f"cannot hold a new file ({exc.strerror})"
        raise OutputError(exc.errno or errno.EIO, f"cannot write {path}: the folder {path.parent} {why}; "
                                                  "expected a writable folder") from None
    os.fchmod(fd, 0o666 & ~_umask())   # mkstemp makes 0600; results get the usual permissions
    try:
        if "b" in mode:
            f = os.fdopen(fd, mode)
        else:
            f = os.fdopen(fd, mode, encoding=encoding, newline=newline)
        with f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            raise OutputError(errno.ENOSPC, f"cannot write {path}: no space left on the device; nothing was "
                                            "written (the previous file, if any, is unchanged)") from None
        raise


def write_text_atomic(text: str, path) -> Path:
    """Write ``text`` to ``path`` atomically (UTF-8, line endings kept as given)."""
    with atomic_writer(path) as f:
        f.write(text)
    return Path(path)


def write_table_atomic(df: pd.DataFrame, path, float_format: str = CSV_FLOAT_FORMAT) -> Path:
    """Write ``df`` as CSV atomically: index=False, ``float_format`` ('%.6g'),
    '\\n' line endings. Note '%.6g' keeps 6 significant digits: use it for
    results, not for hand-curated input data."""
    with atomic_writer(path) as f:
        df.to_csv(f, index=False, float_format=float_format, lineterminator="\n")
    return Path(path)


def write_json_atomic(obj: Any, path, *, allow_nan: bool = False) -> Path:
    """Write ``obj`` as JSON atomically (sort_keys, indent=2, trailing newline).
    Serialisation happens before the file is touched, so an unserialisable
    object raises without creating anything."""
    text = json.dumps(obj, sort_keys=True, indent=2, allow_nan=allow_nan,
                      default=_json_default) + "\n"
    return write_text_atomic(text, path)


# metadata keys that would differ between runs or versions, set to None (= left out) per format
_FIGURE_METADATA = {"png": {"Software": None},
                    "pdf": {"Creator": None, "Producer": None, "CreationDate": None, "ModDate": None},
                    "svg": {"Creator": None, "Date": None}}


def subplots(nrows: int = 1, ncols: int = 1, *, sharex=False, sharey=False, **figure_kwargs):
    """``(fig, axes)`` like ``matplotlib.pyplot.subplots`` but without pyplot: a ``matplotlib.figure.Figure``
    that no backend manages, so the library never selects or switches the user's backend, opens no window,
    works headless and needs no ``close``; saving it renders with Agg (the same bytes as an Agg pyplot figure).
    ``figure_kwargs`` go to ``Figure`` (figsize, dpi, constrained_layout, ...)."""
    from matplotlib.figure import Figure  # noqa: PLC0415  (0.5 s import; io is used by every layer, few draw)

    fig = Figure(**figure_kwargs)
    return fig, fig.subplots(nrows, ncols, sharex=sharex, sharey=sharey)


def save_figure_atomic(fig, path, **savefig_kwargs) -> Path:
    """``fig.savefig`` onto ``path`` atomically, format from the suffix, deterministic bytes (no time
    stamp, no software version; SVG ids from a fixed hash salt)."""
    path = Path(path)
    fmt = savefig_kwargs.pop("format", None) or path.suffix.lstrip(".").lower() or "png"
    meta = dict(_FIGURE_METADATA.get(fmt, {}))
    meta.update(savefig_kwargs.pop("metadata", None) or {})
    import matplotlib  # noqa: PLC0415  (0.5 s import; io is used by every layer, few draw)

    with matplotlib.rc_context({"svg.hashsalt": "lumbar"}), atomic_writer(path, "wb") as f:
        fig.savefig(f, format=fmt, metadata=meta, **savefig_kwargs)
    return path


def _json_default(o):
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.floating):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"Object of type {type(o).__name__} is not JSON serializable")
