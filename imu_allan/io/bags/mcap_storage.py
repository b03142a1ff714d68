"""
MCAP storage: chunks found by a record walk and the summary, checked, decoded in bulk.

Part of :mod:`imu_allan.io.bag_reader`.  The file is read with plain reads, never
mapped: a file that shrinks while it is read is a short read (a truncation), not a
SIGBUS.  Every chunk whose uncompressed CRC is stated is checked (MCAP specification,
Chunk record, https://mcap.dev/spec); a damaged chunk is skipped with a warning and the
walk goes on past a damaged record, to the next chunk the summary's chunk index names
or the next plausible record header.  Message indexes are only counts here: every
chunk is walked record by record, so a damaged index loses nothing.
"""

import os
from pathlib import Path
import struct
from typing import Callable, Iterator, NamedTuple
import zlib

import lz4.frame
from mcap.reader import make_reader
import numpy as np
import zstandard

from imu_allan.errors import InputError
from imu_allan.io.bags.base import _FETCH_ROWS, _make_piece, Backend, MCAP_MAGIC, Piece, Topic
from imu_allan.io.bags.mcap_records import (_MCAP_MESSAGE, _OP_CHANNEL, _OP_CHUNK,
                                            _OP_DATA_END, _OP_FOOTER, _OP_HEADER, _OP_MESSAGE,
                                            _OP_MESSAGE_INDEX, _OP_SCHEMA, walk)
from imu_allan.io.imu_cdr import read_records

#: Bytes read at a time while walking small records.
_WINDOW = 1 << 16
_COMPRESSIONS = (b'', b'zstd', b'lz4')


class _Chunk(NamedTuple):
    """One chunk record: where it is, its start log time and its indexed counts."""

    pos: int
    end: int                           # end of the record (or of the file, if cut)
    start_ns: int
    counts: dict[int, int] | None      # message index entries per channel, if indexed


class _Loose(NamedTuple):
    """A run of Message records outside chunks: [start, end) and their offsets."""

    start: int
    end: int
    offsets: np.ndarray


# Long by design: one reader of one MCAP file; its state (open file, summary, chunk
# list, channel table) is shared by the reading steps, each a short method.
class _McapBackend(Backend):
    """MCAP storage (ros2 or ros1 profile), chunked or not, with or without a summary."""

    storage = 'mcap'

    def __init__(self, path: Path, warnings: list[str],
                 decompress: Callable[[bytes], bytes] | None = None) -> None:
        super().__init__(path, warnings, decompress)
        self.zstd = zstandard.ZstdDecompressor()
        self.file = open(path, 'rb')
        self.size = os.fstat(self.file.fileno()).st_size
        self.schemas: dict[int, str] = {}
        self.channels: dict[int, tuple[str, int, str]] = {}
        self.counts: dict[int, int] | None = None
        self.indexed: list[tuple[int, int]] = []      # (start, end) from the chunk index
        self.items: list[_Chunk | _Loose] = []
        self.damage: list[str] = []
        self.data_crc = (0, 0)                        # (DataEnd position, its CRC)
        self.stated = False                           # counts from the summary's statistics
        self.stated_extent: tuple[int, int, int] | None = None
        self._window = (0, b'')
        try:
            self._open()
        except BaseException as err:
            self.close()
            if isinstance(err, (struct.error, ValueError, IndexError, UnicodeDecodeError,
                                OverflowError, OSError)):
                raise InputError(f'{path}: damaged MCAP file ({err})') from None
            raise

    # -- plain reads ----------------------------------------------------------------
    def _read(self, pos: int, n: int) -> bytes:
        """Return up to n bytes at pos (fewer at the end of the file)."""
        if n <= 0 or pos >= self.size:
            return b''
        return os.pread(self.file.fileno(), min(n, self.size - pos), pos)

    def _peek(self, pos: int, n: int) -> bytes:
        """Return n bytes at pos through a small read-ahead window (short at the end)."""
        start, data = self._window
        if not (start <= pos and pos + n <= start + len(data)):
            data = self._read(pos, max(n, _WINDOW))
            self._window = start, data = pos, data
        return data[pos - start:pos - start + n]

    # -- opening --------------------------------------------------------------------
    def _open(self) -> None:
        head = self._read(0, 17)
        if head[:8] != MCAP_MAGIC or len(head) < 17 or head[8] != _OP_HEADER:
            raise InputError(f'{self.path}: not an MCAP file (bad magic or header)')
        self.data_start = 17 + struct.unpack_from('<Q', head, 9)[0]
        tail = self._read(self.size - 37, 37) if self.size >= self.data_start + 37 else b''
        self.complete = tail[-8:] == MCAP_MAGIC and tail[:1] == bytes([_OP_FOOTER])
        self.data_end = self.size
        if self.complete:
            summary_start = struct.unpack_from('<Q', tail, 9)[0]
            if self.data_start <= summary_start <= self.size - 37:
                self.data_end = summary_start or self.size - 37
            if summary_start:
                self._read_summary()
        self._scan()
        if not self.complete:
            self.warnings.append(f'{self.path}: MCAP file is truncated (no footer: recording cut '
                                 'short?); every complete message is read')

    def _read_summary(self) -> None:
        try:
            self.file.seek(0)
            summary = make_reader(self.file).get_summary()
        except Exception as err:   # noqa: B902 - any failure of the library: scan instead
            self.warnings.append(f'{self.path}: unreadable MCAP summary '
                                 f'({type(err).__name__}: {err}); scanning the data')
            return
        if summary is None:
            return
        for schema in summary.schemas.values():
            self.schemas[schema.id] = schema.name
        for channel in summary.channels.values():
            self.channels[channel.id] = (channel.topic, channel.schema_id,
                                         channel.message_encoding)
        if summary.statistics is not None:
            stats = summary.statistics
            self.counts = dict(stats.channel_message_counts)
            self.stated = True
            if stats.message_count:
                self.stated_extent = (stats.message_start_time, stats.message_end_time,
                                      stats.message_count)
        self.indexed = sorted((c.chunk_start_offset, c.chunk_start_offset + c.chunk_length)
                              for c in summary.chunk_indexes)

    def _add_record(self, op: int, buf: bytes, pos: int) -> None:
        """Register a Schema or Channel record whose body starts at pos in buf."""
        try:
            if op == _OP_SCHEMA:
                schema_id, size = struct.unpack_from('<HI', buf, pos)
                self.schemas.setdefault(schema_id, bytes(buf[pos + 6:pos + 6 + size])
                                        .decode('utf-8', 'replace'))
            else:
                channel_id, schema_id, size = struct.unpack_from('<HHI', buf, pos)
                topic = bytes(buf[pos + 8:pos + 8 + size]).decode('utf-8', 'replace')
                size2 = struct.unpack_from('<I', buf, pos + 8 + size)[0]
                start = pos + 12 + size
                encoding = bytes(buf[start:start + size2]).decode('utf-8', 'replace')
                self.channels.setdefault(channel_id, (topic, schema_id, encoding))
        except struct.error:
            self.damage.append(f'damaged schema or channel record at byte {pos}')

    # -- data section walk ----------------------------------------------------------
    def _header(self, pos: int) -> tuple[int, int] | None:
        """(opcode, record end) of the record at pos, or None where none can be."""
        head = self._peek(pos, 9)
        if len(head) < 9:
            return None
        op, length = head[0], struct.unpack_from('<Q', head, 1)[0]
        if op == 0 or 0x10 <= op < 0x80:
            return None
        return op, pos + 9 + length

    def _chunk_ok(self, pos: int, end: int) -> bool:
        """Whether a plausible Chunk record starts at pos (its lengths add up)."""
        head = self._peek(pos, 45)
        if len(head) < 41 or head[0] != _OP_CHUNK:
            return False
        length = struct.unpack_from('<Q', head, 1)[0]
        name_len = struct.unpack_from('<I', head, 37)[0]
        if name_len > 4:
            return False
        body = self._peek(pos + 41, name_len + 8)
        if len(body) < name_len + 8 or body[:name_len] not in _COMPRESSIONS:
            return False
        data_len = struct.unpack_from('<Q', body, name_len)[0]
        return length == 40 + name_len + data_len and (pos + 9 + length <= end
                                                       or not self.complete)

    def _message_ok(self, pos: int, end: int) -> bool:
        """Whether a plausible loose Message record starts at pos, followed by another."""
        head = self._peek(pos, 11)
        if len(head) < 11 or head[0] != _OP_MESSAGE:
            return False
        length = struct.unpack_from('<Q', head, 1)[0]
        channel = struct.unpack_from('<H', head, 9)[0]
        nxt = pos + 9 + length
        return (22 <= length and nxt <= end and channel in self.channels
                and (nxt == end or self._header(nxt) is not None))

    def _resync(self, pos: int, end: int) -> int | None:
        """Return the next position after pos where a plausible record starts."""
        known = [s for s, _ in self.indexed if s > pos]
        limit = min(known[0] if known else end, end)
        at = pos + 1
        while at < limit:
            window = self._read(at, min(1 << 20, limit - at))
            if not window:
                break
            for k in np.flatnonzero((np.frombuffer(window, np.uint8) == _OP_CHUNK)
                                    | (np.frombuffer(window, np.uint8) == _OP_MESSAGE)).tolist():
                if self._chunk_ok(at + k, end) or self._message_ok(at + k, end):
                    return at + k
            at += len(window)
        return known[0] if known and known[0] < end else None

    def _scan(self) -> None:
        """
        Walk the data section's records: chunks and loose message runs in file order.

        A record that cannot be (opcode 0, a length past the data section of a complete
        file) is damage: the walk resumes at the next plausible record; chunks that the
        summary's chunk index names and the walk missed are added.
        """
        pos, end = self.data_start, self.data_end
        counts: dict[int, dict[int, int]] = {}
        loose: list[int] = []
        found: set[int] = set()
        last_chunk: int | None = None

        def flush():
            if loose:
                last = self._header(loose[-1])
                self.items.append(_Loose(loose[0], last[1] if last else end,
                                         np.array(loose, np.int64)))
                loose.clear()
        while pos + 9 <= end:
            rec = self._header(pos)
            if rec is not None and rec[1] > end and not self.complete and rec[0] == _OP_CHUNK:
                flush()
                self.items.append(_Chunk(pos, end, self._start_ns(pos), None))
                found.add(pos)
                break
            if rec is None or rec[1] > end:
                if not self.complete and rec is not None:
                    break   # the last record, cut short
                flush()
                nxt = self._resync(pos, end)
                self.damage.append(f'damaged record at byte {pos}'
                                   + ('' if nxt is None else f', resumed at byte {nxt}'))
                if nxt is None:
                    break
                pos = nxt
                continue
            op, rec_end = rec
            if op != _OP_MESSAGE_INDEX:
                last_chunk = None
            if op == _OP_MESSAGE:
                loose.append(pos)
                if len(loose) >= _FETCH_ROWS:
                    flush()
            elif op == _OP_MESSAGE_INDEX and last_chunk is not None:
                body = self._peek(pos + 9, 6)
                if len(body) == 6:
                    channel_id, size = struct.unpack_from('<HI', body)
                    per = counts.setdefault(last_chunk, {})
                    per[channel_id] = per.get(channel_id, 0) + size // 16
            else:
                flush()
                if op == _OP_CHUNK:
                    if self._chunk_ok(pos, end):
                        self.items.append(_Chunk(pos, rec_end, self._start_ns(pos), None))
                        found.add(pos)
                        last_chunk = pos
                    else:
                        self.damage.append(f'damaged chunk header at byte {pos}')
                elif op in (_OP_SCHEMA, _OP_CHANNEL):
                    self._add_record(op, self._peek(pos + 9, rec_end - pos - 9), 0)
                elif op == _OP_DATA_END:
                    body = self._peek(pos + 9, 4)
                    self.data_crc = (pos, struct.unpack('<I', body)[0] if len(body) == 4 else 0)
                    break
                elif op == _OP_FOOTER:
                    break
            pos = rec_end
        flush()
        for start, stop in self.indexed:
            if start not in found and stop <= end and self._chunk_ok(start, end):
                self.items.append(_Chunk(start, stop, self._start_ns(start), None))
        self.items = self._without_overlap(
            [it._replace(counts=counts.get(it.pos)) if isinstance(it, _Chunk) else it
             for it in self.items])
        chunks = [it for it in self.items if isinstance(it, _Chunk)]
        if len(chunks) == len(self.items):
            # Chunks may overlap in time (valid MCAP): read them in start-time order.
            chunks.sort(key=lambda c: (c.start_ns, c.pos))
            self.items = list(chunks)
        if self.counts is None:
            self.counts = self._index_counts()
        if not self.channels or self.counts is None:
            self._discover()

    @staticmethod
    def _without_overlap(items: list) -> list:
        """Drop loose messages inside a chunk (found by a resync into its records)."""
        spans = sorted((it.pos, it.end) for it in items if isinstance(it, _Chunk))
        if not spans:
            return items
        starts = np.array([a for a, _ in spans], np.int64)
        ends = np.array([b for _, b in spans], np.int64)
        out = []
        for it in items:
            if isinstance(it, _Loose):
                k = np.searchsorted(starts, it.offsets, 'right') - 1
                inside = (k >= 0) & (it.offsets < ends[np.maximum(k, 0)])
                if inside.all():
                    continue
                it = it._replace(offsets=it.offsets[~inside])
            out.append(it)
        return out

    def _start_ns(self, pos: int) -> int:
        head = self._peek(pos + 9, 8)
        return struct.unpack('<Q', head)[0] if len(head) == 8 else 0

    def _index_counts(self) -> dict[int, int] | None:
        """Message counts per channel from the message indexes, when every chunk has them."""
        chunks = [it for it in self.items if isinstance(it, _Chunk)]
        if not chunks or any(c.counts is None for c in chunks) or not self.complete:
            return None
        total: dict[int, int] = {}
        for chunk in chunks:
            for channel_id, k in (chunk.counts or {}).items():
                total[channel_id] = total.get(channel_id, 0) + k
        return total

    def _discover(self) -> None:
        """Count messages per channel by reading the data (no usable summary or index)."""
        counts: dict[int, int] = {}
        for item in self.items:
            if isinstance(item, _Chunk):
                raw = self._chunk_data(item, lambda text: None)
                if raw is None:
                    for channel_id, k in (item.counts or {}).items():
                        counts[channel_id] = counts.get(channel_id, 0) + k
                    continue
                u8 = np.frombuffer(raw, np.uint8)
                offsets = walk(raw, self._add_record)
                ids = read_records(u8, offsets[offsets + 31 <= u8.size], _MCAP_MESSAGE)['channel']
            else:
                data = np.frombuffer(self._read(item.start, item.end - item.start), np.uint8)
                offsets = item.offsets - item.start
                ids = read_records(data, offsets[offsets + 31 <= data.size],
                                   _MCAP_MESSAGE)['channel']
            for channel_id, k in zip(*np.unique(ids, return_counts=True)):
                counts[int(channel_id)] = counts.get(int(channel_id), 0) + int(k)
        self.counts = counts

    # -- chunks ---------------------------------------------------------------------
    def _chunk_data(self, chunk: _Chunk, lost: Callable[[str], None]) -> bytes | None:
        """Return a chunk's records decompressed and CRC-checked, or None (with a reason)."""
        record = self._read(chunk.pos, chunk.end - chunk.pos)
        complete = len(record) == chunk.end - chunk.pos and chunk.end <= self.data_end
        if len(record) < 41:
            return None
        size, crc, name_len = struct.unpack_from('<QII', record, 25)
        compression = record[41:41 + name_len]
        data_len = struct.unpack_from('<Q', record, 41 + name_len)[0]
        data_pos = 49 + name_len
        data = memoryview(record)[data_pos:data_pos + data_len]
        complete = complete and len(data) == data_len
        try:
            if compression == b'':
                raw = bytes(data)
            elif compression == b'zstd' and complete:
                raw = self.zstd.decompress(data, max_output_size=max(size, 1))
            elif compression == b'zstd':
                raw = self.zstd.decompressobj().decompress(data)   # a cut chunk's whole blocks
            elif compression == b'lz4' and complete:
                raw = lz4.frame.decompress(bytes(data))
            elif compression == b'lz4':
                raw = lz4.frame.LZ4FrameDecompressor().decompress(bytes(data))
            else:
                lost(f'chunk compression {compression!r} is not supported')
                return None
        except (zstandard.ZstdError, RuntimeError, ValueError, MemoryError) as err:
            if complete:
                lost(f'undecompressable chunk at byte {chunk.pos} ({err})')
                return None
            raw = b''
        if complete and (len(raw) != size or (crc and zlib.crc32(raw) != crc)):
            lost(f'chunk at byte {chunk.pos} fails its CRC check')
            return None
        return raw

    def _data_crc_ok(self) -> bool:
        """Check the DataEnd record's CRC of the data section (no chunk CRC covers it)."""
        end, want = self.data_crc
        crc, pos = 0, 0
        while want and pos < end:
            block = self._read(pos, min(1 << 24, end - pos))
            if not block:
                return False
            crc = zlib.crc32(block, crc)
            pos += len(block)
        return not want or crc == want

    # -- reading --------------------------------------------------------------------
    def topics(self) -> list[Topic]:
        """Return one entry per topic and type (channels of both are merged)."""
        found: dict[tuple[str, str], Topic] = {}
        for channel_id, (name, schema_id, encoding) in sorted(self.channels.items()):
            count = None if self.counts is None else self.counts.get(channel_id, 0)
            msgtype = self.schemas.get(schema_id, '')
            old = found.get((name, msgtype))
            if old is not None:
                both = None if count is None or old.n_messages is None else old.n_messages + count
                found[name, msgtype] = old._replace(n_messages=both)
            else:
                found[name, msgtype] = Topic(name, msgtype, count, encoding)
        return list(found.values())

    def count(self, topic: Topic) -> int | None:
        """
        Return the topic's count as the file states it, or None when it cannot be known.

        A truncated file lost its summary; counts gathered from indexes or a scan of a
        damaged file miss what the damage hid.
        """
        if not self.complete or (self.damage and not self.stated):
            return None
        return topic.n_messages

    def extent(self) -> tuple[int | None, int | None, int | None]:
        """Return the summary's time span and count, else the first chunk's start time."""
        if self.stated_extent is not None and not self.damage:
            return self.stated_extent
        starts = [it.start_ns for it in self.items if isinstance(it, _Chunk)]
        return (min(starts) if starts else None), None, None

    def _message_piece(self, buf: np.ndarray, offsets: np.ndarray, wanted: set,
                       encoding: str) -> Piece | None:
        """Decode the Message records at (k,) offsets of buf that belong to wanted."""
        offsets = offsets[offsets + 31 <= buf.size]
        if offsets.size == 0:
            return None
        heads = read_records(buf, offsets, _MCAP_MESSAGE)
        channels = heads['channel']
        if len(wanted) == 1:
            mine = channels == next(iter(wanted))
        else:
            mine = np.isin(channels, list(wanted))
        lengths = heads['length'].astype(np.int64) - 22
        mine &= (lengths >= 0) & (offsets + 31 + lengths <= buf.size)
        if not mine.all():
            offsets, heads, lengths = offsets[mine], heads[mine], lengths[mine]
        if offsets.size == 0:
            return None
        return _make_piece(buf, offsets + 31, lengths, heads['log_time'].astype(np.int64),
                           encoding, self.decompress)

    def pieces(self, topic: Topic) -> Iterator[Piece]:
        """Yield the topic's messages chunk by chunk; damage is skipped with a warning."""
        # By name and type: another message type on the same topic is not this topic.
        wanted = {cid for cid, (name, schema_id, _) in self.channels.items()
                  if name == topic.name and self.schemas.get(schema_id, '') == topic.msgtype}
        for text in self.damage:
            self.warnings.append(f'{self.path}: {text}')
        if any(isinstance(it, _Loose) for it in self.items) and not self._data_crc_ok():
            self.warnings.append(f'{self.path}: the data section fails its CRC check: values '
                                 'of messages outside chunks may be damaged')
        for item in self.items:
            if isinstance(item, _Chunk):
                raw = self._chunk_data(item, lambda text: self.warnings.append(
                    f'{self.path}: {text}; chunk skipped'))
                if raw is None:
                    continue
                offsets = walk(raw, self._add_record)
                piece = self._message_piece(np.frombuffer(raw, np.uint8), offsets,
                                            wanted, topic.encoding)
            else:
                data = self._read(item.start, item.end - item.start)
                piece = self._message_piece(np.frombuffer(data, np.uint8),
                                            item.offsets - item.start, wanted, topic.encoding)
            if piece is not None:
                yield piece

    def close(self) -> None:
        """Close the file."""
        self.file.close()
