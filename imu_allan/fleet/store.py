"""
The fleet store: every result of every run, one Parquet file per input, appended.

Layout of a store directory::

    results/<key>.ok.parquet       six rows (one per axis) of an analysed input
    results/<key>.failed.parquet   one row: the input and its one-line reason
    keys.json                      content keys of inputs already hashed, by size+mtime

A result is written (atomically: temporary file, then rename) as soon as its input is
done, so a crash loses at most the inputs in flight; a file per content key means a
retried or re-run input replaces its own file and is never counted twice.  The table is
read with pyarrow; the rows are plain dicts (:data:`FIELDS`).
"""

import json
import math
from pathlib import Path

from imu_allan.atomic import write_atomic
from imu_allan.errors import InputError

#: Parameters kept per axis, each with value, 95 % interval and kind.
PARAMS = ('N', 'B', 'K', 'T_B')
#: Columns of the store: (name, 'str' | 'int' | 'float').
FIELDS = ([('key', 'str'), ('path', 'str'), ('imu_id', 'str'), ('model', 'str'),
           ('topic', 'str'), ('frame_id', 'str'), ('start_ns', 'int'), ('duration_s', 'float'),
           ('rate_hz', 'float'), ('n_samples', 'int'), ('status', 'str'), ('reason', 'str'),
           ('cpu_s', 'float'), ('axis', 'str'), ('unit', 'str')]
          + [(f'{p}{s}', t) for p in PARAMS
             for s, t in (('', 'float'), ('_lo', 'float'), ('_hi', 'float'), ('_kind', 'str'))]
          + [('effects', 'str'), ('model_consistent', 'int'), ('warnings', 'str'),
             ('version', 'str')])
_EMPTY = {'str': '', 'int': -1, 'float': math.nan}
_STATUSES = ('ok', 'failed')


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError('the fleet store needs pyarrow: pip install imu_allan[fleet]') \
            from None
    return pa, pq


def complete_row(row: dict) -> dict:
    """Return a row with every column of :data:`FIELDS`, missing ones empty."""
    return {name: row.get(name, _EMPTY[kind]) for name, kind in FIELDS}


class FleetStore:
    """
    A directory of fleet results (created when missing).

    Parameters
    ----------
    root : str or Path
        The store directory.

    """

    def __init__(self, root):
        self.root = Path(root)
        self.results = self.root / 'results'
        try:
            self.results.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f'store {self.root}: cannot create it ({exc.strerror})') from None
        self._keys_path = self.root / 'keys.json'
        self._keys = self._load_keys()

    def _load_keys(self) -> dict:
        try:
            keys = json.loads(self._keys_path.read_text())
            return keys if isinstance(keys, dict) else {}
        except (OSError, ValueError):
            return {}   # a missing or damaged cache only costs hashing again

    def cached_key(self, signature: str) -> str | None:
        """Return the content key remembered for an input signature, or None."""
        return self._keys.get(signature)

    def remember_keys(self, keys: dict) -> None:
        """Remember content keys by input signature (one atomic write)."""
        self._keys.update(keys)
        text = json.dumps(self._keys, indent=0, sort_keys=True)
        write_atomic(self._keys_path, lambda f: f.write(text), mode='w')

    def done(self) -> dict[str, str]:
        """Return the status ('ok' or 'failed') of every content key in the store."""
        out: dict[str, str] = {}
        for p in self.results.glob('*.parquet'):
            key, _, status = p.name.removesuffix('.parquet').rpartition('.')
            if status in _STATUSES and (out.get(key) != 'ok'):
                out[key] = status
        return out

    def write(self, key: str, status: str, rows: list[dict]) -> Path:
        """
        Store the rows of one input under its content key, replacing an older result.

        Returns
        -------
        Path
            The file written.

        """
        if status not in _STATUSES:
            raise ValueError(f'status must be one of {_STATUSES}, got {status!r}')
        pa, pq = _pyarrow()
        full = [complete_row(r) for r in rows]
        table = pa.table({name: pa.array([r[name] for r in full], type={
            'str': pa.string(), 'int': pa.int64(), 'float': pa.float64()}[kind])
            for name, kind in FIELDS})
        path = write_atomic(self.results / f'{key}.{status}.parquet',
                            lambda f: pq.write_table(table, f))
        for other in _STATUSES:
            if other != status:
                (self.results / f'{key}.{other}.parquet').unlink(missing_ok=True)
        return path

    def rows(self, status: str | None = None) -> list[dict]:
        """Return every stored row (optionally of one status), oldest file first."""
        _, pq = _pyarrow()
        out: list[dict] = []
        for p in sorted(self.results.glob('*.parquet'), key=lambda q: q.stat().st_mtime_ns):
            try:
                out += pq.read_table(p).to_pylist()
            except (OSError, ValueError) as exc:
                raise InputError(f'store file {p} is unreadable ({exc})') from None
        return [r for r in out if status is None or r['status'] == status]
