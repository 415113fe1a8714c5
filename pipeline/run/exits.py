"""Exit status of the ``meshphase`` command and the run status behind it.

One table, used by every subcommand (also in README.md, "Exit status", and in the
:mod:`meshphase.cli` docstring):

====  ==========================================================================================
code  meaning
====  ==========================================================================================
0     ok: every requested result was computed, none of them empty or all NaN (and no
      phasing is flagged unreliable)
1     input or scene error, nothing usable: unreadable / corrupt / truncated file, a channel
      the scene names that the file lacks, no gauge channel, every gauge channel all NaN/inf
      or constant while a requested result is empty, a bad scene, a non-regular file given as
      input, an OS error (permission, no space left, name too long, ...), out of memory; a
      campaign in which every recording failed (its folder is written all the same:
      ``campaign.json`` and ``campaign.csv`` give each recording's cause)
2     usage error (bad command line: argparse's own message)
3     partial result: outputs written, but some requested result is missing: its stage
      failed, was skipped because a stage it needs failed, or ran and left the result empty
      or all NaN (a gauge without a measured pass, load sharing without a factor, nothing to
      compare); summary.json has ``"status": "partial"`` and ``missing_results`` with each
      cause, whatever stage noticed it; or a phasing result is flagged unreliable
      (``"status": "unreliable"``); a campaign with any recording failed, partial or
      unreliable
130   interrupted (Ctrl-C / SIGINT); the output folder of the interrupted run is removed
      (with ``--overwrite`` the previous folder stays as it was; a campaign keeps its finished
      recordings in ``OUT.partial`` for ``--resume``)
141   standard output closed early by the reader (``meshphase info --json | head -1``): quiet,
      the status a process killed by SIGPIPE gets
143   terminated (SIGTERM; 129: SIGHUP) while writing: the run unwinds as for Ctrl-C and
      leaves nothing (no output folder, no staging folder, no temporary file)
====  ==========================================================================================

:func:`run_status` turns a :class:`meshphase.run.context.RunContext` into that status (it goes
into ``summary.json`` and decides the exit code) by inspecting the results themselves and the
run's typed failures and messages (:mod:`meshphase.run.state`), not the stages' own verdicts;
:func:`status_line` says it in one line. The output folder a run writes into is
:mod:`meshphase.run.outdir`'s; :func:`recording_read_errors` (from :mod:`meshphase.io.base`)
turns the HDF5 library's exceptions into a :class:`~meshphase.io.RecordingFileError` naming
the file.
"""

from __future__ import annotations

import re

import numpy as np

from ..io.base import recording_read_errors  # noqa: F401 (public here too)
from ..recording import GAUGE_KINDS
from .declare import RESULT_OF_STAGE
from .state import FailureKind, RunMessage

__all__ = ["EXIT_OK", "EXIT_ERROR", "EXIT_USAGE", "EXIT_PARTIAL", "EXIT_INTERRUPTED",
           "EXIT_PIPE", "RESULT_OF_STAGE", "run_status", "status_line", "recording_read_errors"]

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_PARTIAL = 3
EXIT_INTERRUPTED = 130
EXIT_PIPE = 141

#: exception class names that add nothing to a message that names the file and the problem
_GENERIC = {"ValueError", "TypeError", "KeyError", "OSError", "RecordingFileError",
            "CorruptFileError", "SceneError", "PermissionError", "FileNotFoundError",
            "IsADirectoryError", "NotADirectoryError", "TimeoutError", "InterruptedError"}
#: ``str()`` of an OSError with a file name: "[Errno 13] Permission denied: '/x.h5'"
_OS_TEXT = re.compile(r"^\[Errno \d+\] (?P<text>.*): (?P<q>['\"])(?P<file>.*)(?P=q)$")


def _load_error(failure) -> str:
    """A failed load stage's message without a generic exception class, the file name
    first."""
    msg = failure.reason if failure.exception in _GENERIC else str(failure)
    m = _OS_TEXT.match(msg)
    return f"{m['file']}: {m['text']}" if m else msg


def _root_causes(failed: dict, stage: str, seen: frozenset = frozenset()) -> list[tuple[str, str]]:
    """(stage, message) of the stages that really failed behind ``stage``'s entry."""
    f = failed.get(stage)
    if f is None or f.kind is not FailureKind.BLOCKED or stage in seen:
        return [(stage, "" if f is None else str(f))]
    out = []
    for dep in f.blocked_by:
        if dep in failed:
            out.extend(_root_causes(failed, dep, seen | {stage}))
        else:
            out.append((dep, "did not run"))
    return list(dict.fromkeys(out))


def _cause(failed: dict, stage: str) -> str:
    f = failed[stage]
    if f.kind is not FailureKind.BLOCKED:
        return str(f)
    roots = _root_causes(failed, stage)
    return "skipped: " + "; ".join(f"{s} failed ({m})" for s, m in roots)


def _stage_reasons(messages, stage: str, gauge: str | None = None) -> list[str]:
    """The texts of ``stage``'s messages (those about ``gauge``'s gauge when given, without
    their leading ``"<gauge> gauge (<channel>): "``)."""
    out = []
    for m in messages:
        if not isinstance(m, RunMessage) or m.stage != stage:
            continue
        if gauge is not None:
            if m.gauge != gauge:
                continue
            out.append(m.detail)
        else:
            out.append(m.text)
    return out


def _all_nan(values) -> bool:
    """No finite number in ``values`` (None and an empty array count as all NaN)."""
    if values is None:
        return True
    a = np.asarray(values, dtype=float)
    return not np.isfinite(a).any()


def _empty_results(ctx, failed: dict) -> list[dict]:
    """The requested results whose stage ran but left them empty or all NaN, with the cause
    (the run's own messages about it, else what is empty)."""
    requested = set(getattr(ctx.scene, "results", None) or ())
    out = []

    def missing(result: str, stage: str, what: str, reasons) -> None:
        reasons = list(dict.fromkeys(r for r in reasons if r))
        out.append({"result": result, "stage": stage,
                    "cause": what + (f" ({'; '.join(reasons)})" if reasons else "")})

    ph = ctx.phasing
    if "phasing" in requested and "phasing" not in failed and ph is not None:
        if not ph.tables:
            missing("phasing", "phasing", "no gauge measured", _stage_reasons(ctx.messages, "phasing"))
        channels = getattr(ctx.load.recording, "channels", ()) if ctx.load is not None else ()
        for gauge, table in ph.tables.items():
            if len(table) == 0 or _all_nan(table.gamma):
                notes = [n for n in getattr(table, "notes", None) or () if n != "no usable pass"]
                names = [c.name for c in channels if (c.gear or c.kind) == gauge]
                data = [t for st in ("load", "condition", "onsets")
                        for t in _stage_reasons(ctx.messages, st)
                        if any(f"channel {n!r}" in t for n in names)]
                # the verdict's own causes first (a wiring finding names the channel and the fix)
                rel = [r for r in ((getattr(ph, "reliability", None) or {}).get(gauge) or {}).get("reasons", ())
                       if r != "no pass could be measured"]
                missing("phasing", "phasing", f"{gauge} gauge: no measured pass",
                        rel + _stage_reasons(ctx.messages, "phasing", gauge) + notes + data)
    ls = ctx.load_sharing
    if "load_sharing" in requested and "load_sharing" not in failed and ls is not None:
        if ls.sharing is None or _all_nan(ls.sharing.factors):
            what = ("no ring gauge to read" if ls.sharing is None and ls.channel is None
                    else f"no planet's factor from the {ls.channel or 'ring'} gauge")
            missing("load_sharing", "load_sharing", what, _stage_reasons(ctx.messages, "load_sharing"))
    cmp = ctx.compare
    if "compare" in requested and "compare" not in failed and cmp is not None and not cmp.by_gear:
        missing("compare", "compare", "no gauge with measured phasing to compare",
                _stage_reasons(ctx.messages, "compare"))
    ident = ctx.identify
    if "identify" in requested and "identify" not in failed and ident is not None:
        idf = ident.identification
        if getattr(idf, "n_passes", 0) == 0 or _all_nan(getattr(idf, "rms_after", None)):
            missing("identify", "identify", "nothing identified",
                    _stage_reasons(ctx.messages, "identify"))
    ideal = ctx.ideal
    if "ideal_phasing" in requested and "ideal" not in failed and ideal is not None \
            and (_all_nan(ideal.gamma_s) and _all_nan(ideal.gamma_r)):
        missing("ideal_phasing", "ideal", "no finite ideal phasing", ())
    return out


def _nothing_usable(ctx) -> str | None:
    """Why nothing usable was read (every gauge channel all NaN/inf or constant in the load
    stage's raw-sample quality), else None."""
    if ctx.load is None:
        return None
    kinds = {c.name: c.kind for c in getattr(ctx.load.recording, "channels", ())}
    why = []
    for q in ctx.load.quality or ():
        name = q.get("channel")
        if kinds.get(name) not in GAUGE_KINDS:
            continue
        n, bad = int(q.get("n_samples", 0)), int(q.get("n_nonfinite", 0))
        if bad >= n:
            why.append(f"{name}: all {n} samples NaN/inf")
        elif q.get("min") == q.get("max"):
            why.append(f"{name}: constant {q.get('min'):g}")
        else:
            return None
    return "; ".join(why) or None


def run_status(ctx) -> dict:
    """What a run computed, what it could not and why, and the exit code that says so.

    Parameters
    ----------
    ctx : meshphase.run.context.RunContext
        A finished run (``failed``, ``ran``, ``phasing``, ``messages``).

    Returns
    -------
    dict
        ``status``: "ok", "partial" (a requested result is missing), "unreliable" (all
        computed, but a gauge's phasing is flagged unreliable) or "failed" (the recording
        could not be loaded, no stage ran at all, or a requested result is missing and
        every gauge channel of the recording is all NaN/inf or constant: nothing usable
        was read); ``exit_code`` (0, 3, 3, 1); ``error`` (the cause of "failed", else
        None); ``missing_results``: one dict per requested result not computed,
        ``{"result", "stage", "cause"}``: a stage that failed (the cause of a skipped
        stage names the stage that failed behind it), then a result its stage left empty
        or all NaN, decided from the result itself (phasing: one entry per gauge without
        a measured pass; load sharing without a finite factor; compare without a gauge;
        identify without a pass; the cause quotes the stage's own messages about it);
        ``unreliable``: gauge -> reasons
        (:func:`meshphase.run.context.phasing_verdict`, as
        :func:`meshphase.campaign.runner.phasing_reliability` gives it).

    Raises
    ------
    TypeError
        ``ctx`` is not a run context.
    """
    if not all(hasattr(ctx, a) for a in ("failed", "ran", "phasing", "messages")):
        raise TypeError(f"ctx must be a RunContext (meshphase.run.stages.run_scene), got {type(ctx).__name__}")
    failed = {k: v for k, v in ctx.failed.items() if not v.benign}
    missing = [{"result": RESULT_OF_STAGE[s], "stage": s, "cause": _cause(failed, s)}
               for s in failed if s in RESULT_OF_STAGE]
    empty = _empty_results(ctx, failed)
    # the run's result types (meshphase.run.results, through .context): not loaded for the
    # command line's start-up (meshphase --help; tests/test_core_imports.py)
    from .context import phasing_verdict

    rel = phasing_verdict(ctx.phasing, ctx.messages)
    unreliable = {g: list(v["reasons"]) for g, v in rel.items() if not v["reliable"]}
    error = None
    unusable = _nothing_usable(ctx) if (missing or empty) else None
    if "load" in failed:
        status = "failed"
        error = "cannot load the recording: " + _load_error(failed["load"])
    elif failed and not ctx.ran:
        status = "failed"
        error = "; ".join(f"{s}: {_cause(failed, s)}" for s in failed)
    elif unusable:
        status = "failed"
        error = (f"nothing usable in the recording {ctx.load.source}: every gauge channel is "
                 f"NaN/inf or constant ({unusable})")
    elif failed or empty:
        status = "partial"
    elif unreliable:
        status = "unreliable"
    else:
        status = "ok"
    code = {"ok": EXIT_OK, "failed": EXIT_ERROR}.get(status, EXIT_PARTIAL)
    return {"status": status, "exit_code": code, "error": error, "missing_results": missing + empty,
            "unreliable": unreliable}


def status_line(status: dict) -> str:
    """One line for a run status (:func:`run_status`), as ``process``, ``run`` and
    ``campaign`` print it: ``ok``, ``partial: not computed: phasing, compare``,
    ``unreliable: phasing of the sun gauge``, ``failed: load: ...``."""
    if not isinstance(status, dict) or "status" not in status:
        raise TypeError(f"status must be a dict from run_status, got {type(status).__name__}")
    s = status["status"]
    if s == "partial":
        names = list(dict.fromkeys(m["result"] for m in status.get("missing_results") or []))
        return f"partial: not computed: {', '.join(names) or '?'}"
    if s == "unreliable":
        return f"unreliable: phasing of the {' and '.join(status.get('unreliable') or ['?'])} gauge"
    if s == "failed":
        return f"failed: {status.get('error') or '?'}"
    return s
