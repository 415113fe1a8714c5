"""From onsets to measured phasing: the kinematic angle model of a recording (carrier, sun,
ring and planet angles as smooth functions of time, with encoders and tachos as angle
observations), the pass selection of each gauge, the measured sun-planet and ring-planet mesh
phasing with its uncertainty, the pass rates, the member speeds and the planet loads.

May import :mod:`meshphase.onsets`, :mod:`meshphase.signal`, :mod:`meshphase.models`,
:mod:`meshphase.runtime` and the root helpers; knows nothing of files, scenes or reports.
"""
