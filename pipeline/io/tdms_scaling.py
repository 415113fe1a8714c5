"""NI scaling of TDMS channels, from NI's documented ``NI_Scale[k]_...`` properties.

A channel is scaled when its properties (else its group's, else the file's: the first of
the three with ``NI_Number_Of_Scales`` > 0 or ``NI_Scale[k]_Scale_Type`` properties) say
``NI_Scaling_Status = "unscaled"`` (the default) and list scales. Scale ``NI_Number_Of_Scales
- 1`` is the output; each scale takes the raw data (input source 0xFFFFFFFF) or another
scale as input. This module computes the two scale types NI DAQ rigs log for strain and
voltage, ``Linear`` (slope, y intercept) and ``Polynomial`` (coefficients, lowest order
first), the same way npTDMS does (same arithmetic on the stored type, so the results are
equal bit for bit); :func:`parse` returns None for a chain with any other type, and the
reader then asks npTDMS (``TdmsChannel.read_data(scaled=True)``) for those channels.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = ["Scale", "Chain", "has_scales", "parse", "linear_gain", "RAW_INPUT"]

#: input source meaning "the raw data"
RAW_INPUT = 0xFFFFFFFF
_TYPE_KEY = re.compile(r"NI_Scale\[(\d+)\]_Scale_Type$")


@dataclass(frozen=True)
class Scale:
    """One scale: ``kind`` "Linear" (coefficients (slope, intercept)) or "Polynomial"
    (coefficients c0, c1, ...), applied to ``source`` (RAW_INPUT or another scale's index)."""

    kind: str
    coefficients: tuple
    source: int


@dataclass(frozen=True)
class Chain:
    """The scales of one channel; scale ``len(scales) - 1`` gives the physical values."""

    scales: tuple

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Physical values of the stored values ``raw`` (float64 unless both are float32 and
        linear, as npTDMS computes them)."""
        return self._value(len(self.scales) - 1, raw, 0)

    def _value(self, k: int, raw: np.ndarray, depth: int) -> np.ndarray:
        if k == RAW_INPUT:
            return raw
        if not 0 <= k < len(self.scales) or depth > len(self.scales):
            raise ValueError(f"NI scale input source {k} is not a scale of this channel")
        s = self.scales[k]
        x = self._value(s.source, raw, depth + 1)
        if s.kind == "Linear":
            slope, intercept = s.coefficients
            return x * slope + intercept
        if not s.coefficients:
            return np.zeros(len(x), dtype=np.float64)
        return np.polynomial.polynomial.polyval(x.astype(np.float64, copy=False), list(s.coefficients))


def _count(props) -> int | None:
    n = props.get("NI_Number_Of_Scales")
    if n is not None:
        return int(n)
    found = [int(m.group(1)) for m in (_TYPE_KEY.match(k) for k in props) if m]
    return max(found) + 1 if found else None


def has_scales(props) -> bool:
    """True when ``props`` (one object's properties) asks for NI scaling."""
    if props.get("NI_Scaling_Status", "unscaled") == "scaled":
        return False
    n = _count(props)
    return bool(n) and n > 0


def _scale(props, k: int) -> Scale | None:
    kind = props.get(f"NI_Scale[{k}]_Scale_Type")
    if kind == "Linear":
        return Scale("Linear", (props[f"NI_Scale[{k}]_Linear_Slope"], props[f"NI_Scale[{k}]_Linear_Y_Intercept"]),
                     int(props.get(f"NI_Scale[{k}]_Linear_Input_Source", RAW_INPUT)))
    if kind == "Polynomial":
        n = int(props.get(f"NI_Scale[{k}]_Polynomial_Coefficients_Size", 4))
        return Scale("Polynomial", tuple(props[f"NI_Scale[{k}]_Polynomial_Coefficients[{i}]"] for i in range(n)),
                     int(props.get(f"NI_Scale[{k}]_Polynomial_Input_Source", RAW_INPUT)))
    return None


def parse(*props_levels) -> tuple[bool, Chain | None]:
    """(whether NI scaling applies, its chain or None when it uses a type computed only by
    npTDMS) from the channel's, group's and file's properties, in that order."""
    for props in props_levels:
        if not has_scales(props):
            continue
        try:
            scales = tuple(_scale(props, k) for k in range(_count(props)))
        except (KeyError, TypeError, ValueError):
            return True, None
        return True, (None if any(s is None for s in scales) else Chain(scales))
    return False, None


def linear_gain(chain: Chain | None) -> float | None:
    """Slope of a single, zero-intercept linear scale on the raw data, else None."""
    if chain is None or len(chain.scales) != 1:
        return None
    s = chain.scales[0]
    if s.kind == "Linear" and s.coefficients[1] == 0 and s.source == RAW_INPUT:
        return float(s.coefficients[0])
    return None
