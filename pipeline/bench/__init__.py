"""Benchmarks behind ``meshphase bench``: measured, never asserted.

- :mod:`.io`          read throughput per format as a ratio to a raw .npy read, peak memory;
                      peak RSS of ``meshphase convert`` and ``meshphase process`` from
                      10 min to 3 h of 8 channels
- :mod:`.models`      Monte Carlo error against run time (plain vs Sobol sampling)
- :mod:`.processing`  onset timing error vs the Cramer-Rao bound, detection throughput; peak
                      RSS and wall time of ``meshphase process`` from 2 min to 3 h of 8 channels;
                      start-up time of the command (:mod:`.startup`)
- :mod:`.rss`         the child-process peak-memory measurement both use
- :mod:`.campaign`    the same campaign timed with 1, 2, ... local workers
                      (:func:`.campaign.measure_speedup`; not one of :func:`run_bench`'s kinds)

:func:`run_bench` runs one or all of them into one output folder.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from ..runtime.log import logger

__all__ = ["run_bench", "rss_summary"]

KINDS = ("io", "models", "processing")


def run_bench(what: str, out_dir, *, minutes: float = 60.0, quick: bool = False,
              rss_minutes=None) -> dict:
    """Run the ``what`` benchmark ("io", "models", "processing" or "all") into ``out_dir``.

    Parameters
    ----------
    what : str
    out_dir : path
        Created if missing; each benchmark writes its JSON + Markdown (+ figure) there.
    minutes : float
        Length of the io benchmark's generated recording [min].
    quick : bool
        Small sizes for a smoke run.
    rss_minutes : sequence of float, optional
        Lengths [min] of the 8-channel recordings whose peak memory (RSS) of ``meshphase
        convert`` and ``meshphase process`` is measured (io: both; processing: process).
        Default: 10 min, 1 h and 3 h for io (:data:`.io.CONVERT_MINUTES`),
        :data:`.processing.PROCESS_MINUTES` for processing; 0.5 and 1 min when ``quick``;
        an empty sequence measures none.

    Returns
    -------
    dict
        ``{"files": {name: path}, "results": {kind: result dict}, "wall_s": {kind: s}}``
    """
    if what not in KINDS + ("all",):
        raise ValueError(f"what must be one of {KINDS + ('all',)}, got {what!r}")
    if rss_minutes is not None:
        from ..validate import as_positive

        if isinstance(rss_minutes, (str, bytes)) or not hasattr(rss_minutes, "__iter__"):
            raise TypeError(f"rss_minutes must be a sequence of minutes, got {rss_minutes!r}")
        rss_minutes = tuple(float(as_positive(m, "rss_minutes")) for m in rss_minutes)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kinds = KINDS if what == "all" else (what,)
    results, wall = {}, {}
    for kind in kinds:
        t = time.perf_counter()
        logger.info("bench %s -> %s", kind, out)
        if kind == "io":
            from .io import CONVERT_MINUTES, run_io_bench
            rss = rss_minutes if rss_minutes is not None else (
                (0.5, 1.0) if quick else CONVERT_MINUTES)
            results[kind] = run_io_bench(out, minutes=(min(minutes, 0.5) if quick else minutes),
                                         convert_minutes=rss, process_minutes=rss)
        elif kind == "models":
            from .models import run_models_bench
            results[kind] = run_models_bench(out, quick=quick)
        else:
            from .processing import PROCESS_MINUTES, run_processing_bench
            rss = rss_minutes if rss_minutes is not None else (
                (0.5, 1.0) if quick else PROCESS_MINUTES)
            results[kind] = run_processing_bench(out, quick=quick, process_minutes=rss)
        wall[kind] = time.perf_counter() - t
    files = {p.name: str(p) for p in sorted(out.iterdir()) if p.is_file()}
    summary = {"kinds": list(kinds), "wall_s": wall, "files": list(files)}
    (out / "bench_summary.json").write_text(json.dumps(summary, indent=2))
    files["bench_summary.json"] = str(out / "bench_summary.json")
    report = combined_report(out, kinds, wall)
    files[report.name] = str(report)
    md = out / "bench_report.md"
    files[md.name] = str(md)
    return {"files": files, "results": results, "wall_s": wall}


def rss_summary(results: dict) -> list[str]:
    """One line per peak-memory measurement of :func:`run_bench`'s results (what ``meshphase
    bench`` prints): command, length, data size, peak RSS [MB = 2**20 B] and wall time [s]."""
    lines = []
    io = results.get("io") or {}
    for r in io.get("convert") or []:
        lines.append(f"convert {r['source']:>4} -> {r['target']:<4} {r['minutes']:>6g} min x "
                     f"{r['n_channels']} ch ({r['data_mb']:7.0f} MB): peak RSS "
                     f"{r['peak_rss_mb']:6.0f} MB, {r['wall_s']:7.1f} s")
    proc = list(io.get("process") or []) + list((results.get("processing") or {}).get("process") or [])
    for r in proc:
        lines.append(f"process              {r['minutes']:>6g} min x {r['n_channels']} ch "
                     f"({r['data_mb']:7.0f} MB): peak RSS {r['peak_rss_mb']:6.0f} MB, "
                     f"{r['wall_s']:7.1f} s ({r['status']})")
    return lines


def combined_report(out: Path, kinds, wall: dict) -> Path:
    """One table-and-figure set of every benchmark in ``out``: ``bench_report.md`` (the
    benchmarks' Markdown tables, in order) and ``bench_report.html`` (the same tables plus
    every figure, self-contained)."""
    from ..report.html import Report

    titles = {"io": "Read throughput and memory (ratios to a raw .npy read)",
              "models": "Monte Carlo: error against run time",
              "processing": "Onsets: timing error against the Cramer-Rao bound, throughput"}
    parts = ["# meshphase benchmarks", ""]
    rep = Report("meshphase benchmarks", "measured on this machine; numbers, not assertions")
    for kind in kinds:
        sec = rep.section(titles[kind])
        sec.text(f"wall time of the benchmark: {wall.get(kind, float('nan')):.1f} s")
        for mdf in sorted(out.glob(f"{kind}_*.md")):
            text = mdf.read_text()
            parts += [f"## {titles[kind]}", "", text, ""]
            sec.html(f"<pre>{_escape(text)}</pre>")
        for png in sorted(out.glob(f"{kind}_*.png")):
            sec.figure(png.read_bytes(), caption=png.stem)
    (out / "bench_report.md").write_text("\n".join(parts))
    return rep.write(out / "bench_report.html")


def _escape(text: str) -> str:
    import html

    return html.escape(text)
