"""Units of gauge channels, checked when a recording is loaded: strain to m/m, bridge volts.

A gauge channel (kind sun, ring or facewidth) carries a unit string from its file (a TDMS
``unit_string``, an HDF5 ``units`` attribute, a CSV ``[units]`` header or units row, an MCAP
channel's metadata) or from the scene's ``[[channels]]`` entry (``units``, which wins). The
samples the run conditions are strain [m/m]: :func:`parse_unit` says what a unit string is
and its factor to SI, :func:`gauge_unit_gains` turns the gauges' units into gains on the
channel specs (the block sources multiply them in as they read, :mod:`meshphase.run.stream`), so
a recording in microstrain is streamed in m/m without a copy of the file.

- a strain unit (``m/m``, ``µm/m``, ``µε``, ``ue``, ``microstrain``, ``mm/m``, ``%``,
  ``Strain`` as NI writes it, any length/length or strain expression): factor to m/m;
- a bridge ratio (``mV/V``, ``V/V``) or a voltage (``V``, ``mV``) on a channel with a bridge
  entry: factor to volts (a ratio times the excitation), converted to strain by
  :mod:`meshphase.io.bridge`; on a channel without one: a :class:`UnitError` asking for it;
- an empty unit: taken as m/m (volts with a bridge entry), with one
  :class:`meshphase.errors.FormatWarning` naming the channel;
- any other unit: a :class:`UnitError` (a ValueError: the load stage fails) naming the
  channel and echoing the unit.

The common spellings are in a table (:data:`STRAIN_UNITS`, :data:`RATIO_UNITS`,
:data:`VOLT_UNITS`); any other string is parsed with pint (imported and its registry built on
first use only: the first pint parse, its import and registry build, took 0.9-2.7 s on a
shared 2-core machine, a table look-up some microseconds; ``meshphase info``/``convert`` and
the common spellings never pay it).
"""

from __future__ import annotations

import functools
import warnings
from typing import Sequence

from ..errors import FormatWarning
from ..recording import GAUGE_KINDS, ChannelSpec

__all__ = ["STRAIN_UNITS", "RATIO_UNITS", "VOLT_UNITS", "UnitError", "parse_unit",
           "gauge_unit_gains"]

_MICRO = ("µ", "μ", "u")        # micro sign U+00B5, Greek mu U+03BC, the ASCII stand-in
#: strain spellings -> factor to m/m [m/m per unit]
STRAIN_UNITS: dict[str, float] = {
    "m/m": 1.0, "strain": 1.0, "Strain": 1.0, "ε": 1.0, "mm/mm": 1.0,
    "mm/m": 1e-3, "%": 1e-2, "percent": 1e-2,
    "microstrain": 1e-6, "Microstrain": 1e-6, "ue": 1e-6, "uE": 1e-6,
    **{f"{p}{u}": 1e-6 for p in _MICRO for u in ("m/m", "ε", "strain", "e", "E")},
}
#: bridge output ratio spellings -> factor to V/V [V/V per unit]
RATIO_UNITS: dict[str, float] = {"V/V": 1.0, "mV/V": 1e-3, **{f"{p}V/V": 1e-6 for p in _MICRO}}
#: voltage spellings -> factor to V [V per unit]
VOLT_UNITS: dict[str, float] = {"V": 1.0, "Volts": 1.0, "volts": 1.0, "volt": 1.0, "mV": 1e-3,
                                **{f"{p}V": 1e-6 for p in _MICRO}}
#: pint base units (prefix stripped) that are pure ratios, strain-like
_RATIO_NAMES = ("strain", "percent", "permille", "ppm", "ppb", "dimensionless")


class UnitError(ValueError):
    """A gauge channel's unit that is not strain (nor a bridge's volts or ratio)."""


@functools.lru_cache(maxsize=1)
def _registry():
    import pint  # only for spellings outside the tables: its import and registry are slow

    return pint.UnitRegistry()


@functools.lru_cache(maxsize=256)
def _parse_pint(text: str) -> tuple[str, float] | None:
    """(quantity, factor) of ``text`` parsed by pint, or None when pint does not know it or
    it is neither strain, a voltage ratio nor a voltage."""
    ureg = _registry()
    try:
        u = ureg.parse_units(text)
    except Exception:   # pint raises its own errors, ValueError, AttributeError, TokenError
        return None
    volt = ureg.volt.dimensionality
    if u.dimensionality == volt:
        return "volt", float(ureg.Quantity(1.0, u).to("V").magnitude)
    if not u.dimensionless:
        return None
    names = list(u._units)
    bases = [(ureg.parse_unit_name(n) or (("", n, ""),))[0][1] for n in names]
    if all(ureg.Unit(n).dimensionality in (volt, ureg.meter.dimensionality) or b in _RATIO_NAMES
           for n, b in zip(names, bases)):
        what = "ratio" if any(ureg.Unit(n).dimensionality == volt for n in names) else "strain"
        return what, float(ureg.Quantity(1.0, u).to("dimensionless").magnitude)
    return None


def parse_unit(text: str) -> tuple[str, float] | None:
    """What a unit string measures and its factor to SI.

    Parameters
    ----------
    text : str
        The unit as a file or scene gives it (surrounding blanks ignored).

    Returns
    -------
    (str, float) or None
        ``("strain", f)`` with f [m/m per unit], ``("ratio", f)`` with f [V/V per unit],
        ``("volt", f)`` with f [V per unit]; None when the string is none of these (unknown
        to pint, or another quantity: Pa, s, counts, angles). An empty string gives
        ``("", 1.0)`` (no unit given).

    Raises
    ------
    TypeError
        ``text`` is not a string.
    """
    if not isinstance(text, str):
        raise TypeError(f"a unit must be a string, got {text!r}")
    t = text.strip()
    if not t:
        return "", 1.0
    for what, table in (("strain", STRAIN_UNITS), ("ratio", RATIO_UNITS), ("volt", VOLT_UNITS)):
        f = table.get(t, table.get(t.replace(" ", "")))
        if f is not None:
            return what, f
    return _parse_pint(t)


def gauge_unit_gains(specs: Sequence, bridges: dict | None = None,
                     source: str = "the recording", raw_units: dict | None = None):
    """The gauges' units as gains to m/m (or to volts on bridge channels), for a block source.

    Parameters
    ----------
    specs : sequence of ChannelSpec
        The channels after any scene mapping, in column order.
    bridges : dict of str to BridgeConfig, optional
        Bridge channels (their volts become strain afterwards, :mod:`meshphase.io.bridge`).
    source : str
        The recording, for messages.
    raw_units : dict of str to str, optional
        Units of bridge channels as the file or scene gave them (the mapped spec of a
        bridge channel already says m/m).

    Returns
    -------
    specs : list of ChannelSpec
        The gauges in units "m/m" (bridge channels: their spec unchanged); other channels as
        given.
    gains : list of (int, float)
        (column, factor) for gauges whose samples need one [SI per unit].
    converted : dict of str to dict
        Per converted channel: ``units`` as given, ``factor``, ``to`` ("m/m" or "V"), for the
        recording's history.

    Raises
    ------
    UnitError
        A gauge's unit is not strain, or is volts or a bridge ratio without a bridge entry,
        or a bridge channel's unit is not volts or a ratio; the message names the channel
        and the unit.
    """
    bridges = dict(bridges or {})
    raw_units = dict(raw_units or {})
    out, gains, converted, missing = [], [], {}, []
    for j, s in enumerate(specs):
        if not isinstance(s, ChannelSpec):
            raise TypeError(f"specs must be ChannelSpecs, got {s!r}")
        if s.kind not in GAUGE_KINDS and s.name not in bridges:
            out.append(s)
            continue
        given = raw_units.get(s.name, s.units) if s.name in bridges else s.units
        parsed = parse_unit(given)
        if s.name in bridges:
            f = _bridge_factor(s.name, given, parsed, bridges[s.name], source)
            to = "V"
        else:
            f = _strain_factor(s.name, given, parsed, source)
            to = "m/m"
            s = ChannelSpec.from_dict({**s.to_dict(), "units": "m/m"})
        if parsed[0] == "":
            missing.append(s.name)
        if f != 1.0:
            gains.append((j, f))
        if f != 1.0 or given.strip() not in ("", to):
            converted[s.name] = {"units": given, "factor": f, "to": to}
        out.append(s)
    if missing:
        warnings.warn(FormatWarning(
            f"{source}: gauge channel(s) {', '.join(repr(n) for n in missing)} carry no unit; "
            "taken as m/m (bridge channels: as volts): give it in the file or as the scene's "
            '[[channels]] units = "µm/m" (or "m/m", "mV/V", ...)'), stacklevel=3)
    return out, gains, converted


def _strain_factor(name: str, given: str, parsed, source: str) -> float:
    """Factor to m/m of a gauge without a bridge entry; UnitError naming it otherwise."""
    if parsed is not None and parsed[0] in ("strain", ""):
        return parsed[1]
    if parsed is not None:      # volts or a ratio: the bridge must be named
        raise UnitError(f"{source}: gauge channel {name!r} is in {given!r}, a bridge's "
                        f"{'output ratio' if parsed[0] == 'ratio' else 'voltage'}: give its bridge in "
                        "the scene's [[channels]] entry (bridge, gauge_factor, excitation_V) so it "
                        'becomes strain, or its strain unit (units = "µm/m"); a channel that is no '
                        'gauge (the tacho) needs its own kind (kind = "tacho")')
    raise UnitError(f"{source}: gauge channel {name!r} has the unit {given!r}, which is not a "
                    "strain unit (m/m, µm/m, µε, microstrain, mm/m, %) nor a bridge's V or mV/V; "
                    'say what it is in the scene\'s [[channels]] entry (units = "µm/m")')


def _bridge_factor(name: str, given: str, parsed, cfg, source: str) -> float:
    """Factor to volts of a bridge channel (a ratio times the excitation); UnitError when
    the unit is neither volts nor a ratio."""
    if parsed is not None and parsed[0] in ("volt", ""):
        return parsed[1]
    if parsed is not None and parsed[0] == "ratio":
        return parsed[1] * cfg.excitation
    raise UnitError(f"{source}: bridge channel {name!r} has the unit {given!r}; a bridge "
                    "channel holds its output in volts (V, mV) or as a ratio (mV/V, V/V): give "
                    'that unit in the scene\'s [[channels]] entry (units = "mV/V")')

