"""Peak memory of whole commands, measured in a child process (``meshphase bench``).

:func:`run_child` runs one job (a function of this module) in a fresh Python process and
returns what the job returns plus the child's wall time and peak resident set size: the
``VmHWM`` the child reads from ``/proc/self/status`` at the end of the job (kernel accounting
of every page its address space touched, C libraries included: what tracemalloc cannot
see). The ``ru_maxrss`` that :func:`os.wait4` reports is kept beside it but is only an upper
bound: the kernel carries the parent's high-water mark into a posix_spawn'ed child.

Jobs: :func:`write_job` (a synthetic 8-channel recording written block by block),
:func:`convert_job` (``meshphase convert``), :func:`process_job` (``meshphase process``)
and :func:`sosfiltfilt_job` (the reference: one zero-phase filter pass).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["run_child", "bench_config", "write_job", "convert_job", "process_job",
           "hdf5_pass_job", "sosfiltfilt_job", "reference_sos", "import_job", "free_bytes", "BENCH_GEARSET",
           "N_CHANNELS"]

#: Channels of the benchmark recordings: sun and ring gauges, 3 + 2 face-width gauges, tacho.
N_CHANNELS = 8

#: The seed rig's gearset and speeds as a ``--gearset`` scene (tests/seed_rig_toml.py).
BENCH_GEARSET = """\
[gearset]
name = "seed 000 rig"
z_sun = 25
z_ring = 87
z_planet = 31
n_planets = 4
carrier_radius_mm = 112.5
face_width_mm = 40
direction = "cw"

[speeds]
sun_rpm = 18.19
carrier_rpm = 1.06
"""


def bench_config(duration: float, dtype: str = "float64"):
    """The benchmark recording: the seed rig (5120 Hz) with realistic acquisition (30 dB SNR,
    1/f noise, drift, 50 Hz hum, 24-bit ADC) and 8 channels: sun and ring gauges, three
    face-width gauges on a sun tooth, two on a ring tooth, and the carrier tacho.

    Parameters
    ----------
    duration : float
        [s]
    dtype : {"float64", "float32"}

    Returns
    -------
    meshphase.synthetic.config.SynthConfig
    """
    from meshphase.synthetic.config import Artefacts, GaugeConfig, SynthConfig, TachoConfig
    from meshphase.synthetic.scenarios import FACE_WIDTH, seed_rig_gearset, seed_rig_speeds

    from ..models.tolerance import table2_case

    g = seed_rig_gearset()
    b = FACE_WIDTH
    sun = dict(amplitude=150e-6, contact_ratio=1.6)
    ring = dict(amplitude=100e-6, contact_ratio=1.8)
    gauges = (GaugeConfig("sun", "sun", tooth=0, **sun), GaugeConfig("ring", "ring", tooth=0, **ring),
              *(GaugeConfig(f"sun_fw{i + 1}", "sun", tooth=5, face_position=z * b, **sun)
                for i, z in enumerate((-0.4, 0.0, 0.4))),
              *(GaugeConfig(f"ring_fw{i + 1}", "ring", tooth=10, face_position=z * b, **ring)
                for i, z in enumerate((-0.3, 0.3))))
    art = Artefacts(snr_db=30.0, pink_fraction=0.3, pink_fmin=0.05, drift_amplitude=8e-6,
                    drift_time_constant=900.0, hum_amplitude=2e-6, hum_frequency=50.0,
                    adc_bits=24, adc_range=2e-3)
    return SynthConfig(name="bench8", description="benchmark: seed rig, 8 channels", gearset=g,
                       speeds=seed_rig_speeds(g), fs=5120.0, duration=float(duration),
                       gauges=gauges, errors=table2_case(1)[2], tacho=TachoConfig(),
                       artefacts=art, dtype=dtype)


def free_bytes(path) -> int:
    """Free space on the filesystem of ``path`` [B]."""
    return int(shutil.disk_usage(Path(path)).free)


# ------------------------------------------------------------------------------ child process
def _vmhwm() -> float | None:
    """Peak resident set size of this process [MB] from /proc/self/status (Linux)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def _child(spec: str) -> None:
    from ..runtime.heap import limit_heap_growth

    limit_heap_growth()                   # as ``meshphase`` does at start (pipeline/runtime/heap.py)
    job = json.loads(spec)
    fn = globals()[job["job"]]
    t = time.perf_counter()
    out = fn(**job.get("kwargs", {}))
    out["job_s"] = time.perf_counter() - t
    out["vmhwm_mb"] = _vmhwm()
    sys.stdout.write("\n@@RESULT@@" + json.dumps(out, default=float) + "\n")
    sys.stdout.flush()


def run_child(job: str, **kwargs) -> dict:
    """Run ``job(**kwargs)`` (a ``*_job`` function of this module) in a fresh Python process.

    The child is started with :func:`os.posix_spawn` (stdout and stderr to temporary files,
    BLAS thread pools at one thread unless the environment sets them) and reaped with
    :func:`os.wait4`, whose resource usage is that child's alone.

    Returns
    -------
    dict
        The job's result, plus ``wall_s`` (child start to exit, imports included),
        ``peak_rss_mb`` [MB = 2**20 B] (the child's own VmHWM from /proc/self/status at the
        end of the job, also as ``vmhwm_mb``; ``ru_maxrss`` where /proc is missing) and
        ``ru_maxrss_mb`` (what :func:`os.wait4` reports: an upper bound that also counts
        the parent's high-water mark at the spawn). RuntimeError with the child's stderr
        tail when it fails.
    """
    import tempfile

    if job not in __all__ or not job.endswith("_job"):
        raise ValueError(f"job must be one of the *_job functions of {__name__}, got {job!r}")
    env = child_env()
    # BLAS on one thread unless the caller chose: the per-core figures of the processing
    # bench; a multi-threaded BLAS on a loaded 2-core machine made the phasing stage's
    # least-squares fits up to 10x slower (spinning threads), not faster
    for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(v, "1")
    code = "import sys; from meshphase.bench.rss import _child; _child(sys.argv[1])"
    spec = json.dumps({"job": job, "kwargs": kwargs})
    with tempfile.TemporaryDirectory(prefix="meshphase-rss-") as tmp:
        out_p, err_p = os.path.join(tmp, "out"), os.path.join(tmp, "err")
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC
        t = time.perf_counter()
        pid = os.posix_spawn(sys.executable, [sys.executable, "-c", code, spec], env,
                             file_actions=[(os.POSIX_SPAWN_OPEN, 1, out_p, flags, 0o600),
                                           (os.POSIX_SPAWN_OPEN, 2, err_p, flags, 0o600)])
        _, status, ru = os.wait4(pid, 0)
        wall = time.perf_counter() - t
        rc = os.waitstatus_to_exitcode(status)
        out = Path(out_p).read_bytes()
        err = Path(err_p).read_bytes()
    if rc != 0 or b"@@RESULT@@" not in out:
        raise RuntimeError(f"bench job {job} failed (exit {rc}):\n"
                           f"{err.decode(errors='replace')[-3000:]}")
    res = json.loads(out.split(b"@@RESULT@@")[-1].decode())
    # ru_maxrss is in KiB on Linux. It is an upper bound only: posix_spawn starts the child
    # in the parent's address space (vfork-like) and the kernel carries that address space's
    # high-water mark into the child's maxrss at exec, so a parent that once held 600 MB
    # gives every child >= 600 MB (measured). VmHWM belongs to the child's own address space.
    ru_mb = ru.ru_maxrss / 1024.0
    own = res.get("vmhwm_mb")
    res.update(wall_s=wall, returncode=rc, ru_maxrss_mb=ru_mb,
               peak_rss_mb=own if own is not None else ru_mb)
    return res


# ------------------------------------------------------------------------------ jobs
def write_job(path: str, minutes: float, dtype: str = "float64", seed: int = 1) -> dict:
    """Write the benchmark recording (:func:`bench_config`) of ``minutes`` to ``path``
    (format from the suffix), generated and written block by block."""
    from meshphase.synthetic import generate_blocks

    from .. import io

    stream = generate_blocks(bench_config(60.0 * minutes, dtype), seed=seed)
    t = time.perf_counter()
    io.write_blocks(stream, (blk.data for blk in stream), path, dtype=stream.dtype, overwrite=True)
    write_s = time.perf_counter() - t
    # the file's dirty pages to disk now (a 1-h file is 1.2 GB), not by the kernel's
    # write-back while the timed run that reads the file next is going: that time belongs
    # to this write, not to the processing
    t = time.perf_counter()
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    return {"n_samples": int(stream.n_samples), "n_channels": len(stream.channels),
            "write_s": write_s, "sync_s": time.perf_counter() - t, "bytes": os.path.getsize(path)}


def convert_job(src: str, dst: str) -> dict:
    """``meshphase -q convert SRC DST --overwrite``: the command's one call,
    :func:`meshphase.io.convert` (the CLI adds only argument parsing and a progress bar)."""
    from ..io import convert

    convert(src, dst, overwrite=True)
    return {"rc": 0, "bytes": os.path.getsize(dst)}


def process_job(path: str, gearset: str, out_dir: str) -> dict:
    """``meshphase process PATH --gearset GEARSET --out OUT_DIR --overwrite``, in-process:
    the stage timings, the peak RSS reached by the end of each stage (VmHWM) and the run's
    status come back."""
    import warnings

    from ..run import stages
    from ..run.exits import run_status
    from ..run.stages import process_recording

    hwm = {}
    for name, fn in list(stages.STAGE_FUNCTIONS.items()):   # this child process only
        def wrapped(ctx, fn=fn, name=name):
            fn(ctx)
            hwm[name] = _vmhwm()
        stages.STAGE_FUNCTIONS[name] = wrapped
    from ..runtime.threads import run_threads

    c0 = time.process_time()                 # every thread of this process
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx, files = process_recording(path, gearset, out_dir=out_dir, overwrite=True)
    cpu = time.process_time() - c0
    ons = ctx.onsets.by_channel if ctx.onsets is not None else {}
    timings = ctx.condition.timings if ctx.condition is not None else {}
    memory = ctx.condition.memory if ctx.condition is not None else {}
    return {"status": run_status(ctx)["status"], "timings": dict(ctx.timings), "hwm_mb": hwm,
            "failed": {k: str(v) for k, v in ctx.failed.items()}, "n_onsets": int(sum(len(o) for o in ons.values())),
            "onsets_s": float(timings.get("onsets_s", float("nan"))),
            "memory_estimate_mb": (memory.get("total", 0) / 2**20) or None,
            "threads": run_threads(), "cpu_s": cpu}


def hdf5_pass_job(path: str, block: int = 1 << 18) -> dict:
    """Seconds of one pass over every channel of an HDF5 recording, block by block as
    ``meshphase process`` reads it: ``checked_s`` (HDF5 checks the fletcher32 checksums,
    the first pass), ``unchecked_s`` (``verify=False``: the chunks at their byte offsets,
    the later passes) and ``library_s`` (unchecked through h5py's ``read_direct_chunk``,
    the library path kept beside it); best of two each."""
    import h5py

    from ..io import hdf5

    def one(verify: bool) -> float:
        t = time.perf_counter()
        for _ in hdf5.iter_blocks(path, block, 0, verify=verify):
            pass
        return time.perf_counter() - t

    def library() -> float:
        t = time.perf_counter()
        with h5py.File(path, "r", rdcc_nbytes=0) as f:
            dsets = list(f["channels"].values())
            n = dsets[0].shape[0]
            for a in range(0, n, block):
                b = min(n, a + block)
                buf = np.empty((len(dsets), b - a), dtype=dsets[0].dtype)
                for j, ds in enumerate(dsets):
                    hdf5._read_raw_chunks(ds, buf[j], a, b, None)
        return time.perf_counter() - t

    return {"checked_s": min(one(True) for _ in range(2)),
            "unchecked_s": min(one(False) for _ in range(2)),
            "library_s": min(library() for _ in range(2)), "bytes": os.path.getsize(path)}


def reference_sos(fs: float = 5120.0) -> np.ndarray:
    """The reference pass's filter: the conditioning's low-pass, a 4th-order Butterworth at
    4 f_m = 28.6 Hz of the bench rig (second-order sections at ``fs`` [Hz])."""
    from scipy import signal

    return signal.butter(4, 28.6, btype="lowpass", fs=fs, output="sos")


def sosfiltfilt_job(n: int = 1 << 22, repeats: int = 3) -> dict:
    """Rate of one :func:`scipy.signal.sosfiltfilt` pass [samples/s]: the conditioning's
    low-pass (4th-order Butterworth at 4 f_m = 28.6 Hz, 5120 Hz) over ``n`` float64 samples,
    best of ``repeats``."""
    from scipy import signal

    x = np.random.default_rng(0).normal(size=int(n))
    sos = reference_sos()
    best = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        signal.sosfiltfilt(sos, x)
        best = min(best, time.perf_counter() - t)
    return {"n": int(n), "best_s": best, "samples_per_s": n / best}


def child_env(**extra: str) -> dict:
    """The environment of a bench child process: this one's, plus ``extra``, with
    PYTHONPATH set to this interpreter's ``sys.path`` so the child imports the very same
    meshphase (editable checkout, wheel or source tree alike), and without
    ``PYTHONDONTWRITEBYTECODE``: the child writes and reuses ``.pyc`` files as a user's
    interpreter does after its first run. Where that variable is set (the development
    machine's environment sets it), every timed start compiled meshphase's sources again."""
    env = dict(os.environ, **extra)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    return env


def import_job() -> dict:
    """Import what ``process`` imports (the children after it find its bytecode written)."""
    t = time.perf_counter()
    import meshphase.run.stages  # noqa: F401

    return {"import_s": time.perf_counter() - t}
