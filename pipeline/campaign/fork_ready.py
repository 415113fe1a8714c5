"""Importing this module readies a campaign workers' fork server, then freezes its heap.

A campaign's local workers fork from a server that has imported what their tasks need
(:func:`meshphase.campaign.cluster.worker_server`, with :func:`meshphase.campaign.job.worker_modules`,
of which this module is the last). Such a server can only import modules before it forks,
so this module does its work when it is imported:

1. It pays the costs that every worker's first recording would otherwise pay for itself,
   once:

   - the stages' scipy modules (:data:`meshphase.runtime.lazy.PROCESSING_SCIPY`), which the
     package imports on first use, and with them scipy's BLAS, before its thread limit (not
     counted in :data:`FIRST_USE_S`: they came with the processing stack's imports);
   - matplotlib's pyplot on Agg (:func:`meshphase.report.campaign_report.pyplot`), which
     the report's module no longer imports itself, and one small figure drawn to PNG as the
     report's are: matplotlib loads its font and fills its text caches on the first text it
     lays out;
   - jsonschema builds each validator and resolves the schema's references on its first
     use. Here that is the scene schema, on the packaged demo scene, and the HDF5 layout and
     channel schemas, through :func:`meshphase.io.read_info` of a two-channel recording
     written to a temporary folder;
   - threadpoolctl finds the loaded BLAS libraries and holds them to one thread for good
     (:func:`meshphase.runtime.threads.hold_blas_single_thread`; it keeps the controller): a forked
     OpenBLAS starts its thread pool again on the first call, and each worker's first
     recording started two BLAS threads that took CPU from the other worker's core;
   - numba's filter and onset kernels (:func:`load_kernels`), loaded from the per-user cache
     (compiled into it by the first run ever, or ``meshphase bench --warmup``). With numba
     loaded, a worker's filters and onsets take its kernels, as ``meshphase process`` does
     (:func:`meshphase.signal.iir.pick_engine`, :func:`meshphase.onsets.fastpath.dense`); without
     it they took scipy's filters and numpy's onsets, the slower engines (the iir and onset
     rows of ``meshphase bench processing``), so that no worker loaded numba for itself.
     Where numba is not installed (it is optional), the server loads scipy.signal
     instead, the filters' engine then.

2. It freezes the heap (:func:`gc.freeze`), as the docs of ``gc.freeze`` advise before a
   ``fork()`` without ``exec()``. The objects the imports made (:data:`FROZEN_OBJECTS`:
   210 000-240 000 here, an HDF5 campaign to one over every format) move to the
   collector's permanent generation. A worker's collections then never walk them, and so
   never write to, and copy, the pages they share with the server.

Why the freeze matters is measured by ``meshphase bench campaign`` (its first-figure rows: a
forked child draws one figure of the combined report twice, with and without this module):
whether a full collection falls into a worker's first figure depends on what the server
imported; with the heap frozen, it never walks those objects.

A failure of the first uses (a full temporary disk, say) leaves them to the workers: the
import itself never fails.

Remote workers import it when they connect (:func:`meshphase.campaign.job.warm_up`): their
modules' objects stay alive for the worker's life anyway. Nothing else imports it.
"""

from __future__ import annotations

import gc
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from ..io import read_info, write
from ..onsets import fastpath
from ..recording import Recording
from ..report.campaign_report import figure_png, load_sharing_across_recordings
from ..run.demo import DEMO_SCENE
from ..run.scene import scene_schema_errors
from ..runtime.lazy import load_all
from ..runtime.lazy import signal as scipy_signal
from ..runtime.threads import hold_blas_single_thread
from ..signal import iir

__all__ = ["FROZEN_OBJECTS", "FIRST_USE_S", "KERNELS", "pay_first_use", "load_kernels"]


def pay_first_use() -> None:
    """Import matplotlib on Agg and draw a small figure, validate the demo scene and read the
    header of a small recording, in this process (what a worker's first recording and first
    figure do first)."""
    # matplotlib on Agg and one of the report's figures, small: matplotlib loads its font and
    # fills its text caches on the first text it lays out, which a worker's first figure
    # otherwise paid (the bench's first-figure rows)
    figure_png(load_sharing_across_recordings, ["a", "b"], [[1.0, 1.0], [1.0, 1.0]])
    raw = tomllib.loads(DEMO_SCENE)
    scene_schema_errors(raw)
    with tempfile.TemporaryDirectory(prefix="meshphase-fork-ready-") as tmp:
        path = Path(tmp) / "ready.h5"
        write(Recording(np.zeros((64, 2)), 5120.0, ["sun_g1", "ring_g1"]), path)
        read_info(path)


def load_kernels() -> dict:
    """Load numba's filter and onset kernels into this process (from the per-user cache;
    compiled into it when it has none), when numba is importable; else scipy.signal, the
    filters' engine then.

    Returns
    -------
    dict
        ``filters`` and ``onsets``: the engine each now takes ("numba"; "scipy" / "numpy"
        without numba), and ``seconds`` [s] the loads took.

    Raises
    ------
    ValueError, ImportError
        numba is installed but does not import.
    """
    t = time.perf_counter()
    filters, onsets = iir.warmup(check=False)["engine"], fastpath.warmup()["engine"]
    if filters == "scipy":
        # no numba (it is optional): the filters are scipy's, loaded here once rather than
        # by every worker's first recording
        load_all([scipy_signal])
    return {"filters": filters, "onsets": onsets, "seconds": time.perf_counter() - t}


try:
    # with the processing stack the server imported before this module: the stages' scipy
    # modules are imported on first use (meshphase.runtime.lazy), here before any worker forks
    load_all()
except ImportError:  # reported by the first recording that needs them
    pass
_t = time.perf_counter()
try:
    pay_first_use()
    #: What :func:`pay_first_use` took on import [s]; NaN when it failed.
    FIRST_USE_S = time.perf_counter() - _t
except Exception:  # noqa: BLE001 - a full temporary disk, say: the workers pay it, and start
    FIRST_USE_S = float("nan")
del _t
try:
    #: What :func:`load_kernels` gave on import; None when it failed (the workers then load
    #: numba themselves or run without it, as a ``process`` would).
    KERNELS: dict | None = load_kernels()
except Exception:  # noqa: BLE001 - a broken numba install, a read-only cache that fails
    KERNELS = None
try:
    # after every import: the limit reaches the BLAS libraries loaded by then (scipy's comes
    # with the stages' scipy modules, loaded above)
    hold_blas_single_thread()
except Exception:  # noqa: BLE001 - threadpoolctl failing: each run still holds BLAS itself
    pass
# no collection first: the server's garbage is a few import-time leftovers, and a collection
# would walk every object once more (0.09 s) on the way to the campaign's first task
gc.freeze()
#: Objects in the permanent generation once this module was imported [-].
FROZEN_OBJECTS = gc.get_freeze_count()
