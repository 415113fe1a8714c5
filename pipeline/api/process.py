"""The Python API: :func:`read` a recording, :func:`process` it, look at the :class:`Result`.

::

    import meshphase
    rec = meshphase.read("run.h5")
    res = meshphase.process(rec, "gearset.toml")
    res.phasing            # per gauge and planet: measured mean, sd, ideal, model, residual
    res.plot("phasing")

:func:`process` runs exactly the stages ``meshphase process`` runs (the scene is built by
:mod:`meshphase.api.scene`, the run is :func:`meshphase.run.stages.run_scene`), so the numbers
are the CLI's. A recording file is streamed block by block as the CLI does; a
:class:`~meshphase.recording.Recording` in memory is streamed the same way from its own
samples (:class:`meshphase.recording.MemorySource`, no copy), with the same numbers as the
same recording written to a file and processed from there.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Callable

from .. import io
from .scene import build_scene
from ..run.exits import run_status
from ..recording import Recording
from .result import Result
from ..run.stages import run_scene
from ..validate import as_regular_file

__all__ = ["read", "process", "Result", "ProcessingFailed"]

read = io.read


class ProcessingFailed(ValueError):
    """Nothing usable came out of :func:`process` (the recording could not be loaded, or no
    stage ran); ``context`` holds the run for a closer look."""

    def __init__(self, message: str, context):
        super().__init__(message)
        self.context = context


def _check_window(start, stop) -> None:
    for name, v in (("start", start), ("stop", stop)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise TypeError(f"{name} must be a time [s] or None, got {type(v).__name__} {v!r}")


def process(recording, gearset=None, *, scene=None, results=None, start: float | None = None,
            stop: float | None = None,
            progress: Callable[[str, int, int], None] | None = None,
            tolerance: bool = False) -> Result:
    """Process a recording as ``meshphase process`` does and return its :class:`Result`.

    Parameters
    ----------
    recording : Recording, str or Path
        A recording in memory (:func:`read`, :func:`meshphase.synthetic.generate`) or a
        recording file (hdf5, mcap, csv, tdms).
    gearset : str, Path, dict or Gearset, optional
        A scene TOML path (as ``process --gearset``: its gearset, speeds, tolerances, channel
        mapping), a dict (a scene's ``[gearset]`` table in mm and deg, a
        ``Gearset.to_dict()`` dict in SI, or a whole scene), or a
        :class:`meshphase.models.Gearset`. Default: the recording's metadata gearset
        (synthetic recordings carry one).
    scene : Scene, str, Path or dict, optional
        A whole scene instead of ``gearset`` (not both).
    results : sequence of str, optional
        Results to compute (``meshphase.run.scene.RESULTS``); default those of ``meshphase
        process`` (phasing, load_sharing, compare; centroids when the scene asks).
    start, stop : float, optional
        Time window [s] of the recording to process (half-open).
    progress : callable(stage, i, n), optional
        Called before each stage.
    tolerance : bool
        Also run the scene's Monte Carlo (its ``[tolerances]``) and compare the measured
        phasing against its band, as ``meshphase process --tolerance``.

    Returns
    -------
    Result

    Raises
    ------
    TypeError
        ``recording``, ``gearset``, ``scene``, ``results``, ``start``/``stop`` or
        ``progress`` of the wrong type.
    ValueError
        An empty recording, no gearset anywhere, unknown results, a scene that does not
        validate (SceneError), a window outside the recording.
    FileNotFoundError, IsADirectoryError, NotRegularFileError, OSError
        The recording path is no regular file, or the file system refused it (a
        symbolic-link loop ...): the checks and classes of :func:`read` and of the
        ``meshphase`` command (:mod:`meshphase.errors`).
    ProcessingFailed
        The run produced nothing usable (the recording could not be loaded, no gauge
        channel, every gauge channel NaN/inf or constant); the message says why.
    """
    _check_window(start, stop)
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be callable(stage, i, n) or None, got "
                        f"{type(progress).__name__}")
    if isinstance(recording, Recording):
        if recording.n_samples == 0 or recording.n_channels == 0:
            raise ValueError(f"the recording is empty ({recording.n_samples} samples x "
                             f"{recording.n_channels} channels): nothing to process")
        if start is not None or stop is not None:
            recording = recording.slice_time(start, stop)

        def meta():
            return recording.meta.get("gearset")
    elif isinstance(recording, (str, os.PathLike)):
        path = as_regular_file(recording, "the recording")

        def meta():
            return io.read_info(path).meta.get("gearset")
    else:
        raise TypeError(f"recording must be a meshphase.Recording or a recording file path, got "
                        f"{type(recording).__name__}")
    if not isinstance(tolerance, bool):
        raise TypeError(f"tolerance must be True or False, got {tolerance!r}")
    sc = build_scene(gearset, scene, results, meta_gearset=meta, tolerance=tolerance)
    if isinstance(recording, Recording):
        ctx = _run_in_memory(sc, recording, progress)
    else:
        sc.input = {"recording": path.resolve(), "start": start, "stop": stop}
        ctx = run_scene(sc, progress=progress)
    st = run_status(ctx)
    if st["status"] == "failed":
        raise ProcessingFailed(f"meshphase.process: nothing usable: {st['error']}", ctx)
    return Result(ctx)


def _run_in_memory(scene, rec: Recording, progress):
    """Run ``scene`` on ``rec`` streamed from memory; the load result keeps no source (the
    samples stay the caller's)."""
    scene.input = {"memory": rec}
    ctx = run_scene(scene, progress=progress)
    if ctx.load is not None:
        ctx.record("load", dataclasses.replace(ctx.load, stream=None))
    return ctx
