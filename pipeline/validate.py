"""Shared argument validation used at every public entry point.

Each helper raises ``ValueError`` for a bad value and ``TypeError`` for a bad type, with a
message naming the parameter and echoing the value, and returns the normalised value.
"""

from __future__ import annotations

import numbers
import os
import stat
from pathlib import Path
from typing import Any

import numpy as np

from .errors import NotRegularFileError

__all__ = [
    "as_float",
    "as_positive",
    "as_nonnegative",
    "as_int",
    "as_positive_int",
    "as_finite_array",
    "as_choice",
    "as_signal",
    "as_regular_file",
]


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def as_float(value: Any, name: str, *, finite: bool = True) -> float:
    """Return ``value`` as a Python float; reject non-numbers and (by default) NaN/inf."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.number)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {_short(value)}")
    out = float(value)
    if finite and not np.isfinite(out):
        raise ValueError(f"{name} must be finite, got {out!r}")
    return out


def as_positive(value: Any, name: str) -> float:
    """Return ``value`` as a finite float > 0."""
    out = as_float(value, name)
    if not out > 0.0:
        raise ValueError(f"{name} must be > 0, got {out!r}")
    return out


def as_nonnegative(value: Any, name: str) -> float:
    """Return ``value`` as a finite float >= 0."""
    out = as_float(value, name)
    if out < 0.0:
        raise ValueError(f"{name} must be >= 0, got {out!r}")
    return out


def as_int(value: Any, name: str) -> int:
    """Return ``value`` as a Python int; floats with a fractional part are rejected."""
    if isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be an integer, got bool {value!r}")
    if isinstance(value, (numbers.Integral, np.integer)):
        return int(value)
    if isinstance(value, (numbers.Real, np.floating)) and float(value).is_integer():
        return int(value)
    if isinstance(value, (numbers.Real, np.floating)):
        raise ValueError(f"{name} must be a whole number, got {value!r}")
    raise TypeError(f"{name} must be an integer, got {type(value).__name__} {_short(value)}")


def as_positive_int(value: Any, name: str) -> int:
    """Return ``value`` as an int >= 1."""
    out = as_int(value, name)
    if out < 1:
        raise ValueError(f"{name} must be a positive integer, got {out!r}")
    return out


def as_finite_array(value: Any, name: str, *, ndim: int | None = None, dtype=np.float64,
                    allow_empty: bool = True) -> np.ndarray:
    """Return ``value`` as a float array with only finite entries.

    Parameters
    ----------
    value : array_like
        Input values.
    name : str
        Parameter name used in error messages.
    ndim : int, optional
        Required number of dimensions.
    dtype : numpy dtype
        Output dtype (float64 by default).
    allow_empty : bool
        Whether a zero-size array is accepted.
    """
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be numeric array_like, got {_short(value)}") from exc
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {arr.shape}")
    if not allow_empty and arr.size == 0:
        raise ValueError(f"{name} must not be empty")
    if arr.size and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise ValueError(f"{name} must be finite, got {bad} non-finite value(s)")
    return arr


def as_choice(value: Any, name: str, choices) -> str:
    """Return ``value`` if it is one of ``choices`` (strings), else raise ValueError."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a string, one of {sorted(choices)}, got {_short(value)}")
    if value not in choices:
        raise ValueError(f"{name} must be one of {sorted(choices)}, got {value!r}")
    return value


def as_signal(value: Any, name: str = "x", *, float64: bool = False) -> np.ndarray:
    """One channel of samples as a 1-D numeric array; NaN/inf allowed (they are data-quality
    findings, not errors). ``float64`` converts (no copy when already float64)."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D (one channel), got shape {arr.shape}")
    return arr.astype(np.float64, copy=False) if float64 else arr


_FILE_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
               (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
               (stat.S_ISSOCK, "a socket"))


def as_regular_file(value: Any, name: str) -> Path:
    """Return ``value`` as a Path to an existing regular file, without opening it.

    Checked with ``os.stat`` only, so a FIFO, a device or a socket is refused before anything
    could block reading it; symbolic links are followed (a link to a regular file is fine).

    Raises
    ------
    TypeError
        ``value`` is not a str or os.PathLike.
    FileNotFoundError
        Nothing exists at the path (or a dangling link).
    IsADirectoryError
        The path is a directory.
    NotADirectoryError
        A part of the path is a file.
    NotRegularFileError
        The path is a FIFO, a device or a socket (the message says which; a ValueError).
    ValueError
        The path is empty.
    OSError
        ``os.stat`` failed otherwise (permission on a parent folder, a symbolic-link loop,
        a name too long ...); the same class with its errno and the file name, the message
        naming ``name``.
    """
    if not isinstance(value, (str, os.PathLike)):
        raise TypeError(f"{name} must be a path (str or Path), got {type(value).__name__} {_short(value)}")
    if not os.fspath(value):
        raise ValueError(f"{name} must be a file path, got an empty path {value!r}")
    path = Path(value)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such file ({name})") from None
    except OSError as exc:
        if exc.errno is None:
            raise
        # ELOOP ("Too many levels of symbolic links"), ENAMETOOLONG, EACCES, ENOTDIR ...
        raise type(exc)(exc.errno, f"{exc.strerror or os.strerror(exc.errno)} ({name})",
                        str(path)) from None
    if stat.S_ISREG(st.st_mode):
        return path
    kind = next((k for test, k in _FILE_KINDS if test(st.st_mode)), "not a regular file")
    if kind == "a directory":
        raise IsADirectoryError(f"{path}: is a directory; {name} must be a file")
    raise NotRegularFileError(path, kind, name)
