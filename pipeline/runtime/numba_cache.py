"""Where meshphase's numba kernels are cached, and their import on first use.

numba is optional (extras "fast" and "test"). Its kernels (the Monte Carlo's in
:mod:`meshphase.models._kernels_numba`, the onsets' in :mod:`meshphase.onsets._numba_kernels`)
compile with ``cache=True`` into a per-user directory, so that a read-only or empty cache
beside the installed source never costs a compilation at every first use.
"""

from __future__ import annotations

import importlib
import os
import sys

__all__ = ["numba_cache_dir", "import_kernels"]


def numba_cache_dir() -> str:
    """Where numba caches the compiled kernels: ``NUMBA_CACHE_DIR`` when set, else
    ``$XDG_CACHE_HOME/meshphase/numba`` (``~/.cache/meshphase/numba``): per user, writable,
    not beside the installed source (an empty or read-only cache there cost 4-5 s of
    compilation at every first use)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return env
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "meshphase", "numba")


def import_kernels(module: str):
    """The numba kernel module ``module`` (absolute name), imported on first use with the
    per-user cache set.

    Raises
    ------
    ImportError
        numba is installed but the module cannot be imported (a broken numba install); the
        message names the cause.
    """
    if module not in sys.modules:
        os.environ.setdefault("NUMBA_CACHE_DIR", numba_cache_dir())
    try:
        return importlib.import_module(module)
    except Exception as exc:  # pragma: no cover - a broken numba install
        raise ImportError(f"{module or repr(module)} does not import ({exc!r})") from exc
