"""Conditioning of tooth-root strain channels and their quality: zero-phase filters (second-order
sections), drift and hum removal, Savitzky-Golay smoothing, spectra, the noise floor of the
pulses and the Cramér-Rao bound on their timing, and the data-quality flags (NaN runs, clipping,
gaps, dropouts). Every conditioning step is a block filter (:mod:`meshphase.signal.blocks`:
push blocks, flush the rest), the whole-array functions of :mod:`meshphase.signal.condition`
push the whole array through the same filters.

Array code: numpy in, numpy out, samples and SI units. May import :mod:`meshphase.runtime`,
:mod:`meshphase.recording` and the root helpers; never onsets, kinematics or anything above.
"""
