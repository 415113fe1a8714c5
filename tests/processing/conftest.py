"""Pulse trains with known truth for the conditioning and onset tests.

The trains are generated in code with :mod:`meshphase.bench.processing` (a sin^2 tensile
lobe of ``contact_ratio`` mesh periods between two compressive lobes, per-planet amplitudes,
load drift, jittered spacing, white noise of a given peak SNR); the end-to-end scenarios of
``synthetic/`` are tested elsewhere.
"""

import numpy as np
import pytest

from meshphase.bench.processing import PulseShape, pulse_scenario

FS = 5120.0


def make_train(*, mesh_samples=40.0, spacing_samples=240.0, n_pulses=60, snr_db=20.0,
               rng=0, bandlimit=None, level=0.5, dtype=np.float64, **kw):
    """(x, truth, shape) for a train of ``n_pulses`` pulses at FS.

    ``mesh_samples`` is the mesh period in samples (tensile FWHM = 0.8 of it);
    truth["onset"] holds the half-rise times [s] (``level``) that detect_onsets reports.
    """
    shape = PulseShape(mesh_samples / FS, bandlimit=bandlimit, fs=FS if bandlimit else None)
    n = int(np.ceil((n_pulses + 5) * spacing_samples))
    x, truth = pulse_scenario(n, FS, shape, spacing_samples / FS, snr_db=snr_db, rng=rng,
                              level=level, dtype=dtype, **kw)
    return x, truth, shape


@pytest.fixture(scope="session", name="make_train")
def make_train_fixture():
    """The :func:`make_train` helper, as a fixture (test modules must not ``import
    conftest``: with several conftest.py files that name is ambiguous)."""
    return make_train
