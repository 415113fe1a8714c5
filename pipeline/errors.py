"""Warning classes of meshphase.

Every silent-looking fallback in the package (unscaled data, a skipped channel, a NaN run
kept in the data, a pass that could not be measured) is announced with one of these classes
so that a user can filter, log or escalate them (``warnings.simplefilter("error",
MeshphaseWarning)``). Errors are plain ``ValueError`` / ``TypeError`` with a message that
names the parameter (or file) and echoes the value.
"""

from __future__ import annotations

__all__ = [
    "MeshphaseWarning",
    "DataQualityWarning",
    "FormatWarning",
    "ModelWarning",
    "ConvergenceWarning",
    "ProcessingWarning",
    "SceneWarning",
    "DeprecatedNameWarning",
]


class MeshphaseWarning(UserWarning):
    """Base class of every warning issued by meshphase."""


class DataQualityWarning(MeshphaseWarning):
    """The samples carry something a user must know about: NaN/inf runs, gaps, clipping."""


class FormatWarning(MeshphaseWarning):
    """A file was readable but something in it was missing or unusual (e.g. no scaling)."""


class ModelWarning(MeshphaseWarning):
    """A model was evaluated outside the range where it is accurate or meaningful."""


class ConvergenceWarning(ModelWarning):
    """An iterative solver stopped before its tolerance; the residual is reported."""


class ProcessingWarning(MeshphaseWarning):
    """A processing stage produced a partial result (missing pass, unassigned pulse...)."""


class SceneWarning(MeshphaseWarning):
    """A scene value that is valid but worth a second look before the run (e.g. a Monte Carlo
    that will take a long time); the message names the file, the key and the line."""


class DeprecatedNameWarning(MeshphaseWarning, FutureWarning):
    """A renamed parameter, attribute or scene key was used under its old name. It still
    works; the message names the new one (a FutureWarning, so it shows by default)."""
