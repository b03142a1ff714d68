"""
Fast CSV input and output of IMU records.

The contract format (docs/contracts.md) is a header ``t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,
accel_z`` (extra columns allowed and ignored unless asked for), t in seconds, samples in
SI units (rad/s, m/s^2), optionally gzip-compressed (``.gz``).  Also read: any header
with the columns named explicitly, and headerless numeric files (one or more columns,
``#`` comment lines allowed) such as a frequency record, for which the sample rate must
be given.

Reading reads the file (never maps it: a file that shrinks while it is read cannot
crash the process) and parses the whole text in one call of numpy's loadtxt, then
validates; only when both fail does
a line-by-line pass run, to name the first bad row.  A lone carriage return (which some
readers take for a line end and the parser for blank space) is refused.
"""

import gzip
import io
import os
from pathlib import Path
import re
from typing import Iterator, NamedTuple, Sequence
import warnings
import zlib

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError

#: Names accepted for the time column [s].
TIME_COLUMNS = ('t', 'time', 't_s')

PathLike = str | os.PathLike


class CsvData(NamedTuple):
    """
    A record read from a CSV file.

    Attributes
    ----------
    t_s : np.ndarray or None
        Shape (n,), sample times [s], or None when the file has no time column.
    samples : np.ndarray
        Shape (n, k), float64 samples of the selected columns [SI].
    columns : tuple of str
        The k column names, in the order of ``samples``.
    rate_hz : float
        Sample rate [Hz]: as given, else 1 / median step of ``t_s``.

    """

    t_s: np.ndarray | None
    samples: np.ndarray
    columns: tuple
    rate_hz: float


def _read_bytes(path: Path) -> bytes:
    """
    Whole file content, gunzipped when the name ends in .gz.

    Read, not mapped: a file that shrinks while it is read is a short read, not a
    SIGBUS that would end the process.
    """
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    if path.is_dir():
        raise InputError(f'{path}: is a directory, not a CSV file')
    try:
        if path.name.lower().endswith('.gz'):
            return gzip.decompress(path.read_bytes())
        return path.read_bytes()
    except (OSError, EOFError, zlib.error, ValueError) as exc:
        raise InputError(f'{path}: cannot read: {exc}') from None


def _split_header(raw: bytes,
                  path: Path) -> tuple[list | None, memoryview, int]:
    """
    Separate leading comment/blank lines and an optional header from the data.

    Returns (header names or None, the data as a view of raw (no copy of a large
    file), 1-based line number of the first data line).  Skips the UTF-8 mark that
    spreadsheets write.
    """
    pos = 3 if raw[:3] == b'\xef\xbb\xbf' else 0
    line_no = 1
    n = len(raw)
    while pos < n:
        end = raw.find(b'\n', pos)
        end = n if end < 0 else end
        line = raw[pos:end].strip()
        if line and not line.startswith(b'#'):
            break
        pos = end + 1
        line_no += 1
    if pos >= n:
        raise InputError(f'{path}: file is empty (no data rows)')
    end = raw.find(b'\n', pos)
    end = n if end < 0 else end
    first = raw[pos:end].strip()
    try:
        text = first.decode('utf-8')
    except UnicodeDecodeError:
        raise InputError(f'{path}: line {line_no} is not text (binary file?)') from None
    fields = [f.strip() for f in text.split(',')]
    if all(_is_number(f) for f in fields):
        return None, memoryview(raw)[pos:], line_no
    names = [f.strip('"\'') for f in fields]
    if any(not f for f in names):
        raise InputError(f'{path}: line {line_no}: empty column name in header {text!r}')
    if len(set(names)) != len(names):
        raise InputError(f'{path}: line {line_no}: repeated column name in header {text!r}')
    return names, memoryview(raw)[end + 1:], line_no + 1


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _parse_fast(data: memoryview, n_cols: int, path: Path | None = None,
                skip_lines: int = 0) -> np.ndarray | None:
    """
    Parse the data rows in one call of numpy's loadtxt; None when anything is off.

    Given the path of a plain file, loadtxt reads the file itself (skipping the
    ``skip_lines`` lines before the data), which is quicker than through a Python file
    object.
    """
    source = path if path is not None else io.BytesIO(data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            table = np.loadtxt(source, delimiter=',', comments='#', dtype=np.float64,
                               ndmin=2, skiprows=skip_lines if path is not None else 0)
    except ValueError:
        return None
    if table.size == 0:
        return np.zeros((0, n_cols))
    if table.shape[1] != n_cols:
        return None
    return table


def _parse_careful(data: memoryview, n_cols: int, names: Sequence[str], path: Path,
                   first_line: int) -> np.ndarray:
    """Line-by-line parse that names the first bad row; blank and # lines skipped."""
    rows = []
    for k, raw_line in enumerate(bytes(data).split(b'\n')):
        line = raw_line.strip()
        if not line or line.startswith(b'#'):
            continue
        line_no = first_line + k
        fields = line.split(b',')
        if len(fields) != n_cols:
            raise InputError(f'{path}: row {line_no}: expected {n_cols} fields, '
                             f'found {len(fields)}')
        vals = []
        for name, field in zip(names, fields):
            try:
                vals.append(float(field))
            except ValueError:
                shown = field.decode('utf-8', 'replace').strip() or '(empty)'
                raise InputError(f'{path}: row {line_no}: {shown!r} in column {name} is '
                                 'not a number') from None
        rows.append(vals)
    if not rows:
        raise InputError(f'{path}: file has a header but no data rows')
    return np.array(rows, dtype=np.float64)


def _line_of_row(data: memoryview, row: int, first_line: int) -> int:
    """1-based file line number of data row ``row`` (0-based, comments skipped)."""
    seen = -1
    for k, raw_line in enumerate(bytes(data).split(b'\n')):
        line = raw_line.strip()
        if not line or line.startswith(b'#'):
            continue
        seen += 1
        if seen == row:
            return first_line + k
    return first_line + row


def _columns(header: list, has_header: bool, columns: Sequence[str] | None,
             optional: Sequence[str], path: Path) -> tuple[list, list, list, int | None]:
    """
    Choose the columns to return: (names, their indexes, the indexes checked finite, t).

    The columns asked for (default the six axes, else every column but t) must all be
    there; ``optional`` ones follow when the header has them.
    """
    time_col = next((i for i, h in enumerate(header) if h.lower() in TIME_COLUMNS), None)
    if columns is None:
        if all(a in header for a in AXES):
            want = list(AXES)
        else:
            want = [h for i, h in enumerate(header) if i != time_col]
            if not want:
                raise InputError(f'{path}: no data columns besides the time column')
    else:
        want = [str(c) for c in columns]
        missing = [c for c in want if c not in header]
        if missing:
            where = 'header' if has_header else 'headerless file (columns'
            avail = ', '.join(header)
            tail = '' if has_header else ')'
            raise InputError(f'{path}: column(s) {", ".join(missing)} not in the {where} '
                             f'{avail}{tail}')
    used = [header.index(c) for c in want] + ([time_col] if time_col is not None else [])
    want += [c for c in optional if c in header and c not in want]
    return want, [header.index(c) for c in want], used, time_col


def _check_lines(raw: bytes, path: Path, first_line: int = 1) -> None:
    """Refuse a lone carriage return (a line end to some readers, blank to others)."""
    if raw.count(b'\r') != raw.count(b'\r\n'):
        # A lone carriage return ends a line for some readers and is blank space for
        # others (a flipped '-' is one): refuse rather than guess.
        found = re.search(b'\r(?!\n)', raw)
        line = first_line + raw.count(b'\n', 0, found.start() if found is not None else 0)
        raise InputError(f'{path}: line {line}: carriage return inside a line (old Mac line '
                         'ends or a damaged file)')


def _table(data: memoryview, header: list, path: Path, first_line: int,
           plain: Path | None, used: list) -> np.ndarray:
    """Parse data rows (fast, else line by line naming the first bad row); check finite."""
    n_cols = len(header)
    table = _parse_fast(data, n_cols, plain, first_line - 1)
    if table is None:
        table = _parse_careful(data, n_cols, header, path, first_line)
    # Column by column: strided views, no copy of the table.
    bad = [int(np.argmin(np.isfinite(table[:, j]))) for j in used
           if not np.isfinite(table[:, j]).all()]
    if bad:
        row = min(bad)
        line = _line_of_row(data, row, first_line)
        col = next(header[j] for j in used if not np.isfinite(table[row, j]))
        raise InputError(f'{path}: row {line}: column {col} is {table[row, header.index(col)]}'
                         ' (NaN or infinite values are not allowed)')
    return table


def _headerless(raw: bytes, data: memoryview) -> list:
    """Name the columns of a file without header: value, or column1, column2 ..."""
    start = len(raw) - len(data)
    end = raw.find(b'\n', start)
    first = raw[start:end if end >= 0 else len(raw)].strip()
    n_cols = len(first.split(b','))
    return ['value'] if n_cols == 1 else [f'column{i + 1}' for i in range(n_cols)]


def _rate(t_s: np.ndarray | None, rate_hz: float | None, path: Path) -> float:
    """Return the sample rate [Hz]: as given, else 1 / the median step of t."""
    if rate_hz is not None:
        rate = float(rate_hz)
        if not (np.isfinite(rate) and rate > 0):
            raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
        return rate
    if t_s is None:
        raise InputError(f'{path}: no time column (t): give the sample rate (--rate HZ)')
    if t_s.size < 2:
        raise InputError(f'{path}: one row is too few to derive a sample rate from t')
    step = float(np.median(steps := np.diff(t_s)))
    if step == 0 and (steps >= 0).all() and t_s[-1] > t_s[0]:
        # Rows share stamps, never running back: a stamp clock coarser than the samples.
        return (t_s.size - 1) / float(t_s[-1] - t_s[0])
    if not step > 0:
        raise InputError(f'{path}: the time column t does not increase (median step '
                         f'{step:g} s); fix the stamps or give the rate (--rate HZ)')
    return 1.0 / step


def read_csv(path: PathLike, columns: Sequence[str] | None = None,
             rate_hz: float | None = None, optional: Sequence[str] = ()) -> CsvData:
    """
    Read an IMU (or any numeric) record from a CSV file, optionally gzip-compressed.

    Parameters
    ----------
    path : str or Path
        File name; ``.gz`` files are decompressed.
    columns : sequence of str, optional
        Columns to return, in this order.  Default: the six contract axes when the
        header has them all, else every column except the time column.  For a file
        without header the columns are named ``value`` (one column) or ``column1``,
        ``column2``, ...
    rate_hz : float, optional
        Sample rate [Hz]; overrides the rate derived from the time column, and is
        required when there is no time column.
    optional : sequence of str
        Columns returned too (after ``columns``) when the header has them, e.g.
        ``temperature``; NaN is allowed there (a missing reading).

    Returns
    -------
    CsvData
        Times [s] (or None), samples (n, k) [SI], the column names and the rate [Hz].

    Raises
    ------
    InputError
        Missing or empty file, missing columns, non-numeric or non-finite values (the
        message names the file, the row and what is wrong), or no way to know the rate.

    """
    path = Path(path)
    raw = _read_bytes(path)
    header, data, first_line = _split_header(raw, path)
    _check_lines(raw, path)
    has_header = header is not None
    header = header if header is not None else _headerless(raw, data)
    want, idx, used, time_col = _columns(header, has_header, columns, optional, path)
    plain = path if not path.name.lower().endswith('.gz') else None
    table = _table(data, header, path, first_line, plain, used)
    if table.shape[0] == 0:
        raise InputError(f'{path}: file has a header but no data rows')
    # All columns in file order (a one-column record): the table itself, no copy.
    samples = table if idx == list(range(len(header))) else np.ascontiguousarray(table[:, idx])
    t_s = np.ascontiguousarray(table[:, time_col]) if time_col is not None else None
    return CsvData(t_s=t_s, samples=samples, columns=tuple(want),
                   rate_hz=_rate(t_s, rate_hz, path))


#: Bytes of text parsed per block of a streamed CSV (about 200,000 rows of seven values).
BLOCK_BYTES = 1 << 24


class CsvStream(NamedTuple):
    """
    A CSV file opened for reading in blocks (:func:`open_csv`).

    Attributes
    ----------
    columns : tuple of str
        The column names of every block's samples.
    rate_hz : float
        The rate [Hz] as given, else from the first block's median step of t.
    blocks : Iterator of CsvData
        The blocks, in file order; each parsed and checked as :func:`read_csv` checks
        a whole file (the same one-line errors, with the file's line numbers).

    """

    columns: tuple
    rate_hz: float
    blocks: Iterator


def open_csv(path: PathLike, columns: Sequence[str] | None = None,
             rate_hz: float | None = None, optional: Sequence[str] = (),
             block_bytes: int = BLOCK_BYTES) -> CsvStream:
    """
    Open a CSV record to read in blocks: memory bounded by ``block_bytes``, not the file.

    Parameters
    ----------
    path : str or Path
        File name; ``.gz`` files are decompressed as they are read.
    columns, rate_hz, optional
        As :func:`read_csv`; the rate, when not given, comes from the first block.
    block_bytes : int
        Bytes of text per block (whole lines; at least one line).

    Returns
    -------
    CsvStream
        The columns, the rate and the blocks.

    Raises
    ------
    InputError
        As :func:`read_csv`, for the header and the first block at once, for a later
        block when it is reached.

    """
    path = Path(path)
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    if path.is_dir():
        raise InputError(f'{path}: is a directory, not a CSV file')
    gz = path.name.lower().endswith('.gz')
    try:
        f = gzip.open(path, 'rb') if gz else open(path, 'rb')
    except OSError as exc:
        raise InputError(f'{path}: cannot read: {exc}') from None

    def read(n: int) -> bytes:
        try:
            return f.read(n)
        except (OSError, EOFError, zlib.error, ValueError) as exc:
            f.close()
            raise InputError(f'{path}: cannot read: {exc}') from None

    raw = read(block_bytes)
    while raw and raw.count(b'\n') < 2:          # the header and one whole line at least
        more = read(block_bytes)
        if not more:
            break
        raw += more
    header, data, first_line = _split_header(raw, path)
    has_header = header is not None
    header = header if header is not None else _headerless(raw, data)
    want, idx, used, time_col = _columns(header, has_header, columns, optional, path)

    def parse(chunk: bytes, line: int) -> CsvData | None:
        _check_lines(chunk, path, line)
        table = _table(memoryview(chunk), header, path, line, None, used)
        if table.shape[0] == 0:
            return None
        return CsvData(None if time_col is None else np.ascontiguousarray(table[:, time_col]),
                       np.ascontiguousarray(table[:, idx]), tuple(want), 0.0)

    pending, line = bytes(data), first_line
    at_end = False

    def next_block() -> CsvData | None:
        # Whole lines up to the last line end of what is read; the rest waits.
        nonlocal pending, line, at_end
        while not at_end:
            more = read(block_bytes)
            at_end = not more
            buf = pending + more
            cut = len(buf) if at_end else buf.rfind(b'\n') + 1
            if cut == 0:
                pending = buf
                continue
            chunk, pending = buf[:cut], buf[cut:]
            first, line = line, line + chunk.count(b'\n')
            block = parse(chunk, first)
            if block is not None:
                return block
        return None

    first_block = next_block()
    if first_block is None:
        f.close()
        raise InputError(f'{path}: file has a header but no data rows')
    rate = _rate(first_block.t_s, rate_hz, path)

    def blocks() -> Iterator:
        try:
            block: CsvData | None = first_block
            while block is not None:
                yield block._replace(rate_hz=rate)
                block = next_block()
        finally:
            f.close()
    return CsvStream(tuple(want), rate, blocks())


def write_csv(path: PathLike, t_s: np.ndarray, samples: np.ndarray,
              columns: Sequence[str]) -> None:
    """
    Write a record as CSV with header ``t,<columns>``; gzip when the name ends in .gz.

    Times are written with 9 decimals (ns), samples with 17 significant digits, so a
    read back returns the same float64 values.

    Parameters
    ----------
    path : str or Path
        Output file name.
    t_s : np.ndarray
        Shape (n,), sample times [s].
    samples : np.ndarray
        Shape (n, k), samples [SI].
    columns : sequence of str
        The k column names.

    """
    path = Path(path)
    t_s = np.asarray(t_s, dtype=np.float64).reshape(-1)
    samples = np.asarray(samples, dtype=np.float64)
    if samples.ndim == 1:
        samples = samples[:, None]
    columns = [str(c) for c in columns]
    if samples.shape != (t_s.size, len(columns)):
        raise InputError(f'write_csv: samples of shape {samples.shape} do not match '
                         f'{t_s.size} times and {len(columns)} columns')
    row_fmt = '%.9f' + ',%.17g' * len(columns) + '\n'
    opener = gzip.open if path.name.lower().endswith('.gz') else open
    table = np.column_stack([t_s, samples])
    try:
        with opener(path, 'wt', encoding='ascii', newline='') as f:
            f.write(','.join(['t'] + columns) + '\n')
            step = 20000
            for r0 in range(0, table.shape[0], step):
                chunk = table[r0:r0 + step]
                f.write((row_fmt * chunk.shape[0]) % tuple(chunk.ravel().tolist()))
    except OSError as exc:
        raise InputError(f'{path}: cannot write: {exc}') from None
