"""
The MCAP part of the bag writer: chunked, indexed MCAP files as rosbag2 writes them.

Messages go out as numpy-built Message records, one zstd-compressed chunk of about
:data:`~imu_allan.io.bag_writer.MCAP_CHUNK_BYTES` at a time, with message indexes and a
summary section (schema, channel, statistics, chunk indexes, rosbag2 metadata), so
readers can seek; the ``mcap`` package's record classes encode the small records.
"""

from pathlib import Path
import struct
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel, ChunkIndex, DataEnd, Footer, Header, Metadata, MetadataIndex, Schema,
    Statistics, SummaryOffset)
import numpy as np
import yaml
import zstandard

from imu_allan import __version__
from imu_allan.io.bags.base import MCAP_MAGIC
from imu_allan.io.imu_cdr import imu_msgdef, IMU_MSGTYPE


def _mcap_message_records(payloads: np.ndarray, recv_ns: np.ndarray,
                          first_seq: int) -> np.ndarray:
    """
    Lay out MCAP Message records (opcode 0x05) back to back.

    Parameters
    ----------
    payloads : numpy.ndarray
        (k, L) uint8 serialised messages.
    recv_ns : numpy.ndarray
        (k,) int64 log_time = publish_time [ns].
    first_seq : int
        Sequence number of the first message.

    Returns
    -------
    numpy.ndarray
        (k,) structured records, each 31 + L bytes.

    """
    size = payloads.shape[1]
    rec = np.dtype({'names': ['op', 'length', 'channel', 'seq', 'log', 'pub', 'data'],
                    'formats': ['u1', '<u8', '<u2', '<u4', '<u8', '<u8', ('u1', (size,))],
                    'offsets': [0, 1, 9, 11, 15, 23, 31], 'itemsize': 31 + size})
    out = np.empty(recv_ns.size, rec)
    out['op'] = Opcode.MESSAGE
    out['length'] = 22 + size
    out['channel'] = 1
    out['seq'] = (np.arange(recv_ns.size, dtype=np.uint64) + first_seq) % 2**32
    out['log'] = recv_ns
    out['pub'] = recv_ns
    out['data'] = payloads
    return out


def _write_mcap(mcap_path: Path, topic: str, batches, info: dict) -> None:
    """
    Write a ros2-profile MCAP file: zstd chunks, message indexes and a full summary.

    Parameters
    ----------
    mcap_path : pathlib.Path
        New .mcap file.
    topic : str
        Topic name.
    batches : iterable of (numpy.ndarray, numpy.ndarray)
        ((k, L) uint8 serialised messages, (k,) int64 receive time [ns]) pairs; each batch
        becomes one chunk.
    info : dict
        rosbag2_bagfile_information, stored as the 'rosbag2' metadata record.

    """
    msgdef, rihs01 = imu_msgdef()
    builder = RecordBuilder()
    schema = Schema(id=1, name=IMU_MSGTYPE, encoding='ros2msg', data=msgdef.encode())
    channel = Channel(id=1, topic=topic, message_encoding='cdr', schema_id=1,
                      metadata={'offered_qos_profiles': '', 'topic_type_hash': rihs01})
    compressor = zstandard.ZstdCompressor(level=1)
    chunk_indexes = []
    n_messages, t_first, t_last = 0, 0, 0
    with open(mcap_path, 'xb') as out:
        out.write(MCAP_MAGIC)
        Header(profile='ros2', library=f'imu_allan {__version__}').write(builder)
        schema.write(builder)
        channel.write(builder)
        out.write(builder.end())
        for payloads, recv_ns in batches:
            records = _mcap_message_records(payloads, recv_ns, n_messages)
            raw = records.tobytes()
            packed = compressor.compress(raw)
            t_min, t_max = int(recv_ns.min()), int(recv_ns.max())
            t_first = t_min if not n_messages else min(t_first, t_min)
            t_last = max(t_last, t_max)
            n_messages += recv_ns.size
            chunk_start = out.tell()
            body = 8 + 8 + 8 + 4 + 4 + 4 + 8 + len(packed)
            out.write(struct.pack('<BQQQQII4sQ', Opcode.CHUNK, body, t_min, t_max, len(raw),
                                  zlib.crc32(raw), 4, b'zstd', len(packed)))
            out.write(packed)
            index_start = out.tell()
            index = np.empty((recv_ns.size, 2), '<u8')
            index[:, 0] = recv_ns
            index[:, 1] = np.arange(recv_ns.size, dtype=np.uint64) * records.itemsize
            out.write(struct.pack('<BQHI', Opcode.MESSAGE_INDEX, 6 + index.nbytes, 1,
                                  index.nbytes))
            out.write(index.tobytes())
            chunk_indexes.append(ChunkIndex(
                message_start_time=t_min, message_end_time=t_max, chunk_start_offset=chunk_start,
                chunk_length=index_start - chunk_start, message_index_offsets={1: index_start},
                message_index_length=out.tell() - index_start, compression='zstd',
                compressed_size=len(packed), uncompressed_size=len(raw)))
        meta_start = out.tell()
        # rosbag2's own MCAP plug-in stores the bag information as a 'rosbag2' record too.
        Metadata(name='rosbag2',
                 metadata={'serialized_metadata': yaml.safe_dump(info, sort_keys=False)}
                 ).write(builder)
        meta_index = MetadataIndex(offset=meta_start, length=builder.count, name='rosbag2')
        DataEnd(data_section_crc=0).write(builder)
        out.write(builder.end())
        summary_start = out.tell()
        statistics = Statistics(
            message_count=n_messages, schema_count=1, channel_count=1, attachment_count=0,
            metadata_count=1, chunk_count=len(chunk_indexes), message_start_time=t_first,
            message_end_time=t_last, channel_message_counts={1: n_messages})
        groups: list[tuple[int, list]] = [
            (Opcode.SCHEMA, [schema]), (Opcode.CHANNEL, [channel]),
            (Opcode.STATISTICS, [statistics]), (Opcode.CHUNK_INDEX, chunk_indexes),
            (Opcode.METADATA_INDEX, [meta_index])]
        offsets: list = []
        for opcode, group in groups:
            group_start = builder.count
            for record in group:
                record.write(builder)
            if builder.count > group_start:
                offsets.append(SummaryOffset(group_opcode=opcode,
                                             group_start=summary_start + group_start,
                                             group_length=builder.count - group_start))
        offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        # The footer CRC covers the summary and the footer's own fields before the CRC.
        crc = zlib.crc32(struct.pack('<BQQQ', Opcode.FOOTER, 20, summary_start, offset_start),
                         zlib.crc32(summary))
        out.write(summary)
        Footer(summary_start=summary_start, summary_offset_start=offset_start,
               summary_crc=crc).write(builder)
        out.write(builder.end())
        out.write(MCAP_MAGIC)
