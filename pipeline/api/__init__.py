"""The Python face of meshphase: :func:`~meshphase.api.process.process` a recording (or a file)
with a scene built from what a notebook user has at hand, and look at the
:class:`~meshphase.api.result.Result` as pandas DataFrames and figures.

May import :mod:`meshphase.run` and everything below it; nothing in the package imports it
except the command line and the package's top-level lazy names (``meshphase.process``).
"""
