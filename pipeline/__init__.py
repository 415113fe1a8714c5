"""meshphase: planetary gear test-rig strain recordings -> measured mesh phasing.

The core (this package without :mod:`meshphase.report`) never imports matplotlib.
"""

from __future__ import annotations

from .errors import (ConvergenceWarning, DataQualityWarning, FormatWarning, MeshphaseWarning,
                     ModelWarning, ProcessingWarning)
from .log import logger
from .recording import ChannelSpec, Recording, CHANNEL_KINDS

__version__ = "0.1.0"

__all__ = [
    "Recording", "ChannelSpec", "CHANNEL_KINDS", "logger", "__version__",
    "MeshphaseWarning", "DataQualityWarning", "FormatWarning", "ModelWarning",
    "ConvergenceWarning", "ProcessingWarning",
]
