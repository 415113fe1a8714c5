"""The checked options of one detection run (:func:`~meshphase.onsets.detect_onsets`'s
keywords in samples), shared by the whole-array and the streaming entry points."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..validate import as_choice, as_float, as_nonnegative, as_positive, as_positive_int
from .fastpath import check_engine
from .template import Template
from .runs import check_runs

__all__ = ["DetectOptions", "check_options", "DEFAULT_BLOCK"]

#: analysis block of the matched filter [samples] when ``block`` is None
DEFAULT_BLOCK = 1 << 20


@dataclass
class DetectOptions:
    """The keywords of :func:`~meshphase.onsets.detect_onsets` checked, lengths in samples
    (``width``, ``mesh_width``, ``min_spacing``, ``block``, ``gap_guard``) and runs as
    merged absolute ``[start, stop)`` sample rows (:func:`check_options` builds it)."""

    fs: float
    t0: float
    width: float | None            # samples
    mesh_width: float | None       # samples, from mesh_freq
    min_spacing: float | None      # samples
    template: Template | None
    relearn: str
    polarity: str | None
    reference: str
    level: float
    k_sigma: float
    min_corr: float
    block: int                     # samples
    decimation: int | None
    max_template_pulses: int
    min_template_pulses: int
    n_align: int
    flag_runs: np.ndarray          # absolute samples, merged
    gap_guard: int                 # samples
    channel: str | None
    gap_runs: np.ndarray           # absolute samples, merged: finite samples that are gaps
    engine: str = "auto"           # numba kernels for dense blocks (see .fastpath)


def check_options(fs, *, t0=0.0, width=None, mesh_freq=None, min_spacing=None, template=None,
                  relearn="auto", polarity=None, reference="rise", level=0.5, k_sigma=5.0,
                  min_corr=0.5, block=None, decimation=None, max_template_pulses=256,
                  min_template_pulses=8, n_align=2, flag_runs=None, gap_guard=0.0,
                  channel=None, gap_runs=None, engine="auto") -> DetectOptions:
    """The keywords of :func:`~meshphase.onsets.detect_onsets` (which documents them)
    checked and converted to samples; TypeError or ValueError naming the bad one."""
    fs = as_positive(fs, "fs")
    t0 = as_float(t0, "t0")
    w = None if width is None else as_positive(width, "width") * fs
    mw = None
    if mesh_freq is not None:
        # tensile FWHM of a pulse of contact ratio ~1.6: about 0.8 mesh periods
        mw = 0.8 * fs / as_positive(mesh_freq, "mesh_freq")
    sp = None if min_spacing is None else as_positive(min_spacing, "min_spacing") * fs
    if template is not None and not isinstance(template, Template):
        raise TypeError(f"template must be a Template, got {type(template).__name__}")
    if template is not None and template.fs != fs:
        raise ValueError(f"template was learnt at fs = {template.fs!r} Hz, data are at {fs!r} Hz")
    relearn = as_choice(relearn, "relearn", ("auto", "block", "never"))
    if polarity is not None:
        polarity = as_choice(polarity, "polarity", ("positive", "negative", "auto"))
        if template is not None and polarity != "auto" and \
                (1 if polarity == "positive" else -1) != template.polarity:
            raise ValueError(f"polarity={polarity!r} contradicts the template's polarity "
                             f"{template.polarity:+d}")
    reference = as_choice(reference, "reference", ("rise", "peak"))
    level = as_float(level, "level")
    if not 0.0 <= level < 1.0:
        raise ValueError(f"level must be in [0, 1), got {level!r}")
    k_sigma = as_positive(k_sigma, "k_sigma")
    min_corr = as_float(min_corr, "min_corr")
    if not -1.0 <= min_corr <= 1.0:
        raise ValueError(f"min_corr must be in [-1, 1], got {min_corr!r}")
    blk = DEFAULT_BLOCK if block is None else max(16, int(round(as_positive(block, "block") * fs)))
    dec = None if decimation is None else as_positive_int(decimation, "decimation")
    if template is not None:
        if dec is not None and dec != template.decimation:
            raise ValueError(f"decimation={dec} contradicts the template's {template.decimation}")
        dec = template.decimation
    mtp = as_positive_int(max_template_pulses, "max_template_pulses")
    mnp = as_positive_int(min_template_pulses, "min_template_pulses")
    n_align = as_positive_int(n_align, "n_align")
    fr = check_runs(flag_runs, "flag_runs")
    gr = check_runs(gap_runs, "gap_runs")
    guard = int(math.ceil(as_nonnegative(gap_guard, "gap_guard") * fs))
    if channel is not None and not isinstance(channel, str):
        raise TypeError(f"channel must be a string, got {channel!r}")
    engine = check_engine(engine)
    return DetectOptions(fs, t0, w, mw, sp, template, relearn, polarity, reference, level, k_sigma,
                         min_corr, blk, dec, mtp, mnp, n_align, fr, guard, channel, gr, engine)

