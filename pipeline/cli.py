# PYTHON_ARGCOMPLETE_OK
"""The ``meshphase`` command.

The processing stack (the stages, the onset detectors and the filters, ~0.3 s of imports),
dask, matplotlib and the synthetic generator are imported only by the subcommands that use
them, so ``meshphase --help``, ``info`` and ``convert`` start without them; scipy loads on
first use (:mod:`meshphase.runtime.lazy`; scipy.signal, whose import pulls scipy.stats in,
only where numba is not installed: the filter designs are meshphase.signal.sos_design's);
tqdm (with importlib.metadata), the run's result types and the campaign machinery load with
the first progress bar, run or campaign (tests hold the modules each loads; ``meshphase
bench`` times the start-up).

Exit status (every subcommand; README.md "Exit status"; constants in :mod:`meshphase.run.exits`):

====  ==========================================================================================
0     ok: every requested result computed, none of them empty or all NaN
1     input or scene error, nothing usable: unreadable / corrupt file, a channel the scene
      names that the file lacks, no gauge channel, every gauge channel NaN/inf or constant,
      a bad scene, a FIFO / device / folder where a file is expected, an OS error
      (permission, no space left, name too long, ...), out of memory; a campaign in which
      every recording failed (its folder is written all the same: campaign.json and
      campaign.csv give each recording's cause)
2     usage error (argparse)
3     partial result: outputs written, but a requested result is missing (its stage failed,
      was skipped for a failed stage it needs, or left it empty or all NaN; summary.json
      ``"status": "partial"`` and ``missing_results`` with each cause), or phasing flagged
      unreliable (``"status": "unreliable"``); a campaign with any recording failed, partial
      or unreliable
130   interrupted (Ctrl-C); the interrupted run's output folder is removed
141   standard output closed by the reader (``| head``): no message
143   terminated (SIGTERM; 129: SIGHUP) while writing: no message, nothing left
====  ==========================================================================================

Every message is one line on stderr in one style, ``meshphase COMMAND: LEVEL: TEXT``
(:func:`meshphase.runtime.log.message_line`; the log formatter too): errors, one per cause,
``meshphase COMMAND: error: ...``, never a traceback (``--debug`` or ``MESHPHASE_DEBUG=1``
re-raises them with the traceback and logs the traceback of each failed stage); a run's
``partial`` / ``unreliable`` causes; warnings, each distinct line once, ``meshphase COMMAND:
warning: FormatWarning: ...`` and, collected by a run, ``meshphase COMMAND: warning: STAGE:
ProcessingWarning: ...``; log records ``meshphase COMMAND: info: ...``. Results go to
stdout. ``tests/faults``
runs a corpus of faulty inputs and outputs through this boundary.
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import gc
import json
import logging
import math
import operator
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .version import __version__
from .io.channels import mapping_report
from .run.demo import demo_scene_path
from .errors import DataQualityWarning
from .run.exits import (EXIT_ERROR, EXIT_INTERRUPTED, EXIT_PIPE, recording_read_errors,
                        run_status, status_line)
from .runtime.heap import limit_heap_growth
from .io import FormatChoices, convert, detect_format, format_of_suffix, get_spec, iter_blocks, read_info
from .io.base import ANY_FS_ENV, CorruptFileError, RecordingFileError
from .io.tdms_rows import warmup as warmup_rows
from .models._kernels import warmup as warmup_models
from .runtime.log import MessageFormatter, logger, message_line, stderr_is_terminal
from .signal.runs import RunTracker
from .run.scene import SceneError, load_scene, read_options, with_recording
from .validate import as_regular_file

__all__ = ["main", "build_parser", "describe_error"]


def _bars(args) -> bool:
    """Progress bars for this command: not ``-q``, and stderr a terminal (a log file or a
    pipe gets no bar lines)."""
    return not args.quiet and stderr_is_terminal()


def _progress(total: int | None, desc: str, enabled: bool):
    # tqdm.auto: the widget in a notebook, the text bar in a terminal; with the first bar
    # tqdm loads importlib.metadata (~20 ms)
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="S", unit_scale=True, disable=not enabled,
                leave=False, file=sys.stderr)


# ---------------------------------------------------------------------------- input options
#: Read options of the command line's input options: option -> (flag, scene table).
_OPTION_SOURCES = {"topics": ("--topics", "[input.mcap]"), "fs": ("--fs", "[input] fs_Hz"),
                   "header_row": ("--header-row", "[input.csv]"),
                   "skip_rows": ("--skip-rows", "[input.csv]"),
                   "decimal": ("--decimal", "[input.csv]"),
                   "delimiter": ("--delimiter", "[input.csv]")}


def _whole_number(minimum: int):
    """argparse type: a whole number >= ``minimum`` (a row count, a number of runs)."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number >= {minimum}, got {text!r}") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {n}")
        return n
    parse.__name__ = f"whole number >= {minimum}"   # argparse names the type in its messages
    return parse


_nonnegative_int = _whole_number(0)
_positive_int = _whole_number(1)
_repeats = _whole_number(1)


def _positive_hz(text: str) -> float:
    """argparse type: a finite sample rate > 0 [Hz]."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a sample rate in Hz: {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a finite rate > 0 Hz, got {text!r}")
    return v


def _one_char(text: str) -> str:
    """argparse type: one character (``\\t`` for a tab)."""
    text = {"\\t": "\t", "tab": "\t", "TAB": "\t"}.get(text, text)
    if len(text) != 1:
        raise argparse.ArgumentTypeError(f"expected one character, got {text!r}")
    return text


def parse_topics_arg(values) -> dict | list:
    """The ``--topics`` values as the ``topics=`` option of :func:`meshphase.io.read`.

    Each value is either JSON (a dict ``{"sun_T3": "/rig/strain:gauges.sun_T3"}`` or a list
    of tables with ``name``, ``topic``, ``field`` ..., as in Python) or comma-separated
    ``NAME=TOPIC:FIELD`` pairs; several values are joined.

    Parameters
    ----------
    values : list of str

    Returns
    -------
    dict or list
        A dict when every value gives pairs or a dict, else a list of tables.

    Raises
    ------
    ValueError
        An empty list, a malformed value (named), a channel given twice.
    """
    if isinstance(values, str):
        values = [values]
    if not values:
        raise ValueError("--topics: give NAME=TOPIC:FIELD pairs, e.g. --topics "
                         "sun_T3=/rig/strain:gauges.sun_T3")
    pairs: dict = {}
    tables: list = []
    for text in values:
        s = str(text).strip()
        if s.startswith(("{", "[")):
            try:
                val = json.loads(s)
            except json.JSONDecodeError as exc:
                raise ValueError(f"--topics {text!r}: not valid JSON ({exc})") from None
            if isinstance(val, dict):
                items = val.items()
            else:
                tables.extend(val)
                continue
        else:
            items = []
            for part in filter(None, (p.strip() for p in s.split(","))):
                name, sep, target = part.partition("=")
                if not sep or not name.strip() or not target.strip():
                    raise ValueError(f"--topics {text!r}: {part!r} is no NAME=TOPIC:FIELD pair, "
                                     "e.g. sun_T3=/rig/strain:gauges.sun_T3")
                items.append((name.strip(), target.strip()))
            if not items:
                raise ValueError(f"--topics {text!r}: no NAME=TOPIC:FIELD pair in it")
        for name, target in items:
            if name in pairs:
                raise ValueError(f"--topics: channel {name!r} is mapped twice")
            pairs[name] = target
    if tables:
        return tables + [{"name": n, **({"topic": t.rpartition(":")[0], "field": t.rpartition(":")[2]}
                                        if isinstance(t, str) else t)} for n, t in pairs.items()]
    return pairs


def _flag_options(args) -> dict:
    """The read options given as flags (``--topics``, ``--fs``, ``--header-row`` ...)."""
    out: dict = {}
    if getattr(args, "topics", None):
        from .io.mcap import parse_topics  # the mcap library: only for a mapping

        out["topics"] = parse_topics_arg(args.topics)
        try:
            parse_topics(out["topics"])
        except (TypeError, ValueError) as exc:
            raise ValueError(f"--topics: {exc}") from None
    for opt in ("fs", "header_row", "skip_rows", "decimal", "delimiter"):
        v = getattr(args, opt, None)
        if v is not None:
            out[opt] = v
    return out


def _input_scene(args, path=None):
    """The ``--scene`` of a command (None without one), loaded for reading a recording given
    beside it."""
    scene_path = getattr(args, "scene", None)
    if not scene_path:
        return None
    return load_scene(as_regular_file(scene_path, "the scene (--scene)"), recording_given=True)


def check_read_options(path, fmt: str, options: dict) -> None:
    """Refuse read options the format of ``path`` does not take, naming the flag or scene
    table that gave each and the options the format takes.

    Parameters
    ----------
    path : str or Path
    fmt : str
        The file's format (:func:`meshphase.io.detect_format`).
    options : dict
        Read options.

    Raises
    ------
    ValueError
        An option ``fmt``'s :class:`~meshphase.io.FormatSpec` does not declare.
    """
    takes = get_spec(fmt).read_options
    for key in options:
        if key != "verify" and key not in takes:
            flag, table = _OPTION_SOURCES.get(key, (key, "the scene"))
            raise ValueError(f"{path}: a {fmt} file takes no read option {key!r} (given by {flag} "
                             f"or the scene's {table}); the {fmt} reader's options: "
                             f"{', '.join(sorted(takes)) or 'none'}")


def input_options(args, path, scene=None) -> tuple[str, dict]:
    """(format, read options) of recording ``path`` for a command: the scene's ``[input.*]``
    tables and ``fs_Hz`` (``scene``, or ``--scene``), the flags over them; checked against
    the file's format (:func:`check_read_options`).

    Parameters
    ----------
    args : argparse.Namespace
        With the input options (:func:`add_input_options`).
    path : Path
    scene : Scene, optional
        The scene whose tables hold (default: ``--scene``'s).

    Returns
    -------
    (str, dict)
    """
    if scene is None:
        scene = _input_scene(args)
    flags = _flag_options(args)
    if scene is not None:
        opts = read_options(dataclasses.replace(scene, input=with_recording(scene, path, flags)))
    else:
        opts = flags
    with recording_read_errors(path):
        fmt = detect_format(path)
    check_read_options(path, fmt, opts)
    return fmt, opts


def add_input_options(parser: argparse.ArgumentParser, *, scene: bool = True) -> None:
    """The input options every reading command shares: ``--topics``, ``--scene`` (unless
    the command's scene is positional), ``--header-row``, ``--skip-rows``, ``--fs``,
    ``--decimal``, ``--delimiter``; forwarded as the format's read options
    (:func:`input_options`)."""
    g = parser.add_argument_group(
        "input options", "how to read the recording (over the scene's [input.*] tables; a "
        "format that does not take an option refuses it)")
    g.add_argument("--topics", action="append", metavar="NAME=TOPIC:FIELD",
                   help="an MCAP file of another tool: which topic fields are the channels, "
                        "comma-separated NAME=TOPIC:FIELD pairs or JSON as Python's topics= "
                        "(repeatable)")
    if scene:
        g.add_argument("--scene", metavar="SCENE",
                       help="a scene whose [input.mcap] / [input.csv] tables, [input] fs_Hz and "
                            "[[channels]] mapping read the recording")
    g.add_argument("--header-row", type=_positive_int, metavar="N",
                   help="text: line number of the channel names (from 1, as editors count)")
    g.add_argument("--skip-rows", type=_nonnegative_int, metavar="N",
                   help="text: lines of preamble above the channel names")
    g.add_argument("--fs", type=_positive_hz, metavar="HZ",
                   help="sample rate [Hz] of a file that states none (TDMS without wf_increment, "
                        "text without a time column ...)")
    g.add_argument("--decimal", type=_one_char, metavar="CHAR", help="text: decimal mark (. or ,)")
    g.add_argument("--delimiter", type=_one_char, metavar="CHAR",
                   help="text: field delimiter (default detected; \\t for a tab)")


# ---------------------------------------------------------------------------- info
def _fmt_seconds(s: float) -> str:
    if s >= 3600:
        return f"{s / 3600:.3f} h"
    if s >= 60:
        return f"{s / 60:.3f} min"
    return f"{s:.6g} s"


class _QualityScan:
    """The quality summary of ``meshphase info --quality`` in one pass over the blocks: per
    channel the non-finite samples and their runs, the finite range, and the runs of at least
    3 samples at the channel's extreme values (those of :func:`meshphase.signal.quality.clipped_runs`
    of the whole channel: the runs at the running extremes, restarted when a block passes
    them). Whole-block numpy reductions; per channel only the run bookkeeping."""

    def __init__(self, names):
        self.names = list(names)
        k = len(self.names)
        self.nonfinite = [RunTracker() for _ in range(k)]
        self.n_nonfinite = np.zeros(k, dtype=np.int64)
        self.lo = np.full(k, np.inf)
        self.hi = np.full(k, -np.inf)
        self.at_hi = [RunTracker() for _ in range(k)]
        self.at_lo = [RunTracker() for _ in range(k)]
        self.pos = 0

    def feed(self, data: np.ndarray) -> None:
        """The next block, shape (n, channels)."""
        n = data.shape[0]
        if n == 0:
            return
        fin = np.isfinite(data)
        bad_cols = set(np.flatnonzero(~fin.all(axis=0)).tolist())
        with np.errstate(invalid="ignore"):
            bhi = np.where(fin, data, -np.inf).max(axis=0) if bad_cols else data.max(axis=0)
            blo = np.where(fin, data, np.inf).min(axis=0) if bad_cols else data.min(axis=0)
        for j in range(len(self.names)):
            col = data[:, j]
            bad = ~fin[:, j]
            if j in bad_cols:
                self.n_nonfinite[j] += int(bad.sum())
            self.nonfinite[j].add(bad)    # closes a run left open by the block before
            for ext, new, trackers, better in ((self.hi, bhi[j], self.at_hi, operator.gt),
                                               (self.lo, blo[j], self.at_lo, operator.lt)):
                if better(new, ext[j]):
                    ext[j] = new
                    t = RunTracker()
                    t.n = self.pos            # runs before this block lie below the new extreme
                    trackers[j] = t
                trackers[j].add(col == ext[j])
        self.pos += n

    def result(self) -> dict:
        """Channel name -> ``n_nonfinite``, ``nonfinite_runs``, ``clipped_runs``, ``min``, ``max``."""
        out = {}
        for j, name in enumerate(self.names):
            finite = self.hi[j] >= self.lo[j]
            clipped = 0
            if finite and self.hi[j] > self.lo[j]:
                for t in (self.at_hi[j], self.at_lo[j]):
                    r = t.runs()
                    clipped += int(((r[:, 1] - r[:, 0]) >= 3).sum())
            out[name] = {"n_nonfinite": int(self.n_nonfinite[j]),
                         "nonfinite_runs": len(self.nonfinite[j].runs()), "clipped_runs": clipped,
                         "min": float(self.lo[j]) if finite else float("inf"),
                         "max": float(self.hi[j]) if finite else float("-inf")}
        return out


#: Samples per channel per block of ``info --quality`` (2**20: 64 MB of 8 float64 channels).
QUALITY_BLOCK = 2 ** 20


def _quality(path, fmt: str, opts: dict, info, enabled: bool) -> dict:
    """``info --quality``: :class:`_QualityScan` over the file's blocks."""
    scan = _QualityScan([c.name for c in info.channels])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataQualityWarning)  # counted here instead
        with _progress(info.n_samples, "quality", enabled) as bar, recording_read_errors(path):
            for block in iter_blocks(path, QUALITY_BLOCK / info.fs, format=fmt, **opts):
                scan.feed(block.data)
                bar.update(block.n_samples)
    return scan.result()


def _foreign_mcap_topics(path, fmt: str, opts: dict, exc: BaseException):
    """The topics of an MCAP file of another tool read without a mapping
    (:func:`meshphase.io.mcap.describe_topics`), or None when ``exc`` is another error (a
    damaged file, a mapping given)."""
    if fmt != "mcap" or "topics" in opts or isinstance(exc, CorruptFileError) \
            or not isinstance(exc, RecordingFileError):
        return None
    from .io.mcap import describe_topics  # the mcap library: only for an MCAP file

    try:
        return describe_topics(path)
    except Exception:  # noqa: BLE001 - the read's own error says it better
        return None


def _print_topics(path, topics: list) -> None:
    """The plain listing of ``info`` on an MCAP file of another tool."""
    print(f"file      {path}")
    print("format    mcap, written by another tool (no meshphase layout): map its topic fields "
          "onto channels")
    print(f"topics    {len(topics)}")
    for t in topics:
        rate = t["rate_Hz"]
        fields = t["numeric_fields"]
        shown = ("no decoder for this encoding" if fields is None else
                 ", ".join(f["path"] + ("" if f["length"] is None else f" [{f['length']}]")
                           for f in fields) or "no numeric fields")
        print(f"  {t['topic']}: schema {t['schema'] or '(none)'} ({t['schema_encoding'] or 'none'}), "
              f"messages {t['message_encoding']}, {t['message_count']} message(s)"
              + (f" at {rate:.6g} Hz" if rate is not None else ""))
        print(f"    numeric fields: {shown}")
    print("map      --topics NAME=TOPIC:FIELD[,...] or a scene's [[input.mcap.channels]] with --scene "
          "(data_schemas/mcap.md)")


def cmd_info(args) -> int:
    path = as_regular_file(args.file, "the recording")  # a FIFO would block detect_format
    scene = _input_scene(args)          # before the file: a bad scene fails at once
    fmt, opts = input_options(args, path, scene)
    try:
        with recording_read_errors(path):
            info = read_info(path, format=fmt, **opts)
    except Exception as exc:
        topics = _foreign_mcap_topics(path, fmt, opts, exc)
        if topics is None:
            raise
        if args.json:
            print(json.dumps({"file": str(path), "format": fmt, "foreign": True, "topics": topics},
                             indent=2, default=str))
        else:
            _print_topics(path, topics)
        return 0
    out = {
        "file": str(path), "format": fmt, "fs_hz": info.fs, "n_samples": info.n_samples,
        "duration_s": info.duration, "t0_s": info.t0, "start_datetime": info.start_datetime,
        "channels": [c.to_dict() for c in info.channels], "meta": info.meta,
        "history": info.history,
    }
    if opts:
        out["read_options"] = opts
    if scene is not None:
        out["channel_map"] = dict(mapping_report(info.channels, scene.channels, str(path)),
                                  scene=str(args.scene))
    if args.quality:
        out["quality"] = _quality(path, fmt, opts, info, _bars(args))
    if args.json:
        print(json.dumps(out, indent=2, default=str))
        return 0
    print(f"file      {path}")
    print(f"format    {fmt}")
    print(f"fs        {info.fs:g} Hz")
    print(f"samples   {info.n_samples} ({_fmt_seconds(info.duration)})")
    print(f"start     t0 = {info.t0:g} s" + (f", {info.start_datetime}" if info.start_datetime else ""))
    print(f"channels  {len(info.channels)}")
    header = f"  {'name':<16} {'kind':<10} {'units':<8} {'gain':>10} {'tooth':>6} {'face [mm]':>10}"
    if "quality" in out:
        header += f" {'NaN':>8} {'NaN runs':>9} {'clipped':>8} {'min':>12} {'max':>12}"
    print(header)
    for c in info.channels:
        face = "" if c.face_position is None else f"{c.face_position * 1e3:.3f}"
        line = (f"  {c.name:<16} {c.kind:<10} {c.units:<8} {c.gain:>10.4g} "
                f"{'' if c.tooth is None else c.tooth:>6} {face:>10}")
        if "quality" in out:
            q = out["quality"][c.name]
            line += (f" {q['n_nonfinite']:>8} {q['nonfinite_runs']:>9} {q['clipped_runs']:>8} "
                     f"{q['min']:>12.5g} {q['max']:>12.5g}")
        print(line)
    if info.history:
        print(f"history   {len(info.history)} step(s): " + ", ".join(str(h.get('step', h)) for h in info.history))
    if "channel_map" in out:
        _print_channel_map(out["channel_map"])
    if "quality" not in out:
        print("quality   not scanned (--quality scans every sample)")
    return 0


def _print_channel_map(m: dict) -> None:
    print(f"mapping   scene {m['scene']}")
    print(f"  {'channel':<16} {'kind':<10} {'gear':<7} {'tooth':>5} {'units':<6} scene entry")
    for r in m["rows"]:
        how = f" [{r['matched by']}]" if r["matched by"] else ""
        print(f"  {r['channel']:<16} {r['kind']:<10} {r['gear']:<7} {r['tooth']!s:>5} "
              f"{r['units']:<6} {r['scene entry']}{how}")
    if m["unmapped"]:
        print(f"unmapped  {', '.join(m['unmapped'])}: as the file describes them")


# ---------------------------------------------------------------------------- convert
class _LayoutChoices:
    """The MCAP writer's layouts (:data:`meshphase.io.mcap.LAYOUTS`) as argparse ``choices``,
    read when used (building the parser loads no mcap library)."""

    def _names(self) -> tuple:
        from .io.mcap import LAYOUTS

        return tuple(LAYOUTS)

    def __contains__(self, item) -> bool:
        return item in self._names()

    def __iter__(self):
        return iter(self._names())


def cmd_convert(args) -> int:
    src, dst = as_regular_file(args.input, "the input recording"), Path(args.output)
    out_fmt = args.format or format_of_suffix(dst)
    if args.compression and out_fmt == "csv":
        raise ValueError(f"--compression {args.compression}: CSV is written uncompressed "
                         "(compression is for hdf5 and mcap)")
    options = {"compression": args.compression} if args.compression else {}
    if args.layout:
        if out_fmt is not None and "layout" not in get_spec(out_fmt).write_options:
            raise ValueError(f"--layout {args.layout}: a {out_fmt} file has no layouts (--layout is "
                             "for mcap output)")
        options["layout"] = args.layout
    _, read_opts = input_options(args, src)
    done = convert(src, dst, format=args.format, overwrite=args.overwrite,
                   progress=lambda total, desc: _progress(total, desc, _bars(args)),
                   read_options=read_opts, **options)
    logger.info("wrote %s", done.path)
    if not args.quiet:
        print(f"{src} ({done.source_format}) -> {done.path} ({done.n_samples} samples x "
              f"{done.n_channels} channels)")
    return 0


# ---------------------------------------------------------------------------- synth
def cmd_synth(args) -> int:
    from meshphase.synthetic import cli_synth, describe_scenarios  # heavy (numba, scipy.stats): only here

    if args.list or not args.scenario or not args.output:
        rows = describe_scenarios()
        for r in rows:
            print(f"{r['name']:<24} {r['fs']:>8g} Hz {r['duration']:>7g} s  {r['description']}")
        if not args.list:
            print("usage: meshphase synth SCENARIO OUT [--minutes M] [--seed N] [--format F]",
                  file=sys.stderr)
            print(message_line("synth", "error", "SCENARIO and OUT are required (the scenarios are "
                               "listed above)"), file=sys.stderr)
            return 2
        return 0

    path, truth = cli_synth(args.scenario, args.output, minutes=args.minutes, seed=args.seed,
                            format=args.format, overwrite=args.overwrite, progress=_bars(args))
    print(f"wrote {path}\ntruth {truth}")
    return 0


# ---------------------------------------------------------------------------- bench
def cmd_bench(args) -> int:
    # bench drives the CLI's own commands (bench.rss runs `convert` through main), so it is
    # imported here, not at the top: cli -> bench only when benchmarking, no import loop
    if args.warmup:
        # the onset detectors and the filters: the processing stack (~0.05-0.1 s of imports),
        # not loaded for every command's start-up
        from .onsets.fastpath import warmup as warmup_onsets
        from .signal.iir import warmup as warmup_iir

        w = warmup_models()
        print(f"numba kernel ready in {w['seconds']:.2f} s, cache {w['cache_dir']}"
              if w["engine"] == "numba" else "numba is not importable: the numpy path needs no "
              "compilation")
        wo = warmup_onsets()              # the onset stage's kernels, into the same cache
        if wo["engine"] == "numba":
            print(f"onset kernels ready in {wo['seconds']:.2f} s")
        wr = warmup_rows()                # the interleaved TDMS rows' kernel
        if wr["engine"] == "numba":
            print(f"TDMS rows kernel ready in {wr['seconds']:.2f} s")
        wf = warmup_iir()                 # the conditioning filters' kernel
        if wf["engine"] == "numba":
            print(f"filter kernel ready in {wf['seconds']:.2f} s")
        return 0
    out = Path(args.out)
    if args.accuracy:
        if args.what != "processing":
            raise ValueError(f"--accuracy belongs to 'meshphase bench processing', got "
                             f"'meshphase bench {args.what}'")
        from .bench.conditions import QUICK_CONDITIONS, run_conditions

        res = run_conditions(out, QUICK_CONDITIONS if args.quick else None)
        print(res["markdown"], end="")
        for name, path in res["files"].items():
            print(f"{name:<24} {path}")
        return 0
    if args.what == "campaign":
        return _bench_campaign(out, args.quick, args.repeats)
    if args.what == "reference":
        from .bench.models_reference import build_reference, reference_line

        ref = build_reference(out, evaluations=args.evaluations, plain=args.plain,
                              progress=_bars(args))
        print(reference_line(ref))
        return 0
    from .bench import rss_summary, run_bench

    res = run_bench(args.what, out, minutes=args.minutes, quick=args.quick,
                    rss_minutes=args.rss_minutes)
    for name, path in res.get("files", {}).items():
        print(f"{name:<24} {path}")
    for line in rss_summary(res.get("results", {})):
        print(line)
    return 0


def _bench_campaign(out: Path, quick: bool, repeats: int | None = None) -> int:
    """``meshphase bench campaign``: :func:`meshphase.bench.campaign.measure_speedup` into
    ``out/campaign_bench.json``, one line per timed run and the speed-ups on stdout
    (``repeats`` timed runs per worker count; None: 3, or 1 with ``quick``)."""
    from .bench.campaign import measure_speedup

    n, minutes, default_repeats = (2, 0.5, 1) if quick else (8, 2.0, 3)
    repeats = default_repeats if repeats is None else repeats
    from .bench.first_figure import first_figure_rows

    res = measure_speedup(n, minutes, (1, 2), repeats=repeats)
    res["first_figure"] = first_figure_rows(1 if quick else 6)
    from .bench.campaign import measure_overhead, overhead_lines  # dask scheduler/worker processes

    res["overhead"] = measure_overhead(*((6, 0.5) if quick else (200, 2.0)), 2)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "campaign_bench.json"
    path.write_text(json.dumps(res, indent=2, default=str))
    print(f"campaign bench: {n} x {minutes:g} min, load before {res['loadavg'][0]:.1f}")
    for r in res["runs"]:
        print(f"  {r['workers']} worker(s): {r['wall_s']:6.1f} s total, processing "
              f"{r['processing_s']:6.1f} s, scene-level {r['scene_level_s']:5.1f} s, report "
              f"{r['report_s']:5.1f} s, cluster wait {r.get('cluster_wait_s', float('nan')):5.1f} s")
    print(f"speed-up 2 vs 1 worker: {res['speedup'][2]:.2f}x total, "
          f"{res['processing_speedup'][2]:.2f}x processing (best of {repeats})")
    pairs = res["paired_speedup"][2]["pairs"]
    if len(pairs) > 1:
        print(f"  each repeat's 1-worker run over its 2-worker run: "
              f"{', '.join(f'{v:.2f}' for v in pairs)}x (median {res['paired_speedup'][2]['median']:.2f}x; "
              f"processing median {res['paired_processing_speedup'][2]['median']:.2f}x)")
    if math.isfinite(res["task_cpu_ratio"][2]):
        print(f"  task CPU, two workers over one: {res['task_cpu_ratio'][2]:.3f} (medians; 1 = no contention)")
    if res["first_figure"]:
        print("a forked worker's first report figure over its second [s] (meshphase.campaign.fork_ready):")
        for case in ("without fork_ready", "with fork_ready"):
            rows = [r for r in res["first_figure"] if r["case"] == case]
            print(f"  {case:>18}: " + ", ".join(f"{r['figure']} {r['first_excess_s']:.3f}" for r in rows))
    print("\n".join(overhead_lines(res["overhead"])))
    print(f"{path.name:<24} {path}")
    return 0


def _minutes_list(text: str) -> tuple:
    """``--rss-minutes 10,60,180`` -> (10.0, 60.0, 180.0); "" or "none" -> ()."""
    if text.strip().lower() in ("", "none"):
        return ()
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected minutes separated by commas "
                                         f"(e.g. 10,60,180), got {text!r}") from None
    bad = [v for v in vals if not (v > 0 and math.isfinite(v))]
    if bad:
        raise argparse.ArgumentTypeError(f"minutes must be positive and finite, got {text!r}")
    return vals


# ---------------------------------------------------------------------------- run / process / demo
def _stage_progress(enabled: bool):
    if not enabled:
        return None
    bar = {"b": None}

    def cb(name, i, n):
        if bar["b"] is None:
            from tqdm.auto import tqdm

            bar["b"] = tqdm(total=n, desc="stages", leave=False, file=sys.stderr)
        bar["b"].set_postfix_str(name)
        bar["b"].n = i
        bar["b"].refresh()
        if name == "done":
            bar["b"].close()
    return cb


#: warnings of a run printed at most (all are in summary.json ``messages``)
_MAX_MESSAGES = 10


def _print_run(ctx, files, command: str) -> None:
    """The results of a run on stdout; its warnings on stderr (:func:`message_line`)."""
    from .run.stages import summary_dict  # the processing stack: see the module docstring
    s = summary_dict(ctx)
    print(f"scene     {ctx.scene.name}")
    print(f"stages    {', '.join(ctx.ran)}" + (f"  (failed: {', '.join(ctx.failed)})" if ctx.failed else ""))
    if ctx.channels_unused:
        kinds = {c["name"]: c["kind"] for c in (s.get("recording") or {}).get("channels", [])}
        print("unused    " + ", ".join(f"{n} ({kinds.get(n, '?')})" for n in ctx.channels_unused)
              + ": channel(s) read but used by no stage")
    for gear, t in s.get("phasing", {}).items():
        print(f"{gear} phasing ({t['n_passes']} passes)   planet  mean gamma   std      range")
        for n, v in t["per_planet"].items():
            print(f"                        {n:>6}  {v['mean']:.5f}    {v['std']:.2e} {v['range']:.2e}"
                  if v.get("mean") is not None else f"                        {n:>6}  –")
    for row in s.get("load_sharing", []) or []:
        ls, se = row["load_sharing"], row["std_error"]
        print(f"load sharing planet {row['planet']}: " + ("–" if ls is None else f"{ls:.4f}")
              + ("" if se is None else f" ± {se:.4f}"))
    relative = set(ctx.phasing.labels_relative or []) if ctx.phasing is not None else set()
    for gear, c in s.get("compare", {}).items():
        vm = c.get("vs_model") or c.get("vs_ideal")
        rms = vm.get("rms") if vm else None
        # relative labels (planet 1 = the first pulse seen) need not be the truth's numbers;
        # the phasing values do not depend on them
        how = "labels relative, as truth" if gear in relative else "labels as truth"
        extra = (f", vs truth {c['vs_truth']['rms']:.2e} ({how}: "
                 f"{c['vs_truth']['label_match']:.0%})") if c.get("vs_truth") else ""
        print(f"{gear}: RMS residual vs model " + ("–" if rms is None else f"{rms:.2e}") + f" cycles{extra}")
    for stage, t in ctx.timings.items():
        print(f"  {stage:<16} {t:8.3f} s  {ctx.error_estimates.get(stage, '')}")
    for name, p in files.items():
        print(f"{name:<18} {p}")
    for m in ctx.messages[:_MAX_MESSAGES]:
        print(message_line(command, "warning", m), file=sys.stderr)  # "stage: Category: text"
    if len(ctx.messages) > _MAX_MESSAGES:
        print(message_line(command, "warning", f"{len(ctx.messages) - _MAX_MESSAGES} more warning(s) "
                           "in summary.json (messages)"), file=sys.stderr)



def _finish_run(args, ctx, files) -> int:
    """Print a run, its status line, one stderr line per cause; return the exit code."""
    st = run_status(ctx)
    if st["status"] == "failed":
        # nothing usable and nothing written: the cause is the whole story
        print(message_line(args.command, "error", st["error"]), file=sys.stderr)
        return st["exit_code"]
    _print_run(ctx, files, args.command)
    print(f"status    {status_line(st)}")
    for m in st["missing_results"]:
        print(message_line(args.command, "partial", f"{m['result']} not computed: {m['cause']}"),
              file=sys.stderr)
    for gauge, reasons in st["unreliable"].items():
        print(message_line(args.command, "unreliable", f"{gauge} gauge phasing: "
                           f"{'; '.join(reasons) or 'flagged unreliable'}"), file=sys.stderr)
    return st["exit_code"]


def _run_and_write(args, scene, base, *, report: bool = True):
    """Reserve the output folder, run the scene, write the outputs unless nothing is usable.

    ``scene`` is a Scene or a function of the reserved folder returning one (the demo writes
    its scene file there first). The folder is removed again when the run fails or is
    interrupted (:class:`meshphase.run.outdir.OutputDir`)."""
    from .run.stages import run_to_folder  # the processing stack: see the module docstring
    return run_to_folder(scene, base, overwrite=args.overwrite, report=report,
                         progress=_stage_progress(_bars(args)))


def cmd_run(args) -> int:
    scene = load_scene(as_regular_file(args.scene, "the scene"))
    if not scene.results:
        # an empty scene (or a gearset file) would "succeed" at computing nothing
        raise SceneError(args.scene, "results", "no results requested, nothing to run; add e.g. "
                         'results = ["ideal_phasing", "phasing"] (`meshphase process FILE --gearset '
                         f"{args.scene}` takes a gearset file without results)")
    flags = _flag_options(args)
    if flags:
        rec = scene.input.get("recording")
        if not rec:
            raise ValueError(f"{', '.join(_OPTION_SOURCES[k][0] for k in flags)}: the scene "
                             f"{args.scene} reads no recording file ([input] recording)")
        scene.input = with_recording(scene, rec, flags) | {
            k: v for k, v in scene.input.items() if k in ("start", "stop")}
        if Path(rec).is_file():
            input_options(args, rec, scene)       # a format that takes no such option: said now
    base = Path(args.out) if args.out else (scene.output or Path.cwd() / (Path(args.scene).stem
                                                                          + "-meshphase"))
    ctx, files = _run_and_write(args, scene, base, report=not args.no_report)
    return _finish_run(args, ctx, files)


def _gearset_line(g) -> str:
    return f"Z {g.z_sun}/{g.z_ring}/{g.z_planet}, {g.n_planets} planets"


def cmd_process(args) -> int:
    # the files checked before the stages' imports: a mistyped path fails before they load
    path = as_regular_file(args.file, "the recording")
    gearset = (load_scene(as_regular_file(args.gearset, "the gearset scene (--gearset)"),
                          recording_given=True) if args.gearset else None)
    scene_in = _input_scene(args)
    fmt, opts = input_options(args, path, scene_in or gearset)
    from .run.stages import process_recording  # the processing stack: see the module docstring

    if gearset is None and scene_in is not None and scene_in.gearset is not None:
        gearset = scene_in
    if gearset is None:
        from .api.scene import build_scene  # beside the processing stack

        with recording_read_errors(path):
            meta = read_info(path, format=fmt, **opts).meta.get("gearset")
        if not meta:
            raise ValueError(f"{path}: no gearset: give --gearset GEARSET.toml (a scene with a "
                             "[gearset] table) or --scene SCENE with one; this file's metadata "
                             "carries none")
        gearset = build_scene(scene=scene_in, meta_gearset=lambda: meta, label=str(path))
        print(message_line(args.command, "info", f"gearset: from the file's metadata "
                           f"({_gearset_line(gearset.gearset)}); --gearset GEARSET.toml gives "
                           "another"), file=sys.stderr)
    elif scene_in is not None and gearset is not scene_in:
        gearset.channels = scene_in.channels       # --scene's mapping over the gearset file's
    # process_recording returns the paths as published (the output folder's final name)
    ctx, files = process_recording(path, gearset, out_dir=args.out, overwrite=args.overwrite,
                                   progress=_stage_progress(_bars(args)), tolerance=args.tolerance,
                                   options=opts)
    return _finish_run(args, ctx, files)


def cmd_demo(args) -> int:
    t = time.perf_counter()
    # the scene file goes into the output folder first: `meshphase run` on it reproduces the run
    ctx, files = _run_and_write(args, lambda out: load_scene(demo_scene_path(out)), Path(args.out))
    rc = _finish_run(args, ctx, files)
    if files:
        print(f"demo finished in {time.perf_counter() - t:.1f} s; open {files['report']}")
    return rc


def cmd_campaign(args) -> int:
    from .campaign.runner import cli_campaign  # the campaign machinery: with the first campaign

    as_regular_file(args.scene, "the scene")
    out = Path(args.out) if args.out else Path.cwd() / (Path(args.scene).stem + "-campaign")
    res = cli_campaign(args.scene, args.inputs, scheduler=args.scheduler, workers=args.workers,
                       out=out, overwrite=args.overwrite, progress=_bars(args),
                       recording_reports=args.recording_reports, task_timeout=args.task_timeout,
                       resume=args.resume, dashboard=args.dashboard, recursive=args.recursive,
                       read_options=_flag_options(args) or None)
    c = res["counts"]
    print(f"campaign  {res['scene']}: {c['ok']} ok, {c['unreliable']} unreliable, {c['partial']} partial, "
          f"{c['failed']} failed in {res['timing_s'].get('total', float('nan')):.1f} s "
          f"({res['cluster']['n_workers']} worker(s), scheduler {res['cluster']['scheduler']})"
          + (f"; {res['resume']['n_resumed']} resumed" if res["resume"]["enabled"] else ""))
    for r in res["recordings"]:
        if r.get("status") != "ok":
            line = status_line({"status": r.get("status"), "error": r.get("error"),
                                "missing_results": r.get("missing_results") or [],
                                "unreliable": r.get("unreliable") or {}})
            print(f"{r.get('status', 'failed'):<11}{r.get('name')}")
            level, _, rest = line.partition(": ")
            print(message_line("campaign", level, f"{r.get('recording')}: {rest}"), file=sys.stderr)
    scene_status = res.get("scene_status") or {}
    if scene_status.get("status", "ok") != "ok":
        print(f"scene     {status_line(scene_status)}")
        level, _, rest = status_line(scene_status).partition(": ")
        print(message_line("campaign", level, f"scene-level results: {rest}"), file=sys.stderr)
    for name, p in res["files"].items():
        print(f"{name:<22} {p}")
    return res["exit_code"]


# ---------------------------------------------------------------------------- parser
def _seconds(text: str) -> float:
    """argparse type: a finite, non-negative number of seconds."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number of seconds: {text!r}") from None
    if not (v >= 0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds >= 0, got {text!r}")
    return v


#: The global flags, accepted before and after the subcommand: flag -> (dest, argparse kwargs).
_GLOBAL_FLAGS = {
    ("-v", "--verbose"): ("verbose", dict(action="count", help="more log output (-vv debug)")),
    ("-q", "--quiet"): ("quiet", dict(action="store_true",
                                      help="no progress bars (convert: no summary line either)")),
    ("--debug",): ("debug", dict(action="store_true", help="developers: re-raise errors with their "
                                 "traceback (also MESHPHASE_DEBUG=1)")),
    ("--any-fs",): ("any_fs", dict(action="store_true", help="accept a recording's sample rate "
                                   "outside 1e-3 to 1e8 Hz (refused by default as a damaged header; "
                                   "also MESHPHASE_ANY_FS=1)")),
}
#: Prefix of the dests the global flags get after the subcommand (merged by :func:`_merge_globals`).
_AFTER = "after_"


def _global_flags(parser: argparse.ArgumentParser, *, after: bool) -> None:
    """The global flags on ``parser``: the main parser's (defaults 0 / False), or a
    subcommand's (``after``: their own dests, absent unless given)."""
    g = parser.add_argument_group("global options") if after else parser
    for flags, (dest, kw) in _GLOBAL_FLAGS.items():
        kw = dict(kw)
        if after:
            g.add_argument(*flags, dest=_AFTER + dest, default=argparse.SUPPRESS, **kw)
        else:
            g.add_argument(*flags, dest=dest, default=0 if kw["action"] == "count" else False, **kw)


def _merge_globals(args: argparse.Namespace) -> argparse.Namespace:
    """The global flags given after the subcommand added to those before it (``-v`` counts
    add up)."""
    for _, (dest, _kw) in _GLOBAL_FLAGS.items():
        after = getattr(args, _AFTER + dest, None)
        if after is None:
            continue
        delattr(args, _AFTER + dest)
        setattr(args, dest, getattr(args, dest) + after if dest == "verbose" else True)
    return args


class _Sub:
    """``add_parser`` of the subcommands with the global flags on each (accepted after the
    subcommand as before it)."""

    def __init__(self, sub):
        self.sub = sub

    def add_parser(self, name: str, **kw) -> argparse.ArgumentParser:
        s = self.sub.add_parser(name, **kw)
        _global_flags(s, after=True)
        return s


def build_parser() -> argparse.ArgumentParser:
    """The ``meshphase`` argument parser: global options (before or after the command), one
    subparser per command."""
    p = argparse.ArgumentParser(
        prog="meshphase",
        description="Planetary gear rig strain recordings -> measured mesh phasing vs models.")
    p.add_argument("--version", action="version", version=f"meshphase {__version__}")
    _global_flags(p, after=False)
    sub = _Sub(p.add_subparsers(dest="command", required=True, metavar="COMMAND"))
    _add_info(sub)
    _add_convert(sub)
    _add_synth(sub)
    _add_demo(sub)
    _add_run(sub)
    _add_process(sub)
    _add_campaign(sub)
    _add_bench(sub)
    _add_completion(sub)
    return p


def _add_info(sub) -> None:
    """The ``meshphase info`` subcommand."""
    s = sub.add_parser("info", help="header, channels, kinds, fs, duration and start of a recording "
                                    "(the topics of another tool's MCAP); --quality scans the samples")
    s.add_argument("file", help="recording file (hdf5, mcap, csv, tdms ...; format recognised by content)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    q = s.add_mutually_exclusive_group()
    q.add_argument("--quality", action="store_true",
                   help="also scan every sample: NaN/inf counts and runs, clipped runs, range "
                        "(one pass in large blocks)")
    q.add_argument("--no-quality", dest="quality", action="store_false",
                   help="header only, the default (kept for scripts that pass it)")
    add_input_options(s)
    s.set_defaults(func=cmd_info)


def _add_convert(sub) -> None:
    """The ``meshphase convert`` subcommand."""
    s = sub.add_parser("convert", help="convert a recording between formats (hdf5, mcap, csv, tdms, ...)")
    s.add_argument("input", help="recording to read (.h5, .mcap, .csv, .tdms, ...)")
    s.add_argument("output", help="file to write (.h5, .mcap, .csv, .tdms, ...)")
    s.add_argument("--format", choices=FormatChoices(writable=True), help="output format (default: from the suffix)")
    s.add_argument("--compression", help="hdf5: gzip|lzf; mcap: lz4|zstd; csv: none (default none)")
    s.add_argument("--layout", choices=_LayoutChoices(),
                   help="mcap output: meshphase (sample blocks, the default) or foxglove "
                        "(JSON messages Foxglove plots)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    add_input_options(s)
    s.set_defaults(func=cmd_convert)


def _scenario_completer(**_kw):
    """Completions of a synthetic scenario name (argcomplete)."""
    from .io.sources import scenario_names

    return scenario_names("synthetic")


def _add_synth(sub) -> None:
    """The ``meshphase synth`` subcommand."""
    s = sub.add_parser("synth", help="write a synthetic recording of a named scenario plus its truth sidecar")
    s.add_argument("scenario", nargs="?", help="scenario name (see `meshphase synth --list`)"
                   ).completer = _scenario_completer
    s.add_argument("output", nargs="?", help="output file: .h5, .mcap, .csv or .tdms")
    s.add_argument("--list", action="store_true", help="list the scenarios and exit")
    s.add_argument("--minutes", type=float, help="duration [min] (default: the scenario's)")
    s.add_argument("--seed", type=int, help="random seed (recorded in the truth sidecar)")
    s.add_argument("--format", choices=FormatChoices(writable=True),
                   help="output format (default: from the suffix)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace an existing output file and its truth sidecar")
    s.set_defaults(func=cmd_synth)


def _add_demo(sub) -> None:
    """The ``meshphase demo`` subcommand."""
    s = sub.add_parser("demo", help="generate the seed rig recording, run the full scene on it, write the report")
    s.add_argument("--out", default="meshphase-demo", help="output folder (default ./meshphase-demo; never overwritten: -2, -3, ...)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the output folder (atomically, when the run finishes)")
    s.set_defaults(func=cmd_demo)


def _add_run(sub) -> None:
    """The ``meshphase run`` subcommand."""
    s = sub.add_parser("run", help="run a scene (TOML) and write results, figures and the HTML report")
    s.add_argument("scene", help="scene file (TOML; data_schemas/scene.md)")
    s.add_argument("--out", help="output folder (default: the scene's `output`, else STEM-meshphase, "
                                 "both in the current directory, e.g. rig.toml -> ./rig-meshphase; "
                                 "never overwritten: -2, -3, ...)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the output folder (atomically, when the run finishes)")
    s.add_argument("--no-report", action="store_true", help="results only, no HTML/figures")
    add_input_options(s, scene=False)
    s.set_defaults(func=cmd_run)


def _add_process(sub) -> None:
    """The ``meshphase process`` subcommand."""
    s = sub.add_parser(
        "process", help="process one recording: phasing, load sharing, comparison with the ideal "
        "and identified model (CSV + summary.json, no report; no Monte Carlo unless --tolerance)")
    s.add_argument("file", help="the recording (.h5, .mcap, .csv, .tdms ...)")
    s.add_argument("--gearset",
                   help="scene TOML with [gearset], [speeds], [[channels]], ... (its [input] "
                        "recording is replaced by FILE, its [input.*] tables read FILE; of its "
                        "results only centroids are computed: `meshphase run` a scene for the "
                        "others); default: --scene's [gearset], else the gearset in FILE's metadata")
    s.add_argument("--out", help="output folder (default: STEM-meshphase in the current directory, "
                                 "e.g. rig.h5 -> ./rig-meshphase; an existing folder is never "
                                 "overwritten: -2, -3, ...)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the output folder (atomically, when the run finishes)")
    s.add_argument("--tolerance", action="store_true",
                   help="also run the tolerance Monte Carlo of the gearset file's [tolerances] "
                        "(band coverage in the comparison)")
    add_input_options(s)
    s.set_defaults(func=cmd_process)


def _add_campaign(sub) -> None:
    """The ``meshphase campaign`` subcommand."""
    s = sub.add_parser("campaign", help="process many recordings with one scene as a Dask job")
    s.add_argument("scene", help="scene TOML (gearset, tolerances, results, [input.*] tables); each "
                                 "recording replaces [input] recording")
    s.add_argument("inputs", nargs="+", metavar="DIR_OR_FILE", help="recording files or folders of them")
    s.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a LocalCluster)")
    s.add_argument("--workers", type=int, help="LocalCluster worker processes (default: one per core)")
    s.add_argument("--out", help="output folder (default ./SCENE-campaign in the current directory; "
                                 "never overwritten: -2, -3, ...)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the output folder (atomically, when the campaign finishes)")
    s.add_argument("--resume", action="store_true",
                   help="reuse the complete results in the output folder (and OUT.partial, kept by an "
                        "unfinished run); redo changed or missing recordings")
    s.add_argument("--task-timeout", type=_seconds, metavar="SECONDS",
                   help="fail a recording whose task runs longer (its worker is restarted); "
                        "0: no limit (default: 300 s + 10 s per MB of the recording)")
    s.add_argument("--dashboard", nargs="?", const="127.0.0.1:0", metavar="ADDRESS",
                   help="serve the Dask dashboard of the local cluster (default off; without ADDRESS "
                        "on 127.0.0.1, a free port; it has no authentication)")
    s.add_argument("--recording-reports", action="store_true", help="an HTML report per recording too")
    s.add_argument("--recursive", action="store_true",
                   help="look for recordings in the folders' subfolders too (not hidden ones, "
                        "symbolic links or meshphase output folders)")
    add_input_options(s, scene=False)
    s.set_defaults(func=cmd_campaign)


def _add_bench(sub) -> None:
    """The ``meshphase bench`` subcommand."""
    s = sub.add_parser("bench", help="benchmarks: io, models, processing or all (tables + figures)")
    s.add_argument("what", nargs="?", default="all",
                   choices=["io", "models", "processing", "all", "campaign", "reference"],
                   help="which benchmarks (default all: io, models, processing); campaign: the "
                        "same 8 x 2 min campaign on 1 and 2 local workers (--quick: 2 x 0.5 min), "
                        "its speed-up and phase timings, and 200 x 2 min (--quick: 6 x 0.5) on a "
                        "scheduler and 2 workers as processes against plain `process` (the "
                        "overhead per recording); reference: build (or read) the "
                        "models bench's 1e7-evaluation reference in --out as its own step")
    s.add_argument("--out", default="bench-results", help="output folder (default ./bench-results)")
    s.add_argument("--minutes", type=float, default=60.0, help="io: recording length [min] (default 60)")
    s.add_argument("--quick", action="store_true", help="small sizes, for a smoke run")
    s.add_argument("--repeats", type=_repeats, default=None, metavar="N",
                   help="campaign: timed runs per worker count, interleaved 1, 2, 1, 2, ... "
                        "(default 3; --quick: 1); more repeats, more pairs on a noisy machine")
    s.add_argument("--evaluations", type=int, default=10 ** 7,
                   help="reference: full-model evaluations (default 1e7)")
    s.add_argument("--plain", action="store_true",
                   help="reference: the plain pseudo-random reference instead of the directional one")
    s.add_argument("--accuracy", action="store_true",
                   help="processing: only the accuracy table of the conditions where measured "
                        "phasing was once confident and wrong (error, floor, target, "
                        "RMS(error/sigma), coverage, verdict per condition and gauge), printed "
                        "as Markdown and written as conditions.json/.csv/.md into --out "
                        "(--quick: one short row)")
    s.add_argument("--warmup", action="store_true",
                   help="only compile the numba kernels (Monte Carlo, dense onsets, interleaved TDMS rows) "
                        "into the per-user cache "
                        "(~/.cache/meshphase/numba or NUMBA_CACHE_DIR) and say how long it took")
    s.add_argument("--rss-minutes", type=_minutes_list, default=None, metavar="M[,M...]",
                   help="lengths [min] of the 8-channel recordings whose peak memory of convert "
                        "and process is measured (default io: 10,60,180, a few minutes for the "
                        "3 h one; processing: 2,10,60,180; --quick: 0.5,1; none: skip)")
    s.set_defaults(func=cmd_bench)


def _add_completion(sub) -> None:
    """The ``meshphase completion`` subcommand."""
    s = sub.add_parser("completion", help="print the shell code that completes meshphase's commands, "
                                          "options, formats and scenarios (bash, zsh, fish)")
    s.add_argument("shell", choices=COMPLETION_SHELLS, help="the shell: eval \"$(meshphase completion "
                                                            "bash)\" in ~/.bashrc (zsh: ~/.zshrc)")
    s.set_defaults(func=cmd_completion)


#: Shells ``meshphase completion`` writes the activation code of (argcomplete's).
COMPLETION_SHELLS = ("bash", "zsh", "fish")


def cmd_completion(args) -> int:
    import argcomplete  # only here and when completing

    print(argcomplete.shellcode(["meshphase"], shell=args.shell))
    return 0


def _complete(parser: argparse.ArgumentParser) -> None:
    """Shell completion (argcomplete): when the shell asks (``_ARGCOMPLETE`` set), print the
    completions of the command line in ``COMP_LINE`` and exit; otherwise return at once."""
    if "_ARGCOMPLETE" not in os.environ:
        return
    import argcomplete

    argcomplete.autocomplete(parser)


def _one_line(text) -> str:
    """``text`` on one line (messages of nested errors can hold newlines)."""
    return " ".join(str(text).split())


_OS_HINTS = {
    errno.EACCES: "check the permissions of the file or folder",
    errno.EPERM: "check the permissions of the file or folder",
    errno.ENOSPC: "free some space or write the outputs elsewhere (--out)",
    errno.EDQUOT: "disk quota exceeded: free some space or write elsewhere (--out)",
    errno.ENAMETOOLONG: "a file or folder name is longer than the file system allows, usually 255 bytes",
    errno.ELOOP: "a symbolic-link loop in the path",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.EISDIR: "a folder where a file is expected",
    errno.EROFS: "the file system is read-only",
}


def describe_error(exc: BaseException) -> str:
    """One line for an exception that ends a command (no traceback, no class name where the
    message says it all).

    Parameters
    ----------
    exc : BaseException

    Returns
    -------
    str
    """
    if isinstance(exc, MemoryError):
        return ("out of memory" + (f" ({exc})" if str(exc) else "") + "; process a shorter time "
                "window ([input] start_s / stop_s) or on a machine with more memory")
    if isinstance(exc, OSError) and exc.errno is not None:
        names = " -> ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
        text = exc.strerror or str(exc)
        hint = _OS_HINTS.get(exc.errno)
        return _one_line((f"{names}: " if names else "") + text + (f" ({hint})" if hint else ""))
    if isinstance(exc, KeyError):
        return _one_line(f"missing key {exc.args[0]!r}" if exc.args else "KeyError")
    if isinstance(exc, (ValueError, TypeError, OSError)):
        return _one_line(exc)  # ours name the file / parameter; h5py's OSErrors say HDF5
    return _one_line(f"{type(exc).__name__}: {exc} (unexpected; `meshphase --debug ...` shows "
                     "the traceback)")


def _once(show):
    """``warnings.showwarning`` that shows each distinct warning line once per command."""
    seen = set()

    def showwarning(message, category, filename, lineno, file=None, line=None):
        key = (category, _one_line(message))
        if key in seen:
            return
        seen.add(key)
        show(message, category, filename, lineno, file, line)
    return showwarning


def _stdout_closed() -> int:
    """The reader of our stdout went away (``| head``): send the rest to devnull and exit
    quietly (the Python docs' recipe, signal module, "Note on SIGPIPE")."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout replaced in-process (tests)
        pass
    return EXIT_PIPE


def main(argv=None) -> int:
    """Run the command line; returns the exit code (the table in the module docstring).

    The one error boundary of the command: every error becomes one line on stderr and an
    exit code; ``--debug`` / ``MESHPHASE_DEBUG=1`` re-raises instead."""
    parser = build_parser()
    _complete(parser)                     # the shell asking for completions: answered, exits
    args = _merge_globals(parser.parse_args(argv))  # usage errors: argparse prints them, exits 2
    limit_heap_growth()                   # streamed runs: peak memory flat in length
    debug = bool(args.debug) or os.environ.get("MESHPHASE_DEBUG", "").strip() not in ("", "0")
    level = logging.DEBUG if debug else logging.WARNING - 10 * min(args.verbose, 2)
    handler = logging.StreamHandler()          # stderr, one style with every other message
    handler.setFormatter(MessageFormatter(args.command))
    logging.basicConfig(level=level, handlers=[handler])
    logger.setLevel(level)
    logging.captureWarnings(False)
    # warnings on one line each ("meshphase info: warning: FormatWarning: ..."), not file:line + source,
    # and each line once (a warning repeats when a block reader meets it again, or when a
    # filter change resets the registry that "default" uses to show it once)
    old_format, old_show = warnings.formatwarning, warnings.showwarning
    warnings.formatwarning = lambda message, category, *_a, **_k: (
        message_line(args.command, "warning", f"{category.__name__}: {message}") + "\n")
    warnings.showwarning = _once(old_show)
    old_any_fs = os.environ.get(ANY_FS_ENV)
    if args.any_fs:               # the environment: campaign workers inherit it
        os.environ[ANY_FS_ENV] = "1"
    try:
        rc = int(args.func(args) or 0)
        sys.stdout.flush()                 # a closed pipe shows here, not at interpreter exit
        return rc
    except BrokenPipeError:
        return _stdout_closed()
    except KeyboardInterrupt:
        if debug:
            raise
        print(message_line(args.command, "interrupted", ""), file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the boundary: one line, never a traceback
        if debug:
            raise
        try:
            print(message_line(args.command, "error", describe_error(exc)), file=sys.stderr)
        except OSError:
            pass
        return EXIT_ERROR
    finally:
        warnings.formatwarning, warnings.showwarning = old_format, old_show
        if args.any_fs:
            if old_any_fs is None:
                os.environ.pop(ANY_FS_ENV, None)
            else:
                os.environ[ANY_FS_ENV] = old_any_fs


def console_main(argv=None) -> int:
    """The ``meshphase`` console script (and ``python -m meshphase``): :func:`main`, then
    one garbage collection and the heap frozen (:func:`gc.freeze`), so that the interpreter's
    exit skips its own collections.

    Those collections walk every object the command's imports made (about 187 000 with the
    campaign workers' stack: dask, matplotlib, pandas, h5py, scipy) and free next to nothing,
    since the process is ending. From the last ``atexit`` handler to the process reaped:
    0.38-0.52 s with that stack loaded, 0.04-0.05 s with the heap frozen, after a collection
    of 0.08-0.09 s here (``meshphase bench processing``, its exit table). That collection
    still runs the finalizers of any unreachable cycle, as the exit's own would; ``atexit``
    handlers and C-level exit handlers such as HDF5's run as before. Not in :func:`main`: a
    process that calls it and goes on (tests, notebooks) would never collect the frozen
    objects.

    Parameters
    ----------
    argv : list of str, optional
        As :func:`main`.

    Returns
    -------
    int
        :func:`main`'s exit code.
    """
    rc = main(argv)
    gc.collect()
    gc.freeze()
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
