"""Onset timing error against the Cramer-Rao bound, and detection throughput.

``run_processing_bench(out_dir)`` writes ``processing_bench.json`` and
``processing_bench.md`` (and ``phasing_error_vs_runtime.png``): the measured-phasing
accuracy matrix of :mod:`meshphase.bench.phasing` (error, timing floor, calibration and run
time per rig condition), the accuracy table of the conditions where measured phasing was
once confident and wrong (:mod:`meshphase.bench.conditions`), and, for pulse trains with
known truth (generated here, see :class:`PulseShape` and :func:`pulse_train`), the timing
error of each detector setting at several SNRs next to the Cramer-Rao bound
(:func:`meshphase.signal.crb.crb_delay_std`), and the
throughput of each stage in MSamples per CPU-second (``time.process_time``: all threads of
the process counted, so a multi-threaded BLAS cannot flatter it; that is the one-core
figure) next to the wall time. Measured, never asserted.

SNR definition (used throughout): peak pulse power over noise variance,
``SNR = 10 log10(A^2 / sigma^2)`` [dB], ``A`` the tensile peak above baseline of a pulse of
mean amplitude, ``sigma`` the white-noise standard deviation per sample.

Detector settings
-----------------
``coarse``        :func:`meshphase.onsets.coarse_peaks` alone (smoothed maximum, integer
                  samples at the decimated rate).
``refine_once``   :func:`meshphase.onsets.detect_onsets` with the template learnt once
                  (``relearn="never"``).
``refine_block``  :func:`meshphase.onsets.detect_onsets` with the template re-learnt in
                  every analysis block (``relearn="block"``, the former default).
``refine_auto``   :func:`meshphase.onsets.detect_onsets` defaults (template learnt once per
                  operating point, ``relearn="auto"``).
``refine_oracle`` matched filter with the template learnt from the noise-free train (the
                  shape known exactly: the setting the bound speaks about).

Errors are measured on the onset feature of each setting, with the mean offset (bias: a
constant offset between features, irrelevant to phasing) removed and reported separately.

Peak memory and wall time of ``meshphase process`` (``process_minutes``; ``meshphase bench
processing`` measures 2 min, 10 min, 1 h and 3 h): the 8-channel benchmark recording
(:func:`meshphase.bench.rss.bench_config`, float64 HDF5 written block by block) processed with
the seed rig's gearset in a child process (peak RSS: its VmHWM), with each stage's
time, and the whole run and the streamed stages (load, condition, onsets: the two reads
over the samples) as multiples of one :func:`scipy.signal.sosfiltfilt` pass over the same
samples (the conditioning's 4th-order low-pass, timed just before and just after each run:
the mean of the two times).
"""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ..signal.crb import crb_delay_std
from ..runtime.log import logger
from ..validate import as_float, as_nonnegative, as_positive
from .rss import child_env

__all__ = ["PulseShape", "pulse_train", "pulse_scenario", "match_onsets", "run_processing_bench",
           "process_rss_rows", "identify_rows", "ACCURACY_COLUMNS", "THROUGHPUT_COLUMNS",
           "PROCESS_COLUMNS", "PROCESS_MINUTES", "IDENTIFY_COLUMNS"]

#: Columns of the accuracy table (processing_bench.json "accuracy", and the Markdown).
ACCURACY_COLUMNS = ("scenario", "setting", "snr_db", "fwhm_samples", "n_true", "n_matched",
                    "n_missed", "n_false", "bias_samples", "std_samples", "rmse_samples",
                    "crb_samples", "std_over_crb", "runtime_s", "msamples_per_s")
#: Columns of the throughput table.
THROUGHPUT_COLUMNS = ("stage", "scenario", "n_samples", "n_pulses", "runtime_s", "msamples_per_s",
                      "wall_s")
#: Columns of the ``meshphase process`` peak-memory table.
PROCESS_COLUMNS = ("minutes", "dtype", "n_channels", "n_samples", "data_mb", "status", "n_onsets",
                   "wall_s", "peak_rss_mb", "streamed_peak_mb", "rss_over_data",
                   "memory_estimate_mb", "load_s",
                   "condition_s", "onsets_s", "phasing_s", "identify_s", "identify_share",
                   "other_s", "sosfiltfilt_s", "sosfiltfilt_msps",
                   "wall_over_sosfiltfilt", "streamed_over_sosfiltfilt", "threads", "cpu_s",
                   "cpu_over_sosfiltfilt", "read_checked_s", "read_unchecked_s", "read_library_s")
#: Recording lengths of ``meshphase bench processing``'s process table [min].
PROCESS_MINUTES = (2.0, 10.0, 60.0, 180.0)


# ====================================================================== test pulses
class PulseShape:
    """A tooth-root strain pulse with an analytic derivative (peak 1, baseline 0).

    Time ``u`` [s] from the contact start: a tensile ``sin^2(pi u / T_c)`` lobe while the
    tooth carries load (``0 <= u < T_c``, ``T_c = contact_ratio * mesh_period``) and
    compressive ``-lobe * sin^2`` lobes of one mesh period before and after it (the
    neighbouring teeth carrying load). C1-continuous.

    Parameters
    ----------
    mesh_period : float
        Mesh period T_m [s].
    contact_ratio : float
        Contact ratio [-] (1.4-1.8 typical).
    lobe : float
        Depth of the compressive lobes relative to the tensile peak [-].
    bandlimit : float, optional
        When given, the pulse is passed through an ideal-ish anti-alias low-pass at
        ``bandlimit * fs`` (raised-cosine roll-off from 0.9 of it), as a DAQ does; needed to
        sample pulses only a few samples wide without aliasing. Requires ``fs``.
    fs : float, optional
        Sample rate [Hz] for ``bandlimit``.
    """

    def __init__(self, mesh_period: float, contact_ratio: float = 1.6, lobe: float = 0.25,
                 bandlimit: float | None = None, fs: float | None = None):
        self.tm = as_positive(mesh_period, "mesh_period")
        self.cr = as_positive(contact_ratio, "contact_ratio")
        self.lobe = as_nonnegative(lobe, "lobe")
        self.tc = self.cr * self.tm
        self.bandlimit = None
        self._table = None
        if bandlimit is not None:
            self.bandlimit = as_positive(bandlimit, "bandlimit")
            if self.bandlimit >= 0.5:
                raise ValueError(f"bandlimit must be < 0.5 (fraction of fs), got {bandlimit!r}")
            if fs is None:
                raise ValueError("bandlimit needs fs [Hz]")
            self._build_table(as_positive(fs, "fs"))

    # -- raw analytic shape
    def _raw(self, u):
        u = np.asarray(u, dtype=np.float64)
        tc, tm, b = self.tc, self.tm, self.lobe
        main = np.where((u >= 0) & (u < tc), np.sin(np.pi * u / tc) ** 2, 0.0)
        pre = np.where((u >= -tm) & (u < 0), np.sin(np.pi * (u + tm) / tm) ** 2, 0.0)
        post = np.where((u >= tc) & (u < tc + tm), np.sin(np.pi * (u - tc) / tm) ** 2, 0.0)
        return main - b * (pre + post)

    def _raw_deriv(self, u):
        u = np.asarray(u, dtype=np.float64)
        tc, tm, b = self.tc, self.tm, self.lobe
        main = np.where((u >= 0) & (u < tc), (np.pi / tc) * np.sin(2 * np.pi * u / tc), 0.0)
        pre = np.where((u >= -tm) & (u < 0), (np.pi / tm) * np.sin(2 * np.pi * (u + tm) / tm), 0.0)
        post = np.where((u >= tc) & (u < tc + tm), (np.pi / tm) * np.sin(2 * np.pi * (u - tc) / tm), 0.0)
        return main - b * (pre + post)

    def _build_table(self, fs: float) -> None:
        q = 64
        pad = 64.0 / fs
        lo, hi = -self.tm - pad, self.tc + self.tm + pad
        n = int(math.ceil((hi - lo) * fs * q)) + 1
        n2 = 1 << int(math.ceil(math.log2(n)))
        t = lo + np.arange(n2) / (fs * q)
        raw = self._raw(t)
        spec = np.fft.rfft(raw)
        f = np.fft.rfftfreq(n2, 1.0 / (fs * q))
        fc = self.bandlimit * fs
        gain = np.clip((fc - f) / (0.1 * fc), 0.0, 1.0)
        gain = 0.5 - 0.5 * np.cos(np.pi * gain)
        val = np.fft.irfft(spec * gain, n2)
        der = np.fft.irfft(spec * gain * (2j * np.pi * f), n2)
        self._table = (t, val, der)
        self._fs = fs

    @property
    def support(self) -> tuple[float, float]:
        """(start, stop) of the pulse relative to the contact start [s]."""
        if self._table is not None:
            return float(self._table[0][0]), float(self._table[0][-1])
        return -self.tm, self.tc + self.tm

    def value(self, u) -> np.ndarray:
        """Pulse s(u) [-] at times ``u`` [s] from the contact start."""
        if self._table is None:
            return self._raw(u)
        t, v, _ = self._table
        return np.interp(u, t, v, left=0.0, right=0.0)

    def derivative(self, u) -> np.ndarray:
        """ds/du [1/s]."""
        if self._table is None:
            return self._raw_deriv(u)
        t, _, dv = self._table
        return np.interp(u, t, dv, left=0.0, right=0.0)

    def rise_time(self, level: float = 0.5) -> float:
        """Time of the leading-edge crossing of ``level`` x peak after the contact start [s]."""
        level = as_float(level, "level")
        if self._table is None:
            if not 0.0 <= level < 1.0:
                raise ValueError(f"level must be in [0, 1), got {level!r}")
            return self.tc * math.asin(math.sqrt(level)) / math.pi
        t, v, _ = self._table
        k = int(np.argmax(v))
        below = np.flatnonzero(v[:k] < level * v[k])
        j = int(below[-1])
        return float(t[j] + (level * v[k] - v[j]) / (v[j + 1] - v[j]) * (t[j + 1] - t[j]))

    @property
    def fwhm(self) -> float:
        """Full width at half maximum of the tensile lobe [s] (T_c / 2 unfiltered)."""
        if self._table is None:
            return 0.5 * self.tc
        t, v, _ = self._table
        k = int(np.argmax(v))
        above = np.flatnonzero(v >= 0.5 * v[k])
        return float(t[above[-1]] - t[above[0]])


#: samples of pulse rows worked on at a time by :func:`pulse_train` and
#: :func:`pulse_scenario` (32 MB per float64 array: 2^24 samples of 2-sample pulses hold
#: 1.1 million rows of 258 samples, 2.3 GB per array at once and ~16 GB of peak memory)
_PULSE_ROW_SAMPLES = 1 << 22


def _pulse_chunks(n_pulses: int, row: int):
    """(first, stop) pulse ranges of at most ``_PULSE_ROW_SAMPLES // row`` pulses."""
    step = max(1, _PULSE_ROW_SAMPLES // max(1, row))
    return [(a, min(a + step, n_pulses)) for a in range(0, n_pulses, step)]


def pulse_train(n: int, fs: float, contact_times, amplitudes, shape: PulseShape, *,
                sigma: float = 0.0, rng=None, dtype=np.float64) -> np.ndarray:
    """Samples of a pulse train plus white Gaussian noise.

    Parameters
    ----------
    n : int
        Number of samples.
    fs : float
        Sample rate [Hz]; sample i is at t = i / fs.
    contact_times : array_like
        Contact start of each pulse [s].
    amplitudes : array_like or float
        Tensile peak of each pulse [data units].
    shape : PulseShape
    sigma : float
        Noise standard deviation per sample [data units].
    rng : None, int or Generator
    dtype : numpy dtype
        float64 or float32.

    Returns
    -------
    ndarray, shape (n,)
    """
    rng = np.random.default_rng(rng)
    fs = as_positive(fs, "fs")
    tcs = np.asarray(contact_times, dtype=np.float64).ravel()
    amps = np.broadcast_to(np.asarray(amplitudes, dtype=np.float64), tcs.shape)
    x = np.zeros(int(n))
    for _, _, idx, _, vals in _pulse_rows(fs, tcs, amps, shape):
        _add_rows(x, idx, vals)
    return _with_noise(x, sigma, rng, dtype)


def _pulse_rows(fs: float, contact: np.ndarray, amps: np.ndarray, shape: PulseShape):
    """The pulses' sample rows, chunk after chunk in pulse order (:func:`_pulse_chunks`):
    ``(a, b, idx, tt, vals)`` for pulses ``a .. b - 1``, ``idx`` the sample indices of each
    row, ``tt`` [s] their times from the pulse's contact start, ``vals`` the pulse samples
    (amplitude times :meth:`PulseShape.value`)."""
    lo, hi = shape.support
    s = int(math.ceil((hi - lo) * fs)) + 2
    i0 = np.ceil((contact + lo) * fs).astype(np.int64)
    for a, b in _pulse_chunks(contact.size, s):
        idx = i0[a:b, None] + np.arange(s)[None, :]
        tt = idx / fs - contact[a:b, None]
        yield a, b, idx, tt, amps[a:b, None] * shape.value(tt)


def _add_rows(x: np.ndarray, idx: np.ndarray, vals: np.ndarray) -> None:
    """Add the rows' samples into ``x`` (in row order: chunk after chunk gives the same sums
    as all at once), those past its ends dropped."""
    m = (idx >= 0) & (idx < x.size)
    np.add.at(x, idx[m], vals[m])


def _with_noise(x: np.ndarray, sigma: float, rng, dtype) -> np.ndarray:
    """``x`` plus white Gaussian noise of std ``sigma`` (none for 0), as ``dtype``."""
    if sigma > 0:
        x += rng.normal(0.0, as_nonnegative(sigma, "sigma"), x.size)
    return x.astype(dtype, copy=False)


def pulse_scenario(n: int, fs: float, shape: PulseShape, spacing: float, *, snr_db: float,
                   planet_amplitudes=(1.0, 0.8, 1.2, 0.9), load_swing: float = 0.1,
                   level: float = 0.5, rng=None, dtype=np.float64) -> tuple[np.ndarray, dict]:
    """A pulse train with per-planet amplitudes, load drift, jittered spacing and truth.

    Returns
    -------
    x : ndarray
    truth : dict
        ``contact`` contact start times [s], ``onset`` the rise feature at ``level`` [s],
        ``amplitude`` [-], ``sigma`` noise std, ``crb`` per-pulse Cramer-Rao bound on the
        delay [s] (known pulse in white noise, amplitude and baseline unknown).
    """
    rng = np.random.default_rng(rng)
    lo, hi = shape.support
    t_first = -lo + 2.0 * spacing
    n_p = max(0, int((n / fs - t_first - hi - spacing) // spacing))
    contact = t_first + spacing * np.arange(n_p) + rng.uniform(-0.1, 0.1, n_p) * spacing
    pa = np.asarray(planet_amplitudes, dtype=np.float64)
    amp = pa[np.arange(n_p) % pa.size] * (1.0 + load_swing * np.sin(2 * np.pi * np.arange(n_p) / max(n_p, 1)))
    amp = amp / pa.mean()
    sigma = 10.0 ** (-snr_db / 20.0)
    # the train (as pulse_train) and each pulse's bound from the same rows, evaluated once
    x = np.zeros(int(n))
    crb = np.empty(n_p)
    for a, b, idx, tt, pul in _pulse_rows(as_positive(fs, "fs"), contact, amp, shape):
        _add_rows(x, idx, pul)
        crb[a:b] = crb_delay_std(amp[a:b, None] * shape.derivative(tt), sigma, pulse=pul)
    x = _with_noise(x, sigma, rng, dtype)
    truth = {"contact": contact, "onset": contact + shape.rise_time(level), "amplitude": amp,
             "sigma": sigma, "crb": np.atleast_1d(crb)}
    return x, truth


def match_onsets(detected, truth, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Pair each true onset with the nearest detection within ``tol`` [s].

    Returns
    -------
    (i_true, i_det) : index arrays of the matched pairs (one-to-one, nearest first).
    """
    det = np.asarray(detected, dtype=np.float64)
    tru = np.asarray(truth, dtype=np.float64)
    if det.size == 0 or tru.size == 0:
        e = np.empty(0, dtype=np.int64)
        return e, e.copy()
    j = np.clip(np.searchsorted(det, tru), 1, det.size) - 1
    jn = np.clip(j + 1, 0, det.size - 1)
    pick = np.where(np.abs(det[jn] - tru) < np.abs(det[j] - tru), jn, j)
    ok = np.abs(det[pick] - tru) <= tol
    it, idt = np.flatnonzero(ok), pick[ok]
    # one-to-one: keep the closest truth per detection
    order = np.argsort(np.abs(det[idt] - tru[it]), kind="stable")
    _, first = np.unique(idt[order], return_index=True)
    sel = np.sort(order[first])
    return it[sel], idt[sel]


# ====================================================================== the bench
def _scenarios(quick: bool):
    fs = 5120.0
    sc = {
        # mesh frequency 51.2 Hz: pulses ~80 samples FWHM
        "wide": dict(shape=PulseShape(100 / fs), spacing=600 / fs),
        # the seed rig's sun gauge: sun 18.19, carrier 1.06 r/min, Z_s = 25, 4 planets
        "seed_sun": dict(shape=PulseShape(60.0 / (17.13 * 25)), spacing=60.0 / (17.13 * 4)),
        # mesh frequency 0.4 fs: pulses ~2 samples FWHM, band-limited like a DAQ
        "narrow": dict(shape=PulseShape(2.5 / fs, bandlimit=0.45, fs=fs), spacing=15 / fs),
    }
    if quick:
        sc.pop("seed_sun")
    return fs, sc


def _accuracy_rows(name, x, truth, fs, shape, snr_db, settings):
    from ..onsets import coarse_peaks, detect_onsets, learn_template

    rows = []
    n = x.size
    tol = 0.4 * (truth["contact"][1] - truth["contact"][0]) if truth["contact"].size > 1 else 1.0
    crb = float(np.sqrt(np.mean(truth["crb"] ** 2))) * fs if truth["crb"].size else float("nan")
    for setting in settings:
        t = time.process_time()
        if setting == "coarse":
            cp = coarse_peaks(x, fs, width=shape.fwhm)
            det = cp.index / fs
        elif setting == "refine_once":
            det = detect_onsets(x, fs, relearn="never").times
        elif setting == "refine_block":
            det = detect_onsets(x, fs, relearn="block").times
        elif setting == "refine_auto":
            det = detect_onsets(x, fs).times
        else:  # oracle: template from the noise-free train
            clean = pulse_train(n, fs, truth["contact"], truth["amplitude"], shape)
            ci = np.round((truth["contact"] + shape.tc / 2) * fs).astype(np.int64)
            tpl = learn_template(clean, fs, ci, width=shape.fwhm)
            t = time.process_time()
            det = detect_onsets(x, fs, template=tpl).times
        dt = time.process_time() - t
        it, idt = match_onsets(det, truth["onset"] if setting != "coarse" else
                               truth["contact"] + shape.tc / 2, tol)
        err = (det[idt] - (truth["onset"][it] if setting != "coarse"
                           else truth["contact"][it] + shape.tc / 2)) * fs
        bias = float(err.mean()) if err.size else float("nan")
        std = float(err.std()) if err.size > 1 else float("nan")
        rmse = float(np.sqrt(np.mean(err ** 2))) if err.size else float("nan")
        rows.append({
            "scenario": name, "setting": setting, "snr_db": snr_db,
            "fwhm_samples": shape.fwhm * fs, "n_true": int(truth["onset"].size),
            "n_matched": int(it.size), "n_missed": int(truth["onset"].size - it.size),
            "n_false": int(det.size - idt.size), "bias_samples": bias, "std_samples": std,
            "rmse_samples": rmse, "crb_samples": crb,
            "std_over_crb": std / crb if crb > 0 else float("nan"),
            "runtime_s": dt, "msamples_per_s": n / dt / 1e6 if dt > 0 else float("nan"),
        })
    return rows


def _median_of_3(fn):
    """``fn()`` three times: (median CPU seconds of this process, median wall seconds, the
    last result)."""
    cpu, wall = [], []
    for _ in range(3):
        t, tw = time.process_time(), time.perf_counter()
        out = fn()
        cpu.append(time.process_time() - t)
        wall.append(time.perf_counter() - tw)
    return float(np.median(cpu)), float(np.median(wall)), out


def _throughput_rows(fs, scen, n, rng):
    from ..signal.condition import filter_signal, notch_hum, remove_drift
    from ..onsets import detect_onsets
    from ..onsets.fastpath import warmup as warmup_onsets

    rows = []
    load = getattr(os, "getloadavg", lambda: (float("nan"),))   # 1-minute load average [-]
    warmup_onsets()                                      # the numba kernels (when importable)
    for name, sc in scen.items():
        x, truth = pulse_scenario(n, fs, sc["shape"], sc["spacing"], snr_db=20.0, rng=rng)
        detect_onsets(x[: min(n, 1 << 18)], fs)          # warm-up (imports, FFT plans)
        # onsets end to end per core (width estimate, coarse, template, sub-sample
        # refinement): the default (template learnt once per operating point, numba
        # kernels for every block: numba is loaded here, as in `process`, whose filters
        # load it; see meshphase.onsets.fastpath), the same on the numpy
        # path alone (engine=numpy: the ratio shows what the kernels buy) and the template
        # re-learnt in every analysis block. Medians of three runs (CPU and wall time
        # apart); load_avg: the 1-minute load average after them (the machine may be
        # shared: CPU seconds are the per-core figure)
        for stage, kw in (("onsets.detect_onsets", {}),
                          ("onsets.detect_onsets engine=numpy", {"engine": "numpy"}),
                          ("onsets.detect_onsets relearn=block", {"relearn": "block"})):
            dt, wall, on = _median_of_3(lambda: detect_onsets(x, fs, **kw))
            rows.append({"stage": stage, "scenario": name, "n_samples": n, "n_pulses": len(on),
                         "runtime_s": dt, "msamples_per_s": n / dt / 1e6,
                         "wall_s": wall, "load_avg": float(load()[0])})
    x, _ = pulse_scenario(n, fs, scen["wide"]["shape"], scen["wide"]["spacing"], snr_db=20.0, rng=rng)
    for stage, fn in (("condition.remove_drift", lambda: remove_drift(x, fs)),
                      ("condition.filter_signal", lambda: filter_signal(x, fs, mesh_freq=51.2)),
                      ("condition.notch_hum", lambda: notch_hum(x, fs, freqs=[50.0, 150.0]))):
        t, tw = time.process_time(), time.perf_counter()
        fn()
        dt, wall = time.process_time() - t, time.perf_counter() - tw
        rows.append({"stage": stage, "scenario": "wide", "n_samples": n, "n_pulses": 0,
                     "runtime_s": dt, "msamples_per_s": n / dt / 1e6, "wall_s": wall})
    rows += _hum_rows(x[: int(min(n, 120.0 * fs))], fs)
    rows += _filter_rows(x, fs)
    rows += _median_rows(x[: int(min(n, 120.0 * fs))])
    return rows


def _median_rows(x):
    """The robust statistics' median (noise and SNR estimates, quality levels, the onset
    detector's noise level) on the samples of 2 min at most: ``np.median`` against
    :func:`meshphase.signal.median.median_of_finite`, medians of three, CPU seconds of one core;
    ``max_diff`` 0 when both give the same value."""
    from ..signal.median import median_of_finite

    rows, vals = [], {}
    for stage, fn in (("np.median", np.median), ("median_of_finite", median_of_finite)):
        dt, wall, vals[stage] = _median_of_3(lambda: fn(x))
        rows.append({"stage": stage, "scenario": "wide", "n_samples": int(x.size), "n_pulses": 0,
                     "runtime_s": dt, "msamples_per_s": x.size / dt / 1e6 if dt > 0 else float("nan"),
                     "wall_s": wall})
    rows[-1]["max_diff"] = float(abs(vals["median_of_finite"] - vals["np.median"]))
    return rows


def _filter_rows(x, fs):
    """The conditioning's zero-phase filters on both engines of :mod:`meshphase.signal.iir`: the
    low-pass (4th-order Butterworth at 28.6 Hz, the reference pass of the process table) and
    a hum notch pair (50 and 100 Hz, Q 30), each two sections. Medians of three, CPU
    seconds of one core; ``max_diff`` is the largest difference of the numba result from
    scipy's over the largest |x| (0: equal bit for bit)."""
    from ..signal import iir
    from ..signal.condition import design_notch
    from .rss import reference_sos

    filters = {"lowpass 28.6 Hz": reference_sos(fs),
               "notch 50 + 100 Hz": design_notch((50.0, 100.0), fs, 30.0)}
    engines = ["scipy"] + (["numba"] if iir.HAVE_NUMBA else [])
    if iir.HAVE_NUMBA:
        iir.warmup()                       # the kernel loaded (or compiled) before timing
    rows = []
    for fname, sos in filters.items():
        padlen = iir.padlen_for(sos)
        ref = None
        for eng in engines:
            dt, wall, y = _median_of_3(lambda: iir.sosfiltfilt(sos, x, padlen=padlen, engine=eng))
            if ref is None:
                ref = y
            rows.append({"stage": f"iir.sosfiltfilt engine={eng}", "scenario": fname,
                         "n_samples": int(x.size), "n_pulses": 0, "runtime_s": dt,
                         "msamples_per_s": x.size / dt / 1e6, "wall_s": wall,
                         "max_diff": float(np.max(np.abs(y - ref)) / np.max(np.abs(x)))})
        if iir.HAVE_NUMBA:
            # two channels in one sweep (what the streamed conditioning does with two gauges
            # of a gear): samples of both channels per CPU second
            xb = x[::-1].copy()
            dt, wall, (ya, _) = _median_of_3(
                lambda: iir.sosfiltfilt_pair(sos, x, sos, xb, padlen=padlen))
            rows.append({"stage": "iir.sosfiltfilt_pair (two channels)", "scenario": fname,
                         "n_samples": int(2 * x.size), "n_pulses": 0, "runtime_s": dt,
                         "msamples_per_s": 2 * x.size / dt / 1e6, "wall_s": wall,
                         "max_diff": float(np.max(np.abs(ya - ref)) / np.max(np.abs(x)))})
    return rows


def _hum_rows(x, fs):
    """The hum search (what ``process`` runs on each channel's first 120 s) and its Welch
    PSD two ways: segments detrended by the library (``scipy.signal.detrend``, linear) and
    by :func:`meshphase.signal.condition.detrend_linear`, which ``detect_hum`` uses. Medians of
    three, CPU seconds of one core."""
    from scipy import signal

    from ..signal.condition import detrend_linear, hum_nperseg, detect_hum

    t = np.arange(x.size) / fs
    y = x + 0.1 * np.sin(2 * np.pi * 50.0 * t)
    nper = hum_nperseg(y.size, fs)
    rows = []
    for stage, fn in (("condition.detect_hum", lambda: detect_hum(y, fs)),
                      ("welch detrend=linear (scipy)",
                       lambda: signal.welch(y, fs, nperseg=nper, detrend="linear")),
                      ("welch detrend=detrend_linear",
                       lambda: signal.welch(y, fs, nperseg=nper, detrend=detrend_linear))):
        cpu, wall = [], []
        for _ in range(3):
            t0, tw = time.process_time(), time.perf_counter()
            fn()
            cpu.append(time.process_time() - t0)
            wall.append(time.perf_counter() - tw)
        dt = float(np.median(cpu))
        rows.append({"stage": stage, "scenario": "wide + 50 Hz", "n_samples": int(y.size),
                     "n_pulses": 0, "runtime_s": dt, "msamples_per_s": y.size / dt / 1e6,
                     "wall_s": float(np.median(wall))})
    return rows


def _fmt(v) -> str:
    if isinstance(v, (tuple, list)):
        return " / ".join(_fmt(x) for x in v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "-"
        return f"{v:.3g}"
    return str(v)


def _md_table(rows, cols) -> list:
    """Markdown lines of a table: header ``cols``, one line per row (missing keys blank)."""
    return (["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
            + ["| " + " | ".join(_fmt(r.get(c)) for c in cols) + " |" for r in rows])


def _markdown(res: dict) -> str:
    lines = ["# Processing benchmark: onset timing vs the Cramer-Rao bound", "",
             f"Machine: {res['meta']['machine']}; quick={res['meta']['quick']}.", "",
             "SNR = 10 log10(A^2 / sigma^2), A the tensile peak of a mean-amplitude pulse. "
             "Errors in samples, bias (a constant feature offset) removed from std; crb = RMS "
             "over pulses of the Cramer-Rao bound (known pulse, white noise, amplitude and "
             "baseline unknown).", "", "## Timing error", ""]
    lines += _md_table(res["accuracy"], ACCURACY_COLUMNS)
    lines += ["", "## Throughput (MSamples per CPU-second; runtime_s is CPU time)", ""]
    lines += _md_table(res["throughput"], THROUGHPUT_COLUMNS)
    diffs = [f"{r['stage'].split()[0]} {r['scenario']} {r['max_diff']:.2g}"
             for r in res["throughput"]
             if r["stage"] in ("iir.sosfiltfilt engine=numba", "iir.sosfiltfilt_pair (two channels)")]
    if diffs:
        lines += ["", "iir numba kernels against engine=scipy, largest difference "
                  "over the largest |x| (0: bit for bit): " + ", ".join(diffs) + "."]
    if res.get("process"):
        lines += ["", "## meshphase process: peak memory and time against recording length", "",
                  "8 channels (sun, ring, 5 face-width gauges, tacho) at 5120 Hz, HDF5 of the "
                  "row's dtype; wall_over_sosfiltfilt: the run's wall time over that pass; "
                  "child process, BLAS on one thread; times in s. sosfiltfilt_s: one zero-phase "
                  "pass of the conditioning low-pass over the same samples, at the mean time of "
                  "the pass timed just before and just after the run (sosfiltfilt_msps: those "
                  "two rates; median of all "
                  f"{res['meta'].get('sosfiltfilt_msps', float('nan')):.1f} MS/s here); streamed = "
                  "load + condition + onsets (the reads of the samples: the scan, then conditioning and onsets); "
                  "streamed_peak_mb: the peak RSS (VmHWM) when they are done, peak_rss_mb: of "
                  "the whole run (phasing and the later stages work on the passes, whose "
                  "number grows with the length). read_*_s: one pass over the file's "
                  "8 channels, checked (HDF5's fletcher32 check: process's first pass), "
                  "unchecked at the chunks' byte offsets (its later passes) and unchecked "
                  "through h5py's read_direct_chunk (the library path). Before "
                  "streaming, process peaked at ~5x the samples' size (10 min: 0.96 GB, 1 h: "
                  "5.1 GB, measured on this machine; 3 h would need ~15 GB).", ""]
        lines += _md_table(res["process"], PROCESS_COLUMNS)
        for sk in res.get("process_skipped", []):
            lines.append(f"\nSkipped {sk['minutes']:g} min: {sk['reason']}")
    from .startup import EXIT_COLUMNS, STARTUP_COLUMNS

    for key, title, note, cols in (
            ("startup", "Start-up: fresh interpreters, median wall time [s]",
             "over_python_s = median minus that of `python -c pass`; ready_s = median from the "
             "start to the end of the case's code (the imports done), before the interpreter's "
             "exit (the exit table); modules = sys.modules at exit. `meshphase process` pays "
             "the stages' import (scipy.linalg, .interpolate, .optimize, .ndimage; not "
             "scipy.signal, which imports scipy.stats: its row shows what that would add) on "
             "top of `--version`, and the filters' numba kernel (`meshphase bench --warmup` "
             "times its load).", STARTUP_COLUMNS),
            ("exit", "Exit: from the last atexit handler to the process reaped [s]",
             "Fresh interpreters with the campaign workers' stack imported, after `meshphase "
             "info FILE`: the interpreter's own finalization (its garbage collections walk "
             "every object the imports made), and what is left of it after "
             "meshphase.cli.console_main's collection (collect_s) and gc.freeze.", EXIT_COLUMNS),
            ("identify", "identify: model evaluations and wall time per Jacobian",
             "identify_errors on the exact passes of the bench rig (Table 2 case 1 offsets, "
             "every offset free); 2-point = scipy finite differences (before), analytic = "
             "closed form (meshphase.models.phasing_jacobian). The share of a run is "
             "identify_share in the process table.", IDENTIFY_COLUMNS)):
        if res.get(key):
            lines += ["", f"## {title}", "", note, ""] + _md_table(res[key], cols)
    if res.get("phasing"):
        from .phasing import TARGET_ABS, TARGET_FLOOR_RATIO, markdown_table, pooled_calibration

        cal = pooled_calibration(res["phasing"])
        lines += ["", "## Measured phasing against truth on the rig's conditions", "",
                  "Per-pass RMS error of the measured phasing [mesh cycles] against the synthetic "
                  "truth; floor = RMS of the two onsets' timing bound per pass; target = "
                  f"max({TARGET_ABS:g}, {TARGET_FLOOR_RATIO:g} x floor); z_rms = RMS of error / "
                  "sigma and coverage95 = share of passes inside 1.96 sigma (calibration of the "
                  "per-pass uncertainty); process_s = wall time of the stages (load to compare). "
                  "Scenarios: meshphase.bench.phasing.", "",
                  f"Pooled calibration over the table: z_rms {cal['z_rms']:.2f}, coverage95 "
                  f"{cal['coverage95']:.3f} over {cal['n']} passes; {cal['n_ok']} of "
                  f"{cal['n_rows']} rows meet the target.", "", markdown_table(res["phasing"])]
    if res.get("conditions"):
        from .conditions import conditions_markdown

        lines += ["", "## Conditions where measured phasing was once confident and wrong", "",
                  "Per condition, seed and gauge (meshphase.bench.conditions; `meshphase bench "
                  "processing --accuracy` runs this table alone): error, floor and target as "
                  "above; verdict = the run's reliability flag and its causes; meets = within "
                  "target, or flagged unreliable with RMS(error/sigma) <= 1.5.", "",
                  conditions_markdown(res["conditions"])]
    return "\n".join(lines) + "\n"


def process_rss_rows(work, minutes, *, seed: int = 1,
                     dtype: str = "float64") -> tuple[list, list, float]:
    """Peak memory, wall and stage times of ``meshphase process`` on the 8-channel benchmark
    recording of each length in ``minutes`` (written to ``work`` with samples of ``dtype``,
    "float64" or "float32", removed again).

    Returns
    -------
    (rows, skipped, rate) : (list of dict, list of dict, float)
        Rows with the keys :data:`PROCESS_COLUMNS`; lengths skipped for want of disk space;
        the median sosfiltfilt rate [samples/s]. Each row's ratios take the mean time of
        the reference pass timed just before and just after its run (``sosfiltfilt_msps``:
        the two rates [MS/s]).
    """
    from .rss import BENCH_GEARSET, N_CHANNELS, free_bytes, run_child

    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    run_child("import_job")              # the bytecode written once, as a user's first run does
    rates = []
    gearset = work / "gearset.toml"
    gearset.write_text(BENCH_GEARSET, encoding="utf-8")
    rows, skipped = [], []
    if dtype not in ("float64", "float32"):
        raise ValueError(f"dtype must be 'float64' or 'float32', got {dtype!r}")
    for m in minutes:
        m = as_positive(m, "process_minutes")
        n = int(round(m * 60.0 * 5120.0))
        data = n * N_CHANNELS * np.dtype(dtype).itemsize
        if free_bytes(work) < int(1.1 * data) + (256 << 20):
            skipped.append({"minutes": m, "reason": f"needs {1.1 * data / 1e9:.1f} GB free on {work}"})
            logger.warning("processing bench: process %g min skipped: not enough disk space", m)
            continue
        path = work / f"process_{m:g}.h5"
        logger.info("processing bench: writing the %g min x %d channel recording", m, N_CHANNELS)
        run_child("write_job", path=str(path), minutes=m, seed=seed, dtype=dtype)
        # one pass over the file three ways: checked (process's first pass), unchecked at
        # the chunks' byte offsets (its later passes), unchecked through h5py's
        # read_direct_chunk (the library path beside that)
        rd = run_child("hdf5_pass_job", path=str(path))
        # the reference pass timed just before and just after the run (a shared machine's
        # speed drifts over minutes): the mean of the two times is the run's yardstick
        before = run_child("sosfiltfilt_job")["samples_per_s"]
        r = run_child("process_job", path=str(path), gearset=str(gearset),
                      out_dir=str(work / f"process_{m:g}-out"))
        after = run_child("sosfiltfilt_job")["samples_per_s"]
        rates += [before, after]
        t = r["timings"]
        streamed = sum(t.get(k, 0.0) for k in ("load", "condition", "onsets"))
        ref = n * N_CHANNELS * 0.5 * (1.0 / before + 1.0 / after)
        rows.append({"minutes": m, "dtype": dtype, "n_channels": N_CHANNELS, "n_samples": n, "data_mb": data / 2**20,
                     "status": r["status"], "n_onsets": r["n_onsets"], "wall_s": r["wall_s"],
                     "peak_rss_mb": r["peak_rss_mb"],
                     "streamed_peak_mb": (r.get("hwm_mb") or {}).get("onsets"),
                     "rss_over_data": r["peak_rss_mb"] / (data / 2**20),
                     "memory_estimate_mb": r.get("memory_estimate_mb"),
                     "load_s": t.get("load"), "condition_s": t.get("condition"),
                     "onsets_s": r.get("onsets_s"), "phasing_s": t.get("phasing"),
                     "identify_s": t.get("identify"),
                     "identify_share": (t.get("identify") or 0.0) / r["wall_s"],
                     "other_s": sum(v for k, v in t.items()
                                    if k not in ("load", "condition", "onsets", "phasing")),
                     "sosfiltfilt_s": ref, "sosfiltfilt_msps": (before / 1e6, after / 1e6),
                     "wall_over_sosfiltfilt": r["wall_s"] / ref,
                     "streamed_over_sosfiltfilt": streamed / ref,
                     # worker threads (meshphase.runtime.threads): the CPU time of all of them beside
                     # the wall time, against the single-threaded sosfiltfilt pass
                     "threads": r.get("threads"), "cpu_s": r.get("cpu_s"),
                     "cpu_over_sosfiltfilt": (r["cpu_s"] / ref) if r.get("cpu_s") else None,
                     "read_checked_s": rd["checked_s"], "read_unchecked_s": rd["unchecked_s"],
                     "read_library_s": rd["library_s"]})
        logger.info("processing bench: process %g min: %.1f s, peak RSS %.0f MB", m, r["wall_s"],
                    r["peak_rss_mb"])
        path.unlink(missing_ok=True)
        import shutil

        shutil.rmtree(work / f"process_{m:g}-out", ignore_errors=True)
    rate = float(np.median(rates)) if rates else run_child("sosfiltfilt_job")["samples_per_s"]
    return rows, skipped, rate


#: Columns of the identification table (processing_bench.json "identify").
IDENTIFY_COLUMNS = ("minutes", "jac", "n_passes", "evaluations", "jacobians", "wall_s",
                    "rms_after")


def identify_rows(minutes=(10.0,), *, jacs=("2-point", "analytic")) -> list:
    """Evaluations and wall time of :func:`meshphase.compare.identify.identify_errors` per Jacobian.

    The passes are the exact engagements (:func:`meshphase.synthetic.kinematics.engagement_events`)
    of the benchmark rig (:data:`meshphase.bench.rss.BENCH_GEARSET`, Z_p 31, sun 18.19 and
    carrier 1.06 r/min) with seed 000 Table 2 case 1 offsets (0.2 mm, sun and ring gauges),
    through :func:`meshphase.kinematics.pass_table.measured_phasing`, every offset free: what the identify
    stage of a run of that length fits. Rows: :data:`IDENTIFY_COLUMNS`.
    """
    from ..compare.identify import identify_errors
    from ..models.gearset import Gearset, Speeds
    from ..models.mesh_phasing import ShaftHoleErrors
    from ..kinematics.pass_table import measured_phasing
    from meshphase.synthetic.kinematics import engagement_events

    g = Gearset.equally_spaced(25, 87, 31, 4, 112.5e-3)
    sp = Speeds.kinematic(g, sun=18.19 * math.pi / 30.0, carrier=1.06 * math.pi / 30.0)
    err = ShaftHoleErrors.from_mm_deg(e_sun=0.2, kappa_sun=4.0, e_ring=0.2, kappa_ring=60.0,
                                      e_planet=0.2, kappa_planet=20.0)
    rows = []
    for m in minutes:
        m = as_positive(m, "minutes")
        tables = []
        for gear, z in (("sun", 25), ("ring", 87)):
            ev = engagement_events(g, sp, gear, -0.02, 0.0, 60.0 * m, errors=err)
            tables.append(measured_phasing(ev.time, ev.planet - 1, z, 4, gauge=gear, z_planet=31))
        for jac in jacs:
            t0 = time.perf_counter()
            res = identify_errors(tables, g, jac=jac)
            rows.append({"minutes": m, "jac": jac, "n_passes": res.n_passes,
                         "evaluations": res.cost_evaluations,
                         "jacobians": res.jacobian_evaluations,
                         "wall_s": time.perf_counter() - t0, "rms_after": res.rms_after})
            logger.info("processing bench: identify %g min, jac %s: %d evaluations, %.2f s", m,
                        jac, res.cost_evaluations, rows[-1]["wall_s"])
    return rows


_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def run_processing_bench(out_dir, *, quick: bool = False, rng=0, process_minutes=None) -> dict:
    """Run the processing benchmark into ``out_dir``.

    Parameters
    ----------
    out_dir : path
        Created if missing; receives ``processing_bench.json`` and ``processing_bench.md``.
    quick : bool
        Tiny sizes and one start-up timing per case (a smoke run, under a minute).
    rng : None, int or Generator
        Noise seed.
    process_minutes : sequence of float, optional
        Lengths [min] of the 8-channel recordings ``meshphase process`` runs on for the peak
        memory table (:func:`process_rss_rows`); default :data:`PROCESS_MINUTES`, none when
        ``quick``.

    Returns
    -------
    dict
        ``{"accuracy": [row...], "throughput": [row...], "process": [row...], "conditions":
        [row...], "meta": {...}, "files": {...}}``; row keys are :data:`ACCURACY_COLUMNS`,
        :data:`THROUGHPUT_COLUMNS`, :data:`PROCESS_COLUMNS` and
        :data:`meshphase.bench.conditions.CONDITION_COLUMNS`.

    Notes
    -----
    The measurement runs in a child process with the BLAS thread pools set to one thread
    (``OPENBLAS_NUM_THREADS=1`` ...): the detector's matrix products are small, and a
    multi-threaded BLAS spends more CPU spinning than it saves; the figures are per core.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if isinstance(rng, np.random.Generator):
        rng = int(rng.integers(2 ** 32))
    elif rng is not None:
        rng = int(rng)
    if process_minutes is None:
        process_minutes = () if quick else PROCESS_MINUTES
    process_minutes = tuple(float(as_positive(m, "process_minutes")) for m in process_minutes)
    if all(os.environ.get(v) == "1" for v in _THREAD_VARS):
        res = _run(out, quick, rng, process_minutes)
    else:
        env = child_env(**{v: "1" for v in _THREAD_VARS})
        code = ("import sys; from meshphase.bench.processing import _run; "
                f"_run(sys.argv[1], {bool(quick)!r}, {rng!r}, {process_minutes!r})")
        proc = subprocess.run([sys.executable, "-c", code, str(out)], env=env,
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"processing bench child process failed:\n{proc.stderr[-4000:]}")
        res = json.loads((out / "processing_bench.json").read_text())
    res["files"] = {"json": str(out / "processing_bench.json"),
                    "md": str(out / "processing_bench.md")}
    return res


def _run(out_dir, quick: bool, rng, process_minutes=()) -> dict:
    rng = np.random.default_rng(rng)
    out = Path(out_dir)
    fs, scen = _scenarios(quick)
    n_pulses = 40 if quick else 400
    snrs = (20.0,) if quick else (10.0, 20.0, 30.0)
    settings = ("coarse", "refine_once", "refine_block", "refine_auto", "refine_oracle")
    acc = []
    for name, sc in scen.items():
        n = int(math.ceil((n_pulses + 5) * sc["spacing"] * fs))
        for snr in snrs:
            if name == "narrow" and snr < 15.0:
                continue   # below the coarse detector's reach for 2-sample pulses (see docs)
            x, truth = pulse_scenario(n, fs, sc["shape"], sc["spacing"], snr_db=snr, rng=rng)
            acc += _accuracy_rows(name, x, truth, fs, sc["shape"], snr, settings)
            logger.info("processing bench: %s at %g dB done", name, snr)
    thr = _throughput_rows(fs, scen, (1 << 17) if quick else (1 << 24), rng)
    proc, proc_skipped, rate = [], [], float("nan")
    if process_minutes:
        import shutil
        import tempfile

        work = Path(tempfile.mkdtemp(prefix="process_bench_", dir=out))
        try:
            proc, proc_skipped, rate = process_rss_rows(work, process_minutes)
        finally:
            shutil.rmtree(work, ignore_errors=True)
    from .phasing import matrix_cases, phasing_rows

    phs = phasing_rows(matrix_cases(quick))
    from .conditions import CONDITIONS, QUICK_CONDITIONS, condition_rows

    conds = condition_rows(QUICK_CONDITIONS if quick else CONDITIONS)
    ident = identify_rows((2.0,) if quick else (10.0, 60.0))
    from .startup import exit_rows, startup_rows

    # a quick run times each start-up case once (each case costs its fresh interpreters)
    start = startup_rows(1 if quick else 7)
    ends = exit_rows(1 if quick else 7)
    res = {"accuracy": acc, "throughput": thr, "phasing": phs, "conditions": conds,
           "process": proc, "identify": ident,
           "startup": start, "exit": ends,
           "process_skipped": proc_skipped,
           "meta": {"machine": f"{platform.machine()} {platform.processor() or ''} "
                               f"python {platform.python_version()}".strip(),
                    "quick": quick, "fs": fs, "sosfiltfilt_msps": rate / 1e6,
                    "blas_threads": {v: os.environ.get(v) for v in _THREAD_VARS},
                    "snr_definition": "10 log10(A^2/sigma^2), A = tensile peak of a mean pulse"}}
    (out / "processing_bench.json").write_text(json.dumps(res, indent=2, default=float))
    (out / "processing_bench.md").write_text(_markdown(res))
    if phs:
        from .phasing import error_vs_runtime_figure

        error_vs_runtime_figure(phs, out / "phasing_error_vs_runtime.png")
    return res
