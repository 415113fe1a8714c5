"""``meshphase bench io``, MCAP part: meshphase's own block layout read by its fast path,
against the generic decoder path (``mcap``'s ``iter_decoded_messages`` + a mapping) that
reads the ``foxglove`` layout and files other tools write.

The generic path costs tens of microseconds per message, so it is measured on a short
recording (:data:`SECONDS` of the bench's channels and rate), the fast path on the same
samples, so the figures compare like with like.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from mcap.reader import make_reader
from mcap.writer import Writer

from ..recording import Recording

__all__ = ["mcap_path_rows", "SECONDS", "COLUMNS", "markdown"]

#: Length of the recording the MCAP paths are compared on [s].
SECONDS = 10.0
#: Samples per message of the "array per message" foreign files.
ARRAY_MESSAGE = 512
COLUMNS = ("layout", "reader", "messages", "file_mb", "write_s", "read_s", "read_msps",
           "x_fast", "exact")

_ROS2_MSGDEF = "float64[] gauges\n"


def _json_scalar(rec: Recording, path: Path) -> dict:
    """One JSON message per sample time, every channel a field (a DAQ logger's file)."""
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="bench")
        sid = w.register_schema("bench.Sample", "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/daq", "json", sid)
        for k, row in enumerate(rec.data.tolist()):
            t = 10**18 + (k * 10**9) // int(rec.fs)
            w.add_message(cid, t, json.dumps(dict(zip(rec.names, row))).encode(), t)
        w.finish()
    return {n: f"/daq:{n}" for n in rec.names}


def _ros2_arrays(rec: Recording, path: Path) -> dict:
    """ROS 2 (CDR) messages of :data:`ARRAY_MESSAGE` samples per channel topic."""
    from mcap_ros2.writer import Writer as Ros2Writer  # the ROS 2 message parser: only here

    with open(path, "wb") as fh:
        w = Ros2Writer(fh)
        schema = w.register_msgdef("bench_msgs/msg/Block", _ROS2_MSGDEF)
        for a in range(0, rec.n_samples, ARRAY_MESSAGE):
            t = 10**18 + (a * 10**9) // int(rec.fs)
            for j, n in enumerate(rec.names):
                w.write_message(f"/{n}", schema, {"gauges": rec.data[a:a + ARRAY_MESSAGE, j].tolist()},
                                log_time=t)
        w.finish()
    return {n: f"/{n}:gauges" for n in rec.names}


def mcap_path_rows(rec: Recording, work: Path, timer) -> list[dict]:
    """Read throughput of each MCAP path on the first :data:`SECONDS` of ``rec``.

    Parameters
    ----------
    rec : Recording
        The bench's recording (its first :data:`SECONDS` are used; its rate is an integer
        number of Hz for the foreign files' stamps).
    work : Path
        Folder for the files (removed after each row).
    timer : callable
        ``timer(fn) -> (best wall time [s], last result)`` of repeated calls of ``fn`` (the
        io bench's best-of-``repeats``).

    Returns
    -------
    list of dict
        Keys :data:`COLUMNS`: the layout written, the reader, messages in the file, file
        size [MB], write time [s], best read time [s], MSamples/s, throughput relative to
        the fast path, and whether the samples read back exactly.
    """
    from .. import io as pio
    from ..io.mcap import foreign

    if rec.n_samples < 2:
        raise ValueError(f"the MCAP paths need a recording of at least 2 samples, got {rec.n_samples}")
    n = min(rec.n_samples, max(2, int(SECONDS * rec.fs)))
    short = rec.slice_samples(0, n)
    short = Recording(np.ascontiguousarray(short.data), short.fs, short.channels)
    cases = [
        ("meshphase (blocks of 5120)", "fast path (chunk parser)",
         lambda p: (pio.write(short, p), None)[1]),
        ("foxglove (JSON per sample time)", "generic decoder path",
         lambda p: (pio.write(short, p, layout="foxglove", compression="none"), None)[1]),
        ("foreign JSON, scalar per message", "generic decoder path + mapping",
         lambda p: _json_scalar(short, p)),
        (f"foreign ROS 2 CDR, {ARRAY_MESSAGE} samples per message", "generic decoder path + mapping",
         lambda p: _ros2_arrays(short, p)),
    ]
    rows = []
    for k, (layout, reader, write) in enumerate(cases):
        p = Path(work) / f"mcap_path_{k}.mcap"
        t = time.perf_counter()
        topics = write(p)
        write_s = time.perf_counter() - t

        def read():
            foreign._CACHE.clear()  # decode anew every time (the registry keeps one file)
            return pio.read(p, topics=topics)

        read_s, back = timer(read)
        with open(p, "rb") as fh:
            stats = make_reader(fh).get_summary().statistics
        rows.append({"layout": layout, "reader": reader, "messages": int(stats.message_count),
                     "file_mb": p.stat().st_size / 1e6, "write_s": write_s, "read_s": read_s,
                     "read_msps": short.data.size / read_s / 1e6, "x_fast": None,
                     "exact": bool(back.data.shape == short.data.shape
                                   and np.array_equal(back.data, short.data))})
        back = None
        p.unlink()
        foreign._CACHE.clear()
    for r in rows:
        r["x_fast"] = r["read_msps"] / rows[0]["read_msps"]
    return rows


def markdown(rows: list[dict], n_channels: int, fs: float) -> list[str]:
    """The MCAP-paths section of ``io_bench.md``."""
    if not rows:
        return []
    out = ["## MCAP: own layout (fast path) against the generic decoder path", "",
           f"{SECONDS:g} s x {n_channels} channels at {fs:g} Hz, best read of the bench's repeats "
           f"(foreign files: timestamps checked, mapped by topic field).", "",
           "| layout | reader | messages | file MB | write s | read s | read MS/s | x fast | exact |",
           "|" + "---|" * 9]
    for r in rows:
        out.append(f"| {r['layout']} | {r['reader']} | {r['messages']} | {r['file_mb']:.2f} | "
                   f"{r['write_s']:.2f} | {r['read_s']:.3f} | {r['read_msps']:.3g} | {r['x_fast']:.3g} | "
                   f"{'yes' if r['exact'] else 'no'} |")
    out.append("")
    return out
