"""The TDMS writers of synthetic recordings: those of :mod:`meshphase.io.tdms_write`.

:func:`write_tdms` (npTDMS segments, one per generated block, flat memory) and
:func:`write_ni_log` (the small-segment layout of NI-DAQmx logging) are the tdms format's
writers; the synthetic generator and its tests use them from here as well.
"""

from __future__ import annotations

from meshphase.io.tdms_write import LABVIEW_ZERO, write_ni_log, write_tdms

__all__ = ["write_tdms", "write_ni_log", "LABVIEW_ZERO"]
