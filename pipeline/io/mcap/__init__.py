"""MCAP recordings: blocks of samples per message, one MCAP channel per recording channel.

Layout (full description, with the reasons, in ``data_schemas/mcap.md``):

* One Schema record ``meshphase.SampleBlock`` (encoding ``meshphase-layout``) whose data is a
  JSON description of the payload, validated by ``data_schemas/mcap_message.schema.json``.
* One MCAP channel per recording channel: topic = channel name, message encoding
  ``meshphase-block``, channel metadata = every :class:`~meshphase.recording.ChannelSpec`
  field plus ``fs``, ``index`` and ``dtype`` (``data_schemas/mcap_channel_metadata.schema.json``).
* One Metadata record ``meshphase.recording``: fs, t0, n_samples, channel order, dtype, block,
  log-time origin, start_datetime, meta and history (JSON).
* Messages: a 16-byte little-endian header (first sample index uint64, n_samples uint32,
  n_channels uint16 = 1, dtype code uint8, layout version uint8) followed by ``block`` samples
  (5120 by default) of one channel. ``log_time = log_time_origin_ns + floor(first_sample *
  1e9 / fs)`` [ns], with ``log_time_origin_ns = round(t0 * 1e9)`` for 0 <= t0 < 2**63 ns and 0
  otherwise (negative t0: log times count from the first sample).
* Chunks hold messages of one channel only, written in time-ordered groups (all channels of
  one stretch of time, then the next), so a one-channel read skips the other channels'
  chunks through the chunk index and a time-window read skips chunks outside the window.

Reads take the summary section (chunk index, channels, schema, metadata) from
``mcap.reader.make_reader`` and pick the chunks of the wanted channels whose log-time range
meets the wanted samples. The library's own message iteration costs ~15 us and three copies
per message (measured ~0.1 GS/s), so the chunks are read here: each is read whole into one
reused buffer, decompressed if needed, and its messages are copied once into one
preallocated Fortran-order output array (a chunk of full messages of one channel, as
:func:`write` makes them, in a single strided copy). Every wanted sample must arrive
exactly once. Anything the file does not hold as promised (truncated, another writer's
MCAP, metadata missing or inconsistent, samples missing) raises
:class:`~meshphase.io.base.RecordingFileError` naming the file and the problem.

Integrity (``verify=True``, the default of :func:`read`, :func:`read_info` and
:func:`iter_blocks`; ``data_schemas/mcap.md`` has the details): once per file (cached by
file identity) the footer's summary CRC and the DataEnd record's data-section CRC are
checked, and every chunk read has its CRC32 (over the uncompressed records) checked, in a
worker thread while the samples are copied. Together they cover every byte of the file but
the leading magic. The data-section CRC is checked without reading the uncompressed chunks'
records: their stored CRC is combined in (``crc32_combine``), and each record byte is checked
by its chunk's CRC when that chunk is read. A mismatch raises
:class:`~meshphase.io.base.CorruptFileError` naming the file, the chunk (number and byte
offset) or byte range, and the CRCs.

MCAP written by other tools (ROS 2 CDR, protobuf, JSON): :func:`read`, :func:`read_info` and
:func:`iter_blocks` take a mapping (``topics=``, see :mod:`.mapping`) of topic fields onto
channels and decode the messages (:mod:`.foreign`: JSON and CDR a chunk at a time with numpy,
:mod:`.bulk`, :mod:`.batch`; the rest with the mcap project's decoders;
:mod:`.timing` fits the stamps to one sample grid); without a mapping the
error lists the file's topics, schemas and numeric fields (:func:`describe`).
:func:`describe_topics` (:mod:`.foreign`) lists any MCAP file's topics as dicts: encodings,
message count, rate, time span and the numeric fields a mapping can name.
``write(..., layout="foxglove")`` (:mod:`.foxglove`) writes one self-describing JSON message
per sample time, stamped in absolute time (the start time + t0 + k / fs, ns since the Unix
epoch), one field per channel named for Foxglove's message paths (:func:`field_names`),
which Foxglove plots, and which reads back without a mapping.

Modules: ``layout`` (names, record framing, payload header, log times, schemas), ``crc``
(summary and data-section CRCs, ``crc32_combine``), ``header`` (opening a file: summary, recording header, per-file cache), ``chunks`` (the chunk
reader, message indexes), ``reader`` (:func:`read`,
:func:`read_info`, :func:`iter_blocks`), ``writer`` (:func:`write`, :func:`write_blocks`);
for other tools' files ``mapping`` (mapping, field access), ``foreign`` (decoding,
:func:`describe_topics`), ``bulk`` and ``batch`` (per-chunk decoding), ``timing``, and
``foxglove`` (the export).
"""

from .crc import crc32_combine
from .layout import (COMPRESSIONS, DEFAULT_BLOCK, DEFAULT_CHUNK_SIZE, FORMAT, FORMAT_VERSION, HEADER_SIZE,
                     LAYOUT, MAGIC, MESSAGE_ENCODING, NAME, PROFILE, RECORDING_METADATA,
                     SCHEMA_ENCODING, SCHEMA_NAME, log_time_ns, sniff)
from .foreign import TOPIC_KEYS, clear_cache, describe, describe_topics, read_foreign
from .foxglove import (FOXGLOVE_METADATA, FOXGLOVE_SCHEMA_NAME, LAYOUTS, TIME_BASES, field_names,
                       time_origin, write_foxglove)
from .header import ForeignMcapError
from .mapping import TopicField, parse_field_path, parse_topics
from .reader import iter_blocks, read, read_info
from .timing import fit_grid
from .writer import write, write_blocks

__all__ = ["NAME", "FORMAT", "MAGIC", "SCHEMA_NAME", "MESSAGE_ENCODING",
           "RECORDING_METADATA", "COMPRESSIONS", "DEFAULT_BLOCK", "sniff", "read_info", "read",
           "write", "write_blocks", "iter_blocks", "log_time_ns", "crc32_combine", "SCHEMA_ENCODING",
           "PROFILE", "FORMAT_VERSION", "DEFAULT_CHUNK_SIZE", "HEADER_SIZE", "LAYOUT",
           "describe", "read_foreign", "write_foxglove", "LAYOUTS", "FOXGLOVE_METADATA",
           "FOXGLOVE_SCHEMA_NAME", "ForeignMcapError", "TopicField", "parse_topics",
           "parse_field_path", "fit_grid", "describe_topics", "TOPIC_KEYS", "field_names", "time_origin",
           "TIME_BASES", "clear_cache"]
