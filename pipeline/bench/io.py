"""I/O benchmark (``meshphase bench io``): read throughput per format against a raw read.

For each format (HDF5, MCAP with no / lz4 / zstd compression, CSV, NI TDMS with large
segments written by ``nptdms.TdmsWriter`` and with the small segments of NI-DAQmx logging,
the interleaved ones on both engines of :mod:`meshphase.io.tdms_rows`)
a generated strain-like recording (1 h x 8 channels at 5120 Hz by default) is written and
read back through :mod:`meshphase.io`, and measured:

* full read throughput [MSamples/s] (``meshphase.io.read``), and its ratio to the raw
  reference read of the same samples from a ``.npy`` file in the same run (read with
  ``readinto`` into a buffer allocated and touched beforehand; ``np.load``, which allocates
  its output like the format readers do, is reported alongside);
* one-channel read and one-time-window read throughput (samples delivered per second);
* for CSV, ``pandas.read_csv(engine="c")`` alone on the same file;
* peak memory of a streaming read (``meshphase.io.iter_blocks`` with blocks of the block
  budget) of a recording equal to the block budget and of one four times as long, measured
  with :mod:`tracemalloc` (Python and numpy allocations; memory held inside the HDF5 or
  TDMS C code is not seen). Flat means the 4x peak stays near the 1x peak.

Times are the best of ``repeats`` runs on files just written (page cache warm): the numbers
are measured and reported against the issue's targets (HDF5 >= 0.5 x raw, MCAP and TDMS >=
0.3 x raw, CSV at least as fast as pandas' C engine alone), never asserted. A format whose
reader module is missing is skipped with a logged message.

Peak memory of ``meshphase convert`` (``convert_minutes``; ``meshphase bench io`` measures
10 min, 1 h and 3 h): the 8-channel benchmark recording (:func:`meshphase.bench.rss.bench_config`,
5120 Hz, float64) is generated and written block by block to HDF5, converted to MCAP and back
(each conversion a child process: its peak RSS (VmHWM), wall time); flat means the
same peak RSS whatever the length. A length whose files do not fit on the disk (2.2 x the
samples' size free) is skipped and listed. Peak memory of ``meshphase process`` on the same
recordings (``process_minutes``, :func:`meshphase.bench.processing.process_rss_rows`) is
measured alongside, so that one table shows both streamed commands flat in the length.

MCAP paths (:mod:`meshphase.bench.mcap_paths`): on the first 10 s of the recording, the own
block layout read by the fast path against the generic decoder path (the ``foxglove`` layout,
a foreign JSON file with one message per sample time, a ROS 2 file with arrays per message).

MCAP generic decode, scalar per message (:func:`generic_decode_rows`): one channel of the
first 10 s written by the official writers as one message per sample (JSON ``{"value": x}``
with ``mcap.writer``; ROS 2 ``std_msgs/msg/Float64`` with ``mcap_ros2.writer``) and read
through a mapping (``meshphase.io.read(path, topics=...)``, decoded chunk by chunk), against
the official reader's per-message decoding of the same file (``iter_decoded_messages``), in
samples/s.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import importlib.util
import json
import math
import os
import platform
import shutil
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

from ..jsonable import json_default
from ..runtime.log import logger
from ..recording import ChannelSpec, Recording
from ..validate import as_positive, as_positive_int
from .mcap_paths import markdown as mcap_paths_markdown, mcap_path_rows

__all__ = ["run_io_bench", "strain_recording", "convert_rss_rows", "IO_FORMATS", "TARGETS",
           "COLUMNS", "CONVERT_COLUMNS", "CONVERT_MINUTES", "generic_decode_rows", "GENERIC_COLUMNS"]

#: Formats the benchmark knows, in report order.
IO_FORMATS = ("hdf5", "mcap", "csv", "tdms")
#: Target read throughput as a ratio to the raw read; CSV is held against pandas.
TARGETS = {"hdf5": 0.5, "mcap": 0.3, "tdms": 0.3}
#: Columns of each result row (JSON keys; the Markdown table shows them in this order).
COLUMNS = ("format", "variant", "file_mb", "write_s", "read_s", "read_msps", "ratio_to_raw",
           "target_ratio", "meets_target", "exact", "one_channel_msps", "window_msps",
           "pandas_c_msps", "csv_over_pandas", "stream_peak_mb_1x", "stream_peak_mb_4x",
           "stream_peak_ratio")
#: Columns of the convert peak-memory table.
CONVERT_COLUMNS = ("minutes", "n_channels", "n_samples", "data_mb", "source", "target",
                   "wall_s", "msps", "peak_rss_mb", "rss_over_data")
#: Recording lengths of ``meshphase bench io``'s convert table [min].
CONVERT_MINUTES = (10.0, 60.0, 180.0)
_MCAP_VARIANTS = ("none", "lz4", "zstd")
_TDMS_LARGE_SEGMENT = 1 << 20  # samples per channel per segment (8 MiB of float64)
_TDMS_SMALL_SEGMENTS = (512, 1000)  # NI-DAQmx logging, contiguous and interleaved
#: TDMS variants read another way than the default (meshphase.io.tdms.reading_path)
_TDMS_PUBLIC = ", npTDMS read_data"
_TDMS_COLD = ", plan not cached"
#: interleaved TDMS rows read by the numpy engine (the default rows: numba, loaded beforehand)
_TDMS_NUMPY_ROWS = ", numpy rows"


# ---------------------------------------------------------------------------------- data
def strain_recording(n_samples: int, n_channels: int = 8, fs: float = 5120.0, rng=None) -> Recording:
    """A noisy strain-like float64 recording for benchmarks (not a model output).

    Each channel carries a train of Gaussian tooth-engagement pulses (peak 1e-4 m/m, planet
    passing at 7.3 Hz, phase shifted per channel), a slow drift and white noise (2e-6 m/m
    rms), so that compression sees realistic, mostly incompressible low bits.

    Parameters
    ----------
    n_samples : int
        Samples per channel [-], >= 0.
    n_channels : int
        Channels [-], >= 1.
    fs : float
        Sample rate [Hz].
    rng : None, int or numpy.random.Generator
        Randomness (``np.random.default_rng(rng)``).

    Returns
    -------
    Recording
    """
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)):
        raise TypeError(f"n_samples must be an integer, got {n_samples!r}")
    if n_samples < 0:
        raise ValueError(f"n_samples must be >= 0, got {n_samples}")
    n_channels = as_positive_int(n_channels, "n_channels")
    fs = as_positive(fs, "fs")
    gen = np.random.default_rng(rng)
    data = np.empty((int(n_samples), n_channels), dtype=np.float64)
    f_pass, width = 7.3, 0.02  # planet passing [Hz], pulse width [cycles]
    step = 1 << 18
    for a in range(0, int(n_samples), step):  # generated in pieces: bounded temporaries
        b = min(int(n_samples), a + step)
        t = np.arange(a, b, dtype=np.float64) / fs
        for j in range(n_channels):
            phase = np.mod(f_pass * t + j / n_channels, 1.0) - 0.5
            col = 1e-4 * np.exp(-0.5 * (phase / width) ** 2)
            col += 5e-6 * np.sin(2 * np.pi * 0.05 * t + j)
            col += gen.normal(0.0, 2e-6, b - a)
            data[a:b, j] = col
    kinds = ("sun", "ring", "facewidth", "other")
    specs = [ChannelSpec(f"gauge_{j}", kind=kinds[j % len(kinds)], units="m/m") for j in range(n_channels)]
    return Recording(data, fs, specs, t0=0.0, meta={"generated_by": "meshphase.bench.io"})


# ---------------------------------------------------------------------------------- writers
def _write_tdms(rec: Recording, path: Path, segment: int) -> None:
    """NI TDMS via nptdms.TdmsWriter, ``segment`` samples per channel per segment."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    n = rec.n_samples
    root = RootObject(properties={"name": "meshphase io bench"})
    group = GroupObject("strain")
    with TdmsWriter(str(path)) as w:
        for k, a in enumerate(range(0, max(n, 1), segment)):
            b = min(n, a + segment)
            objs = [root, group] if k == 0 else []
            for j, spec in enumerate(rec.channels):
                props = ({"wf_increment": 1.0 / rec.fs, "wf_start_offset": rec.t0, "wf_samples": n,
                          "unit_string": spec.units} if k == 0 else {})
                objs.append(ChannelObject("strain", spec.name, np.ascontiguousarray(rec.data[a:b, j]),
                                          properties=props))
            w.write_segment(objs)


def _tdms_reading(fmt: str, variant: str):
    """How a TDMS variant is read: computed offsets with the read plan cached (default),
    the plan built anew on every read (``_TDMS_COLD``), or every sample through npTDMS's
    public ``read_data`` (``_TDMS_PUBLIC``); interleaved rows on the engine ``auto`` picks
    (numba once :func:`_warm_tdms_rows` loaded it) or on numpy (``_TDMS_NUMPY_ROWS``)."""
    if fmt != "tdms":
        return contextlib.nullcontext()
    from ..io.tdms import reading_path

    return reading_path(computed_offsets=not variant.endswith(_TDMS_PUBLIC),
                        cache_plans=not variant.endswith(_TDMS_COLD),
                        rows_engine="numpy" if variant.endswith(_TDMS_NUMPY_ROWS) else "auto")


def _warm_tdms_rows() -> dict:
    """Load numba and the interleaved rows' kernel before the TDMS rows are timed
    (:func:`meshphase.io.tdms_rows.warmup`): ``{"engine", "seconds"}``, the once-per-process
    start-up that the read times leave out."""
    from ..io.tdms_rows import warmup

    return warmup()


def _variants(fmt: str) -> list[tuple[str, str, Callable[[Recording, Path], None]]]:
    """(variant name, file suffix, writer) of one format."""
    from .. import io as pio

    if fmt == "hdf5":
        return [("default", ".h5", lambda r, p: pio.write(r, p, format="hdf5"))]
    if fmt == "mcap":
        return [(c, ".mcap", (lambda c: lambda r, p: pio.write(r, p, format="mcap", compression=c))(c))
                for c in _MCAP_VARIANTS]
    if fmt == "csv":
        return [("default", ".csv", lambda r, p: pio.write(r, p, format="csv"))]
    if fmt == "tdms":
        from meshphase.synthetic.tdms_export import write_ni_log

        def ni_log(spc, il):
            return lambda r, p: write_ni_log(r, p, samples_per_segment=spc, interleaved=il)

        small = _TDMS_SMALL_SEGMENTS[0]
        return ([(f"{_TDMS_LARGE_SEGMENT} samples/segment", ".tdms",
                  lambda r, p: _write_tdms(r, p, _TDMS_LARGE_SEGMENT))]
                + [(f"{spc} samples/segment{', interleaved' if il else ''}", ".tdms", ni_log(spc, il))
                   for spc in _TDMS_SMALL_SEGMENTS for il in (False, True)]
                + [(f"{spc} samples/segment, interleaved{_TDMS_NUMPY_ROWS}", ".tdms", ni_log(spc, True))
                   for spc in _TDMS_SMALL_SEGMENTS]
                + [(f"{small} samples/segment{how}", ".tdms", ni_log(small, False))
                   for how in (_TDMS_COLD, _TDMS_PUBLIC)])
    raise ValueError(f"unknown format {fmt!r}")


# ---------------------------------------------------------------------------------- timing
def _best(fn, repeats: int) -> tuple[float, object]:
    """Best wall time [s] of ``repeats`` calls, and the last result."""
    best, out = math.inf, None
    for _ in range(repeats):
        out = None  # drop the previous result before the next call allocates its own
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


#: Keys of the rows of :func:`generic_decode_rows`.
GENERIC_COLUMNS = ("encoding", "messages", "read_s", "samples_per_s", "per_message_samples_per_s",
                   "x_per_message", "exact")
_GENERIC_SECONDS = 10.0


def _scalar_file(encoding: str, values: np.ndarray, fs: float, path: Path) -> dict:
    """One message per sample, the value its one number, written by the official writer of
    ``encoding`` ("json" or "cdr"); the mapping that reads it."""
    from mcap.writer import Writer

    t0 = 1_790_000_000 * 10**9
    stamps = [t0 + (k * 10**9 * q) // p for k, (p, q) in enumerate([fs.as_integer_ratio()] * values.size)]
    with open(path, "wb") as fh:
        if encoding == "json":
            w = Writer(fh)
            w.start(profile="", library="meshphase bench")
            cid = w.register_channel("/rig/sun_T3", "json",
                                     w.register_schema("bench.Scalar", "jsonschema", b'{"type": "object"}'))
            for t, v in zip(stamps, values.tolist()):
                w.add_message(cid, t, json.dumps({"value": v}).encode(), t)
            w.finish()
            return {"sun_T3": "/rig/sun_T3:value"}
        from mcap_ros2.writer import Writer as Ros2Writer  # the ROS 2 message parser: only here

        w = Ros2Writer(fh)
        schema = w.register_msgdef("std_msgs/msg/Float64", "float64 data\n")
        for t, v in zip(stamps, values.tolist()):
            w.write_message("/rig/sun_T3", schema, {"data": v}, log_time=t, publish_time=t)
        w.finish()
        return {"sun_T3": "/rig/sun_T3:data"}


def _per_message(path: Path, field: str) -> np.ndarray:
    """The official reader's per-message decoding: one Python object per message."""
    from mcap.reader import make_reader

    from ..io.mcap.foreign import decoder_factories

    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=decoder_factories())
        return np.array([getattr(m, field) if not isinstance(m, dict) else m[field]
                         for _, _, _, m in reader.iter_decoded_messages(log_time_order=False)])


def generic_decode_rows(rec: Recording, work: Path, timer) -> list[dict]:
    """MCAP generic decode, scalar per message: samples/s of ``meshphase.io.read`` with a
    mapping on files of one number per message, JSON and ROS 2 CDR.

    Parameters
    ----------
    rec : Recording
        Its first channel's first 10 s (at least 2 samples) are written.
    work : Path
        Folder for the files (removed after each row).
    timer : callable
        ``timer(fn) -> (best wall time [s], last result)``.

    Returns
    -------
    list of dict
        One row per encoding with the keys :data:`GENERIC_COLUMNS`: ``samples_per_s`` of the
        read, ``per_message_samples_per_s`` of ``iter_decoded_messages`` on the same file,
        their ratio, and whether the read gave the written samples bit for bit.
    """
    from ..io import read as io_read
    from ..io.mcap import clear_cache

    n = min(rec.n_samples, int(round(_GENERIC_SECONDS * rec.fs)))
    if n < 2 or rec.n_channels < 1:
        raise ValueError(f"generic decode rows need at least 2 samples of one channel, got {n} x "
                         f"{rec.n_channels}")
    values = np.ascontiguousarray(rec.data[:n, 0], dtype=np.float64)
    rows = []
    for encoding in ("json", "cdr"):
        path = work / f"generic_{encoding}.mcap"
        topics = _scalar_file(encoding, values, float(rec.fs), path)
        field = "value" if encoding == "json" else "data"

        def read():
            clear_cache()  # decode anew every time (a read keeps the last decoded file)
            return io_read(path, topics=topics)

        t_read, got = timer(read)
        t_msg, ref = timer(lambda: _per_message(path, field))
        clear_cache()
        exact = bool(got.n_samples == n and np.array_equal(got.data[:, 0].view(np.uint64), values.view(np.uint64))
                     and np.array_equal(ref, values))
        rows.append({"encoding": encoding, "messages": n, "read_s": t_read, "samples_per_s": n / t_read,
                     "per_message_samples_per_s": n / t_msg, "x_per_message": t_msg / t_read, "exact": exact})
        path.unlink()
    return rows


def _generic_markdown(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    lines = ["## MCAP generic decode, scalar per message", "",
             "One number per message (JSON `{\"value\": x}`, ROS 2 `std_msgs/msg/Float64`), written by the "
             "official writers, read through a mapping; against `iter_decoded_messages` of the same file.", "",
             "| encoding | messages | read s | samples/s | per-message samples/s | x per-message | exact |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['encoding']} | {r['messages']} | {r['read_s']:.3f} | {r['samples_per_s']:,.0f} "
                     f"| {r['per_message_samples_per_s']:,.0f} | {r['x_per_message']:.1f} | {r['exact']} |")
    lines.append("")
    return lines


def _raw_reads(data: np.ndarray, path: Path, repeats: int) -> dict:
    np.save(path, data)
    buf = np.empty_like(data)
    buf.fill(0.0)  # touched once: the reference pays no first-touch page faults

    def into():
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, fortran, dtype = read_header(fh)
            if shape != buf.shape or dtype != buf.dtype or fortran:
                raise ValueError(f"{path}: unexpected .npy header {shape} {dtype}")
            got = fh.readinto(memoryview(buf).cast("B"))
            if got != buf.nbytes:
                raise ValueError(f"{path}: read {got} of {buf.nbytes} bytes")
        return buf

    t_into, _ = _best(into, repeats)
    if not np.array_equal(buf, data):
        raise ValueError("raw reference read returned different samples")
    t_load, _ = _best(lambda: np.load(path), repeats)
    n = data.size
    return {"bytes": int(data.nbytes), "prealloc_s": t_into, "prealloc_msps": n / t_into / 1e6,
            "np_load_s": t_load, "np_load_msps": n / t_load / 1e6}


def _pandas_c(path: Path, repeats: int) -> float:
    """Best time [s] of pandas.read_csv(engine="c") alone, every column as float64."""
    import pandas as pd

    skip = 0
    with open(path, "rb") as fh:
        for line in fh:
            if not line.startswith(b"#"):
                break
            skip += 1
    t, df = _best(lambda: pd.read_csv(path, engine="c", skiprows=skip, header=0, dtype=np.float64),
                  repeats)
    if df.shape[0] == 0:
        raise ValueError(f"{path}: pandas read no rows")
    return t


def _stream_peak(path: Path, block_s: float) -> tuple[float, int]:
    """Peak traced memory [B] of streaming ``path`` in blocks of ``block_s`` [s]."""
    from .. import io as pio

    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        n_blocks = 0
        checksum = 0.0
        for blk in pio.iter_blocks(path, block_s):
            checksum += float(blk.data[-1, 0]) if blk.n_samples and blk.n_channels else 0.0
            n_blocks += 1
            del blk
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return float(peak), n_blocks


# ---------------------------------------------------------------------------------- run
def _check_args(minutes, n_channels, fs, formats, block_budget_mb, repeats):
    minutes = as_positive(minutes, "minutes")
    n_channels = as_positive_int(n_channels, "n_channels")
    fs = as_positive(fs, "fs")
    if isinstance(formats, str):
        formats = (formats,)
    formats = tuple(formats)
    if not formats:
        raise ValueError(f"formats must name at least one of {IO_FORMATS}, got an empty selection")
    bad = [f for f in formats if f not in IO_FORMATS]
    if bad:
        raise ValueError(f"formats must be among {IO_FORMATS}, got unknown {bad}")
    if len(set(formats)) != len(formats):
        raise ValueError(f"formats repeats a format: {formats}")
    if block_budget_mb is not None:
        block_budget_mb = as_positive(block_budget_mb, "block_budget_mb")
    repeats = as_positive_int(repeats, "repeats")
    return minutes, n_channels, fs, formats, block_budget_mb, repeats


def run_io_bench(out_dir, *, minutes: float = 60.0, n_channels: int = 8, fs: float = 5120.0,
                 formats=IO_FORMATS, block_budget_mb: float | None = None, rng=0,
                 progress: bool = True, repeats: int = 3, keep_files: bool = False,
                 convert_minutes=(), process_minutes=()) -> dict:
    """Measure read throughput and streaming memory of every recording format.

    Parameters
    ----------
    out_dir : str or Path
        Folder for ``io_bench.json`` and ``io_bench.md`` (created if missing); the test files
        are written to a temporary folder inside it and removed afterwards.
    minutes : float
        Length of the generated recording [min] (60 by default).
    n_channels : int
        Channels [-].
    fs : float
        Sample rate [Hz].
    formats : sequence of str
        Among ``("hdf5", "mcap", "csv", "tdms")``; a format whose module is missing is skipped
        (logged, listed under ``skipped``).
    block_budget_mb : float, optional
        Memory budget of one streamed block [MB = 1e6 B]; the streaming test reads recordings
        of 1x and 4x this size in blocks of this size. Default: a quarter of the main
        recording's size, at most 64 MB.
    rng : None, int or numpy.random.Generator
        Randomness of the generated data.
    progress : bool
        Show a progress bar (tqdm, on stderr) and log each step.
    repeats : int
        Each timed read is repeated this often; the best time is kept.
    keep_files : bool
        Keep the written files (default False: removed at the end).
    convert_minutes : sequence of float
        Lengths [min] of the 8-channel recordings whose ``meshphase convert`` peak memory is
        measured (:func:`convert_rss_rows`; default none, ``meshphase bench io`` passes
        :data:`CONVERT_MINUTES`).
    process_minutes : sequence of float
        Lengths [min] of the 8-channel recordings whose ``meshphase process`` peak memory and
        wall time are measured (:func:`meshphase.bench.processing.process_rss_rows`; default
        none, ``meshphase bench io`` passes :data:`CONVERT_MINUTES`).

    Returns
    -------
    dict
        ``{"config", "raw", "rows", "convert", "process", "mcap_paths", "generic_decode",
        "skipped", "warnings", "notes", "files"}`` (``mcap_paths``: own MCAP layout by the fast
        path against the generic decoder path, :func:`meshphase.bench.mcap_paths.mcap_path_rows`,
        and ``generic_decode``: :func:`generic_decode_rows`, when MCAP is benchmarked; ``convert``: rows with the keys :data:`CONVERT_COLUMNS`; ``process``: rows
        with the keys :data:`meshphase.bench.processing.PROCESS_COLUMNS`); ``rows`` is a
        list of dicts with the keys :data:`COLUMNS`, throughputs in MSamples/s, sizes in MB,
        times in s (None where a column does not apply).
    """
    minutes, n_channels, fs, formats, block_budget_mb, repeats = _check_args(
        minutes, n_channels, fs, formats, block_budget_mb, repeats)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = int(round(minutes * 60.0 * fs))
    if n < 2:
        raise ValueError(f"minutes={minutes!r} at fs={fs!r} Hz gives {n} sample(s); need at least 2")
    gen = np.random.default_rng(rng)
    rec = strain_recording(n, n_channels, fs, gen)
    if block_budget_mb is None:
        block_budget_mb = min(64.0, rec.data.nbytes / 4 / 1e6)
    budget_samples = max(2, int(block_budget_mb * 1e6 // (8 * n_channels)))
    plan, skipped = _plan(formats)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(plan) + 1, desc="io bench", unit="step")
    work = Path(tempfile.mkdtemp(prefix="io_bench_", dir=out))
    try:
        logger.info("io bench: raw reference (%d samples x %d channels)", n, n_channels)
        raw = _raw_reads(rec.data, work / "raw.npy", repeats)
        (work / "raw.npy").unlink()
        if bar:
            bar.update(1)
        bench = _ReadBench(rec, raw, work, repeats, budget_samples, gen)
        rows, caught, rows_warm = [], [], None
        for fmt, variant, suffix, writer in plan:
            if fmt == "tdms" and rows_warm is None:
                rows_warm = _warm_tdms_rows()
            rows.append(bench.row(fmt, variant, suffix, writer, len(rows), caught, bar))
        convert, process = _rss_tables(work, convert_minutes, process_minutes, skipped)
        mcap_paths = (mcap_path_rows(rec, work, lambda fn: _best(fn, repeats))  # own vs generic
                      if any(f == "mcap" for f, *_ in plan) else [])
        generic = (generic_decode_rows(rec, work, lambda fn: _best(fn, repeats))
                   if any(f == "mcap" for f, *_ in plan) else [])
    finally:
        if bar:
            bar.close()
        if not keep_files:
            shutil.rmtree(work, ignore_errors=True)
    config = _config(minutes, n_channels, fs, n, rec, formats, repeats, block_budget_mb, budget_samples,
                     bench)
    config["tdms_rows_engine"] = rows_warm
    result = {"config": config, "raw": raw, "rows": rows, "convert": convert, "process": process,
              "mcap_paths": mcap_paths, "generic_decode": generic, "skipped": skipped, "warnings": caught,
              "notes": _notes(repeats, rows_warm)}
    files = {"json": str(out / "io_bench.json"), "md": str(out / "io_bench.md")}
    result["files"] = files
    Path(files["json"]).write_text(json.dumps(result, indent=2, default=json_default) + "\n",
                                   encoding="utf-8")
    Path(files["md"]).write_text(_markdown(result), encoding="utf-8")
    return result


def _plan(formats) -> tuple[list, list]:
    """((format, variant, suffix, writer) per variant of each present format, skipped formats)."""
    present, skipped = [], []
    for fmt in formats:
        if importlib.util.find_spec(f"meshphase.io.{fmt}") is None:
            logger.warning("io bench: format %s skipped: module meshphase.io.%s is missing", fmt, fmt)
            skipped.append({"format": fmt, "reason": f"module meshphase.io.{fmt} is missing"})
        else:
            present.append(fmt)
    return [(fmt, *v) for fmt in present for v in _variants(fmt)], skipped


class _ReadBench:
    """One row per format variant: write, full / one-channel / window reads, streaming peaks."""

    def __init__(self, rec: Recording, raw: dict, work: Path, repeats: int, budget_samples: int, gen):
        self.rec, self.raw, self.work, self.repeats = rec, raw, work, repeats
        n_channels = rec.n_channels
        self.block_s = budget_samples / rec.fs
        self.mid = rec.names[n_channels // 2]
        self.w0 = rec.t0 + 0.45 * rec.duration
        self.w1 = rec.t0 + 0.55 * rec.duration
        self.i0, self.i1 = rec.sample_range(self.w0, self.w1)
        self.small = strain_recording(budget_samples, n_channels, rec.fs, gen)
        self.large = strain_recording(4 * budget_samples, n_channels, rec.fs, gen)

    def row(self, fmt, variant, suffix, writer, k: int, caught: list, bar) -> dict:
        """The row of one variant (file ``rec_<fmt>_<k><suffix>``); its warnings join ``caught``."""
        logger.info("io bench: %s (%s)", fmt, variant)
        if bar:
            bar.set_postfix_str(f"{fmt} {variant}")
        row = dict.fromkeys(COLUMNS)
        row.update(format=fmt, variant=variant, target_ratio=TARGETS.get(fmt))
        with warnings.catch_warnings(record=True) as wlist, _tdms_reading(fmt, variant):
            warnings.simplefilter("always")
            self._reads(row, fmt, writer, self.work / f"rec_{fmt}_{k}{suffix}")
            self._stream(row, suffix, writer)
        for wm in wlist:
            text = f"{fmt} ({variant}): {wm.category.__name__}: {wm.message}"
            if text not in caught:
                caught.append(text)
                logger.info("io bench: %s", text)
        logger.info("io bench: %s (%s): %.1f MS/s = %.2f x raw", fmt, variant,
                    row["read_msps"], row["ratio_to_raw"])
        if bar:
            bar.update(1)
        return row

    def _reads(self, row: dict, fmt: str, writer, path: Path) -> None:
        from .. import io as pio

        rec, repeats = self.rec, self.repeats
        total, n = rec.data.size, rec.n_samples
        t = time.perf_counter()
        writer(rec, path)
        row["write_s"] = time.perf_counter() - t
        row["file_mb"] = path.stat().st_size / 1e6
        t_full, back = _best(lambda: pio.read(path), repeats)
        row["exact"] = bool(back.data.shape == rec.data.shape and np.array_equal(back.data, rec.data))
        back = None
        row["read_s"] = t_full
        row["read_msps"] = total / t_full / 1e6
        row["ratio_to_raw"] = row["read_msps"] / self.raw["prealloc_msps"]
        if row["target_ratio"] is not None:
            row["meets_target"] = bool(row["ratio_to_raw"] >= row["target_ratio"])
        t1, _ = _best(lambda: pio.read(path, channels=[self.mid]), repeats)
        row["one_channel_msps"] = n / t1 / 1e6
        tw, _ = _best(lambda: pio.read(path, start=self.w0, stop=self.w1), repeats)
        row["window_msps"] = (self.i1 - self.i0) * rec.n_channels / tw / 1e6
        if fmt == "csv":
            tp = _pandas_c(path, repeats)
            row["pandas_c_msps"] = total / tp / 1e6
            row["csv_over_pandas"] = tp / t_full  # >= 1: our reader is as fast or faster
            row["meets_target"] = bool(row["csv_over_pandas"] >= 1.0)
        path.unlink()

    def _stream(self, row: dict, suffix: str, writer) -> None:
        peaks = []
        for k, r in (("1x", self.small), ("4x", self.large)):
            p = self.work / f"stream_{k}{suffix}"
            writer(r, p)
            peak, _ = _stream_peak(p, self.block_s)
            peaks.append(peak)
            p.unlink()
        row["stream_peak_mb_1x"] = peaks[0] / 1e6
        row["stream_peak_mb_4x"] = peaks[1] / 1e6
        row["stream_peak_ratio"] = peaks[1] / peaks[0] if peaks[0] > 0 else None


def _rss_tables(work: Path, convert_minutes, process_minutes, skipped: list) -> tuple[list, list]:
    """(convert rows, process rows) of the peak-memory tables; skipped lengths join ``skipped``."""
    convert, conv_skipped = convert_rss_rows(work, convert_minutes)
    skipped += conv_skipped
    process = []
    if process_minutes:
        from .processing import process_rss_rows

        process, proc_skipped, _ = process_rss_rows(work / "process", process_minutes)
        skipped += [{"format": f"process {s['minutes']:g} min", "reason": s["reason"]}
                    for s in proc_skipped]
    return convert, process


def _config(minutes, n_channels, fs, n, rec, formats, repeats, block_budget_mb, budget_samples,
            bench: _ReadBench) -> dict:
    return {
        "minutes": minutes, "n_channels": n_channels, "fs": fs, "n_samples": n,
        "total_samples": rec.data.size, "dtype": "float64", "data_mb": rec.data.nbytes / 1e6,
        "formats": list(formats), "repeats": repeats, "block_budget_mb": block_budget_mb,
        "stream_block_samples": budget_samples, "stream_block_s": bench.block_s,
        "window_s": [bench.w0, bench.w1], "one_channel": bench.mid,
        "tdms_segments": [_TDMS_LARGE_SEGMENT, *_TDMS_SMALL_SEGMENTS],
        "python": platform.python_version(), "numpy": np.__version__,
        "machine": platform.machine(), "cpus": os.cpu_count(),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


def _notes(repeats: int, rows_warm: dict | None = None) -> list[str]:
    return [
        "Throughput in MSamples/s (1 sample = one value of one channel), best of "
        f"{repeats} reads of a file just written (page cache warm).",
        "ratio_to_raw = read_msps / raw prealloc_msps: the raw reference reads the same "
        "samples from a .npy file with readinto into a buffer allocated and touched "
        "beforehand; format readers allocate their output on every read (first-touch "
        "page faults are costly on this machine), np_load_msps shows the allocating case.",
        "one_channel_msps and window_msps count the samples delivered (one channel; the "
        "middle 10% of the recording, all channels).",
        "TDMS: 1048576 samples/segment written by npTDMS's TdmsWriter; 512 and 1000 "
        "samples/segment (contiguous, interleaved) laid out as NI-DAQmx logging writes them "
        "(meshphase.synthetic.tdms_export.write_ni_log). Read by computed offsets from the "
        "segment index, the read plan (npTDMS's metadata parse) cached by the first read; "
        "'plan not cached': every read parses the metadata through npTDMS again; "
        "'npTDMS read_data': every sample through npTDMS's public read_data.",
        "TDMS interleaved rows: read on the engine 'auto' picks (meshphase.io.tdms_rows."
        "rows_engine: numba when numba is already loaded in the process); the bench loads "
        "numba and the rows kernel once before the TDMS rows"
        + (f" ({rows_warm['engine']}: {rows_warm['seconds']:.2f} s, left out of the read "
           "times)" if rows_warm else "")
        + "; 'numpy rows': the numpy engine beside it (a read in a process without numba "
        "loaded).",
        "CSV is held against pandas.read_csv(engine='c') alone on the same file: "
        "csv_over_pandas = pandas time / our time (>= 1 meets the target).",
        "stream_peak_mb_*: tracemalloc peak (Python + numpy allocations; HDF5/TDMS C "
        "internals not seen) while streaming meshphase.io.iter_blocks in blocks of the "
        "block budget over a recording of 1x and 4x the budget; flat = ratio near 1.",
        "convert table: `meshphase convert` of the 8-channel benchmark recording "
        "(meshphase.bench.rss.bench_config, float64, 5120 Hz) in a child process; peak_rss_mb "
        "is its VmHWM (every page its address space touched, C libraries included), "
        "rss_over_data its ratio to the samples' size; streamed block by block, so flat "
        "in the length. Before streaming (one buffer for the whole recording) convert "
        "peaked at ~1.2x the samples' size.",
        "process table: `meshphase process` (the seed rig's gearset) of the same recording "
        "in a child process; peak_rss_mb as above; streamed_peak_mb the peak (VmHWM) when "
        "the three streamed passes (load, condition, onsets) are done; the later stages "
        "work on the onsets, whose number grows with the length. Before streaming, process "
        "peaked at ~5x the samples' size.",
        "Measured, never asserted.",
    ]


def convert_rss_rows(work, minutes, *, seed: int = 1) -> tuple[list, list]:
    """Peak memory and wall time of ``meshphase convert`` HDF5 -> MCAP -> HDF5 of the
    8-channel benchmark recording of each length in ``minutes`` (written to ``work``,
    removed again); a length whose files do not fit on the disk is skipped.

    Returns
    -------
    (rows, skipped) : (list of dict, list of dict)
        Rows with the keys :data:`CONVERT_COLUMNS`; skipped lengths with their reason.
    """
    from .rss import N_CHANNELS, free_bytes, run_child

    work = Path(work)
    rows, skipped = [], []
    for m in minutes:
        m = as_positive(m, "convert_minutes")
        n = int(round(m * 60.0 * 5120.0))
        data = n * N_CHANNELS * 8
        need = int(2.2 * data) + (64 << 20)
        if free_bytes(work) < need:
            skipped.append({"format": f"convert {m:g} min",
                            "reason": f"needs {need / 1e9:.1f} GB free on {work}, "
                                      f"{free_bytes(work) / 1e9:.1f} GB are"})
            logger.warning("io bench: convert %g min skipped: not enough disk space", m)
            continue
        h5, mc, back = work / f"conv_{m:g}.h5", work / f"conv_{m:g}.mcap", work / f"back_{m:g}.h5"
        logger.info("io bench: writing the %g min x %d channel recording", m, N_CHANNELS)
        run_child("write_job", path=str(h5), minutes=m, seed=seed)
        for src, dst, a, b in ((h5, mc, "hdf5", "mcap"), (mc, back, "mcap", "hdf5")):
            r = run_child("convert_job", src=str(src), dst=str(dst))
            if r.get("rc") != 0:
                raise RuntimeError(f"convert {src} -> {dst} exited {r.get('rc')}")
            rows.append({"minutes": m, "n_channels": N_CHANNELS, "n_samples": n,
                         "data_mb": data / 2**20, "source": a, "target": b,
                         "wall_s": r["wall_s"], "msps": n * N_CHANNELS / r["wall_s"] / 1e6,
                         "peak_rss_mb": r["peak_rss_mb"],
                         "rss_over_data": r["peak_rss_mb"] / (data / 2**20)})
            logger.info("io bench: convert %g min %s -> %s: %.1f s, peak RSS %.0f MB", m, a, b,
                        r["wall_s"], r["peak_rss_mb"])
        for p in (h5, mc, back):
            p.unlink(missing_ok=True)
    return rows, skipped


def _fmt(v, digits=3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _markdown(res: dict) -> str:
    c, raw = res["config"], res["raw"]
    lines = [
        "# I/O benchmark",
        "",
        f"{c['minutes']:g} min x {c['n_channels']} channels at {c['fs']:g} Hz = "
        f"{c['total_samples']:,} float64 samples ({c['data_mb']:.1f} MB); best of {c['repeats']}; "
        f"{c['cpus']} CPUs, Python {c['python']}, numpy {c['numpy']}, {c['date']}.",
        "",
        f"Raw reference (.npy, readinto a preallocated buffer): **{raw['prealloc_msps']:.1f} MS/s**; "
        f"np.load (allocates): {raw['np_load_msps']:.1f} MS/s.",
        "",
        "Targets: HDF5 >= 0.5 x raw, MCAP and TDMS >= 0.3 x raw, CSV at least as fast "
        "as pandas.read_csv(engine='c') alone.",
        "",
    ]
    head = ["format", "variant", "file MB", "write s", "read MS/s", "x raw", "target", "meets",
            "exact", "1-channel MS/s", "window MS/s", "pandas C MS/s", "CSV / pandas",
            "stream peak 1x MB", "stream peak 4x MB", "4x / 1x"]
    keys = ["format", "variant", "file_mb", "write_s", "read_msps", "ratio_to_raw", "target_ratio",
            "meets_target", "exact", "one_channel_msps", "window_msps", "pandas_c_msps",
            "csv_over_pandas", "stream_peak_mb_1x", "stream_peak_mb_4x", "stream_peak_ratio"]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for row in res["rows"]:
        lines.append("| " + " | ".join(_fmt(row[k]) for k in keys) + " |")
    lines.append("")
    if res.get("convert"):
        lines += ["## meshphase convert: peak memory against recording length", "",
                  "| minutes | channels | MSamples | data MB | from | to | wall s | MS/s | "
                  "peak RSS MB | RSS / data |", "|" + "---|" * 10]
        for r in res["convert"]:
            lines.append(f"| {r['minutes']:g} | {r['n_channels']} | {r['n_samples'] * r['n_channels'] / 1e6:.1f} "
                         f"| {r['data_mb']:.0f} | {r['source']} | {r['target']} | {r['wall_s']:.1f} "
                         f"| {r['msps']:.1f} | {r['peak_rss_mb']:.0f} | {r['rss_over_data']:.3f} |")
        lines.append("")
    if res.get("process"):
        lines += ["## meshphase process: peak memory against recording length", "",
                  "| minutes | channels | data MB | status | onsets | wall s | peak RSS MB | "
                  "streamed peak MB | RSS / data |", "|" + "---|" * 9]
        for r in res["process"]:
            lines.append(f"| {r['minutes']:g} | {r['n_channels']} | {r['data_mb']:.0f} | {r['status']} "
                         f"| {r['n_onsets']} | {r['wall_s']:.1f} | {r['peak_rss_mb']:.0f} "
                         f"| {_fmt(r.get('streamed_peak_mb'))} | {r['rss_over_data']:.3f} |")
        lines.append("")
    lines += mcap_paths_markdown(res.get("mcap_paths") or [], c["n_channels"], c["fs"])
    lines += _generic_markdown(res.get("generic_decode") or [])
    if res["skipped"]:
        lines.append("Skipped: " + "; ".join(f"{s['format']} ({s['reason']})" for s in res["skipped"]))
        lines.append("")
    if res["warnings"]:
        lines.append("Warnings raised while reading/writing:")
        lines.extend(f"- {w}" for w in res["warnings"])
        lines.append("")
    lines.append("Notes:")
    lines.extend(f"- {n}" for n in res["notes"])
    lines.append("")
    return "\n".join(lines)
