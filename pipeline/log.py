"""The one package logger (``logging.getLogger("meshphase")``)."""

from __future__ import annotations

import logging

logger = logging.getLogger("meshphase")
logger.addHandler(logging.NullHandler())

__all__ = ["logger"]
