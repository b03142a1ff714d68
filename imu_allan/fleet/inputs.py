"""
Which recordings a fleet run takes, which IMU each belongs to, and their content keys.

Inputs come from paths, globs and directories (every bag or CSV below them) or from a
manifest (CSV or YAML: ``path``, ``imu_id``, optional ``model``; paths relative to the
manifest).  The IMU of an input is, in this order: its manifest entry, the ``imu`` group
(or the first group) of ``--id-pattern`` matched against its path, or the bag's own
``topic@frame_id`` (filled in when it is read).  A result is keyed by a SHA-256 hash of
the input's content, so a renamed or copied bag is not analysed twice.
"""

import csv
import glob
import hashlib
import os
from pathlib import Path
import re
from typing import NamedTuple

import yaml

from imu_allan.errors import InputError
from imu_allan.io.inputs import check_path

#: File suffixes a directory walk picks up (a rosbag2 directory counts as one input).
INPUT_SUFFIXES = ('.mcap', '.db3', '.bag', '.csv', '.gz')
_HASH_BLOCK = 1 << 22


class FleetInput(NamedTuple):
    """
    One recording of a fleet run.

    Attributes
    ----------
    path : str
        The input (absolute).
    imu_id : str
        The IMU it belongs to ('' when the bag's topic@frame_id is to name it).
    model : str
        IMU model or type: the group whose spread the views compare.

    """

    path: str
    imu_id: str
    model: str


def _is_rosbag2_dir(path: Path) -> bool:
    return path.is_dir() and (path / 'metadata.yaml').is_file()


def _walk(root: Path) -> list[Path]:
    """Every input below a directory: rosbag2 directories whole, other files by suffix."""
    if _is_rosbag2_dir(root):
        return [root]
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        bags = [d for d in dirnames if _is_rosbag2_dir(here / d)]
        found += [here / d for d in bags]
        dirnames[:] = sorted(d for d in dirnames if d not in bags)
        found += [here / f for f in filenames
                  if f.endswith(INPUT_SUFFIXES) and (f.endswith('.csv.gz') or
                                                     not f.endswith('.gz'))]
    return sorted(found)


def expand(patterns: list[str]) -> list[Path]:
    """
    Return the inputs named by paths, globs and directories, in a stable order.

    Raises
    ------
    InputError
        A pattern that names nothing.

    """
    out: list[Path] = []
    for pattern in patterns:
        matches = sorted(glob.glob(pattern, recursive=True)) if glob.has_magic(pattern) \
            else [pattern]
        if not matches:
            raise InputError(f'{pattern}: no input matches')
        for m in matches:
            p = Path(m)
            if p.is_dir():
                out += _walk(p)
            else:
                check_path(p)
                out.append(p)
    return list(dict.fromkeys(p.resolve() for p in out))


def read_manifest(path) -> list[dict]:
    """
    Read a manifest: rows with ``path``, ``imu_id`` and optionally ``model``.

    A ``.csv`` manifest has a header row; a YAML one is a list of mappings (or a mapping
    with an ``inputs`` list).  Relative paths are taken from the manifest's directory.

    Raises
    ------
    InputError
        An unreadable manifest, or a row without ``path`` or ``imu_id``.

    """
    path = Path(path)
    check_path(path)
    rows: object
    try:
        if path.suffix.lower() == '.csv':
            with open(path, newline='') as f:
                rows = list(csv.DictReader(f))
        else:
            loaded = yaml.safe_load(path.read_text())
            rows = loaded.get('inputs') if isinstance(loaded, dict) else loaded
    except (OSError, UnicodeDecodeError, csv.Error, yaml.YAMLError) as exc:
        raise InputError(f'manifest {path}: unreadable ({type(exc).__name__}: {exc})') \
            from None
    if not isinstance(rows, list):
        raise InputError(f'manifest {path}: expected a list of inputs')
    out = []
    for i, row in enumerate(rows, 1):
        if not isinstance(row, dict) or not row.get('path') or not row.get('imu_id'):
            raise InputError(f'manifest {path}: entry {i} needs a path and an imu_id')
        p = Path(str(row['path']))
        out.append({'path': p if p.is_absolute() else path.parent / p,
                    'imu_id': str(row['imu_id']), 'model': str(row.get('model') or '')})
    return out


def fleet_inputs(patterns: list[str], manifest=None, id_pattern: str | None = None,
                 model: str = 'default') -> list[FleetInput]:
    """
    Collect a run's inputs with their IMU identity.

    Parameters
    ----------
    patterns : list of str
        Paths, globs, directories (may be empty with a manifest).
    manifest : path-like, optional
        See :func:`read_manifest`; its entries come first and name their IMU.
    id_pattern : str, optional
        Regular expression searched in each other input's path; its ``imu`` group (or
        its first group, or the whole match) is the IMU id.
    model : str
        Model of inputs whose manifest entry names none.

    Returns
    -------
    list of FleetInput

    Raises
    ------
    InputError
        No inputs, a bad pattern, or a path the id pattern does not match.

    """
    regex = None
    if id_pattern:
        try:
            regex = re.compile(id_pattern)
        except re.error as exc:
            raise InputError(f'--id-pattern {id_pattern!r}: {exc}') from None
    out: dict[str, FleetInput] = {}
    for row in read_manifest(manifest) if manifest else []:
        for p in expand([str(row['path'])]):
            out.setdefault(str(p), FleetInput(str(p), row['imu_id'], row['model'] or model))
    for p in expand(patterns):
        if str(p) in out:
            continue
        imu_id = ''
        if regex is not None:
            m = regex.search(str(p))
            if m is None:
                raise InputError(f'{p}: --id-pattern {id_pattern!r} does not match its path')
            imu_id = m.groupdict().get('imu') or (m.group(1) if regex.groups else m.group(0))
        out[str(p)] = FleetInput(str(p), imu_id, model)
    if not out:
        raise InputError('no inputs: give paths, globs, directories or --manifest')
    return list(out.values())


def _files(path: Path) -> list[Path]:
    if path.is_dir():
        return sorted(p for p in path.rglob('*') if p.is_file())
    return [path]


def stat_key(path) -> str:
    """Return a cheap signature of an input (size and mtime of its files) for the key cache."""
    path = Path(path)
    parts = [f'{p.relative_to(path) if p != path else ""}:{p.stat().st_size}:'
             f'{p.stat().st_mtime_ns}' for p in _files(path)]
    return f'{path}|' + '|'.join(parts)


def content_key(path) -> str:
    """
    Return a hash of an input's content (a directory: names and contents).

    The first 128 bits of SHA-256 (faster than BLAKE2b on CPUs with SHA
    instructions).

    Raises
    ------
    InputError
        The input cannot be read.

    """
    path = Path(path)
    h = hashlib.sha256()
    try:
        for p in _files(path):
            if p != path:
                h.update(str(p.relative_to(path)).encode() + b'\0')
            with open(p, 'rb') as f:
                while block := f.read(_HASH_BLOCK):
                    h.update(block)
    except OSError as exc:
        raise InputError(f'{path}: cannot read it ({exc.strerror or exc})') from None
    return h.hexdigest()[:32]
