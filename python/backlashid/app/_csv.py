"""Reading signals from a delimited text file in bounded memory.

The file is read twice, a line at a time: once to learn its encoding (UTF-8, else Latin-1 as
Windows tools write it; a NUL byte means no text file), then to parse it, keeping only the
selected columns as floats (8 bytes per value; a whole file held as rows of strings took about
12 times its size). The header is the first row if any of its cells is not a number, a units
row under it ("V", "mm") is skipped, a decimal comma is read where ";" or tabs separate the
columns, and every message names the line to look at.
"""

from __future__ import annotations

import codecs
import csv
import re
from array import array
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError

__all__ = ["read_csv", "split_selector"]

_CHUNK = 1 << 20  # bytes read at a time while checking the encoding
_SELECTOR = re.compile(r"^(?P<name>.*?)\[(?P<index>-?\d+)\]$")


def split_selector(text: str) -> tuple[str, int | None]:
    """``NAME[K]`` -> (NAME, K); ``NAME`` or a position ``K`` -> (text, None).

    Examples
    --------
    >>> split_selector("y[2]"), split_selector("load")
    (('y', 2), ('load', None))
    """
    m = _SELECTOR.match(text.strip())
    if m:
        return m.group("name"), int(m.group("index"))
    return text.strip(), None


def read_csv(path: Path, names: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    """The columns ``names`` (``NAME``, ``NAME[K]`` or a position ``K``) of a delimited text
    file, as float64 arrays."""
    encoding = _encoding(path)
    with path.open(encoding=encoding, newline="") as fh:
        first = next((line for line in fh if line.strip()), None)
    if first is None:
        raise DataError(f"{path}: the file is empty")
    delimiter = next((d for d in ",;\t" if d in first), None)
    rows = _rows(path, encoding, delimiter)
    header, first_line, pending = _header(path, rows)
    columns = [_Column(path, header, name) for name in names]
    width = count = 0
    for number, row in pending:
        width, count = max(width, len(row)), count + 1
        for column in columns:
            column.take(row, number)
    if count == 0:
        raise DataError(f"{path}: a header but no data rows")
    return {column.selector: column.result(width) for column in columns}


def _encoding(path: Path) -> str:
    """UTF-8 (a byte-order mark dropped) if the whole file decodes as it, else Latin-1; a file
    that is neither UTF-8 nor free of NUL bytes is refused with the first one's position (no
    text encoding writes one into a CSV; inside UTF-8 text a NUL is a bad cell, named by its line)."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    utf8, offset, lines = True, 0, 0
    nul: tuple[int, int] | None = None  # (byte, line) of the first NUL
    with path.open("rb") as fh:
        while chunk := fh.read(_CHUNK):
            at = chunk.find(b"\0")
            if at >= 0 and nul is None:
                nul = (offset + at, lines + chunk.count(b"\n", 0, at) + 1)
            if utf8:
                try:
                    decoder.decode(chunk)
                except UnicodeDecodeError:
                    utf8 = False  # Windows tools write Latin-1 / cp1252 (a "µm" in a header); digits read the same
            if not utf8 and nul is not None:
                break
            offset += len(chunk)
            lines += chunk.count(b"\n")
    if utf8:
        try:
            decoder.decode(b"", final=True)
        except UnicodeDecodeError:
            utf8 = False
    if not utf8 and nul is not None:
        raise DataError(f"{path}: not a text file (a NUL byte at byte {nul[0]}, line {nul[1]}); give a CSV with one column per signal")
    return "utf-8-sig" if utf8 else "latin-1"


def _rows(path: Path, encoding: str, delimiter: str | None) -> Iterator[tuple[int, list[str]]]:
    """(line number, cells) of every non-blank row. A quoted field must close on its own line:
    a stray quote is refused with the line it opened on (the reader would otherwise swallow
    the rest of the file)."""
    with path.open(encoding=encoding, newline="") as fh:
        if delimiter is None:  # whitespace-separated columns
            for number, line in enumerate(fh, 1):
                if cells := line.split():
                    yield number, cells
            return
        reader = csv.reader(fh, delimiter=delimiter, strict=True)
        start = 1  # the line the next row starts on
        while True:
            try:
                row = next(reader)
            except StopIteration:
                return
            except csv.Error as exc:
                if reader.line_num > start or str(exc).startswith("unexpected end of data"):
                    raise DataError(_open_quote(path, encoding, start)) from None
                raise DataError(f"{path}: line {start} is not valid CSV ({exc}); clean the file") from None
            if reader.line_num != start:  # a quoted field ran on over lines
                raise DataError(_open_quote(path, encoding, start))
            if "".join(row).strip():
                yield start, row
            start = reader.line_num + 1


def _open_quote(path: Path, encoding: str, number: int) -> str:
    with path.open(encoding=encoding, newline="") as fh:
        line = next(line for k, line in enumerate(fh, 1) if k == number).rstrip("\r\n")
    return (f"{path}: a quote opened on line {number} ({line[:40]!r}{'...' if len(line) > 40 else ''}) is not closed on that line; "
            "remove the stray quote (a field of a signal file is one line)")


def _header(path: Path, rows: Iterator[tuple[int, list[str]]]) -> tuple[list[str], int, Iterator[tuple[int, list[str]]]]:
    """The header (empty without one), how many rows precede the data, and the data rows."""
    head = [row for _, row in zip(range(3), rows)]
    numbered = list(head)
    if not numbered:
        raise DataError(f"{path}: the file is empty")
    first = [cell.strip() for cell in numbered[0][1]]
    has_header = not all(_is_number(c) for c in first if c)
    header = first if has_header else []
    for k in range(1, len(header)):  # a blank header continues the one before (a merged cell)
        header[k] = header[k] or header[k - 1]
    body = numbered[1:] if has_header else numbered
    skipped = 1 if has_header else 0
    if has_header and len(body) > 1 and _units_row(body[0][1], body[1][1]):  # a units row under the header: skipped
        body, skipped = body[1:], 2
    return header, skipped, _chain(body, rows)


def _chain(first: list[tuple[int, list[str]]], rest: Iterator[tuple[int, list[str]]]) -> Iterator[tuple[int, list[str]]]:
    yield from first
    yield from rest


def _units_row(row: list[str], after: list[str]) -> bool:
    """Whether ``row``, the first under the header, names units ("V", "mm"): no cell of it is a
    number (a decimal comma counted as one) and the row after it holds numbers."""
    cells = [c.strip() for c in row if c.strip()]
    numbers = [c.strip() for c in after if c.strip()]
    return bool(cells) and not any(_number_like(c) for c in cells) and any(_number_like(c) for c in numbers)


def _number_like(text: str) -> bool:
    return _is_number(text) or _is_number(text.replace(",", "."))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


class _Column:
    """One selected column, its values gathered row by row (the first bad cell remembered)."""

    def __init__(self, path: Path, header: list[str], selector: str) -> None:
        self.path, self.selector = path, selector
        name, index = split_selector(selector)
        self.position, self.by_position = _position(path, header, name, index)
        self.values = array("d")
        self.comma = False  # a decimal comma, learnt from the first cell that needs it
        self.error: str | None = None

    def take(self, row: list[str], number: int) -> None:
        if self.error is not None:
            return
        cell = row[self.position].strip() if self.position < len(row) else ""
        try:
            self.values.append(float(cell.replace(",", ".") if self.comma else cell))
            return
        except ValueError:
            pass
        if not self.comma and "," in cell and _is_number(cell.replace(",", ".")):
            self.comma = True  # "0,27" beside ";" or tabs: a decimal comma
            self.values.append(float(cell.replace(",", ".")))
            return
        what = "is empty" if not cell else f"holds {cell[:30]!r}, not a number"
        self.error = f"{self.path}: column {self.selector!r} {what} on line {number}; clean the file or select another column"

    def result(self, width: int) -> NDArray[np.float64]:
        if self.by_position and self.position >= width:
            raise DataError(f"{self.path}: no column {self.position} (the file has {width}); count columns from 0")
        if self.error is not None:
            raise DataError(self.error)
        return np.frombuffer(self.values, dtype=np.float64).copy()


def _position(path: Path, header: list[str], name: str, index: int | None) -> tuple[int, bool]:
    """The column's position, and whether it was given as one."""
    if name.isdigit() and index is None and name not in header:
        return int(name), True
    if not header:
        raise DataError(f"{path}: the file has no header; select columns by position (0, 1, ...)")
    matches = [k for k, h in enumerate(header) if h == name]
    if not matches:
        shown = ", ".join(repr(h) for h in dict.fromkeys(h for h in header if h))
        raise DataError(f"{path}: no column {name!r}; the columns are {shown}")
    k = 0 if index is None else index
    if not -len(matches) <= k < len(matches):
        raise DataError(f"{path}: {len(matches)} columns are named {name!r}; choose {name}[0] to {name}[{len(matches) - 1}]")
    return matches[k], False
