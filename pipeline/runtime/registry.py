"""Named plug-ins: registries that map names to factories, and the registry of onset
detectors (:data:`ONSET_DETECTORS`).

A registry's built-in entries are import paths (``"package.module:attribute"``), loaded on
first use, so that checking a name a configuration gives (a scene's ``[onsets] detector``,
read at start-up) imports none of the heavy modules behind it. Entries registered at run
time are the factories themselves. This module imports the standard library only.
"""

from __future__ import annotations

import importlib
from typing import Callable

__all__ = ["Registry", "ONSET_DETECTORS", "DEFAULT_ONSET_DETECTOR"]


class Registry:
    """Factories by name.

    Parameters
    ----------
    kind : str
        What the factories build, for messages ("onset detector").
    builtins : dict of str to str
        Names that are always there, each with the ``"module:attribute"`` import path of its
        factory; they can be neither replaced nor removed.
    """

    def __init__(self, kind: str, builtins: dict[str, str]):
        self.kind = kind
        self._builtins = dict(builtins)
        self._added: dict[str, Callable] = {}

    def names(self) -> tuple[str, ...]:
        """The registered names, sorted."""
        return tuple(sorted({**self._builtins, **self._added}))

    def check(self, name) -> str:
        """``name`` when registered; else a ValueError listing the known names (TypeError
        when ``name`` is not a string)."""
        if not isinstance(name, str):
            raise TypeError(f"{self.kind} must be a name (str), got {type(name).__name__}")
        if name not in self._builtins and name not in self._added:
            raise ValueError(f"unknown {self.kind} {name!r}; known: {', '.join(self.names())}")
        return name

    def register(self, name: str, factory: Callable, *, replace: bool = False) -> None:
        """Register ``factory`` as ``name`` (``replace``: over an earlier registration).

        Raises
        ------
        TypeError
            ``name`` is not a string or ``factory`` is not callable.
        ValueError
            ``name`` is empty or built in, or taken and ``replace`` is False.
        """
        if not isinstance(name, str):
            raise TypeError(f"{self.kind} name must be a string, got {type(name).__name__}")
        if not name.strip():
            raise ValueError(f"{self.kind} name must not be empty")
        if not callable(factory):
            raise TypeError(f"factory must be callable, got {type(factory).__name__}")
        if name in self._builtins:
            raise ValueError(f"{name!r} is a built-in {self.kind} and cannot be replaced")
        if name in self._added and not replace:
            raise ValueError(f"a {self.kind} called {name!r} is registered already (replace=True "
                             "to replace it)")
        self._added[name] = factory

    def unregister(self, name: str) -> None:
        """Remove the registration of ``name`` (ValueError for a built-in or unknown one)."""
        if self.check(name) in self._builtins:
            raise ValueError(f"{name!r} is a built-in {self.kind} and cannot be removed")
        del self._added[name]

    def factory(self, name: str) -> Callable:
        """The factory of ``name`` (a built-in one imported now, on first use)."""
        self.check(name)
        if name in self._added:
            return self._added[name]
        module, _, attr = self._builtins[name].partition(":")
        return getattr(importlib.import_module(module), attr)


#: the onset detector a scene uses unless its ``[onsets] detector`` names another
DEFAULT_ONSET_DETECTOR = "matched"

#: onset detectors by name (:mod:`meshphase.onsets.detector`): the matched filter built in
ONSET_DETECTORS = Registry("onset detector",
                           {DEFAULT_ONSET_DETECTOR: "meshphase.onsets.streaming:OnsetStream"})
