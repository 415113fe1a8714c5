"""What a run records beside its results, as typed objects: a stage that did not give its
result (:class:`StageFailure`, why in :class:`FailureKind`) and a warning raised during a
stage (:class:`RunMessage`).

The run status (:func:`meshphase.run.exits.run_status`), the summary, the report and the
campaign read their fields; the text they show is their ``str()`` (``"ValueError: ..."``,
``"skipped: needs onsets"``, ``"phasing: ProcessingWarning: ..."``), never parsed back.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

__all__ = ["FailureKind", "StageFailure", "RunMessage", "failure_texts", "flagged_warning"]

#: how a warning about one gauge starts: "sun gauge: ...", "ring gauge (SG02_ring): ..."
_GAUGE_PREFIX = re.compile(r"^(?P<gauge>[A-Za-z0-9_]+) gauge")


class FailureKind(enum.Enum):
    """Why a planned stage gave no result."""

    #: it raised a stage error (bad input or data)
    RAISED = "raised"
    #: skipped: a stage it needs failed or did not run
    BLOCKED = "blocked"
    #: skipped by design: the recording has nothing for it (no face-width gauges: no
    #: centroid work); not a missing result
    NOT_APPLICABLE = "not applicable"


@dataclass(frozen=True)
class StageFailure:
    """A planned stage that gave no result.

    Attributes
    ----------
    stage : str
    kind : FailureKind
    reason : str
        What went wrong in words (RAISED: the exception's message; NOT_APPLICABLE: what the
        recording lacks; BLOCKED: empty).
    exception : str or None
        The exception's class name (RAISED only).
    blocked_by : tuple of str
        The needed stages that failed or did not run (BLOCKED only).
    """

    stage: str
    kind: FailureKind
    reason: str = ""
    exception: str | None = None
    blocked_by: tuple = ()

    def __post_init__(self):
        if not isinstance(self.kind, FailureKind):
            raise TypeError(f"kind must be a FailureKind, got {type(self.kind).__name__} {self.kind!r}")
        if self.kind is FailureKind.BLOCKED and not self.blocked_by:
            raise ValueError(f"stage {self.stage!r}: a blocked stage names what blocked it")

    @classmethod
    def raised(cls, stage: str, exc: BaseException) -> "StageFailure":
        """The failure of ``stage`` that raised ``exc``."""
        return cls(stage, FailureKind.RAISED, str(exc), type(exc).__name__)

    @classmethod
    def blocked(cls, stage: str, by) -> "StageFailure":
        """``stage`` skipped because the stages ``by`` failed or did not run."""
        return cls(stage, FailureKind.BLOCKED, blocked_by=tuple(by))

    @classmethod
    def not_applicable(cls, stage: str, reason: str) -> "StageFailure":
        """``stage`` skipped by design: ``reason`` says what the recording lacks."""
        return cls(stage, FailureKind.NOT_APPLICABLE, reason)

    @property
    def benign(self) -> bool:
        """True for a skip by design (not a missing result)."""
        return self.kind is FailureKind.NOT_APPLICABLE

    def replace_text(self, old: str, new: str) -> "StageFailure":
        """This failure with ``old`` replaced by ``new`` in its reason (a temporary file's
        path by the name the user knows)."""
        return StageFailure(self.stage, self.kind, self.reason.replace(old, new), self.exception,
                            self.blocked_by)

    def __str__(self) -> str:
        if self.kind is FailureKind.RAISED:
            return f"{self.exception}: {self.reason}" if self.exception else self.reason
        if self.kind is FailureKind.BLOCKED:
            return f"skipped: needs {', '.join(self.blocked_by)}"
        return f"skipped: {self.reason}"


def failure_texts(failed: dict) -> dict:
    """``{stage: str(failure)}`` of a run's failures (as summary.json lists them)."""
    return {k: str(v) for k, v in failed.items()}


class RunMessage(str):
    """A warning raised during a stage: the text ``"stage: Category: text"`` (what the run's
    messages list, summary.json and the report show) with its parts as fields.

    Attributes
    ----------
    stage : str
    category : str
        The warning class name (``"ProcessingWarning"``, ...).
    text : str
        The warning's message.
    gauge : str or None
        The gauge (gear) the warning is about: as its issuer set it
        (:func:`flagged_warning`), else as the text starts (``"sun gauge: ..."``, the
        project's wording of a warning about one gauge).
    unreliable : bool
        The warning flags ``gauge``'s phasing (or, without a gauge, the phasing) as not
        reliable.
    """

    stage: str
    category: str
    text: str
    gauge: str | None
    unreliable: bool

    def __new__(cls, stage: str, category: str, text: str, *, gauge: str | None = None,
                unreliable: bool = False):
        for k, v in (("stage", stage), ("category", category), ("text", text)):
            if not isinstance(v, str):
                raise TypeError(f"{k} must be a str, got {type(v).__name__}")
        self = super().__new__(cls, f"{stage}: {category}: {text}")
        self.stage, self.category, self.text = stage, category, text
        self.gauge, self.unreliable = gauge, bool(unreliable)
        return self

    def __reduce__(self):
        return (_run_message, (self.stage, self.category, self.text, self.gauge, self.unreliable))

    def with_text(self, text: str) -> "RunMessage":
        """The same message with another text (a temporary path replaced, ...)."""
        return RunMessage(self.stage, self.category, text, gauge=self.gauge,
                          unreliable=self.unreliable)

    @classmethod
    def of_warning(cls, stage: str, message, category: type) -> "RunMessage":
        """The run message of a caught warning (``message`` as :mod:`warnings` gives it: a
        Warning instance, with ``gauge`` and ``unreliable`` attributes when its issuer set
        them)."""
        text = str(message)
        gauge = getattr(message, "gauge", None)
        if gauge is None:
            head = _GAUGE_PREFIX.match(text)
            gauge = head["gauge"] if head else None
        return cls(stage, category.__name__, text, gauge=gauge,
                   unreliable=bool(getattr(message, "unreliable", False)))

    @property
    def detail(self) -> str:
        """The text without its leading ``"<gauge> gauge (<channel>): "`` (the whole text
        when it is about no gauge)."""
        if self.gauge is None or ": " not in self.text:
            return self.text
        return self.text.split(": ", 1)[1]


def flagged_warning(category: type, text: str, *, gauge: str | None = None,
                    unreliable: bool = False) -> Warning:
    """A warning instance of ``category`` carrying the typed fields a :class:`RunMessage`
    takes from it (``warnings.warn(flagged_warning(...), stacklevel=...)``).

    Parameters
    ----------
    category : type
        A Warning subclass.
    text : str
    gauge : str, optional
        The gauge (gear) it is about.
    unreliable : bool
        It flags that gauge's phasing as not reliable.
    """
    if not (isinstance(category, type) and issubclass(category, Warning)):
        raise TypeError(f"category must be a Warning subclass, got {category!r}")
    w = category(text)
    w.gauge, w.unreliable = gauge, bool(unreliable)
    return w


def _run_message(stage, category, text, gauge, unreliable) -> RunMessage:
    return RunMessage(stage, category, text, gauge=gauge, unreliable=unreliable)
