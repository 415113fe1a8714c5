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
import errno
import gc
import json
import logging
import math
import os
import sys
import time
import warnings
from pathlib import Path

from .version import __version__
from .io.channels import mapping_report
from .run.demo import demo_scene_path
from .errors import DataQualityWarning
from .run.exits import (EXIT_ERROR, EXIT_INTERRUPTED, EXIT_PIPE, recording_read_errors,
                        run_status, status_line)
from .runtime.heap import limit_heap_growth
from .io import FormatChoices, convert, detect_format, iter_blocks, read_info
from .io.base import ANY_FS_ENV
from .io.tdms_rows import warmup as warmup_rows
from .models._kernels import warmup as warmup_models
from .runtime.log import MessageFormatter, logger, message_line
from .signal.quality import channel_quality
from .run.scene import SceneError, load_scene
from .validate import as_regular_file

__all__ = ["main", "build_parser", "describe_error"]


def _progress(total: int | None, desc: str, enabled: bool):
    from tqdm import tqdm  # with the first bar: tqdm loads importlib.metadata (~20 ms)

    return tqdm(total=total, desc=desc, unit="S", unit_scale=True, disable=not enabled,
                leave=False, file=sys.stderr)


# ---------------------------------------------------------------------------- info
def _fmt_seconds(s: float) -> str:
    if s >= 3600:
        return f"{s / 3600:.3f} h"
    if s >= 60:
        return f"{s / 60:.3f} min"
    return f"{s:.6g} s"


def cmd_info(args) -> int:
    path = as_regular_file(args.file, "the recording")  # a FIFO would block detect_format
    with recording_read_errors(path):
        fmt = detect_format(path)
        info = read_info(path, format=fmt)
    out = {
        "file": str(path), "format": fmt, "fs_hz": info.fs, "n_samples": info.n_samples,
        "duration_s": info.duration, "t0_s": info.t0, "start_datetime": info.start_datetime,
        "channels": [c.to_dict() for c in info.channels], "meta": info.meta,
        "history": info.history,
    }
    if getattr(args, "scene", None):   # before the scan: a bad scene fails at once
        out["channel_map"] = _channel_map(args.scene, info.channels, str(path))
    if not args.no_quality:
        # quality summary streamed in blocks: memory stays flat on long files
        totals = {c.name: {"n_nonfinite": 0, "nonfinite_runs": 0, "clipped_runs": 0,
                           "min": float("inf"), "max": float("-inf")} for c in info.channels}
        block_s = max(1.0, 2**22 / info.fs)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataQualityWarning)  # counted below instead
            with _progress(info.n_samples, "quality", not args.quiet) as bar, \
                    recording_read_errors(path):
                for block in iter_blocks(path, block_s, format=fmt):
                    for i, c in enumerate(block.channels):
                        q = channel_quality(block.data[:, i])
                        t = totals[c.name]
                        t["n_nonfinite"] += q["n_nonfinite"]
                        t["nonfinite_runs"] += len(q["nonfinite_runs"])
                        t["clipped_runs"] += q["n_clipped_runs"]
                        if q["n_samples"] > q["n_nonfinite"]:
                            t["min"] = min(t["min"], q["min"])
                            t["max"] = max(t["max"], q["max"])
                    bar.update(block.n_samples)
        out["quality"] = totals
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
    return 0


def _channel_map(scene_path, channels, source: str) -> dict:
    """``info --scene``: the scene's channel mapping of the recording
    (:func:`meshphase.io.channels.mapping_report`)."""
    scene = load_scene(as_regular_file(scene_path, "the scene"))
    return dict(mapping_report(channels, scene.channels, source), scene=str(scene_path))


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
def cmd_convert(args) -> int:
    src, dst = as_regular_file(args.input, "the input recording"), Path(args.output)
    if args.compression and (args.format or dst.suffix.lower().lstrip(".")) == "csv":
        raise ValueError(f"--compression {args.compression}: CSV is written uncompressed "
                         "(compression is for hdf5 and mcap)")
    options = {"compression": args.compression} if args.compression else {}
    done = convert(src, dst, format=args.format, overwrite=args.overwrite,
                   progress=lambda total, desc: _progress(total, desc, not args.quiet), **options)
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
                            format=args.format, overwrite=args.overwrite, progress=not args.quiet)
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
                              progress=not args.quiet)
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


def _repeats(text: str) -> int:
    """``--repeats N``: a whole number >= 1."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of runs, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"repeats must be at least 1, got {n}")
    return n


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
            from tqdm import tqdm

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
                         progress=_stage_progress(not args.quiet))


def cmd_run(args) -> int:
    scene = load_scene(as_regular_file(args.scene, "the scene"))
    if not scene.results:
        # an empty scene (or a gearset file) would "succeed" at computing nothing
        raise SceneError(args.scene, "results", "no results requested, nothing to run; add e.g. "
                         'results = ["ideal_phasing", "phasing"] (`meshphase process FILE --gearset '
                         f"{args.scene}` takes a gearset file without results)")
    base = Path(args.out) if args.out else (scene.output or Path(args.scene).with_suffix("").with_name(
        Path(args.scene).stem + "-out"))
    ctx, files = _run_and_write(args, scene, base, report=not args.no_report)
    return _finish_run(args, ctx, files)


def cmd_process(args) -> int:
    # both files checked before the stages' imports: a mistyped path fails before they load
    as_regular_file(args.file, "the recording")
    as_regular_file(args.gearset, "the gearset scene (--gearset)")
    from .run.stages import process_recording  # the processing stack: see the module docstring
    # process_recording returns the paths as published (the output folder's final name)
    ctx, files = process_recording(args.file, args.gearset, out_dir=args.out, overwrite=args.overwrite,
                                   progress=_stage_progress(not args.quiet), tolerance=args.tolerance)
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
    res = cli_campaign(args.scene, args.inputs, scheduler=args.scheduler, workers=args.workers,
                       out=args.out, overwrite=args.overwrite, progress=not args.quiet,
                       recording_reports=args.recording_reports, task_timeout=args.task_timeout,
                       resume=args.resume, dashboard=args.dashboard, recursive=args.recursive)
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


def build_parser() -> argparse.ArgumentParser:
    """The ``meshphase`` argument parser: global options, one subparser per command."""
    p = argparse.ArgumentParser(
        prog="meshphase",
        description="Planetary gear rig strain recordings -> measured mesh phasing vs models.")
    p.add_argument("--version", action="version", version=f"meshphase {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv debug)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bars (convert: no summary line either)")
    p.add_argument("--debug", action="store_true",
                   help="developers: re-raise errors with their traceback (also MESHPHASE_DEBUG=1)")
    p.add_argument("--any-fs", action="store_true",
                   help="accept a recording's sample rate outside 1e-3 to 1e8 Hz (refused by default as "
                        "a damaged header; also MESHPHASE_ANY_FS=1)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_info(sub)
    _add_convert(sub)
    _add_synth(sub)
    _add_demo(sub)
    _add_run(sub)
    _add_process(sub)
    _add_campaign(sub)
    _add_bench(sub)
    return p


def _add_info(sub) -> None:
    """The ``meshphase info`` subcommand."""
    s = sub.add_parser("info", help="channels, kinds, fs, duration, start and a quality summary of a recording")
    s.add_argument("file", help="recording file (hdf5, mcap, csv, tdms; format recognised by content)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.add_argument("--no-quality", action="store_true", help="header only (do not scan the samples)")
    s.add_argument("--scene", metavar="SCENE",
                   help="also list what the scene's [[channels]] map each channel to, and what they leave unmapped")
    s.set_defaults(func=cmd_info)


def _add_convert(sub) -> None:
    """The ``meshphase convert`` subcommand."""
    s = sub.add_parser("convert", help="convert a recording between formats (hdf5, mcap, csv, tdms, ...)")
    s.add_argument("input", help="recording to read (.h5, .mcap, .csv, .tdms, ...)")
    s.add_argument("output", help="file to write (.h5, .mcap, .csv, .tdms, ...)")
    s.add_argument("--format", choices=FormatChoices(writable=True), help="output format (default: from the suffix)")
    s.add_argument("--compression", help="hdf5: gzip|lzf; mcap: lz4|zstd; csv: none (default none)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    s.set_defaults(func=cmd_convert)


def _add_synth(sub) -> None:
    """The ``meshphase synth`` subcommand."""
    s = sub.add_parser("synth", help="write a synthetic recording of a named scenario plus its truth sidecar")
    s.add_argument("scenario", nargs="?", help="scenario name (see `meshphase synth --list`)")
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
    s.add_argument("--out", help="output folder (default: the scene's `output`, relative to the scene "
                                 "file, else STEM-out beside it, e.g. rig.toml -> rig-out; never "
                                 "overwritten: -2, -3, ...)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the output folder (atomically, when the run finishes)")
    s.add_argument("--no-report", action="store_true", help="results only, no HTML/figures")
    s.set_defaults(func=cmd_run)


def _add_process(sub) -> None:
    """The ``meshphase process`` subcommand."""
    s = sub.add_parser(
        "process", help="process one recording: phasing, load sharing, comparison with the ideal "
        "and identified model (CSV + summary.json, no report; no Monte Carlo unless --tolerance)")
    s.add_argument("file", help="the recording (.h5, .mcap, .csv, .tdms)")
    s.add_argument("--gearset", required=True,
                   help="scene TOML with [gearset], [speeds], [[channels]], ... (its [input] is "
                        "replaced by FILE; of its results only centroids are computed: `meshphase "
                        "run` a scene for the others)")
    s.add_argument("--out", help="output folder (default: STEM-meshphase beside FILE, e.g. rig.h5 -> "
                                 "rig-meshphase; an existing folder is never overwritten: -2, -3, ...)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the output folder (atomically, when the run finishes)")
    s.add_argument("--tolerance", action="store_true",
                   help="also run the tolerance Monte Carlo of the gearset file's [tolerances] "
                        "(band coverage in the comparison)")
    s.set_defaults(func=cmd_process)


def _add_campaign(sub) -> None:
    """The ``meshphase campaign`` subcommand."""
    s = sub.add_parser("campaign", help="process many recordings with one scene as a Dask job")
    s.add_argument("scene", help="scene TOML (gearset, tolerances, results); each recording replaces [input]")
    s.add_argument("inputs", nargs="+", metavar="DIR_OR_FILE", help="recording files or folders of them")
    s.add_argument("--scheduler", help="address of an existing Dask scheduler (default: a LocalCluster)")
    s.add_argument("--workers", type=int, help="LocalCluster worker processes (default: one per core)")
    s.add_argument("--out", help="output folder (default SCENE-campaign; never overwritten: -2, -3, ...)")
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
    args = parser.parse_args(argv)        # usage errors: argparse prints them, exits 2
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
    """The ``meshphase`` console script (and ``python -m meshphase.cli``): :func:`main`, then
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
