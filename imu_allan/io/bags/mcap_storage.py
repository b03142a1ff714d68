"""
MCAP storage: whole chunks located through the message indexes, decoded in bulk.

Part of :mod:`imu_allan.io.bag_reader`.
"""

import mmap
from pathlib import Path
import struct
from typing import Callable, Iterator, NamedTuple

import lz4.frame
from mcap.exceptions import McapError
from mcap.reader import make_reader
import numpy as np
import zstandard

from imu_allan.core import native
from imu_allan.errors import InputError
from imu_allan.io.bags.base import _Backend, _FETCH_ROWS, _make_piece, _MCAP_MAGIC, _Piece, _Topic
from imu_allan.io.imu_cdr import _records, payload_frame_id

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
_OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX, _OP_DATA_END = 0x05, 0x06, 0x07, 0x0F
_MCAP_MESSAGE = np.dtype({'names': ['op', 'length', 'channel', 'log_time'],
                          'formats': ['u1', '<u8', '<u2', '<u8'], 'offsets': [0, 1, 9, 15],
                          'itemsize': 31})


class _ChunkInfo(NamedTuple):
    """Location of one MCAP chunk and its message index (None when absent)."""

    record_pos: int
    body_end: int
    complete: bool
    indexes: dict[int, np.ndarray] | None


# Long by design: one reader of one MCAP file; its state (open file, summary, chunk
# index, channel table) is shared by the reading steps, each a short method.
class _McapBackend(_Backend):
    """MCAP storage (ros2 or ros1 profile), chunked or not, with or without a summary."""

    storage = 'mcap'

    def __init__(self, path: Path, warnings: list[str],
                 decompress: Callable[[bytes], bytes] | None = None) -> None:
        super().__init__(path, warnings, decompress)
        self.zstd = zstandard.ZstdDecompressor()
        self.file = open(path, 'rb')
        self.mm = mmap.mmap(self.file.fileno(), 0, access=mmap.ACCESS_READ)
        self.u8 = np.frombuffer(self.mm, np.uint8)
        self._released = 0   # pages before this offset were handed back (_release)
        self.schemas: dict[int, str] = {}
        self.channels: dict[int, tuple[str, int, str]] = {}
        self.counts: dict[int, int] | None = None
        try:
            self._open()
        except BaseException as err:
            self.close()
            if isinstance(err, (struct.error, ValueError, IndexError, UnicodeDecodeError)):
                raise InputError(f'{path}: damaged MCAP file ({err})') from None
            raise

    def _open(self) -> None:
        path, size = self.path, self.mm.size()
        if self.mm[:8] != _MCAP_MAGIC or size < 17 or self.mm[8] != _OP_HEADER:
            raise InputError(f'{path}: not an MCAP file (bad magic or header)')
        self.data_start = 9 + 8 + struct.unpack_from('<Q', self.mm, 9)[0]
        tail = self.mm[size - 37:] if size >= self.data_start + 37 else b''
        self.complete = tail[-8:] == _MCAP_MAGIC and tail[:1] == bytes([_OP_FOOTER])
        self.data_end = size
        if self.complete:
            summary_start = struct.unpack_from('<Q', tail, 9)[0]
            self.data_end = summary_start or size - 37
            if summary_start:
                self._read_summary()
        if not self.channels or self.counts is None:
            self._discover()
        if not self.complete:
            self.warnings.append(f'{path}: MCAP file is truncated (no footer: recording cut '
                                 'short?); every complete message is read')

    # -- summary and discovery ------------------------------------------------------
    def _read_summary(self) -> None:
        try:
            self.file.seek(0)
            summary = make_reader(self.file).get_summary()
        except (McapError, struct.error, ValueError, EOFError, OSError) as err:
            self.warnings.append(f'{self.path}: unreadable MCAP summary ({err}); scanning')
            return
        if summary is None:
            return
        for schema in summary.schemas.values():
            self.schemas[schema.id] = schema.name
        for channel in summary.channels.values():
            self.channels[channel.id] = (channel.topic, channel.schema_id,
                                         channel.message_encoding)
        if summary.statistics is not None:
            self.counts = dict(summary.statistics.channel_message_counts)

    def _add_record(self, op: int, buf, pos: int) -> None:
        """Register a Schema or Channel record whose body starts at pos in buf."""
        if op == _OP_SCHEMA:
            schema_id = struct.unpack_from('<H', buf, pos)[0]
            size = struct.unpack_from('<I', buf, pos + 2)[0]
            name = bytes(buf[pos + 6:pos + 6 + size])
            self.schemas[schema_id] = name.decode('utf-8', 'replace')
        elif op == _OP_CHANNEL:
            channel_id, schema_id = struct.unpack_from('<HH', buf, pos)
            size = struct.unpack_from('<I', buf, pos + 4)[0]
            topic = bytes(buf[pos + 8:pos + 8 + size]).decode('utf-8', 'replace')
            pos += 8 + size
            size2 = struct.unpack_from('<I', buf, pos)[0]
            encoding = bytes(buf[pos + 4:pos + 4 + size2]).decode('utf-8', 'replace')
            self.channels[channel_id] = (topic, schema_id, encoding)

    def _discover(self) -> None:
        """Scan the data section for channels and message counts (no usable summary)."""
        counts: dict[int, int] = {}
        for item in self._scan():
            if isinstance(item, _ChunkInfo):
                if item.indexes is not None and all(c in self.channels for c in item.indexes):
                    for channel_id, index in item.indexes.items():
                        counts[channel_id] = counts.get(channel_id, 0) + len(index)
                    continue
                raw = self._chunk_data(item)
                if raw is None:
                    continue
                offsets = self._walk(raw)
                channel_ids = _records(np.frombuffer(raw, np.uint8), offsets,
                                       _MCAP_MESSAGE)['channel']
            else:
                channel_ids = _records(self.u8, item, _MCAP_MESSAGE)['channel']
            for channel_id, k in zip(*np.unique(channel_ids, return_counts=True)):
                counts[int(channel_id)] = counts.get(int(channel_id), 0) + int(k)
        self.counts = counts

    # -- data section scan ----------------------------------------------------------
    def _scan(self) -> Iterator[_ChunkInfo | np.ndarray]:
        """
        Walk the records of the data section.

        Yields
        ------
        _ChunkInfo or numpy.ndarray
            Each chunk (with the message indexes that follow it), or (k,) int64 record
            offsets of a run of messages stored outside chunks.

        """
        mm, end = self.mm, self.data_end
        pos = self.data_start
        pending: _ChunkInfo | None = None
        loose: list[int] = []
        while True:
            if pos + 9 > end:
                break
            op = mm[pos]
            body_end = pos + 9 + struct.unpack_from('<Q', mm, pos + 1)[0]
            if body_end > end:
                if pending is not None:
                    # Cut among the chunk's message indexes: they may be incomplete.
                    yield pending._replace(indexes=None)
                    pending = None
                if op == _OP_CHUNK:
                    yield _ChunkInfo(pos, end, False, None)
                break
            if op == _OP_MESSAGE_INDEX and pending is not None:
                channel_id, size = struct.unpack_from('<HI', mm, pos + 9)
                size = min(size, body_end - pos - 15) // 16 * 16
                index = np.frombuffer(mm, '<u8', count=size // 8, offset=pos + 15)
                indexes = pending.indexes if pending.indexes is not None else {}
                indexes[channel_id] = index.reshape(-1, 2)
                pending = pending._replace(indexes=indexes)
                pos = body_end
                continue
            if pending is not None:
                yield pending
                pending = None
            if op == _OP_MESSAGE:
                loose.append(pos)
                if len(loose) >= _FETCH_ROWS:
                    yield np.array(loose, np.int64)
                    loose = []
                pos = body_end
                continue
            if loose:
                yield np.array(loose, np.int64)
                loose = []
            if op == _OP_CHUNK:
                pending = _ChunkInfo(pos, body_end, True, None)
            elif op in (_OP_SCHEMA, _OP_CHANNEL):
                self._add_record(op, mm, pos + 9)
            elif op in (_OP_DATA_END, _OP_FOOTER):
                break
            pos = body_end
        if pending is not None:
            yield pending
        if loose:
            yield np.array(loose, np.int64)

    def _chunk_data(self, chunk: _ChunkInfo) -> bytes | None:
        """Return a chunk's records decompressed (what is readable, if cut short)."""
        mm, body = self.mm, chunk.record_pos + 9
        try:
            size = struct.unpack_from('<Q', mm, body + 16)[0]
            name_len = struct.unpack_from('<I', mm, body + 28)[0]
            compression = bytes(mm[body + 32:body + 32 + name_len]).decode()
            data_len = struct.unpack_from('<Q', mm, body + 32 + name_len)[0]
        except (struct.error, UnicodeDecodeError):
            return None
        data_pos = body + 40 + name_len
        # A view of the map: zstd reads it in place (a slice of the map is a copy).
        data = memoryview(self.u8[data_pos:min(data_pos + data_len, chunk.body_end)])
        try:
            if compression == '':
                raw = data.tobytes()
            elif compression == 'zstd' and chunk.complete:
                raw = self.zstd.decompress(data, max_output_size=size)
            elif compression == 'zstd':
                # A chunk cut short: keep what its complete zstd blocks hold.
                raw = self.zstd.decompressobj().decompress(data)
            elif compression == 'lz4' and chunk.complete:
                raw = lz4.frame.decompress(data.tobytes())
            elif compression == 'lz4':
                raw = lz4.frame.LZ4FrameDecompressor().decompress(data.tobytes())
            else:
                self.warnings.append(f'{self.path}: chunk compression {compression!r} is not '
                                     'supported; chunk skipped')
                return None
        except (zstandard.ZstdError, RuntimeError, ValueError) as err:
            if chunk.complete:
                self.warnings.append(f'{self.path}: damaged chunk at byte {chunk.record_pos} '
                                     f'skipped ({err})')
            return None
        if chunk.complete and len(raw) != size:
            self.warnings.append(f'{self.path}: damaged chunk at byte {chunk.record_pos} '
                                 f'({len(raw)} of {size} bytes); its complete records are read')
        return raw

    def _walk(self, raw: bytes) -> np.ndarray:
        """
        Return (k,) int64 offsets of the Message records in decompressed chunk data.

        Runs of equally long messages (one topic recorded alone) are stepped over with
        one vectorised check instead of one Python iteration per record.
        """
        u8 = np.frombuffer(raw, np.uint8)
        end = len(raw)
        pos = 0
        runs = []
        unpack = struct.Struct('<Q').unpack_from
        while pos + 9 <= end:
            op = raw[pos]
            length = unpack(raw, pos + 1)[0]
            stride = 9 + length
            if pos + stride > end:
                break
            if op != _OP_MESSAGE:
                if op in (_OP_SCHEMA, _OP_CHANNEL):
                    self._add_record(op, raw, pos + 9)
                pos += stride
                continue
            run = 1
            nxt = pos + stride
            if (length >= 22 and nxt + 9 <= end and raw[nxt] == _OP_MESSAGE
                    and unpack(raw, nxt + 1)[0] == length):
                # Check growing windows of candidates: long runs cost a few numpy calls,
                # short ones (interleaved topics) only a small window.
                k = (end - pos) // stride
                window = 32
                while run < k:
                    cand = pos + stride * np.arange(run, min(k, run + window), dtype=np.int64)
                    if cand[-1] + 31 > end:
                        cand = cand[:-1]
                    heads = _records(u8, cand, _MCAP_MESSAGE)
                    same = (heads['op'] == _OP_MESSAGE) & (heads['length'] == length)
                    if not same.size:
                        break
                    if not same.all():
                        run += int(np.argmin(same))
                        break
                    run += cand.size
                    window *= 8
            runs.append(pos + stride * np.arange(run, dtype=np.int64))
            pos += stride * run
        return np.concatenate(runs) if runs else np.zeros(0, np.int64)

    # -- reading --------------------------------------------------------------------
    def topics(self) -> list[_Topic]:
        """Return one entry per topic (channels with the same topic are merged)."""
        found: dict[str, _Topic] = {}
        for channel_id, (name, schema_id, encoding) in sorted(self.channels.items()):
            count = (self.counts or {}).get(channel_id, 0)
            msgtype = self.schemas.get(schema_id, '')
            if name in found:
                old = found[name]
                found[name] = old._replace(n_messages=(old.n_messages or 0) + count)
            else:
                found[name] = _Topic(name, msgtype, count, encoding)
        return list(found.values())

    def _message_piece(self, buf: np.ndarray, offsets: np.ndarray, wanted: set,
                       encoding: str) -> _Piece | None:
        """Decode the Message records at (k,) offsets of buf that belong to wanted."""
        if offsets.size == 0:
            return None
        inside = offsets + 31 <= buf.size
        if not inside.all():
            offsets = offsets[inside]
        heads = _records(buf, offsets, _MCAP_MESSAGE)
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
        recv_ns = heads['log_time'].astype(np.int64)
        if recv_ns.size > 1 and (np.diff(recv_ns) < 0).any():
            order = np.argsort(recv_ns, kind='stable')
            offsets, lengths, recv_ns = offsets[order], lengths[order], recv_ns[order]
        return _make_piece(buf, offsets + 31, lengths, recv_ns, encoding, self.decompress)

    def _plain_piece(self, buf: np.ndarray, channel: int, offsets: np.ndarray,
                     encoding: str) -> _Piece | None:
        """
        Read one channel's indexed messages of a chunk in one compiled call, or None.

        The common case (every indexed record a Message of the channel, in log-time
        order, with plain Imu payloads, no per-message compression); anything else
        returns None and the chunk takes the general path, with the same result.
        """
        if native.LIB is None or self.decompress is not None or offsets.size == 0:
            return None
        got = native.mcap_imu(buf, offsets, channel, encoding == 'ros1')
        if got is None:
            return None
        first = int(offsets[0])
        size = int.from_bytes(buf[first + 1:first + 9].tobytes(), 'little') - 22
        frame_id = payload_frame_id(buf[first + 31:first + 31 + size].tobytes(), encoding)
        return _Piece(*got, 0, frame_id)

    def pieces(self, topic: _Topic) -> Iterator[_Piece]:
        """Yield the topic's messages chunk by chunk (stop with a warning at damage)."""
        try:
            yield from self._pieces(topic)
        except (struct.error, ValueError, IndexError) as err:
            self.warnings.append(f'{self.path}: damaged MCAP data ({err}); read stopped')

    def _pieces(self, topic: _Topic) -> Iterator[_Piece]:
        wanted = {cid for cid, (name, _, _) in self.channels.items() if name == topic.name}
        for item in self._scan():
            if isinstance(item, _ChunkInfo):
                if item.indexes is not None and not wanted & item.indexes.keys():
                    continue   # the index says: nothing of this topic inside
                raw = self._chunk_data(item)
                if raw is None:
                    continue
                buf = np.frombuffer(raw, np.uint8)
                offsets = None
                piece = None
                if item.indexes is not None:
                    parts = [(c, item.indexes[c][:, 1]) for c in wanted if c in item.indexes]
                    if len(parts) == 1:
                        piece = self._plain_piece(buf, *parts[0], topic.encoding)
                    if piece is None:
                        offsets = np.concatenate([o for _, o in parts]).astype(np.int64)
                        if not ((offsets + 31 <= buf.size).all()
                                and (buf[offsets] == _OP_MESSAGE).all()):
                            offsets = None   # an index that does not match the chunk: walk it
                if piece is None:
                    piece = self._message_piece(
                        buf, self._walk(raw) if offsets is None else offsets, wanted,
                        topic.encoding)
                self._release(item.body_end)
            else:
                piece = self._message_piece(self.u8, item, wanted, topic.encoding)
                self._release(int(item.max()) if item.size else 0)
            if piece is not None:
                yield piece

    def _release(self, pos: int) -> None:
        """
        Drop the pages before ``pos`` from this process's memory (not from the page cache).

        The map is read in file order and a decoded piece holds copies, so pages behind
        the reader are not needed again; without this the whole bag counts in the
        process's resident size (a night's bag: 0.9 GB), which is what a Dask worker's
        memory limit watches.
        """
        end = pos - pos % mmap.PAGESIZE
        if end > self._released and hasattr(mmap, 'MADV_DONTNEED'):
            try:
                self.mm.madvise(mmap.MADV_DONTNEED, self._released, end - self._released)
            except (OSError, ValueError):
                return
            self._released = end

    def close(self) -> None:
        """Release the memory map and the file."""
        self.u8 = np.empty(0, np.uint8)
        try:
            self.mm.close()
        except BufferError:
            pass   # a block still views the map; it closes when collected
        self.file.close()
