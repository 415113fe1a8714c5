"""The detection engine: analysis blocks of a sample stream, each coarsely detected,
template-learnt and refined; and the whole-array entry points built on it.

Blocks are processed with margins and on a fixed grid, so a recording fed whole or as a
stream of chunks of any size gives bit-identical onsets (see :mod:`meshphase.onsets`).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..signal.condition import merge_runs
from ..errors import ProcessingWarning
from ..runtime.log import logger
from ..signal.quality import find_runs
from ..recording import Recording
from ..validate import as_signal
from .coarse import coarse_decimated, decimate, decimation_for, fill_nan
from .learning import half_length, learn_decimated, refine_width, width_autocorr
from .fastpath import dense, refine_pulses
from .matched import gather_windows, Matcher, sublags, window_baseline
from .options import check_options, DetectOptions
from .relearn import TemplateFit, good_median, pulse_period
from .results import (FLAG_CLIPPED, FLAG_EDGE, FLAG_GAP, FLAG_LOW_CORR, FLAG_TEMPLATE, Onsets,
                      empty_onsets)
from .detector import recording_channel
from .template import Template
from .runs import inside_runs, runs_overlap

__all__ = ["BlockEngine", "detect_onsets", "detect_onsets_recording"]


class BlockEngine:
    """Block processor of the matched filter, shared by the whole-array and the streaming
    entry points: :meth:`feed` samples, :meth:`finish` for the onsets.

    Samples are fed in chunks of any size; analysis block ``k`` covers the samples
    ``[k B, (k+1) B)`` (``B`` = ``block_len``) and is processed, with margins, as soon as its
    look-ahead is there, so the segments (and therefore the results) do not depend on the
    chunking.

    Parameters
    ----------
    opt : DetectOptions
        The checked options (:func:`meshphase.onsets.options.check_options`).
    """

    def __init__(self, opt: DetectOptions):
        self.opt = opt
        self.chunks: list[tuple[int, np.ndarray]] = []   # (first sample, samples) still needed
        self.n_fed = 0               # samples fed so far
        self.next_block = 0          # index k of the next analysis block to process
        self.ready = False           # width, decimation and block length are known
        self.polarity = 1            # sign of the pulses' main lobe in the data (+1, -1)
        self.width = None            # current FWHM [samples]
        self.decimation = 1          # block-mean decimation factor D [-]
        self.block_len = opt.block   # analysis block length B [samples]
        self.template: Template | None = opt.template
        self.fit: TemplateFit | None = None  # how the learnt template fitted its block (relearn="auto")
        self.templates: list[Template] = []
        self.out: list[tuple] = []
        self.last_index = -np.inf
        self.n_fallback = 0
        self.n_dropped_gap = 0
        self.warned_width = False
        self._matcher: tuple | None = None   # (template, k, u, Matcher): reused while they hold

    # ---------------------------------------------------------------- buffer
    def feed(self, arr: np.ndarray) -> None:
        """Take the next chunk of samples (1-D, contiguous or not; kept by reference) and
        process every analysis block whose look-ahead is now there."""
        if arr.size == 0:
            return
        self.chunks.append((self.n_fed, arr))
        self.n_fed += arr.size
        if not self.ready:
            if self.n_fed < self.opt.block:
                return
            self._init()
        while self.n_fed >= self._block_hi(self.next_block, final=False):
            self._process(self.next_block, final=False)
            self.next_block += 1
            self._trim()

    def finish(self) -> Onsets:
        """Process the remaining blocks; the onsets of everything fed."""
        opt = self.opt
        if self.n_fed == 0:
            return empty_onsets(opt.fs, opt.t0, opt.channel, opt.reference, opt.level)
        if not self.ready:
            self._init()
        while self.next_block * self.block_len < self.n_fed:
            self._process(self.next_block, final=True)
            self.next_block += 1
        if self.n_fallback:
            warnings.warn(f"{self._who()}{self.n_fallback} analysis block(s) had fewer than "
                          f"{opt.min_template_pulses} clean pulses to learn a template from; their "
                          "onsets carry FLAG_TEMPLATE", ProcessingWarning, stacklevel=3)
        if not self.out:
            return empty_onsets(opt.fs, opt.t0, opt.channel, opt.reference, opt.level, self.templates)
        cols = [np.concatenate(c) for c in zip(*self.out)]
        index, corr, amp, width, flags, tid = cols
        return Onsets(opt.t0 + index / opt.fs, index, corr, amp, width, flags.astype(np.uint8, copy=False),
                      tid.astype(np.int32, copy=False), tuple(self.templates), opt.fs, opt.t0, opt.channel,
                      opt.reference, opt.level, self.polarity)

    def _who(self) -> str:
        return f"channel {self.opt.channel!r}: " if self.opt.channel else ""

    def _get(self, lo: int, hi: int) -> np.ndarray:
        parts = []
        for s, a in self.chunks:
            e = s + a.size
            if e <= lo or s >= hi:
                continue
            parts.append(a[max(lo, s) - s:min(hi, e) - s])
        seg = parts[0] if len(parts) == 1 else np.concatenate(parts)
        # contiguous float64 (one copy of a strided column or of float32 samples, else none)
        seg = np.ascontiguousarray(seg, dtype=np.float64)
        gr = self.opt.gap_runs
        if len(gr):
            # finite samples that are gaps (dropouts) read as NaN, like any other gap
            i = np.searchsorted(gr[:, 1], lo, side="right")
            j = np.searchsorted(gr[:, 0], hi, side="left")
            if j > i:
                r = np.clip(gr[i:j] - lo, 0, seg.size)
                marks = np.zeros(seg.size + 1, dtype=np.int64)
                np.add.at(marks, r[:, 0], 1)
                np.add.at(marks, r[:, 1], -1)
                seg = np.where(np.cumsum(marks[:-1]) > 0, np.nan, seg)
        return seg

    def _trim(self) -> None:
        # the next block reads from k B - its margin, rounded down to the decimation grid
        # (as _process computes it; the geometry does not change before it runs)
        keep_from = max(0, self.next_block * self.block_len - min(self._geom()[3], self.block_len))
        keep_from -= keep_from % self.decimation
        while self.chunks and self.chunks[0][0] + self.chunks[0][1].size <= keep_from:
            self.chunks.pop(0)

    # ---------------------------------------------------------------- geometry
    def _geom(self):
        """Sizes for the next block from the current width: (w_d, h_half, k, margin), the
        last in full-rate samples (uncapped)."""
        d = self.decimation
        w_d = self.width / d
        h_half = half_length(w_d)
        if self.template is not None:
            h_half = max(h_half, self.template.samples.size // 2 + 1)
        # search radius: half a width plus half the coarse smoothing length, plus slack
        k = int(math.ceil(0.5 * w_d + 0.5 * max(1, int(round(0.5 * w_d))))) + 1
        margin = (2 * h_half + 2 * k + int(w_d) + 4) * d
        return w_d, h_half, k, margin

    def _block_hi(self, k: int, final: bool) -> int:
        hi = (k + 1) * self.block_len + min(self._geom()[3], self.block_len)
        return min(hi, self.n_fed) if final else hi

    # ---------------------------------------------------------------- initialisation
    def _init(self) -> None:
        opt = self.opt
        seg = fill_nan(self._get(0, min(self.n_fed, opt.block)))
        if opt.template is not None:
            self.polarity = opt.template.polarity
        elif opt.polarity == "positive":
            self.polarity = 1
        elif opt.polarity == "negative":
            self.polarity = -1
        w0 = None
        if opt.template is None and opt.width is None:
            # the autocorrelation width does not depend on the sign
            w0 = opt.mesh_width if opt.mesh_width is not None else width_autocorr(seg)
        if opt.template is None and opt.polarity in (None, "auto"):
            self.polarity = _auto_polarity(seg, opt.width if opt.width is not None else w0)
        if self.polarity < 0:
            seg = -seg
        if opt.template is not None:
            self.width = opt.template.fwhm * opt.fs
        elif opt.width is not None:
            self.width = opt.width
        else:
            self.width, _ = refine_width(seg, opt.fs, w0, opt.k_sigma, self.polarity, opt.decimation)
        self.decimation = opt.decimation or decimation_for(self.width)
        # blocks at least 4 margins long: the overlap costs at most ~50 % extra work
        self.block_len = int(max(opt.block, 4 * self._geom()[3]))
        self.ready = True
        logger.debug("onsets: fs=%g, width=%.3g samples, decimation=%d, block=%d, polarity=%+d",
                     opt.fs, self.width, self.decimation, self.block_len, self.polarity)

    # ---------------------------------------------------------------- one block
    def _learn_block(self, yd, peaks, lo, d, w_d, h_half, kk, bad_runs):
        """The template for this block and whether it is a fallback (None: no template)."""
        opt = self.opt
        tpl = self.template
        if opt.template is not None or (tpl is not None and opt.relearn == "never"):
            return tpl, False
        clean = peaks
        if len(bad_runs):
            a = lo + (peaks - h_half - kk) * d
            b = lo + (peaks + h_half + kk + 1) * d
            clean = peaks[~runs_overlap(a - opt.gap_guard, b + opt.gap_guard, bad_runs)]
        new = None
        # half the usual distance between pulses bounds the template (see learn_decimated)
        cap = int(0.5 * np.quantile(np.diff(peaks), 0.25)) if peaks.size >= 4 else None
        if clean.size >= 3:
            new = learn_decimated(yd, clean, fs=opt.fs, d=d, w_d=w_d, reference=opt.reference,
                                  level=opt.level, polarity=self.polarity, max_pulses=opt.max_template_pulses,
                                  n_align=opt.n_align, min_corr=opt.min_corr, max_half=cap)
        if new is not None and new.n_pulses >= opt.min_template_pulses:
            return new, False
        if tpl is not None:
            return tpl, True
        if clean.size < peaks.size and (new is None or new.n_pulses < opt.min_template_pulses):
            # too few clean pulses (e.g. every peak clipped): learn from all of them; the
            # leading edge below the rail still times them, and their flags say so
            every = learn_decimated(yd, peaks, fs=opt.fs, d=d, w_d=w_d, reference=opt.reference,
                                    level=opt.level, polarity=self.polarity,
                                    max_pulses=opt.max_template_pulses, n_align=opt.n_align,
                                    min_corr=opt.min_corr, max_half=cap) if peaks.size >= 3 else None
            if every is not None and (new is None or every.n_pulses > new.n_pulses):
                new = every
        if new is not None and new.n_pulses >= 3:
            return new, True
        return None, False

    def _process(self, k: int, final: bool) -> None:
        """Analyse block ``k``: read its segment, detect, learn the template (or reuse it, see
        :meth:`_reuse`), refine the pulses the block owns and keep the onsets not already
        found."""
        opt = self.opt
        w_d, h_half, kk, margin = self._geom()
        lo, hi, gaps, yd = self._segment(k, final, w_d, min(margin, self.block_len))
        spacing = (opt.min_spacing if opt.min_spacing is not None else 2.0 * self.width)
        # a block that can hold DENSE_PULSES pulses at the minimum spacing: numba run maxima
        fast = dense(opt.engine, yd.size * self.decimation / spacing)
        peaks, *_ = coarse_decimated(yd, w_d, spacing / self.decimation, opt.k_sigma, fast)
        if peaks.size == 0:
            return
        bad_runs = merge_runs(np.concatenate([gaps, opt.flag_runs]))
        period = pulse_period(peaks)
        reused = self._reuse(period)
        if reused:
            tpl, fallback = self.template, False
        else:
            tpl, fallback = self._learn_block(yd, peaks, lo, self.decimation, w_d, h_half, kk, bad_runs)
        if tpl is None:
            logger.info("%sblock %d: %d coarse detection(s) but no template could be learnt; "
                        "skipped", self._who(), k, peaks.size)
            return
        own = self._owned(k, final, peaks, lo, h_half)
        if own.size == 0:
            if not reused:                   # as a learnt block, without measuring the fit
                self.template = tpl
                self.n_fallback += int(fallback)
            return
        res = self._refine(yd, own, lo, tpl, kk, gaps, fallback)
        if reused and not self.fit.holds(res[2], res[4]):
            logger.debug("%sblock %d: pulses no longer fit the template (median NCC %.3f, "
                         "learnt at %.3f): re-learnt", self._who(), k,
                         good_median(res[2], res[4]), self.fit.ncc)
            tpl, fallback = self._learn_block(yd, peaks, lo, self.decimation, w_d, h_half, kk, bad_runs)
            if tpl is None:
                return
            res = self._refine(yd, own, lo, tpl, kk, gaps, fallback)
            reused = False
        if not reused:
            self._adopt(tpl, fallback, res, period)
        self._keep(*res, hi, gaps, tpl, spacing)

    def _reuse(self, period: float | None) -> bool:
        """``relearn="auto"``: keep the template learnt in an earlier block when the speed
        (pulse period of this block) moved it by less than ``_SHIFT_TOL`` of the timing bound;
        the shape check follows the refinement (:meth:`TemplateFit.holds`)."""
        if self.opt.relearn != "auto" or self.fit is None or self.template is None:
            return False
        return self.fit.speed_holds(period)

    def _adopt(self, tpl: Template, fallback: bool, res, period: float | None) -> None:
        """Make ``tpl`` the current template; a newly learnt one (not a fallback) also
        becomes the reference of the fit checks and sets the width for the next block."""
        self.template = tpl
        if fallback:
            self.n_fallback += 1
            return
        if self.opt.template is None:
            self.width = tpl.fwhm * self.opt.fs
            if self.opt.relearn == "auto" and res is not None:
                self.fit = TemplateFit.measure(tpl, res[2], res[4], period)

    def _segment(self, k: int, final: bool, w_d: float, margin: int):
        """Block ``k`` with ``margin`` samples before it, polarity-corrected and decimated:
        (lo, hi, gaps, yd), ``[lo, hi)`` the full-rate samples read, ``gaps`` their
        non-finite runs."""
        d = self.decimation
        if w_d < 4 and d > 1 and not self.warned_width:
            self.warned_width = True
            warnings.warn(f"{self._who()}pulse width fell to {w_d:.2g} decimated samples "
                          f"(decimation {d}); timing degrades: pass a smaller decimation or "
                          "split the recording by operating point", ProcessingWarning, stacklevel=5)
        lo = max(0, k * self.block_len - margin)
        lo -= lo % d
        hi = self._block_hi(k, final)
        seg = self._get(lo, hi)
        gaps = np.empty((0, 2), dtype=np.int64)
        if d > 1:
            # a non-finite sample makes its block mean non-finite: one check on the
            # decimated samples (and the dropped tail) instead of one over all of them
            yd = decimate(seg, d, self.polarity)
            if math.isfinite(float(np.sum(yd))) and math.isfinite(float(np.sum(seg[yd.size * d:]))):
                return lo, hi, gaps, yd
        if not math.isfinite(float(np.sum(seg))):
            gaps = find_runs(~np.isfinite(seg)) + lo
            seg = fill_nan(seg)
        if self.polarity < 0:
            seg = -seg
        return lo, hi, gaps, decimate(seg, d)

    def _owned(self, k: int, final: bool, peaks: np.ndarray, lo: int, h_half: int) -> np.ndarray:
        """The coarse maxima block ``k`` owns: in ``[kB - g, (k+1)B + g)`` (``g`` half a
        template); the overlap's duplicates are removed by :meth:`_keep`."""
        d = self.decimation
        is_last = (k + 1) * self.block_len >= self.n_fed if final else False
        g = h_half * d
        full = lo + peaks * d + (d - 1) // 2
        own = np.ones(peaks.size, dtype=bool)
        if k > 0:
            own &= full >= k * self.block_len - g
        if not is_last:
            own &= full < (k + 1) * self.block_len + g
        return peaks[own]

    def _refine(self, yd, peaks, lo, tpl: Template, kk: int, gaps, fallback: bool):
        """Matched-filter refinement of the pulses at ``peaks`` (decimated samples of ``yd``):
        (index [full-rate samples], amplitude, NCC, width [s], flags)."""
        opt = self.opt
        d = self.decimation
        k_ref = max(kk, 2)
        mt = self._matcher_for(tpl, k_ref, sublags(tpl.fwhm * opt.fs / d))
        L = mt.L
        if dense(opt.engine, peaks.size):
            *res, a = refine_pulses(yd, peaks, mt.anchor, k_ref, mt.u, mt.t_all, mt.e0,
                                    np.flatnonzero(mt.tensile), max(1, L // 10), lo, d, tpl.ref,
                                    d / opt.fs, opt.min_corr, FLAG_TEMPLATE if fallback else 0,
                                    FLAG_EDGE, FLAG_LOW_CORR)
            self._run_flags(res[4], a, a + (L + 1) * d, gaps)
            return tuple(res)
        start = peaks - mt.anchor - k_ref
        w, edge0 = gather_windows(yd, start, L + 2 * k_ref)
        lag, cmax, ncc, edge, wa, wmean = mt.match(w)
        pos_d = start + k_ref + lag                      # decimated position of template sample 0
        index = lo + (pos_d + tpl.ref) * d + (d - 1) / 2.0
        amp = cmax / mt.e0
        # pulse FWHM: samples above half the fitted amplitude inside the tensile lobe
        base = window_baseline(wa)
        half = base + 0.5 * amp
        count = np.zeros(peaks.size)
        for j in np.flatnonzero(mt.tensile):          # columns of the tensile lobe
            count += wa[:, j] > half
        width = count * (d / opt.fs)
        flags = np.zeros(peaks.size, dtype=np.uint8)
        flags[edge | edge0] |= FLAG_EDGE
        flags[ncc < opt.min_corr] |= FLAG_LOW_CORR
        if fallback:
            flags |= FLAG_TEMPLATE
        a = lo + np.floor(pos_d).astype(np.int64) * d
        self._run_flags(flags, a, a + (L + 1) * d, gaps)
        return index, amp, ncc, width, flags

    def _matcher_for(self, tpl: Template, k: int, u: int) -> Matcher:
        """The matcher of ``tpl`` at ``k`` lags and ``u`` sub-lags: built once and reused by
        the blocks that reuse the template (it is read-only; its shifted template columns
        are the costly part)."""
        m = self._matcher
        if m is None or m[0] is not tpl or m[1] != k or m[2] != u:
            m = self._matcher = (tpl, k, u, Matcher(tpl, k, u))
        return m[3]

    def _run_flags(self, flags, a, b, gaps) -> None:
        """Flag (in place) the pulse windows ``[a, b)`` [full-rate samples] that touch a
        gap (within the gap guard) or a clipped run."""
        opt = self.opt
        if len(gaps):
            flags[runs_overlap(a - opt.gap_guard, b + opt.gap_guard, gaps)] |= FLAG_GAP
        if len(opt.flag_runs):
            flags[runs_overlap(a, b, opt.flag_runs)] |= FLAG_CLIPPED

    def _keep(self, index, amp, ncc, width, flags, hi: int, gaps, tpl: Template, spacing: float) -> None:
        """Append the onsets inside the data, outside the gaps and after those of the
        previous blocks (overlapping ownership), in time order."""
        # ---- no onset inside a gap or outside the data
        keep = (index >= 0) & (index <= hi - 1)
        if len(gaps):
            inside = inside_runs(index, gaps)
            self.n_dropped_gap += int(inside.sum())
            keep &= ~inside
        cols = (index, amp, ncc, width, flags)
        if index.size > 1 and not np.all(index[1:] >= index[:-1]):
            order = np.argsort(index, kind="stable")
            order = order[keep[order]]
            cols = tuple(v[order] for v in cols)
        elif not keep.all():                        # in order already: the stable sort's order
            cols = tuple(v[keep] for v in cols)
        # ---- de-duplicate against the previous blocks (overlapping ownership): the onsets
        # are in time order, so the fresh ones are a tail
        i0 = int(np.searchsorted(cols[0], self.last_index + 0.5 * spacing, side="left"))
        index, amp, ncc, width, flags = (v[i0:] for v in cols) if i0 else cols
        if index.size:
            if not self.templates or self.templates[-1] is not tpl:
                self.templates.append(tpl)
            self.last_index = float(index[-1])
            self.out.append((index, ncc, amp if self.polarity > 0 else -amp, width, flags,
                             np.full(index.size, len(self.templates) - 1, dtype=np.int32)))


#: quantile of the smoothed signal whose excursion from the median decides the pulses' sign
POLARITY_QUANTILE = 0.999


def _auto_polarity(seg: np.ndarray, width: float) -> int:
    """The sign of the pulses' main lobe (+1 tensile, -1 compressive): the larger excursion
    from the median of the signal averaged over blocks of a quarter of the pulse ``width``
    [samples], at the 0.1 % / 99.9 % quantiles.

    The averaging keeps the lobes (a quarter width changes their height by a few per cent)
    and divides the noise by sqrt(width / 4), so the decision does not rest on the noise's
    tails: on the independent rig's pulse shape (compressive side lobes of 0.16 and 0.24 of
    the peak) at its ring gauge's duty (one pulse per 3.7 s), the raw quantiles (used
    before) chose the wrong sign in some blocks at 0 dB, and this rule chooses right in
    every block tried at 0 and 6 dB (``tests/processing/test_onsets.py``
    ``test_auto_polarity_holds_at_low_snr``).
    """
    d = max(1, int(width // 4)) if math.isfinite(width) else 1
    y = decimate(seg, d) if seg.size >= d else seg
    if y.size == 0:
        return 1
    y = y[:: max(1, y.size >> 16)]
    med = float(np.median(y))
    lo_q, hi_q = np.quantile(y, [1.0 - POLARITY_QUANTILE, POLARITY_QUANTILE])
    return 1 if hi_q - med >= med - lo_q else -1


def detect_onsets(x, fs: float, *, t0: float = 0.0, width: float | None = None,
                  mesh_freq: float | None = None, min_spacing: float | None = None,
                  template: Template | None = None, relearn: str = "auto",
                  polarity: str | None = None, reference: str = "rise", level: float = 0.5,
                  k_sigma: float = 5.0, min_corr: float = 0.5, block: float | None = None,
                  decimation: int | None = None, max_template_pulses: int = 256,
                  min_template_pulses: int = 8, n_align: int = 2, flag_runs=None,
                  gap_guard: float = 0.0, channel: str | None = None, gap_runs=None,
                  engine: str = "auto") -> Onsets:
    """Engagement onsets of the pulses in one conditioned strain channel.

    Parameters
    ----------
    x : array_like, shape (n,)
        Conditioned samples (drift removed, see :mod:`meshphase.signal.condition`) [data units];
        NaN/inf mark gaps. float32 or float64.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of the first sample [s].
    width : float, optional
        Tensile full width at half maximum of the pulses [s]; default: estimated from the
        first analysis block (see :func:`estimate_pulse_width`), or from ``mesh_freq``.
    mesh_freq : float, optional
        Mesh frequency [Hz]: initial width guess ``0.8 / mesh_freq`` (refined on the data).
    min_spacing : float, optional
        Minimum time between two pulses [s]; default twice the width.
    template : Template, optional
        A fixed template (e.g. from :func:`learn_template` or an earlier run); no learning.
    relearn : {"auto", "block", "never"}
        ``"auto"``: learn the template once per operating point and reuse it in later
        analysis blocks while their pulses fit it: re-learnt when the pulse period changed
        enough to move the onset by a tenth of the per-pulse timing bound, or when the
        median correlation fell (see :mod:`meshphase.onsets.relearn`). ``"block"``:
        re-learn in every analysis block (the former default, for comparison).
        ``"never"``: learn once from the first block with enough pulses.
    polarity : {"positive", "negative", "auto"}, optional
        Sign of the pulses' main lobe in ``x`` (negative: a gauge on the compressive fillet,
        or a bridge wired the other way round); default "auto" (the template's when one is
        given; otherwise the larger excursion of the first block, averaged over a quarter
        pulse width, ``_auto_polarity``). Onset amplitudes carry the sign.
    reference : {"rise", "peak"}
        Onset feature of the template (see :mod:`meshphase.onsets`).
    level : float
        Level of the "rise" feature, fraction of the tensile peak [-], in [0, 1).
    k_sigma : float
        Coarse threshold in robust noise standard deviations of the smoothed signal [-].
    min_corr : float
        Normalised correlation below which an onset is flagged ``FLAG_LOW_CORR`` and a pulse
        is left out of the template [-].
    block : float, optional
        Analysis block length [s] (default 2**20 samples; at least 4 pulse windows). The
        template is learnt or checked per block (``relearn``); results do not depend on how
        data are chunked.
    decimation : int, optional
        Block-mean decimation factor (default ``max(1, floor(w / 16))`` samples).
    max_template_pulses, min_template_pulses : int
        Pulses averaged into a template at most; fewer clean pulses than the minimum in a
        block make it re-use the previous template (``FLAG_TEMPLATE``).
    n_align : int
        Alignment iterations when learning a template.
    flag_runs : array_like of int, shape (k, 2), optional
        ``[start, stop)`` sample ranges (relative to the first sample) to flag as
        ``FLAG_CLIPPED`` (e.g. ``ChannelQuality.clipped_runs``).
    gap_guard : float
        Pulses within this time of a gap are flagged ``FLAG_GAP`` too [s] (filter settling,
        ``ChannelQuality.settle``).
    channel : str, optional
        Channel name carried into the result and messages.
    gap_runs : array_like of int, shape (k, 2), optional
        ``[start, stop)`` sample ranges (relative to the first sample) that are gaps although
        their samples are finite (e.g. ``ChannelQuality.dropout_runs``: a DAQ writing zeros
        or holding its last value). Treated exactly as NaN samples: no onset inside, left
        out of template learning, touching pulses flagged ``FLAG_GAP``.
    engine : {"auto", "numba", "numpy"}
        Compiled per-pulse kernels (:mod:`meshphase.onsets.fastpath`): ``"auto"`` uses them
        for dense analysis blocks (``DENSE_PULSES`` pulses or more) when numba is
        importable, ``"numba"`` for every block, ``"numpy"`` never. The onsets agree to
        rounding (~1e-16 relative); ``meshphase bench processing`` measures both.

    Returns
    -------
    Onsets
        Always an :class:`Onsets`; empty arrays when no pulse is found.

    Notes
    -----
    See :mod:`meshphase.onsets` for the method and the onset definition. Measured timing
    jitter (``meshphase.bench.processing``, 400 pulses each): 0.95-1.14 times the
    Cramer-Rao bound at 10, 20 and 30 dB peak SNR for pulses of 80 and 574 samples FWHM,
    and at 20 and 30 dB for 2-sample pulses (mesh frequency 0.4 fs); constant feature
    offset below 0.2 samples (0.9 at 10 dB for 574-sample pulses). Pulses of only a few
    samples need >= ~15 dB to be detected at ``k_sigma = 5``.
    """
    arr = as_signal(x)
    opt = check_options(fs, t0=t0, width=width, mesh_freq=mesh_freq, min_spacing=min_spacing,
                        template=template, relearn=relearn, polarity=polarity, reference=reference,
                        level=level, k_sigma=k_sigma, min_corr=min_corr, block=block,
                        decimation=decimation, max_template_pulses=max_template_pulses,
                        min_template_pulses=min_template_pulses, n_align=n_align,
                        flag_runs=flag_runs, gap_guard=gap_guard, channel=channel, gap_runs=gap_runs,
                        engine=engine)
    eng = BlockEngine(opt)
    eng.feed(arr)
    return eng.finish()


def detect_onsets_recording(rec: Recording, channel: str, *, quality=None, **kwargs) -> Onsets:
    """:func:`detect_onsets` on one channel of a recording.

    Parameters
    ----------
    rec : Recording
        Conditioned recording.
    channel : str
        Channel name.
    quality : ChannelQuality, optional
        The channel's report from :mod:`meshphase.signal.condition`: its clipped runs are flagged
        (``FLAG_CLIPPED``), its dropout runs are gaps (``gap_runs``; already NaN in a
        recording conditioned with ``dropouts="nan"``) and its ``settle`` time is used as
        ``gap_guard``.
    **kwargs
        Passed to :func:`detect_onsets` (not ``fs``, ``t0``, ``channel``).

    Returns
    -------
    Onsets
    """
    x = recording_channel(rec, channel, quality, kwargs, "detect_onsets_recording")
    return detect_onsets(x, rec.fs, t0=rec.t0, channel=channel, **kwargs)

