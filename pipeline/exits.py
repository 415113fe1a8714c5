"""Exit status of the ``meshphase`` command and the run status behind it.

One table, used by every subcommand (also in README.md, "Exit status", and in the
:mod:`pipeline.cli` docstring):

====  ==========================================================================================
code  meaning
====  ==========================================================================================
0     ok: every requested result was computed (and no phasing is flagged unreliable)
1     input or scene error, nothing usable: unreadable / corrupt / truncated file, a channel
      the scene names that the file lacks, no gauge channel, a bad scene, a non-regular file
      given as input, an OS error (permission, no space left, name too long, ...), out of
      memory; a campaign in which every recording failed
2     usage error (bad command line: argparse's own message)
3     partial result: outputs written, but some requested result could not be computed (its
      stage failed, or was skipped because a stage it needs failed: summary.json has
      ``"status": "partial"`` and ``missing_results`` with each cause), or a phasing result
      is flagged unreliable (``"status": "unreliable"``); a campaign with any recording
      failed, partial or unreliable
130   interrupted (Ctrl-C / SIGINT); the output folder of the interrupted run is removed
141   standard output closed early by the reader (``meshphase info --json | head -1``): quiet,
      the status a process killed by SIGPIPE gets
====  ==========================================================================================

:func:`run_status` turns a :class:`pipeline.stages.RunContext` into that status (it goes into
``summary.json`` and decides the exit code); :class:`OutputDir` reserves a run's output folder
and removes what the run put there when it fails or is interrupted;
:func:`recording_read_errors` turns the HDF5 library's exceptions into a
:class:`~pipeline.io.RecordingFileError` naming the file.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import time
from pathlib import Path
from typing import Iterator

__all__ = ["EXIT_OK", "EXIT_ERROR", "EXIT_USAGE", "EXIT_PARTIAL", "EXIT_INTERRUPTED",
           "EXIT_PIPE", "BENIGN_SKIPS", "RESULT_OF_STAGE", "run_status", "status_line",
           "OutputDir", "recording_read_errors"]

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_PARTIAL = 3
EXIT_INTERRUPTED = 130
EXIT_PIPE = 141

#: ``ctx.failed`` entries that are not failures: the scene asked for something the recording
#: does not have (no face-width gauges: no centroid work), by design of the scene planner
BENIGN_SKIPS = ("skipped: the recording has no face-width gauges",)

#: stage -> the result name a scene requests it by (``pipeline.scene.RESULTS`` inverted)
RESULT_OF_STAGE = {"ideal": "ideal_phasing", "phasing": "phasing", "load_sharing": "load_sharing",
                   "centroids": "centroids", "compare": "compare", "identify": "identify",
                   "tolerance": "tolerance", "bearing_moments": "bearing_moments",
                   "tilt": "tilt"}

_SKIP_PREFIX = "skipped: needs "
#: exception class names that add nothing to a message that names the file and the problem
_GENERIC = re.compile(r"^(ValueError|TypeError|KeyError|OSError|RecordingFileError|CorruptFileError|"
                      r"SceneError|PermissionError|FileNotFoundError|IsADirectoryError|"
                      r"NotADirectoryError|TimeoutError|InterruptedError): ")
#: ``str()`` of an OSError with a file name: "[Errno 13] Permission denied: '/x.h5'"
_OS_TEXT = re.compile(r"^\[Errno \d+\] (?P<text>.*): (?P<q>['\"])(?P<file>.*)(?P=q)$")


def _load_error(msg: str) -> str:
    """A failed load stage's message without the exception class, the file name first."""
    msg = _GENERIC.sub("", str(msg), count=1)
    m = _OS_TEXT.match(msg)
    return f"{m['file']}: {m['text']}" if m else msg


def _root_causes(failed: dict, stage: str, seen: frozenset = frozenset()) -> list[tuple[str, str]]:
    """(stage, message) of the stages that really failed behind ``stage``'s entry."""
    msg = str(failed.get(stage, ""))
    if not msg.startswith(_SKIP_PREFIX) or stage in seen:
        return [(stage, msg)]
    out = []
    for dep in (d.strip() for d in msg[len(_SKIP_PREFIX):].split(",")):
        if dep in failed:
            out.extend(_root_causes(failed, dep, seen | {stage}))
        else:
            out.append((dep, "did not run"))
    return list(dict.fromkeys(out))


def _cause(failed: dict, stage: str) -> str:
    msg = str(failed[stage])
    if not msg.startswith(_SKIP_PREFIX):
        return msg
    roots = _root_causes(failed, stage)
    return "skipped: " + "; ".join(f"{s} failed ({m})" for s, m in roots)


def run_status(ctx) -> dict:
    """What a run computed, what it could not and why, and the exit code that says so.

    Parameters
    ----------
    ctx : pipeline.stages.RunContext
        A finished run (``failed``, ``ran``, ``results``, ``messages``).

    Returns
    -------
    dict
        ``status``: "ok", "partial" (a requested result is missing), "unreliable" (all
        computed, but a gauge's phasing is flagged unreliable) or "failed" (the recording
        could not be loaded, or no stage ran at all); ``exit_code`` (0, 3, 3, 1);
        ``error`` (the cause of "failed", else None); ``missing_results``: one dict per
        result not computed, ``{"result", "stage", "cause"}`` (the cause of a skipped
        stage names the stage that failed behind it); ``unreliable``: gauge -> reasons
        (from :func:`pipeline.campaign.phasing_reliability`).

    Raises
    ------
    TypeError
        ``ctx`` is not a run context.
    """
    from .campaign import phasing_reliability

    if not all(hasattr(ctx, a) for a in ("failed", "ran", "results", "messages")):
        raise TypeError(f"ctx must be a RunContext (pipeline.stages.run_scene), got {type(ctx).__name__}")
    failed = {k: v for k, v in ctx.failed.items() if str(v) not in BENIGN_SKIPS}
    missing = [{"result": RESULT_OF_STAGE[s], "stage": s, "cause": _cause(failed, s)}
               for s in failed if s in RESULT_OF_STAGE]
    rel = phasing_reliability(ctx)
    unreliable = {g: list(v["reasons"]) for g, v in rel.items() if not v["reliable"]}
    error = None
    if "load" in failed:
        status = "failed"
        error = "cannot load the recording: " + _load_error(failed["load"])
    elif failed and not ctx.ran:
        status = "failed"
        error = "; ".join(f"{s}: {_cause(failed, s)}" for s in failed)
    elif failed:
        status = "partial"
    elif unreliable:
        status = "unreliable"
    else:
        status = "ok"
    code = {"ok": EXIT_OK, "failed": EXIT_ERROR}.get(status, EXIT_PARTIAL)
    return {"status": status, "exit_code": code, "error": error, "missing_results": missing,
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


class OutputDir:
    """A run's output folder, reserved up front, removed again if the run does not finish.

    ``with OutputDir(base, overwrite=...) as out:`` creates the folder as
    :func:`pipeline.stages.new_output_dir` does (``base``, else ``base-2``, ...) before any
    work, so an unwritable location fails in a second, not after the processing. If the body
    raises (an error, ``KeyboardInterrupt``), everything this run put there is removed: the
    whole folder when the run created it; with ``overwrite`` and an existing folder, the
    entries that are new or were rewritten since the run started (older ones stay).
    :meth:`discard` does the same on request (a run with nothing usable writes nothing).

    Attributes
    ----------
    path : Path
        The folder (after ``__enter__``).
    """

    def __init__(self, base, *, overwrite: bool = False):
        if not isinstance(base, (str, os.PathLike)):
            raise TypeError(f"base must be a path (str or Path), got {type(base).__name__} {base!r}")
        self.base = Path(base)
        self.overwrite = bool(overwrite)
        self.path: Path | None = None
        self._before: set | None = None
        self._t0 = 0

    def __enter__(self) -> "OutputDir":
        from .stages import new_output_dir

        self._t0 = time.time_ns()
        if self.overwrite and self.base.is_dir():
            self._before = set(os.listdir(self.base))
        self.path = new_output_dir(self.base, overwrite=self.overwrite)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is not None:
            self.discard()
        return False

    def discard(self) -> None:
        """Remove what this run put in the folder (the folder itself if the run made it)."""
        if self.path is None or not self.path.exists():
            return
        if self._before is None:
            shutil.rmtree(self.path, ignore_errors=True)
            return
        for name in os.listdir(self.path):
            p = self.path / name
            with contextlib.suppress(OSError):
                if name in self._before and p.lstat().st_mtime_ns < self._t0:
                    continue
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink()


@contextlib.contextmanager
def recording_read_errors(path) -> Iterator[None]:
    """Turn the HDF5 library's errors while reading ``path`` into a RecordingFileError.

    h5py reports HDF5 failures as ``OSError`` without an errno ("Can't synchronously read
    data (filter returned failure during read)"), ``RuntimeError`` ("Special link traversal
    failed (too many links)": a soft-link loop) or ``KeyError`` ("Unable to open object");
    none names the file. OS errors with an errno pass through: unchanged when they carry a
    file name (permission, ...), with ``path`` as their file name when they do not (EIO
    from ``read()``).
    """
    from .io import RecordingFileError

    try:
        yield
    except RecordingFileError:
        raise
    except OSError as exc:
        if exc.errno is not None and exc.filename is None:
            # read() errors (EIO from a failing disk or /proc/self/mem) carry no file name
            raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
        if exc.errno is not None or type(exc) is not OSError:  # ours name the file already
            raise
        raise RecordingFileError(path, f"read error, file corrupt? ({exc})") from exc
    except RuntimeError as exc:
        raise RecordingFileError(path, f"read error ({exc})") from exc
    except KeyError as exc:
        raise RecordingFileError(path, f"read error ({exc.args[0] if exc.args else exc})") from exc
