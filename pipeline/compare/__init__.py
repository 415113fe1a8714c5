"""Measured phasing held against the models: the model's prediction at each measured pass,
residuals and band coverage, the identification of shaft-hole position errors from the
residuals, and the comparison with a synthetic recording's truth.

May import :mod:`meshphase.kinematics` (the pass tables), :mod:`meshphase.models` and the root
helpers; never run, report or io.
"""
