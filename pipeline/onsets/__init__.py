"""Engagement onsets of tooth-root strain pulses, to a fraction of a sample.

A strain gauge at a tooth root sees one pulse per engagement: a compressive lobe, a tensile
peak while the tooth carries load, a compressive lobe. This module finds those pulses and
times each one with a matched filter against a pulse template learnt from the recording.

Onset definition (amplitude independent)
----------------------------------------
Every pulse is timed by its best-fitting shift of the template (maximum of the
cross-correlation with the zero-mean template; amplitude and baseline drop out). The onset
is then a fixed feature *of the template*, carried over to each pulse by that shift:

- ``reference="rise"`` (default), ``level=0.5``: the leading-edge crossing of ``level``
  times the tensile peak height above the baseline (the leading-edge half-amplitude point);
  ``level`` closer to 0 approaches the contact start at the cost of a flatter, noisier edge.
- ``reference="peak"``: the tensile peak of the template.

A fixed threshold on the signal would walk with load and with each planet's share of it;
this feature does not: scaling a pulse changes its amplitude estimate, not its onset.
Phasing only uses differences of onsets within a pass, so the constant offset between this
feature and the physical contact start cancels.

Pipeline (per analysis block, vectorised)
-----------------------------------------
1. Block-mean decimation by ``D = max(1, floor(w / 16))`` (``w`` the tensile full width at
   half maximum in samples): at >= 16 samples per pulse width it keeps essentially all the
   timing information and makes the rest of the work ``D`` times cheaper.
2. Coarse detection: moving average over ``w / 2``, threshold ``median + k_sigma * noise``
   (MAD noise of the pulse-free parts: +-1.5 w around strong maxima masked, because pulses
   every ~8 widths would otherwise inflate a plain MAD), runs above it merged within
   ``min_spacing``, one maximum per run.
3. Template learning, once per operating point (``relearn="auto"``: a later block keeps
   the template while its pulse period and correlations still fit it, see
   :mod:`meshphase.onsets.relearn`; ``"block"`` learns in every block), from the block's own clean pulses: windows around the coarse
   maxima, aligned to sub-sample precision against the running template (Fourier shifts)
   and averaged with least-squares amplitude weights; baseline 0, tensile peak 1, tapered.
   Its peak and level crossings are located by local least-squares fits (not by the noisy
   maximum), see :mod:`meshphase.onsets.features`.
4. Refinement of every detection: correlation with the zero-mean template at lags
   ``-K..K`` in steps of ``1/U`` (one BLAS product with a Toeplitz matrix of shifted
   templates; ``U = ceil(4 / w_D)``, i.e. > 1 only for pulses a few samples wide, whose
   fractional shifts are band-limited FFT shifts) and parabolic interpolation of the
   correlation peak.

The first block also estimates ``w`` (autocorrelation, then the FWHM of a first template)
unless ``width`` or ``template`` is given; later blocks take ``w`` from the previous block's
template, so the detector follows slow speed changes. Blocks are processed with margins
and a fixed grid, so a recording fed whole or as a stream of chunks of any size gives
bit-identical onsets (:func:`detect_onsets_stream`).

Quality per onset: normalised correlation with the template, amplitude (signed, in data
units: the fitted tensile peak above baseline), width (FWHM measured on the pulse) and a
bit mask of flags (``FLAG_*``). No onset is ever placed inside a gap (NaN samples, or the
``gap_runs`` of a quality report's dropouts).

Detectors
---------
The matched filter above is one onset detector, registered as ``"matched"`` (the default);
others are registered by name (:func:`register_detector`) and chosen by a scene's
``[onsets] detector``. Every detector is a block filter returning :class:`Onsets` with a
timing model (timing centres and per-onset uncertainties, :mod:`meshphase.onsets.timing`),
which is all the passes and the phasing use.

Modules
-------
``detector``   the detector interface (:class:`OnsetDetector`), the registry by name and
               :func:`detect_recording`
``results``    the result types (:class:`CoarsePeaks`, :class:`Onsets`) and the ``FLAG_*`` bits
``timing``     the timing model of onsets (:class:`OnsetTiming`) and the matched filter's
               (:class:`TemplateTiming`: timing centres, Cramer-Rao uncertainties)
``template``   the matched filter's pulse template (:class:`Template`)
``coarse``     step 1 and 2: decimation, robust noise level, coarse maxima (:func:`coarse_peaks`)
``learning``   step 3: template learning (:func:`learn_template`) and the pulse width
               (:func:`estimate_pulse_width`); ``features`` measures a template
``relearn``    when a learnt template is kept for the next block (speed and shape checks)
``matched``    step 4: matched-filter refinement at (sub-)sample lags
``fastpath``   the numba kernels of steps 2 and 4 for dense pulse trains (``engine``), and
               the rule that chooses them (``_numba_kernels`` holds the kernels)
``engine``     the block engine and :func:`detect_onsets`, :func:`detect_onsets_recording`;
               ``options`` checks their keywords, ``runs`` handles gap and flag runs
``streaming``  :class:`OnsetStream` (the matched-filter detector), :func:`detect_onsets_stream`

The package imports the root helpers, :mod:`meshphase.runtime` and :mod:`meshphase.signal`
only.
"""

from .coarse import coarse_peaks
from .detector import (DEFAULT_DETECTOR, OnsetDetector, check_detector, detect_recording,
                       detector_names, make_detector, register_detector, unregister_detector)
from .engine import detect_onsets, detect_onsets_recording
from .learning import estimate_pulse_width, learn_template
from .options import DEFAULT_BLOCK
from .results import (FLAG_CLIPPED, FLAG_EDGE, FLAG_GAP, FLAG_LOW_CORR, FLAG_NAMES, FLAG_TEMPLATE,
                      CoarsePeaks, Onsets, empty_onsets)
from .streaming import OnsetStream, detect_onsets_stream
from .template import Template
from .timing import ONSET_RESOLUTION, OnsetTiming, TemplateTiming

__all__ = [
    "Onsets", "Template", "CoarsePeaks", "detect_onsets", "detect_onsets_recording",
    "detect_onsets_stream", "OnsetStream", "learn_template", "coarse_peaks", "estimate_pulse_width",
    "FLAG_GAP", "FLAG_CLIPPED", "FLAG_LOW_CORR", "FLAG_EDGE", "FLAG_TEMPLATE", "FLAG_NAMES",
    "empty_onsets", "OnsetDetector", "DEFAULT_DETECTOR", "register_detector", "unregister_detector",
    "detector_names", "check_detector", "make_detector", "detect_recording", "OnsetTiming",
    "TemplateTiming", "ONSET_RESOLUTION", "DEFAULT_BLOCK",
]
