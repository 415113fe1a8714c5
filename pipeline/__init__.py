"""meshphase: planetary gear test-rig strain recordings -> measured mesh phasing.

The Python API: :func:`read` a recording, :func:`process` it into a :class:`Result`
(:mod:`meshphase.api.process`). ``read``, ``process`` and ``Result`` are imported on first use, so
``import meshphase`` stays light. The core (this package without :mod:`meshphase.report`)
never imports matplotlib.
"""

from __future__ import annotations

from .errors import (ConvergenceWarning, DataQualityWarning, FormatWarning, MeshphaseWarning,
                     ModelWarning, ProcessingWarning)
from .runtime.log import logger
from .recording import ChannelSpec, Recording, CHANNEL_KINDS

from .version import __version__

#: names imported on first use: name -> module that holds it
_LAZY = {"read": "meshphase.io", "process": "meshphase.api.process", "Result": "meshphase.api.result",
         "ProcessingFailed": "meshphase.api.process"}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'meshphase' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "read", "process", "Result", "ProcessingFailed",
    "Recording", "ChannelSpec", "CHANNEL_KINDS", "logger", "__version__",
    "MeshphaseWarning", "DataQualityWarning", "FormatWarning", "ModelWarning",
    "ConvergenceWarning", "ProcessingWarning",
]
