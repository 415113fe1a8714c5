"""One JSON conversion for the whole package: numpy, paths and dates to plain JSON values.

Two policies for non-finite floats, because two kinds of JSON are written:

* results (``summary.json``, campaign tables, bench results): strict JSON, NaN and inf
  become ``null`` ("not computed" reads the same in every JSON reader);
* recording metadata (``meta``/``history`` in HDF5, MCAP, TDMS properties): lossless, the
  value is kept (Python's ``json`` writes ``NaN``/``Infinity`` and reads them back) or, for
  TDMS properties that must stay strict, written as its ``repr`` text.
"""

from __future__ import annotations

import datetime as _dt
import math
from pathlib import PurePath
from typing import Any

import numpy as np

__all__ = ["to_jsonable", "json_default", "NONFINITE"]

#: accepted values of ``nonfinite``
NONFINITE = ("null", "keep", "repr")


def _float(f: float, nonfinite: str):
    if math.isfinite(f) or nonfinite == "keep":
        return f
    return None if nonfinite == "null" else repr(f)


def to_jsonable(v: Any, *, nonfinite: str = "null") -> Any:
    """``v`` with every container, numpy value, path and date turned into JSON values.

    Parameters
    ----------
    v : Any
        dicts (keys become ``str``), lists, tuples, numpy arrays and scalars, floats,
        ``pathlib`` paths, ``datetime``/``date``/``numpy.datetime64`` (ISO 8601 text),
        ``bytes`` (UTF-8, else Latin-1 text). Anything else is returned as is (``json``
        then decides).
    nonfinite : {"null", "keep", "repr"}
        NaN and inf: ``None`` (strict JSON, the default), kept, or their ``repr`` text.

    Returns
    -------
    Any
    """
    if nonfinite not in NONFINITE:
        raise ValueError(f"nonfinite must be one of {NONFINITE}, got {nonfinite!r}")
    return _convert(v, nonfinite)


def _convert(v: Any, nonfinite: str) -> Any:
    if isinstance(v, dict):
        return {str(k): _convert(x, nonfinite) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_convert(x, nonfinite) for x in v]
    if isinstance(v, bool) or v is None or isinstance(v, (str, int)) and not isinstance(v, np.generic):
        return v
    if isinstance(v, np.ndarray):
        if v.dtype.kind == "M":
            return [_convert(x, nonfinite) for x in v]
        return _convert(v.tolist(), nonfinite)
    if isinstance(v, np.datetime64):
        return np.datetime_as_string(v.astype("datetime64[us]"), unit="us") + "+00:00"
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return _float(float(v), nonfinite)
    if isinstance(v, np.generic):
        return _convert(v.item(), nonfinite)
    if isinstance(v, PurePath):
        return str(v)
    if isinstance(v, (_dt.datetime, _dt.date)):
        return v.isoformat()
    if isinstance(v, bytes):
        try:
            return v.decode("utf-8")
        except UnicodeDecodeError:
            return v.decode("latin-1")
    return v


def json_default(obj: Any) -> Any:
    """``default=`` hook for :func:`json.dumps` (numpy values, paths, dates; NaN kept).

    Raises
    ------
    TypeError
        For any other type, naming it.
    """
    out = _convert(obj, "keep")
    if out is obj:
        raise TypeError(f"value of type {type(obj).__name__} is not JSON-serialisable: {obj!r:.80}")
    return out
