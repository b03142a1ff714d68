"""
Opening an input: a file by its signature, a rosbag2 directory by its metadata.

Part of :mod:`imu_allan.io.bag_reader`.
"""

from pathlib import Path, PurePath
import re
import tempfile
from typing import Callable, Iterator

import yaml
import zstandard

from imu_allan.errors import InputError
from imu_allan.io.bags.base import Backend, MCAP_MAGIC, PathLike, Piece, Topic
from imu_allan.io.bags.mcap_storage import _McapBackend
from imu_allan.io.bags.ros1 import _Ros1Backend
from imu_allan.io.bags.rosbag2_sqlite import _SqliteBackend

_SQLITE_MAGIC = b'SQLite format 3\x00'
_ROS1_MAGIC = b'#ROSBAG V2.0\n'
_ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'


def _zstd_decompress(data: bytes) -> bytes:
    """Decompress one zstd frame (rosbag2 message compression)."""
    return zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 30)


def _sniff(path: Path) -> bytes:
    try:
        with open(path, 'rb') as stream:
            return stream.read(16)
    except OSError as err:
        raise InputError(f'{path}: cannot read ({err.strerror})') from None


def _open_file(path: Path, warnings: list[str],
               decompress: Callable[[bytes], bytes] | None = None) -> Backend:
    """Open one storage file, recognised by its signature rather than its suffix."""
    head = _sniff(path)
    if not head:
        raise InputError(f'{path}: empty file (0 bytes)')
    if head.startswith(MCAP_MAGIC):
        return _McapBackend(path, warnings, decompress)
    if head.startswith(_SQLITE_MAGIC):
        return _SqliteBackend(path, warnings, decompress)
    if head.startswith(_ROS1_MAGIC):
        return _Ros1Backend(path, warnings)
    if head.startswith(b'#ROSBAG V'):
        raise InputError(f'{path}: ROS 1 bag format {head[9:12].decode(errors="replace")} is '
                         'not supported (only 2.0; migrate it with `rosbag fix`)')
    if head.startswith(_ZSTD_MAGIC):
        raise InputError(f'{path}: zstd-compressed file; open the rosbag2 directory that '
                         'holds it (its metadata.yaml names the compression)')
    raise InputError(f'{path}: not a bag (no MCAP, sqlite3 or ROS 1 bag signature)')


def _natural_key(path: Path) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r'(\d+)', path.name)]


# Long because a split bag is one storage to its reader: the files' order by their
# contents, repeated and missing files, and the merged topics live together.
class _Rosbag2DirBackend(Backend):
    """A rosbag2 directory: metadata.yaml (any version) plus storage files."""

    def __init__(self, path: Path, warnings: list[str]) -> None:
        super().__init__(path, warnings)
        self.tmp: tempfile.TemporaryDirectory | None = None
        self.parts: list[Backend] = []
        info = self._metadata()
        files, decompress = self._files(info)
        try:
            for file in files:
                self.parts.append(_open_file(file, warnings, decompress))
        except BaseException:
            self.close()
            raise
        if len(self.parts) > 1:
            self.parts = self._in_time_order(self.parts)
        self.storage = self.parts[0].storage
        self._topics = self._merge_topics(info)

    def _in_time_order(self, parts: list[Backend]) -> list[Backend]:
        """
        Order split files by their first receive time; read a repeated file once.

        metadata.yaml's list may be in any order (edited, or written by another tool);
        read in that order, a split bag would jump back in time at every file.  A file
        with the same time span and message count as another (a copy, the same record
        in both storage formats) repeats its messages: it is left out, with a warning.
        """
        extents = [part.extent() for part in parts]
        order = sorted(range(len(parts)), key=lambda k: (
            extents[k][0] is None, extents[k][0] or 0, k))
        kept: list[Backend] = []
        seen: dict[tuple, Backend] = {}
        for k in order:
            part, extent = parts[k], extents[k]
            first = seen.get(extent) if None not in extent else None
            if first is None:
                seen.setdefault(extent, part)
                kept.append(part)
                continue
            self.warnings.append(f'{self.path}: {part.path.name} repeats {first.path.name} '
                                 f'(the same {extent[2]} messages over the same time span); '
                                 'read once')
            part.close()
        return kept

    def _metadata(self) -> dict | None:
        meta = self.path / 'metadata.yaml'
        if not meta.exists():
            self.warnings.append(f'{self.path}: no metadata.yaml; reading the storage files '
                                 'directly')
            return None
        try:
            info = yaml.safe_load(meta.read_text())['rosbag2_bagfile_information']
            if not isinstance(info, dict):
                raise TypeError('not a mapping')
            return info
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError,
                ValueError) as err:
            reason = str(err).splitlines()[0] if str(err) else type(err).__name__
            self.warnings.append(f'{meta}: unparsable ({reason}); reading the storage files '
                                 'directly')
            return None

    def _files(self, info: dict | None) -> tuple[list[Path], Callable | None]:
        """Return the storage files in order and the per-message decompressor, if any."""
        decompress = None
        listed: list[Path] = []
        if info is not None:
            mode = str(info.get('compression_mode') or '').lower()
            fmt = str(info.get('compression_format') or '').lower()
            if mode not in ('', 'none') and fmt != 'zstd':
                raise InputError(f'{self.path}: compression format {fmt!r} is not supported '
                                 '(only zstd)')
            names = info.get('relative_file_paths') or []
            for name in names if isinstance(names, list) else [names]:
                if not isinstance(name, str) or not name:
                    self.warnings.append(f'{self.path}: metadata.yaml names a storage file '
                                         f'{name!r} that is not a file name; ignored')
                    continue
                # Old bags store 'bagname/bagname_0.db3'; the file sits in the directory.
                candidates = [self.path / PurePath(name).name, self.path / name]
                found = next((c for c in candidates if c.is_file()), None)
                if found is None:
                    self.warnings.append(f'{self.path}: listed storage file {name} is missing')
                else:
                    listed.append(found)
            if mode == 'file':
                listed = [self._unpack(f) if f.suffix == '.zstd' else f for f in listed]
            elif mode == 'message':
                decompress = _zstd_decompress
        if not listed:
            listed = sorted((f for f in self.path.iterdir()
                             if f.suffix in ('.mcap', '.db3') and f.is_file()), key=_natural_key)
            if info is not None and listed:
                self.warnings.append(f'{self.path}: metadata.yaml names no readable storage '
                                     f'file; reading {", ".join(f.name for f in listed)}')
        if not listed:
            raise InputError(f'{self.path}: no rosbag2 storage files (.db3 or .mcap) found')
        return listed, decompress

    def _unpack(self, packed: Path) -> Path:
        """Decompress a file-compressed storage file into a private temporary directory."""
        if self.tmp is None:
            self.tmp = tempfile.TemporaryDirectory(prefix='imu_allan_bag_')
        target = Path(self.tmp.name) / packed.stem
        try:
            with open(packed, 'rb') as src, open(target, 'wb') as dst:
                zstandard.ZstdDecompressor().copy_stream(src, dst)
        except (OSError, zstandard.ZstdError) as err:
            raise InputError(f'{packed}: cannot decompress ({err})') from None
        return target

    def _merge_topics(self, info: dict | None) -> dict[tuple[str, str], Topic]:
        merged: dict[tuple[str, str], Topic] = {}
        for part in self.parts:
            for topic in part.topics():
                key = (topic.name, topic.msgtype)
                old = merged.get(key)
                if old is None:
                    merged[key] = topic
                else:
                    both = (None if old.n_messages is None or topic.n_messages is None
                            else old.n_messages + topic.n_messages)
                    merged[key] = old._replace(n_messages=both)
        try:
            entries = (info or {}).get('topics_with_message_count') or []
            counts = {(x['topic_metadata']['name'], x['topic_metadata'].get('type', '')):
                      int(x['message_count']) for x in entries}
        except (KeyError, TypeError, ValueError, AttributeError):
            counts = {}
        for key, count in counts.items():
            # metadata.yaml's counts are hints (they go stale): the files' own counts win.
            if key in merged and merged[key].n_messages is None:
                merged[key] = merged[key]._replace(n_messages=count)
        return merged

    def topics(self) -> list[Topic]:
        """Return the topics of all storage files."""
        return list(self._topics.values())

    @staticmethod
    def _own(part: Backend, topic: Topic) -> Topic | None:
        """Return the entry of a topic (name and type) in one storage file, or None."""
        return next((t for t in part.topics()
                     if (t.name, t.msgtype) == (topic.name, topic.msgtype)), None)

    def count(self, topic: Topic) -> int | None:
        """Count a topic's messages over all files (metadata.yaml's count if they cannot)."""
        total = 0
        for part in self.parts:
            own = self._own(part, topic)
            count = part.count(own) if own is not None else 0
            if count is None:
                return topic.n_messages
            total += count
        return total

    def pieces(self, topic: Topic) -> Iterator[Piece]:
        """Yield the topic's messages file after file (split bags)."""
        for part in self.parts:
            own = self._own(part, topic)
            if own is not None:
                yield from part.pieces(own)

    def close(self) -> None:
        """Close every file and remove decompressed copies."""
        for part in self.parts:
            part.close()
        if self.tmp is not None:
            self.tmp.cleanup()


def open_backend(path: PathLike, warnings: list[str]) -> Backend:
    """Open a bag file or directory with the reader of its storage (InputError when none)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    if path.is_dir():
        if not ((path / 'metadata.yaml').exists() or any(
                f.suffix in ('.mcap', '.db3', '.zstd') for f in path.iterdir())):
            raise InputError(f'{path}: directory without metadata.yaml or .db3/.mcap files: '
                             'not a rosbag2 bag')
        return _Rosbag2DirBackend(path, warnings)
    if path.name == 'metadata.yaml':
        return _Rosbag2DirBackend(path.parent, warnings)
    return _open_file(path, warnings)
