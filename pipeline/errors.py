"""Warning and exception classes of meshphase.

Every silent-looking fallback in the package (unscaled data, a skipped channel, a NaN run
kept in the data, a pass that could not be measured) is announced with one of the warning
classes so that a user can filter, log or escalate them (``warnings.simplefilter("error",
MeshphaseWarning)``).

Errors name the parameter (or file) and echo the value. The Python API (``meshphase.read``,
``meshphase.process``, :mod:`meshphase.io`) and the ``meshphase`` command run the same checks
on an input path (:func:`meshphase.validate.as_regular_file`, by ``os.stat`` before anything
opens the file) and raise the same classes; the command turns each into one line and exit 1::

    TypeError                  an argument of the wrong type
    ValueError                 a bad value (the message names the parameter)
    +-- NotRegularFileError    an input path that is a FIFO, a device or a socket (refused
    |                          before opening it: reading it could block)
    +-- SceneError             a scene that does not validate (meshphase.run.scene)
    +-- RecordingFileError     a recording file that cannot be read as what it claims to be:
    |   |                      empty, unknown format, inconsistent (meshphase.io)
    |   +-- CorruptFileError   damaged bytes: checksum, truncation, malformed row
    |   +-- RecordingTooLargeError  (also a MemoryError) its samples do not fit in memory
    +-- ProcessingFailed       meshphase.process: nothing usable came out of the run
    OSError                    the file system, with errno and file name kept:
    +-- FileNotFoundError      no such file (or a dangling symbolic link)
    +-- IsADirectoryError      a folder where a file is expected
    +-- NotADirectoryError     a part of the path is a file
    +-- PermissionError        no permission
    +-- (errno ELOOP, ENAMETOOLONG, ENOSPC, ...)  a symbolic-link loop, a name too long, a
                               full disk; the message names the file
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
    "NotRegularFileError",
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


class NotRegularFileError(ValueError):
    """An input path names a FIFO, a device or a socket where a regular file is expected
    (refused by ``os.stat`` before anything opens it: reading a pipe or device could block).

    Attributes
    ----------
    path : str
    kind : str
        What the path is: ``"a FIFO (named pipe)"``, ``"a character device"``, ...
    """

    def __init__(self, path, kind: str, name: str):
        self.path = str(path)
        self.kind = kind
        super().__init__(f"{path}: is {kind}, not a regular file; {name} must be a file "
                         "(refused before opening it: reading a pipe or device could block)")
