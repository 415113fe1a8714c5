"""Old names of renamed model parameters: accepted, translated, announced.

A gear engineer's old call (``SinglePinion(beta_1=...)``, ``DoublePinion(beta=...)``) keeps
working with a :class:`~meshphase.errors.DeprecatedNameWarning` that names the new parameter.
"""

from __future__ import annotations

import functools
import warnings

from ..errors import DeprecatedNameWarning


def translate(kwargs: dict, renames: dict, owner: str, stacklevel: int = 3) -> dict:
    """Return ``kwargs`` with old keys replaced by new ones (one warning naming them all).

    Raises TypeError when both an old name and its new name are given.
    """
    out = dict(kwargs)
    used = []
    for old, new in renames.items():
        if old in out:
            if new in out:
                raise TypeError(f"{owner}: give {new!r} only ({old!r} is its old name), got both")
            out[new] = out.pop(old)
            used.append(f"{old!r} is renamed {new!r}")
    if used:
        warnings.warn(f"{owner}: {', '.join(used)} (same value and unit); the old names will be "
                      "removed", DeprecatedNameWarning, stacklevel=stacklevel)
    return out


def accept_old_names(cls, renames: dict):
    """Let a dataclass take and read its renamed fields under the old names (with a warning)."""
    init = cls.__init__

    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        init(self, *args, **translate(kwargs, renames, cls.__name__))

    def __getattr__(self, name):   # only called when normal lookup fails
        if name in renames:
            warnings.warn(f"{cls.__name__}.{name} is renamed {renames[name]!r}; the old name will "
                          "be removed", DeprecatedNameWarning, stacklevel=2)
            return getattr(self, renames[name])
        raise AttributeError(f"{cls.__name__!r} object has no attribute {name!r}")

    cls.__init__ = __init__
    cls.__getattr__ = __getattr__
    cls.renamed_fields = dict(renames)
    return cls


def renamed_kwargs(renames: dict):
    """Decorator: a function also takes its renamed keyword arguments under the old names."""
    def deco(fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            return fn(*args, **translate(kwargs, renames, fn.__name__))
        return wrapper
    return deco
