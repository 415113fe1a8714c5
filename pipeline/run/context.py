"""A run's state: the typed results of the stages that ran (:class:`RunContext`), what did not
run and why, the warnings raised, and the phasing verdict read from them.

The result slots (``ctx.load``, ``ctx.phasing``, ...) and the result type each stage records
come from the stage registry (:data:`meshphase.run.declare.STAGE_REGISTRY`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Generic, TypeVar

from ..models.gearset import Gearset
from . import results
from .declare import STAGE_REGISTRY, check_registry
from .results import PhasingStage, StageResult
from .state import RunMessage, StageFailure

__all__ = ["RunContext", "phasing_verdict", "result_types", "RESULT_TYPES"]

_R = TypeVar("_R", bound=StageResult)


def result_types(registry=STAGE_REGISTRY) -> dict[str, type]:
    """stage -> the type of the result it records (a declared name resolved in
    :mod:`meshphase.run.results`).

    Raises
    ------
    TypeError
        A declared type that is not a :class:`StageResult` subclass (or names none).
    """
    out = {}
    for s in check_registry(registry):
        cls = getattr(results, s.result_type, None) if isinstance(s.result_type, str) else s.result_type
        if not (isinstance(cls, type) and issubclass(cls, StageResult)):
            raise TypeError(f"stage {s.name!r}: result type {s.result_type!r} is not a StageResult "
                            "subclass of meshphase.run.results")
        out[s.name] = cls
    return out


#: stage name -> the type of its result
RESULT_TYPES: dict[str, type] = result_types()


class _StageAttr(Generic[_R]):
    """A run context's typed result of one stage (read only; None until the stage ran)."""

    def __init__(self, name: str, cls: type[_R]):
        self.name, self.cls = name, cls

    def __get__(self, ctx, owner=None) -> _R | None:
        return self if ctx is None else ctx.result(self.name)

    def __set__(self, ctx, value) -> None:
        raise AttributeError(f"ctx.{self.name} is the stage's recorded result: record a new "
                             f"one with ctx.record({self.name!r}, result)")


@dataclass
class RunContext:
    """Everything a run produces.

    Attributes
    ----------
    scene : meshphase.run.scene.Scene
    ran : list of str
        Stages that ran, in order.
    timings : dict
        Wall time per stage [s].
    error_estimates : dict
        Per stage, a short text with its error estimate (what "error against run time" lists).
    messages : list of RunMessage
        Warnings raised during the run (:class:`meshphase.run.state.RunMessage`: the text
        "stage: Category: message" with its parts as fields).
    failed : dict of str to StageFailure
        Stage -> why it gave no result (:class:`meshphase.run.state.StageFailure`: it
        raised, was blocked by a stage it needs, or had nothing to do); the run goes on with
        what it has.
    channels_unused : list of str
        Channels of the recording that no planned stage reads (set by the load stage).
    load, condition, onsets, phasing, load_sharing, centroids, ideal, tolerance, identify, \
compare, bearing_moments, tilt : StageResult or None
        The typed result of each stage of :data:`meshphase.run.declare.STAGE_REGISTRY`
        (:mod:`meshphase.run.results`: :class:`LoadStage`, :class:`PhasingStage`, ...), None
        while the stage has not run.
    gearset : Gearset or None
        The scene's, else the recording's (read only).
    """

    scene: Any                      # meshphase.run.scene.Scene (which imports the stages)
    ran: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    error_estimates: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)
    failed: dict = field(default_factory=dict)
    progress: Callable | None = None
    channels_unused: list = field(default_factory=list)
    _store: dict = field(default_factory=dict, init=False, repr=False)

    @property
    def gearset(self) -> Gearset | None:
        """The scene's gearset, else the one in the recording's metadata (synthetic files
        carry one); None without either."""
        g = self.scene.gearset
        if g is None and self.load is not None:
            meta = self.load.recording.meta.get("gearset")
            if meta:
                g = Gearset.from_dict(meta)
        return g

    def result(self, name: str) -> StageResult | None:
        """The typed result of stage ``name``; None while it has not run."""
        if name not in RESULT_TYPES:
            raise KeyError(f"no stage {name!r}; stages: {', '.join(RESULT_TYPES)}")
        return self._store.get(name)

    def record(self, name: str, result: StageResult) -> StageResult:
        """Keep ``result`` as stage ``name``'s (with the results it supersedes) and its error
        estimate; returns it."""
        cls = RESULT_TYPES[name]
        if not isinstance(result, cls):
            raise TypeError(f"stage {name!r} gives a {cls.__name__}, got {type(result).__name__}")
        self._store[name] = result
        self._store.update(result.supersedes())
        self.error_estimates[name] = result.error_estimate
        return result

    def fail(self, failure: StageFailure) -> None:
        """Record that ``failure.stage`` gave no result."""
        if not isinstance(failure, StageFailure):
            raise TypeError(f"failure must be a StageFailure, got {type(failure).__name__}")
        self.failed[failure.stage] = failure

    def replace_text(self, old: str, new: str) -> None:
        """Replace ``old`` by ``new`` in the failures' reasons and the messages' texts (a
        temporary file's path by the name the user knows)."""
        if not (isinstance(old, str) and isinstance(new, str)):
            raise TypeError("old and new must be str")
        if not old:
            raise ValueError("old must be a non-empty text")
        self.failed = {k: v.replace_text(old, new) for k, v in self.failed.items()}
        self.messages = [m.with_text(m.text.replace(old, new)) if isinstance(m, RunMessage)
                         else str(m).replace(old, new) for m in self.messages]


for _name, _cls in RESULT_TYPES.items():       # one typed slot per declared stage
    setattr(RunContext, _name, _StageAttr(_name, _cls))
del _name, _cls


def phasing_verdict(phasing: PhasingStage | None, messages) -> dict:
    """Whether each gauge's measured phasing is reliable, and why not.

    Parameters
    ----------
    phasing : PhasingStage or None
        Its ``reliability`` decides when given; otherwise ``messages`` do.
    messages : sequence of RunMessage
        The run's messages: one flagged ``unreliable``
        (:func:`meshphase.run.state.flagged_warning`) flags the gauge it names, or every
        gauge with a phasing table when it names none (``"phasing"`` if there is none);
        plain strings (no fields) are not read.

    Returns
    -------
    dict
        gauge -> ``{"reliable": bool, "reasons": list of str}``; empty when no phasing ran
        and nothing was flagged.
    """
    if phasing is not None and not isinstance(phasing, PhasingStage):
        raise TypeError(f"phasing must be a PhasingStage or None, got {type(phasing).__name__}")
    if not isinstance(messages, (list, tuple)):
        raise TypeError(f"messages must be a list of RunMessage, got {type(messages).__name__}")
    given = None if phasing is None else phasing.reliability
    if isinstance(given, dict):
        return {str(g): {"reliable": bool(v.get("reliable", True)),
                         "reasons": [str(r) for r in v.get("reasons") or []]}
                for g, v in given.items()}
    tables = {} if phasing is None else (phasing.tables or {})
    out = {str(g): {"reliable": True, "reasons": []} for g in tables}
    for m in messages:
        if not (isinstance(m, RunMessage) and m.unreliable):
            continue
        gauges = [m.gauge] if m.gauge else (list(out) or ["phasing"])
        for g in gauges:
            entry = out.setdefault(g, {"reliable": True, "reasons": []})
            entry["reliable"] = False
            if m.text not in entry["reasons"]:
                entry["reasons"].append(m.text)
    return out
