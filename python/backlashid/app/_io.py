"""Reading logged signals from CSV, NPZ and MATLAB .mat files.

A signal is chosen by name:

- ``NAME``: a CSV column with that header, an NPZ array or a MATLAB variable (a 1 x N or N x 1
  matrix is taken as a vector);
- ``NAME[K]``: column K (0-based) of a 2-D array or variable, or the K-th CSV column headed
  NAME when several share one header (a blank header cell continues the name before it, as in
  the Wiener-Hammerstein benchmark files);
- ``K`` (digits only): the CSV column at position K (0-based), for files without a header.

Sample ranges are Python slices written ``a:b`` (0-based, b excluded, negatives count from the
end). Every problem raises :class:`~backlashid.errors.DataError` with a one-line message that
names the file and says what to change.
"""

from __future__ import annotations

import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ._csv import read_csv
from ._csv import split_selector as _selector

__all__ = [
    "Record",
    "Selection",
    "concatenate",
    "decimate",
    "load_record",
    "parse_range",
    "read_signals",
    "select_records",
    "split_fraction",
]



@dataclass(frozen=True)
class Record:
    """Input u and output y of one record, and where they came from.

    Attributes
    ----------
    u : ndarray of float64
        Input u(t), 1-D.
    y : ndarray of float64
        Measured output y(t), as long as u.
    source : str
        Where the samples came from: the file, and the range or decimation applied.

    Examples
    --------
    >>> record = bid.app.Record(np.zeros(5), np.ones(5), "bench")
    >>> len(record), record.slice(slice(1, 3), "--range").source
    (5, 'bench[1:3]')
    """

    u: NDArray[np.float64]
    y: NDArray[np.float64]
    source: str

    def __len__(self) -> int:
        return len(self.u)

    def slice(self, part: slice, label: str) -> Record:
        """Samples ``part`` of the record (copies, so the record itself cannot change).

        Parameters
        ----------
        part : slice
            The samples kept, as in ``u[part]``.
        label : str
            What chose the range (``"--range"``, say), named in the error message.

        Returns
        -------
        Record
            The selected samples; its source names the range.

        Raises
        ------
        DataError
            If ``part`` selects no samples.
        """
        u, y = self.u[part].copy(), self.y[part].copy()
        if len(u) == 0:
            raise DataError(f"{label} selects no samples of {self.source} ({len(self)} samples): widen the range")
        return Record(u, y, f"{self.source}[{part.start}:{part.stop}]")


def read_signals(path: str | Path, names: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    """Read the signals ``names`` of one file as float64 vectors of one length.

    Parameters
    ----------
    path : str or Path
        A ``.csv`` (or ``.txt``), ``.npz`` or MATLAB ``.mat`` file.
    names : sequence of str
        The signals, each ``NAME``, ``NAME[K]`` or a column number ``K`` (see the module
        description).

    Returns
    -------
    dict of str to ndarray
        Each selector of ``names`` to its samples.

    Raises
    ------
    DataError
        If the file is missing or unreadable, a signal is absent, not numeric or not finite,
        or the signals differ in length; the message names the file and what to change.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "log.csv"
    >>> _ = path.write_text("t,u,y\\n0,0.5,0.0\\n1,-0.25,0.5\\n")
    >>> bid.app.read_signals(path, ["u", "2"])
    {'u': array([ 0.5 , -0.25]), '2': array([0. , 0.5])}
    """
    signals = _read_signals(path, names)
    for name, values in signals.items():
        _require_finite(values, f"{path}: {name}", "select a range without it")
    return signals


def _read_signals(path: str | Path, names: Sequence[str]) -> dict[str, NDArray[np.float64]]:
    """:func:`read_signals` without the finiteness check (the caller checks the range it uses)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(_missing(path))
    suffix = path.suffix.lower()
    if suffix in (".csv", ".txt"):
        signals = read_csv(path, names)
    elif suffix == ".npz":
        signals = _read_arrays(path, _load_npz(path, names), names, "array")
    elif suffix == ".mat":
        signals = _read_arrays(path, _load_mat(path, names), names, "variable")
    else:
        raise DataError(f"{path}: unknown file type {suffix!r}; give a .csv, .npz or .mat file")
    lengths = {name: len(v) for name, v in signals.items()}
    if len(set(lengths.values())) > 1:
        raise DataError(f"{path}: signals of different lengths {lengths}; choose signals of one record")
    return signals


def _require_finite(values: NDArray[np.float64], what: str, hint: str, offset: int = 0, within: str = "") -> None:
    """Refuse a non-finite sample of ``values``, naming its sample (``offset`` + index: the
    sample of the file) and, for a range, the range (``within``) and the index inside it."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        i = int(bad[0])
        where = f"sample {offset + i}" + (f" (sample {i} of {within})" if within else "")
        raise DataError(f"{what} has a non-finite value at {where}: {values[i]}; clean the record or {hint}")


def _finite_record(record: Record, input: str, output: str, hint: str, offset: int = 0, within: str = "", source: str = "") -> Record:
    """``record``, refused if a sample is not finite (``source``: the file the range is of)."""
    for name, values in ((input, record.u), (output, record.y)):
        _require_finite(values, f"{source or record.source}: {name}", hint, offset, within)
    return record


def _missing(path: Path) -> str:
    """The message for a data file that does not exist: where relative paths start, and where
    the shared benchmark records are (``BACKLASHID_DATA``)."""
    from ..benchmarks import shared_data_folder

    message = f"{path}: no such file"
    if not path.is_absolute():
        message += f" (relative to {Path.cwd()})"
    try:
        folder = shared_data_folder()
    except DataError:
        folder = None
    parts = path.parts
    if "data" in parts and parts.index("data") > 0 and parts[parts.index("data") - 1] == "shared" and folder is not None:
        guess = folder.joinpath(*parts[parts.index("data") + 1 :])
        if guess.is_file():
            return f"{message}; the shared records are in {folder}: did you mean {guess}? (BACKLASHID_DATA names their folder)"
    where = f"found in {folder}" if folder is not None else "not found"
    return (f"{message}; check the path (the shared benchmark records are read from $BACKLASHID_DATA, else shared/data "
            f"beside the repository: {where})")


def load_record(path: str | Path, input: str, output: str) -> Record:
    """Read the input and output signals of one file as a :class:`Record`.

    Parameters
    ----------
    path : str or Path
        A ``.csv``, ``.npz`` or ``.mat`` file.
    input : str
        The input signal, selected as in :func:`read_signals`.
    output : str
        The output signal, selected likewise.

    Returns
    -------
    Record
        The two signals; the source is ``path``.

    Raises
    ------
    DataError
        As :func:`read_signals`.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "log.npz"
    >>> np.savez(path, drive=np.arange(4.0), pos=np.zeros(4))
    >>> record = bid.app.load_record(path, "drive", "pos")
    >>> len(record), record.u.tolist()
    (4, [0.0, 1.0, 2.0, 3.0])
    """
    signals = read_signals(path, [input, output])
    return Record(signals[input], signals[output], str(path))


def _load_unchecked(path: str | Path, input: str, output: str) -> Record:
    signals = _read_signals(path, [input, output])
    return Record(signals[input], signals[output], str(path))


def concatenate(records: Sequence[Record]) -> Record:
    """Join records one after the other.

    The joins are jumps in the signals: mind the warm-up of each part.

    Parameters
    ----------
    records : sequence of Record
        The records, in order.

    Returns
    -------
    Record
        The samples of all of them; the source lists theirs (one record is returned as it is).

    Raises
    ------
    DataError
        If ``records`` is empty.

    Examples
    --------
    >>> a = bid.app.Record(np.zeros(3), np.zeros(3), "a.csv")
    >>> b = bid.app.Record(np.ones(2), np.ones(2), "b.csv")
    >>> joined = bid.app.concatenate([a, b])
    >>> len(joined), joined.source
    (5, 'a.csv + b.csv')
    """
    if not records:
        raise DataError("no records to join")
    if len(records) == 1:
        return records[0]
    return Record(
        np.concatenate([r.u for r in records]),
        np.concatenate([r.y for r in records]),
        " + ".join(r.source for r in records),
    )


def parse_range(text: str, n: int, label: str) -> slice:
    """Read a sample range ``"a:b"`` as a slice of a record of n samples.

    Parameters
    ----------
    text : str
        ``a:b``, 0-based, b excluded; a or b may be empty, negative values count from the end.
    n : int
        Samples in the record.
    label : str
        The option that gave the range, named in the error message.

    Returns
    -------
    slice
        With start and stop inside ``0..n``.

    Raises
    ------
    DataError
        If ``text`` is not ``a:b`` with whole numbers, or selects no sample.

    Examples
    --------
    >>> bid.app.parse_range("100:", 1500, "--validation")
    slice(100, 1500, None)
    >>> bid.app.parse_range(":-500", 1500, "--estimation")
    slice(0, 1000, None)
    """
    parts = text.split(":")
    if len(parts) != 2:
        raise DataError(f"{label} {text!r}: write a sample range as a:b (0-based, b excluded; a or b may be empty)")
    try:
        start = int(parts[0]) if parts[0].strip() else 0
        stop = int(parts[1]) if parts[1].strip() else n
    except ValueError:
        raise DataError(f"{label} {text!r}: the bounds of a:b must be whole numbers") from None
    for bound in (start, stop):
        if not -n <= bound <= n:  # slicing would clip it silently
            raise DataError(f"{label} {text!r}: {bound} lies outside the record of {n} samples; give bounds within -{n}..{n}")
    start, stop, _ = slice(start, stop).indices(n)
    if stop <= start:
        raise DataError(f"{label} {text!r} selects no samples of a record of {n}: give a < b within 0..{n}")
    return slice(start, stop)


def split_fraction(fraction: float, n: int) -> tuple[slice, slice]:
    """Split n samples: the first ``fraction`` for estimation, the rest for validation.

    Parameters
    ----------
    fraction : float
        The estimation share, strictly between 0 and 1.
    n : int
        Samples in the record.

    Returns
    -------
    tuple of slice
        (estimation, validation).

    Raises
    ------
    DataError
        If ``fraction`` is outside (0, 1) or leaves one part empty.

    Examples
    --------
    >>> bid.app.split_fraction(0.6, 1500)
    (slice(0, 900, None), slice(900, 1500, None))
    """
    if not 0.0 < fraction < 1.0:
        raise DataError(f"split {fraction}: give the estimation fraction strictly between 0 and 1")
    cut = int(round(fraction * n))
    if cut < 1 or cut >= n:
        raise DataError(f"split {fraction} of {n} samples leaves one part empty: use a longer record or another fraction")
    return slice(0, cut), slice(cut, n)


# -- file formats --------------------------------------------------------------------------------


def _load_npz(path: Path, names: Sequence[str]) -> dict[str, NDArray]:
    """The arrays ``names`` select of an .npz file (no other member is read), each checked
    against its member's size before it is allocated."""
    with path.open("rb") as fh:
        if fh.read(4) != b"PK\x03\x04":
            raise DataError(f"{path}: not a readable .npz file (not a zip archive); save the arrays with numpy.savez")
    wanted = {_selector(s)[0] for s in names}
    try:
        with zipfile.ZipFile(path) as archive:
            members = {m.filename[:-4]: m for m in archive.infolist() if m.filename.endswith(".npy")}
            out = {}
            for name in sorted(wanted & set(members)):
                with archive.open(members[name]) as fh:
                    out[name] = _npy_member(path, name, fh, members[name].file_size)
            # the names of the others, for a message naming what the file holds
            return {**dict.fromkeys(members), **out}
    except ValueError as exc:  # pickled objects, an unknown .npy format
        raise DataError(f"{path}: cannot read the arrays ({exc}); save plain numeric arrays with numpy.savez") from None
    except (OSError, EOFError, zipfile.BadZipFile, zlib.error, KeyError) as exc:  # a corrupt or truncated archive
        raise DataError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc}); save the arrays again with numpy.savez") from None


def _npy_member(path: Path, name: str, fh: Any, member_size: int) -> NDArray:
    """One .npy member, its header's size checked against the bytes the member holds."""
    fmt = np.lib.format
    version = fmt.read_magic(fh)
    shape, fortran, dtype = fmt.read_array_header_1_0(fh) if version == (1, 0) else fmt.read_array_header_2_0(fh)
    if dtype.hasobject:
        raise DataError(f"{path}: array {name!r} holds Python objects; save plain numeric arrays with numpy.savez")
    claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if claimed > member_size:
        raise DataError(
            f"{path}: array {name!r} claims shape {shape} ({claimed:,} bytes) but its member holds {member_size:,} bytes: "
            "the file is damaged; save the arrays again with numpy.savez"
        )
    data = np.frombuffer(fh.read(claimed), dtype=dtype)
    if data.nbytes != claimed:
        raise DataError(f"{path}: array {name!r} is truncated; save the arrays again with numpy.savez")
    return data.reshape(shape, order="F" if fortran else "C")


# Read in a child process: scipy's MATLAB reader is not hardened against damaged files (a
# complex flag without an imaginary part crashes it with a segmentation fault, scipy 1.17), and a
# crash must cost the caller one error, not its process.
_MAT_CHILD = r"""
import json, sys
import numpy as np
from scipy.io import loadmat, whosmat
path, out, limit, *wanted = sys.argv[1:]
try:
    listed = {n: (int(np.prod(shape, dtype=object)), cls) for n, shape, cls in whosmat(path)}
    for n in wanted:
        if n in listed and 8 * listed[n][0] > int(limit):
            print(json.dumps({"error": f"variable {n!r} claims {listed[n][0]:,} elements, more than the file can hold: the file is damaged"}))
            sys.exit(0)
    present = [n for n in wanted if n in listed]
    data = loadmat(path, squeeze_me=False, variable_names=present) if present else {}
except NotImplementedError:
    print(json.dumps({"v73": True})); sys.exit(0)
except MemoryError:
    print(json.dumps({"memory": True})); sys.exit(0)
except Exception as exc:
    print(json.dumps({"error": f"{type(exc).__name__}: {str(exc)[:120]}"})); sys.exit(0)
arrays = {k: v for k, v in data.items() if not k.startswith("__") and isinstance(v, np.ndarray) and v.dtype.kind in "biuf"}
np.savez(out, **arrays)
print(json.dumps({"listed": {n: c for n, (_, c) in listed.items()}, "saved": sorted(arrays)}))
"""


def _load_mat(path: Path, names: Sequence[str]) -> dict[str, NDArray]:
    """The variables ``names`` select of a MATLAB file (no other is read; each checked against
    the file's size before it is read), read in a child process."""
    import json
    import subprocess
    import sys
    import tempfile

    wanted = sorted({_selector(s)[0] for s in names})
    limit = 1032 * path.stat().st_size + (1 << 20)  # deflate compresses at most 1032:1
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "arrays.npz"
        done = subprocess.run(
            [sys.executable, "-c", _MAT_CHILD, str(path), str(out), str(limit), *wanted], capture_output=True, text=True, check=False
        )
        if done.returncode != 0:
            how = f"crashed with signal {-done.returncode}" if done.returncode < 0 else f"ended with exit code {done.returncode}"
            raise DataError(f"{path}: not a readable MATLAB .mat file (scipy's reader {how}: the file is damaged); save it again")
        said = json.loads(done.stdout.strip().splitlines()[-1])
        if said.get("v73"):
            raise DataError(f"{path}: a MATLAB v7.3 (HDF5) file; save it with save(..., '-v7') or export a CSV")
        if said.get("memory"):
            raise MemoryError(f"{path}: not enough memory to read it")
        if "error" in said:
            raise DataError(f"{path}: not a readable MATLAB .mat file ({said['error']}); save it again")
        arrays = _load_npz(out, said["saved"]) if said["saved"] else {}
    # variables that are no numeric arrays (cells, structs, text) are named with their class
    return {n: arrays.get(n) if arrays.get(n) is not None else np.empty(0, dtype=object) for n in said["listed"]}


def _read_arrays(path: Path, arrays: dict[str, NDArray], names: Sequence[str], kind: str) -> dict[str, NDArray[np.float64]]:
    out = {}
    for selector in names:
        name, index = _selector(selector)
        if name not in arrays:
            shown = ", ".join(sorted(arrays)) or "none"
            raise DataError(f"{path}: no {kind} {name!r}; the {kind}s are {shown}")
        arr = np.asarray(arrays[name])
        if arr.dtype.kind not in "biuf":
            raise DataError(f"{path}: {kind} {name!r} has type {arr.dtype}, not numbers; select a numeric {kind}")
        if arr.ndim == 2 and 1 in arr.shape:
            arr = arr.ravel()
        if index is not None:
            if arr.ndim != 2:
                raise DataError(f"{path}: {name!r} has shape {arr.shape}; [K] selects a column of a 2-D {kind}")
            if not -arr.shape[1] <= index < arr.shape[1]:
                raise DataError(f"{path}: {name!r} has {arr.shape[1]} columns; choose {name}[0] to {name}[{arr.shape[1] - 1}]")
            arr = arr[:, index]
        if arr.ndim != 1:
            hint = f"; select a column with {name}[K]" if arr.ndim == 2 else ""
            raise DataError(f"{path}: {kind} {name!r} has shape {arr.shape}, not a signal{hint}")
        if arr.size == 0:
            raise DataError(f"{path}: {kind} {name!r} is empty")
        out[selector] = arr.astype(np.float64)
    return out


def decimate(record: Record, factor: int) -> Record:
    """Keep every ``factor``-th sample after an anti-alias filter.

    The filter is a zero-phase FIR low-pass (``scipy.signal.decimate``'s: a Hamming-window FIR
    of order 20 ``factor``, its cut-off at the new Nyquist frequency, centred; the record
    mirrored at both ends rather than padded with zeros), :func:`anti_alias`; then
    :func:`keep_every`.

    Parameters
    ----------
    record : Record
        The record to decimate.
    factor : int
        Keep every factor-th sample; 1 returns the record unchanged.

    Returns
    -------
    Record
        The decimated record; its source says by how much.

    Raises
    ------
    DataError
        If ``factor`` is below 1, or the record is too short for the filter.

    Examples
    --------
    >>> record = bid.app.Record(np.sin(np.arange(1000) / 50), np.zeros(1000), "x")
    >>> short = bid.app.decimate(record, 4)
    >>> len(short), short.source
    (250, 'x decimated by 4')
    """
    if factor == 1:
        return record
    return keep_every(anti_alias(record, factor), factor)


def anti_alias(record: Record, factor: int) -> Record:
    """The record low-passed at full rate by :func:`decimate`'s filter (same length, same
    source). A record filtered whole before it is cut leaves no filter transient at the cuts.

    Parameters
    ----------
    record : Record
        The record, finite.
    factor : int
        The decimation the filter prepares (its cut-off at 1 / factor of Nyquist), >= 1.

    Returns
    -------
    Record
        The filtered record.

    Raises
    ------
    DataError
        If ``factor`` is below 1, or the record is too short for the filter.
    """
    if factor < 1:
        raise DataError(f"decimate {factor}: give a whole number >= 1")
    if factor == 1:
        return record
    from scipy.signal import firwin

    need = 3 * (20 * factor + 1) + 1  # three filter lengths (order 20 * factor)
    if len(record) <= need:
        raise DataError(f"{record.source}: {len(record)} samples are too few to decimate by {factor} (need more than {need})")
    b = firwin(20 * factor + 1, 1.0 / factor, window="hamming")  # scipy.signal.decimate's FIR, centred: zero phase
    h = b.size // 2

    def low(x: NDArray[np.float64]) -> NDArray[np.float64]:
        # the record mirrored at both ends: a record far from zero, a position, gets no edge
        # transient where zero padding would pull it to 0 (an odd extension, 2 x(0) - x(k),
        # would double the noise of the end sample)
        padded = np.concatenate([x[h:0:-1], x, x[-2 : -h - 2 : -1]])
        return np.asarray(np.convolve(padded, b, mode="valid"), dtype=np.float64)

    return Record(low(record.u), low(record.y), record.source)


def decimate_piece(record: Record, part: slice | None, factor: int, label: str = "--range") -> Record:
    """Samples ``part`` of ``record`` (all of it for None) at the decimated rate, the anti-alias
    filter run over the whole record first (no filter transient at the cut); a record with
    missing samples has its piece decimated alone (NaN would spread through the filter)."""
    if factor == 1 or not (np.all(np.isfinite(record.u)) and np.all(np.isfinite(record.y))):
        return decimate(record.slice(part, label) if part is not None else record, factor)
    low = anti_alias(record, factor)
    return keep_every(low.slice(part, label) if part is not None else low, factor)


def keep_every(record: Record, factor: int) -> Record:
    """Every ``factor``-th sample of an anti-alias filtered record (:func:`anti_alias`), from
    its first; its source says so."""
    if factor == 1:
        return record
    return Record(record.u[::factor].copy(), record.y[::factor].copy(), f"{record.source} decimated by {factor}")


@dataclass(frozen=True)
class Selection:
    """Estimation and (optional) validation records chosen from files, and how.

    Attributes
    ----------
    estimation : Record
        The record to fit on.
    validation : Record or None
        The record to judge on, if any.
    description : dict
        The input and output selectors, the sources and sample counts of both records and the
        decimation (written into the JSON of ``backlashid fit``).
    estimation_parts : tuple of Record
        The estimation files' records one by one (``estimation`` joins them), for a joint fit
        of several records; empty for one file.
    validation_parts : tuple of Record
        The validation files' records one by one (``validation`` joins them), for a diagnosis
        that starts each from its own state; empty for one file or a range across files.
    """

    estimation: Record
    validation: Record | None
    description: dict[str, object]
    estimation_parts: tuple[Record, ...] = ()
    validation_parts: tuple[Record, ...] = ()


def select_records(
    data: str | Path | None,
    input: str,
    output: str,
    *,
    estimation_files: Sequence[str | Path] = (),
    validation_files: Sequence[str | Path] = (),
    split: float | None = None,
    estimation: str | None = None,
    validation: str | None = None,
    decimate_by: int = 1,
) -> Selection:
    """Choose the estimation and validation records as the command line does.

    Either one file ``data`` split by ``split`` (estimation fraction) or by the sample ranges
    ``estimation`` and ``validation`` (the whole record is for estimation when none is given),
    or ``estimation_files`` joined one after the other (``estimation`` then selects a range of
    each file) with ``validation_files`` (or ``data``, with ``validation`` as its range) for
    validation. Ranges count samples of the files. The decimation's anti-alias filter runs over
    each whole file before any split or range (so the pieces carry no filter transient at
    their cuts), then every N-th sample of each piece is kept; a file with missing samples is
    filtered piece by piece instead.

    Parameters
    ----------
    data : str, Path or None
        The record file, or None when ``estimation_files`` are given.
    input : str
        The input signal, selected as in :func:`read_signals`.
    output : str
        The output signal.
    estimation_files : sequence of str or Path, default ()
        Files joined into the estimation record.
    validation_files : sequence of str or Path, default ()
        Files joined into the validation record.
    split : float, optional
        Estimation fraction of ``data``; the rest validates.
    estimation : str, optional
        Estimation samples ``a:b`` of ``data`` (or of each estimation file).
    validation : str, optional
        Validation samples ``c:d`` of ``data`` (or of the joined validation files).
    decimate_by : int, default 1
        Keep every N-th sample of each record (see :func:`decimate`).

    Returns
    -------
    Selection
        The records and their description.

    Raises
    ------
    DataError
        If the choices contradict each other (``split`` with ranges, say), select nothing, a
        file cannot be read, or a selected sample is not finite (the ranges are applied first:
        samples outside them may be NaN; the message names the range and the sample).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "log.csv"
    >>> d = bid.example_data(bid.example1(), 200, seed=0)
    >>> np.savetxt(path, np.column_stack([d.u, d.noisy]), delimiter=",", header="u,y", comments="")
    >>> sel = bid.app.select_records(path, "u", "y", split=0.75)
    >>> len(sel.estimation), len(sel.validation)
    (150, 50)
    """
    if split is not None and (estimation or validation):
        raise DataError("give either --split or --estimation/--validation ranges, not both")
    files = _Files.read([*([data] if data is not None else []), *estimation_files, *validation_files], input, output, decimate_by)
    parts: list[Record] = []
    if estimation_files:
        parts, val = _from_estimation_files(files, data, estimation_files, validation_files, split, estimation, validation)
        parts = [files.reduced(p) for p in parts]  # each file's piece at the decimated rate, then joined
        est = concatenate(parts)
    else:
        est, val = _from_data_file(files, data, validation_files, split, estimation, validation)
        est = files.reduced(est)
    val = files.reduced_validation(val)
    description: dict[str, object] = {
        "input": input,
        "output": output,
        "estimation": est.source,
        "estimation_samples": len(est),
        "validation": val.source if val is not None else None,
        "validation_samples": len(val) if val is not None else 0,
        "decimate": decimate_by,
        # the outputs the records visited: a compensator's reference beyond them extrapolates the model
        "output_range": [float(min(r.y.min() for r in (est, val) if r is not None)), float(max(r.y.max() for r in (est, val) if r is not None))],
    }
    return Selection(est, val, description, tuple(parts), tuple(files.validation_parts))


_RANGE_HINT = "choose --estimation / --validation ranges without it"


@dataclass
class _Files:
    """The files :func:`select_records` reads, their records (the signals chosen, filtered
    whole when decimated and none has missing samples), and how it cuts and decimates them."""

    records: dict[str, Record]
    input: str
    output: str
    decimate_by: int
    whole: bool  # each file anti-alias filtered whole, before any cut
    validation_parts: list[Record] = field(default_factory=list)  # several validation files, one by one

    @classmethod
    def read(cls, paths: Sequence[str | Path], input: str, output: str, decimate_by: int) -> _Files:
        """The files' records, each filtered whole for the decimation where all are finite."""
        records = {str(f): _load_unchecked(f, input, output) for f in paths}
        whole = decimate_by > 1 and all(np.all(np.isfinite(r.u)) and np.all(np.isfinite(r.y)) for r in records.values())
        if whole:  # one anti-alias filter over each whole file, before any cut
            records = {f: anti_alias(r, decimate_by) for f, r in records.items()}
        return cls(records, input, output, decimate_by, whole)

    def load(self, path: str | Path) -> Record:
        """The file's record."""
        return self.records[str(path)]

    def reduced(self, rec: Record) -> Record:
        """A piece at the decimated rate: every N-th sample of the filtered file's piece, or
        the piece decimated (filter and all) where a file has missing samples."""
        return keep_every(rec, self.decimate_by) if self.whole else decimate(rec, self.decimate_by)

    def pick(self, rec: Record, text: str | None, label: str) -> Record:
        """Range ``text`` of ``rec`` (all of it when None), checked finite only there."""
        if not text:
            return _finite_record(rec, self.input, self.output, _RANGE_HINT)
        part = parse_range(text, len(rec), label)
        return _finite_record(rec.slice(part, label), self.input, self.output, _RANGE_HINT, part.start, f"{label} {text}", rec.source)

    def joined(self, paths: Sequence[str | Path], text: str | None, label: str) -> Record:
        """The files joined, then range ``text`` of them; without a range each file is checked
        finite on its own and, when there are several, kept in ``validation_parts``."""
        records = [self.load(f) for f in paths]
        if text:
            return self.pick(concatenate(records), text, label)
        checked = [_finite_record(r, self.input, self.output, _RANGE_HINT) for r in records]
        if len(checked) > 1:
            self.validation_parts.extend(checked)
        return concatenate(checked)

    def reduced_validation(self, val: Record | None) -> Record | None:
        """The validation record at the decimated rate; with ``validation_parts`` each part
        reduced on its own, then joined (they replace ``val``)."""
        if not self.validation_parts:
            return self.reduced(val) if val is not None else None
        self.validation_parts[:] = [self.reduced(p) for p in self.validation_parts]
        return concatenate(self.validation_parts)


def _from_estimation_files(
    files: _Files, data: str | Path | None, estimation_files: Sequence[str | Path], validation_files: Sequence[str | Path],
    split: float | None, estimation: str | None, validation: str | None,
) -> tuple[list[Record], Record | None]:
    """Range ``estimation`` of each estimation file, and the validation record: range
    ``validation`` of the joined validation files, else of the DATA file, else none."""
    if split is not None:
        raise DataError("--split divides one file; with --estimation-file give --validation-file or a DATA file for validation")
    parts = [files.pick(files.load(f), estimation, "--estimation") for f in estimation_files]
    if validation_files:
        return parts, files.joined(validation_files, validation, "--validation")
    if data is not None:
        return parts, files.pick(files.load(data), validation, "--validation")
    if validation:
        raise DataError("--validation is a range of the DATA file or the --validation-file records: give one")
    return parts, None


def _from_data_file(
    files: _Files, data: str | Path | None, validation_files: Sequence[str | Path], split: float | None,
    estimation: str | None, validation: str | None,
) -> tuple[Record, Record | None]:
    """The estimation and validation records of the DATA file: split by ``split``, or its
    ranges, the validation files validating when no range of it does."""
    if data is None:
        raise DataError("no data: give a DATA file or --estimation-file")
    rec = files.load(data)
    if split is not None:
        if validation_files:
            # checked; several of them, kept in validation_parts, replace the split's tail in the end
            files.joined(validation_files, None, "--validation-file")
        est_part, val_part = split_fraction(split, len(rec))
        label = f"--split {split:g}"
        hint = "choose another --split"
        est = _finite_record(rec.slice(est_part, "--split"), files.input, files.output, hint, 0, f"{label} (estimation)", rec.source)
        val = _finite_record(rec.slice(val_part, "--split"), files.input, files.output, hint, val_part.start, f"{label} (validation)", rec.source)
        return est, val
    est = files.pick(rec, estimation, "--estimation")
    if validation:
        return est, files.pick(rec, validation, "--validation")
    if validation_files:
        return est, files.joined(validation_files, None, "--validation-file")
    return est, None
