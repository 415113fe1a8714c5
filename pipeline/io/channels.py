"""The channel mapping of a scene onto a recording: which recording channel is which gauge.

A scene's ``[[channels]]`` entries name recording channels exactly (``name = "SG01"``), by a
glob (``name = "SG*_sun*"``: ``*``, ``?``, ``[...]`` as in :mod:`fnmatch`, case-sensitive) or by
a regular expression (``regex = 'SG\\d+_sun_T(?P<tooth>\\d+)'``, matched against the whole name
with :func:`re.fullmatch`; a group named ``tooth`` gives the tooth number). A ``name`` that is
a channel's name exactly is taken as that name even if it holds glob characters
(``"Strain [V]"``). Rules (``data_schemas/scene.md``, "Channel mapping"):

- each recording channel is mapped at most once: two entries reaching one channel is an
  error naming both;
- an entry that maps no channel is an error (an exact name, as before, with the nearest
  names; a pattern, with the channels present): a scene written for one rig must not pass
  silently over another's;
- channels no entry maps keep what the file says of them (kind, units), and are listed.

:func:`map_channels` resolves the entries (:class:`ChannelMap`); :func:`mapped_specs` gives
the channel specs after the overrides; :func:`apply_channel_overrides` does both on a
Recording; :func:`check_gauges` refuses a recording without gauges when measured results are
wanted; :func:`mapping_rows` is the listing ``meshphase info --scene`` and the report show.
The load stage (:mod:`meshphase.run.stages`) and the scene's header check
(:func:`meshphase.run.scene.check_recording`) both use these, with the same messages.
"""

from __future__ import annotations

import difflib
import fnmatch
import re
from dataclasses import dataclass
from typing import Sequence

from ..recording import GAUGE_KINDS, ChannelSpec, Recording

__all__ = ["ChannelMapError", "ChannelMatch", "ChannelMap", "GAUGE_KINDS", "map_channels",
           "mapped_specs", "apply_channel_overrides", "check_gauges", "channels_present",
           "mapping_rows", "unmapped_message", "entry_label", "is_glob", "overridden",
           "bridge_configs", "entry_values", "mapping_report", "MESSAGE_NAMES"]

#: keys of a [[channels]] entry (after the scene's parse) that are not ChannelSpec fields
_NOT_SPEC = ("name", "regex", "bridge", "mount_angle")
_GLOB_CHARS = re.compile(r"[*?\[]")


class ChannelMapError(ValueError):
    """A ``[[channels]]`` entry that cannot be mapped; ``entry`` is its index (0-based) and
    ``key`` the entry's key at fault (``name`` or ``regex``), so a scene can give its line."""

    def __init__(self, message: str, entry: int | None = None, key: str = "name"):
        super().__init__(message)
        self.entry, self.key = entry, key


@dataclass(frozen=True)
class ChannelMatch:
    """One recording channel mapped by one ``[[channels]]`` entry.

    Attributes
    ----------
    channel : str
        The recording channel's name.
    entry : int
        Index of the entry in the scene's ``[[channels]]`` (0-based).
    how : {"exact", "glob", "regex"}
    pattern : str
        The entry's ``name`` or ``regex`` as written.
    tooth : int or None
        The tooth number from the regex's ``tooth`` group, if it has one.
    """

    channel: str
    entry: int
    how: str
    pattern: str
    tooth: int | None = None


@dataclass(frozen=True)
class ChannelMap:
    """The resolved mapping: ``matches`` in recording column order, the ``names`` of all
    recording channels, the ``entries`` as given."""

    names: tuple
    matches: tuple
    entries: tuple

    @property
    def unmapped(self) -> tuple:
        """Recording channels no entry maps, in column order."""
        got = {m.channel for m in self.matches}
        return tuple(n for n in self.names if n not in got)

    def match_of(self, channel: str) -> ChannelMatch | None:
        """The match of recording channel ``channel``, or None."""
        return next((m for m in self.matches if m.channel == channel), None)


def is_glob(text: str) -> bool:
    """True when ``text`` holds a glob character (``*``, ``?``, ``[``)."""
    return bool(_GLOB_CHARS.search(text))


def entry_label(entry: dict, i: int) -> str:
    """``[[channels]] 2 (name = "SG*")``: an entry as an error message names it."""
    key = "regex" if "regex" in entry else "name"
    return f'[[channels]] {i + 1} ({key} = "{entry.get(key)}")'


def _entry_matches(entry: dict, i: int, names: Sequence[str]) -> list[ChannelMatch]:
    """The channels one entry maps (an exact name first, then its glob or regex)."""
    if "regex" in entry:
        try:
            rx = re.compile(entry["regex"])
        except re.error as exc:
            raise ChannelMapError(f"{entry_label(entry, i)}: not a regular expression: {exc}",
                                  i, "regex") from None
        out = []
        for n in names:
            m = rx.fullmatch(n)
            if m is not None:
                tooth = m.groupdict().get("tooth")
                out.append(ChannelMatch(n, i, "regex", entry["regex"],
                                        int(tooth) if tooth is not None and tooth.isdigit() else None))
        return out
    name = entry["name"]
    if name in names:
        return [ChannelMatch(name, i, "exact", name)]
    if is_glob(name):
        return [ChannelMatch(n, i, "glob", name) for n in names if fnmatch.fnmatchcase(n, name)]
    return []


#: names a message lists before "... and N more" (a scene can hold any number of entries)
MESSAGE_NAMES = 10


def _missing_exact(missing: list[str], names: Sequence[str], source: str | None,
                   present: str) -> str:
    """The message for exact names not in the recording, with the nearest names: the first
    :data:`MESSAGE_NAMES` of them, then how many more."""
    def near(m):  # a name present inside the one asked for ("sun" in "sun_gauge"), or alike
        inside = [n for n in names if n.lower() in m.lower() or m.lower() in n.lower()]
        return (inside or difflib.get_close_matches(m, names, n=1))[:1]

    shown = missing[:MESSAGE_NAMES]
    more = f" ... and {len(missing) - len(shown)} more" if len(missing) > len(shown) else ""
    hints = [f"{m!r} -> {close[0]!r}?" for m in shown if (close := near(m))]
    return (f"{source or 'the recording'}: the scene's [[channels]] name "
            f"{', '.join(repr(m) for m in shown)}{more} is not in the file; channels "
            f"present: {present}" + (f" (did you mean {', '.join(hints)})" if hints else ""))


def map_channels(names: Sequence[str], entries: Sequence[dict], source: str | None = None,
                 present: str | None = None) -> ChannelMap:
    """Resolve the scene's ``[[channels]]`` entries against a recording's channel names.

    Parameters
    ----------
    names : sequence of str
        The recording's channel names, in column order.
    entries : sequence of dict
        The scene's ``[[channels]]`` (each with ``name`` or ``regex``).
    source : str, optional
        The recording, for messages.
    present : str, optional
        ``name (kind), ...`` of the channels, for messages (default: the names).

    Returns
    -------
    ChannelMap

    Raises
    ------
    ChannelMapError
        An entry maps no channel; two entries map one channel (both named); a bad regex;
        a regex ``tooth`` group next to a ``tooth`` key.
    TypeError
        ``names`` or ``entries`` of the wrong type.
    """
    if isinstance(names, str) or not all(isinstance(n, str) for n in names):
        raise TypeError(f"names must be a sequence of channel names, got {names!r}")
    names = tuple(names)
    entries = tuple(entries)
    for i, e in enumerate(entries):
        if not isinstance(e, dict) or ("name" in e) == ("regex" in e):
            raise ChannelMapError(f"[[channels]] {i + 1}: give name (exact or glob) or regex, "
                                  f"one of them, got {e!r}", i)
    present = present if present is not None else (", ".join(names) or "none")
    found = [_entry_matches(e, i, names) for i, e in enumerate(entries)]
    missing = [e["name"] for e, f in zip(entries, found) if not f and "regex" not in e
               and not is_glob(e["name"])]
    if missing:
        i = next(i for i, e in enumerate(entries) if e.get("name") == missing[0])
        raise ChannelMapError(_missing_exact(missing, names, source, present), i)
    for i, (e, f) in enumerate(zip(entries, found)):
        if not f:
            raise ChannelMapError(f"{source or 'the recording'}: {entry_label(e, i)} matches no "
                                  f"channel; channels present: {present}", i,
                                  "regex" if "regex" in e else "name")
        if "tooth" in e and any(m.tooth is not None for m in f):
            raise ChannelMapError(f"{entry_label(e, i)}: the tooth comes from the regex's "
                                  "tooth group and from the tooth key; give one", i, "regex")
    by_channel: dict[str, ChannelMatch] = {}
    for f in found:
        for m in f:
            if m.channel in by_channel:
                first = by_channel[m.channel]
                raise ChannelMapError(
                    f"{source or 'the recording'}: channel {m.channel!r} is matched by "
                    f"{entry_label(entries[first.entry], first.entry)} and by "
                    f"{entry_label(entries[m.entry], m.entry)}; map each channel once (narrow "
                    "the pattern)", m.entry, "regex" if "regex" in entries[m.entry] else "name")
            by_channel[m.channel] = m
    matches = tuple(by_channel[n] for n in names if n in by_channel)
    return ChannelMap(names, matches, entries)


def mapped_specs(specs: Sequence[ChannelSpec], cmap: ChannelMap) -> tuple[list, list]:
    """The channel specs after the mapping's overrides, and the gains they ask for.

    Parameters
    ----------
    specs : sequence of ChannelSpec
        The recording's, in column order (as ``cmap.names``).
    cmap : ChannelMap

    Returns
    -------
    specs : list of ChannelSpec
        ``kind``, ``gear`` (default the kind for sun/ring), ``tooth`` (or the regex's),
        ``face_position`` [m], ``gain``, ``units`` "m/m" for a bridge channel (its volts
        become strain when loaded: :mod:`meshphase.io.bridge`).
    gains : list of (int, float)
        (column, gain) to apply to the samples, in column order.
    """
    specs = list(specs)
    if [s.name for s in specs] != list(cmap.names):
        raise ValueError("specs and the channel map name different channels")
    gains = []
    for m in cmap.matches:
        o = cmap.entries[m.entry]
        j = cmap.names.index(m.channel)
        d = specs[j].to_dict()
        d.update({k: v for k, v in o.items() if k not in _NOT_SPEC})
        if m.tooth is not None:
            d["tooth"] = m.tooth
        if "kind" in o and "gear" not in o and o["kind"] in ("sun", "ring"):
            d["gear"] = o["kind"]
        if o.get("bridge") is not None:
            d["units"] = "m/m"
        specs[j] = ChannelSpec.from_dict(d)
        if "gain" in o:
            gains.append((j, o["gain"]))
    return specs, gains


def channels_present(rec) -> str:
    """``name (kind), ...`` of every channel of ``rec`` (a Recording or its header), for
    error messages."""
    return ", ".join(f"{c.name} ({c.kind})" for c in rec.channels) or "none"


def apply_channel_overrides(rec, entries: Sequence[dict], source: str | None = None):
    """A Recording with the scene's ``[[channels]]`` applied: specs overridden, gains
    multiplied in, a ``channel_overrides`` history step naming the channels mapped.

    Parameters
    ----------
    rec : meshphase.Recording
    entries : sequence of dict
        The scene's ``[[channels]]``; empty: ``rec`` unchanged.
    source : str, optional
        The recording, for messages.

    Raises
    ------
    ChannelMapError
        As :func:`map_channels`.
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    if not entries:
        return rec
    cmap = map_channels(rec.names, entries, source, channels_present(rec))
    specs, gains = mapped_specs(rec.channels, cmap)
    data = rec.data
    if gains:
        data = data.copy()
        for j, g in gains:
            data[:, j] *= g
    out = Recording(data, rec.fs, specs, rec.t0, rec.start_datetime, rec.meta, rec.history)
    return out.with_history("channel_overrides", channels=overridden(cmap))


def overridden(cmap: ChannelMap) -> list[str]:
    """The channels the map overrides, in the order of the scene's entries (what the
    ``channel_overrides`` history step lists)."""
    return [m.channel for m in sorted(cmap.matches, key=lambda m: m.entry)]


def entry_values(cmap: ChannelMap, key: str) -> dict:
    """{channel: its entry's ``key``} of the mapped channels whose entry gives ``key``."""
    return {m.channel: cmap.entries[m.entry][key] for m in cmap.matches
            if cmap.entries[m.entry].get(key) is not None}


def bridge_configs(cmap: ChannelMap) -> dict:
    """{channel: its entry's ``bridge`` (a :class:`meshphase.io.bridge.BridgeConfig`)} of the
    mapped channels whose entry gives one."""
    return entry_values(cmap, "bridge")


def check_gauges(rec, stages: Sequence[str], results: Sequence[str], source: str) -> list[str]:
    """Refuse a recording without any gauge when measured results are wanted; return the
    channels that no planned stage reads.

    Parameters
    ----------
    rec : Recording or its header
        After the channel mapping.
    stages : sequence of str
        The stages that will run (:func:`meshphase.run.scene.plan`).
    results : sequence of str
        The results the scene asks for (named in the message).
    source : str
        The recording, for messages.

    Returns
    -------
    list of str
        Channels no planned stage reads, in column order.

    Raises
    ------
    ValueError
        ``onsets`` will run and no channel is a gauge (kind sun, ring or facewidth).
    """
    measured = [r for r in results if r in ("phasing", "load_sharing", "centroids",
                                            "compare", "identify")]
    if "onsets" in stages and not any(c.kind in GAUGE_KINDS for c in rec.channels):
        first = rec.channels[0].name if rec.channels else "CHANNEL"
        raise ValueError(f"{source}: no gauge channel (kind sun, ring or facewidth) for the "
                         f"results {', '.join(measured) or 'wanted'}; channels present: "
                         f"{channels_present(rec)}; say which channel is which gauge in the "
                         f'scene, e.g. [[channels]] name = "{first}", kind = "sun"')
    used = set()
    if "onsets" in stages:
        used |= {c.name for c in rec.channels if c.kind in GAUGE_KINDS}
    tacho = [c.name for c in rec.channels if c.kind == "tacho"]
    if "phasing" in stages and tacho:
        used.add(tacho[0])  # the ring pulse that is planet 1, from the first tacho only
    if "phasing" in stages:
        used |= {c.name for c in rec.channels if c.kind == "encoder"}  # angle observations
    return [c.name for c in rec.channels if c.name not in used]


def mapping_rows(specs: Sequence[ChannelSpec], cmap: ChannelMap | None) -> list[dict]:
    """The mapping as a table: one row per recording channel, in column order.

    Parameters
    ----------
    specs : sequence of ChannelSpec
        The channels after the mapping (:func:`mapped_specs`).
    cmap : ChannelMap or None
        None: a scene without ``[[channels]]`` (every channel as the file says).

    Returns
    -------
    list of dict
        ``channel``, ``scene entry`` (``[[channels]] N (name = ...)``, or "unmapped (as in
        the file)"), ``matched by`` (exact, glob, regex or ""), ``kind``, ``gear``,
        ``tooth``, ``units``.
    """
    rows = []
    for s in specs:
        m = cmap.match_of(s.name) if cmap is not None else None
        entry = (entry_label(cmap.entries[m.entry], m.entry) if m is not None
                 else "unmapped (as in the file)")
        rows.append({"channel": s.name, "scene entry": entry, "matched by": m.how if m else "",
                     "kind": s.kind, "gear": s.gear or "", "tooth": "" if s.tooth is None else s.tooth,
                     "units": s.units})
    return rows


def mapping_report(specs: Sequence[ChannelSpec], entries: Sequence[dict],
                   source: str | None = None) -> dict:
    """What a scene's ``[[channels]]`` make of a recording's channels: the one listing that
    ``meshphase info --scene`` prints and the report shows.

    Parameters
    ----------
    specs : sequence of ChannelSpec
        The recording's channels (as the file describes them, or already mapped: mapping
        again gives the same).
    entries : sequence of dict
        The scene's ``[[channels]]`` (empty: every channel as the file says).
    source : str, optional
        The recording, for messages.

    Returns
    -------
    dict
        ``rows`` (:func:`mapping_rows`), ``unmapped`` (channel names), ``message``
        (:func:`unmapped_message` or None).

    Raises
    ------
    ChannelMapError
        As :func:`map_channels`.
    """
    specs = list(specs)
    if not all(isinstance(s, ChannelSpec) for s in specs):
        raise TypeError(f"specs must be ChannelSpecs, got {specs!r}")
    if not entries:
        return {"rows": mapping_rows(specs, None), "unmapped": [], "message": None}
    cmap = map_channels([s.name for s in specs], entries, source,
                        ", ".join(f"{s.name} ({s.kind})" for s in specs) or "none")
    mapped, _ = mapped_specs(specs, cmap)
    return {"rows": mapping_rows(mapped, cmap), "unmapped": list(cmap.unmapped),
            "message": unmapped_message(cmap, mapped)}


def unmapped_message(cmap: ChannelMap, specs: Sequence[ChannelSpec] | None = None) -> str | None:
    """``channel(s) A (other), B (sun) not mapped by the scene's [[channels]] ...``, or None
    when every channel is mapped (or the scene has no ``[[channels]]``)."""
    if not cmap.entries or not cmap.unmapped:
        return None
    kinds = {s.name: s.kind for s in specs or ()}
    listed = ", ".join(f"{n} ({kinds[n]})" if n in kinds else n for n in cmap.unmapped)
    return (f"channel(s) {listed} not mapped by the scene's [[channels]]: kept as the file "
            "describes them")
