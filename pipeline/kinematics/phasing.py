"""Measured mesh phasing of a whole recording (spec section 3): :func:`measure_phasing`.

Every gauge's passes (:class:`meshphase.kinematics.planet_labels.GaugePasses`) are labelled
(:mod:`meshphase.kinematics.planet_labels`; checked against the loads and the other gauges,
:mod:`meshphase.kinematics.label_checks`), the held member is decided from the data and the
nominal speeds, the mesh angle is fitted to every pass train, tacho and encoder at once
(:func:`meshphase.kinematics.angle_windows.fit_angle_windows`), and each gauged gear's
phasing is read off it (:func:`meshphase.kinematics.pass_table.phasing_from_model`) with its
reliability (:mod:`meshphase.kinematics.reliability`). A scene may fix a gauge's planet 1
outright (``label_shifts``). The result is a :class:`PhasingResult`; :func:`relabel_gauge`
moves one gear's labels cyclically afterwards.

The pass table, the labels and the label checks are imported here too
(:class:`~meshphase.kinematics.pass_table.PassTable`, :func:`pass_order`,
:func:`assign_planets_by_pattern`, :class:`GaugePasses`, :class:`GaugeLabels`), for the
callers that take them from this module.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import DataQualityWarning, ProcessingWarning
from .angle_selection import unseen_ripples
from .angle_windows import fit_angle_windows
from .angles import AngleModel
from .encoder import MAX_GAP_PULSES, clean_edges, split_at_gaps
from .label_checks import align_labels, ring_loads, sun_by_loads
from .pass_table import PassTable, measured_phasing, pass_order, phasing_from_model, planet_fractions
from .planet_labels import (GaugeLabels, GaugePasses, assign_planets_by_pattern,
                            relabel_by_tacho, shift_labels)
from .reliability import phasing_reliability
from .shafts import Kinematics, held_member, kinematics, shaft_cycles
from .trains import (encoder_train, gauge_train, mesh_cycles_per_carrier_turn, relabel_train,
                     tacho_train)
from ..validate import as_positive_int

__all__ = ["PassTable", "pass_order", "assign_planets_by_pattern", "measured_phasing", "GaugePasses",
           "GaugeLabels", "PhasingResult", "measure_phasing", "relabel_gauge"]


@dataclass
class PhasingResult:
    """Measured phasing of a recording.

    Attributes
    ----------
    tables : dict of str to PassTable
        Per gear ("sun", "ring"): passes of its main gauge.
    labels : dict of str to GaugeLabels
        Per gear: labels of its main gauge.
    model : AngleModel or None
        The angle model of the whole recording.
    fixed : {"ring", "sun", None}
        The held member used; ``fixed_reason`` says how it was decided.
    reliability : dict of str to dict
        Per gear: ``reliable`` (bool), ``reasons`` (list of str), ``error_estimate`` (RMS of
        the per-pass uncertainty [-]), ``floor`` (RMS of the timing floor [-]: the
        Cramer-Rao bound in the gauge's noise spectrum where it has one) and
        ``floor_factor`` (that floor over the white-noise bound's [-]).
    labels_relative : list of str
        Gears whose planet 1 is only the first pulse seen (no absolute reference).
    notes : list of str
    trains : dict of str to PassTrain
        The angle trains by channel (what :func:`relabel_gauge` recomputes from).
    fractions : dict of str to ndarray
        Each channel's planet fractions in pass order [-].
    gaps : ndarray or None
        Gap intervals used [s].
    """

    tables: dict
    labels: dict
    model: AngleModel | None
    fixed: str | None
    fixed_reason: str
    reliability: dict
    labels_relative: list
    notes: list = field(default_factory=list)
    trains: dict = field(default_factory=dict)
    fractions: dict = field(default_factory=dict)
    gaps: np.ndarray | None = None


def relabel_gauge(result: PhasingResult, gear: str, shift: int, gearset) -> tuple:
    """(PassTable, GaugeLabels) of ``gear``'s main gauge with planet 1 moved ``shift`` places
    along its pass order, recomputed from the same angle model (a cyclic relabelling of a
    symmetric layout: what :func:`meshphase.run.stages.stage_identify` tries when a gauge's labels
    are only relative)."""
    lab = result.labels[gear]
    tr = result.trains[lab.channel]
    frac = result.fractions[lab.channel]
    n = gearset.n_planets
    new_tr = relabel_train(tr, shift, frac, n)
    z = gearset.z_sun if gear == "sun" else gearset.z_ring
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ProcessingWarning)
        tab = phasing_from_model(result.model, new_tr, z, n, gauge=gear, gaps=result.gaps)
    tab.time_origin = result.tables[gear].time_origin if gear in result.tables else 0.0
    seq = np.argsort(frac, kind="stable")
    pl, pos = shift_labels(lab.planet, lab.position, seq, shift)
    new_lab = GaugeLabels(lab.channel, lab.times, lab.amplitude, lab.sigma, pl, pos,
                          lab.decided_by, lab.n_unassigned)
    return tab, new_lab


def measure_phasing(passes, gearset, *, fixed=None, fixed_reason: str = "",
                    tacho_times=None, key_angle: float | None = None, mounts=None,
                    speeds=None, gaps=None, carrier_sense: int | None = None,
                    check_held: bool = False, speeds_resolution=None,
                    label_shifts=None, encoders=None) -> PhasingResult:
    """Label every gauge's pulses, fit one angle model to all of them and the tacho, and
    measure the phasing of each gear's main gauge.

    Parameters
    ----------
    passes : sequence of GaugePasses
        Every sun, ring and face-width gauge with its usable pulses.
    gearset : Gearset
    fixed : {"ring", "sun", None}
        Held member (:func:`meshphase.kinematics.shafts.held_member`); ``fixed_reason`` says why.
    tacho_times : array_like, optional
        Carrier tacho edges [s]: an angle train when a member is held, and planet 1 of the
        held member's gauge when ``key_angle`` and that gauge's ``mounts`` entry are known.
    key_angle : float, optional
        Carrier-frame angle of the tacho key from planet 1 [rad].
    mounts : dict of str to float, optional
        Ground angle of each gauge on the held member [rad], from the tacho probe.
    speeds : Speeds, optional
        Nominal speeds (shaft ratios of a differential; the carrier's sense).
    gaps : array_like, shape (k, 2), optional
        Gap intervals [s]: a pass whose reference lies across one is dropped.
    carrier_sense : {+1, -1}, optional
        Sense of the carrier's rotation (default from the direction and the held member).
    check_held : bool
        Decide the held member again from the data (mesh cycles per carrier turn measured
        between tacho edges, :func:`meshphase.kinematics.trains.mesh_cycles_per_carrier_turn`) together
        with ``speeds`` and their typed ``speeds_resolution``
        (:func:`meshphase.kinematics.shafts.held_member`); ``fixed`` is then only the starting guess.
    label_shifts : dict of str to int, optional
        Per gear ("sun", "ring"): planet 1 of its main gauge is this many places along the
        pass order from its first pulse [-] (the scene's ``[labels]``); what the data say
        otherwise is then only a note.
    encoders : sequence of tuple, optional
        Shaft encoders as angle trains, each ``(name, shaft, pulses_per_rev, edge times [s],
        edge sigma [s] or None)`` (shaft "sun", "input", "carrier" or "ring"; edges from
        :func:`meshphase.kinematics.encoder.edge_times`); used when a member is held.

    Returns
    -------
    PhasingResult
    """
    n = gearset.n_planets
    notes: list[str] = []
    passes = [p for p in passes if isinstance(p, GaugePasses)]
    mounts = dict(mounts or {})
    tach = None if tacho_times is None else np.asarray(tacho_times, dtype=float)
    if check_held and tach is not None and tach.size >= 2 and passes:
        fixed, fixed_reason = _held_from_data(passes, gearset, tach, speeds, speeds_resolution,
                                              (fixed, fixed_reason))
    if carrier_sense is None:
        # clockwise planets: the sun turns counter-clockwise relative to the carrier; with
        # the ring held the carrier turns with the sun (ccw), with the sun held against it
        cw = gearset.direction == "cw"
        carrier_sense = (1 if cw else -1) * (1 if fixed != "sun" else -1)
    held = _HeldGauges(fixed, tach, key_angle, mounts, carrier_sense)
    labels, all_labels, relative = _label_gauges(passes, gearset, held, notes,
                                                 dict(label_shifts or {}))
    trains, train_of = _gauge_trains(all_labels, gearset)
    # one angle model from every train (and the tacho when a member is held)
    kin = kinematics(gearset.z_sun, gearset.z_ring, gearset.z_planet, fixed=fixed, speeds=speeds)
    # the planet terms are shared by every gauge, so every gauge must name the same physical
    # planet alike: align the relatively labelled gauges to the absolute ones (or to the
    # largest), by the planets' own offsets where they differ enough to tell
    symmetric = bool(np.allclose(np.diff(np.sort(planet_fractions(gearset.angles, 1))), 1.0 / n,
                                 atol=1e-9))
    if symmetric and n > 1 and kin.planet_period and len(train_of) > 1:
        trains, train_of = align_labels(trains, train_of, all_labels, labels, kin, n, notes)
        relative = [gear for gear, lab in labels.items()
                    if lab.decided_by == "first pulse" or lab.caution]
    if fixed is not None and tach is not None and tach.size >= 2 and kin.tacho_cycles:
        trains.append(tacho_train(tach, kin.tacho_cycles))
    elif tach is not None and tach.size >= 2 and fixed is None:
        notes.append("differential rig: the carrier tacho does not fix the mesh angle (no held "
                     "member); it is not used")
    n_before = len(trains)
    trains += _encoder_trains(encoders, kin, notes)
    model = None
    tables: dict = {}
    reliability: dict = {}
    if any(tr.kind in ("sun", "ring") and len(tr) >= 2 for tr in trains):
        # an encoder samples the mesh angle many times per planet spin: a common speed
        # ripple at the planet rate is then told from the planets' own terms and is tried
        extra = {"planet_ripple": True} if len(trains) > n_before else {}
        model = fit_angle_windows(trains, kin, n, **extra)
        notes.extend(model.notes)
        unseen = unseen_ripples(trains, kin)
        for shaft, _ in unseen:
            notes.append(f"a speed ripple locked to the {shaft} angle is not seen by "
                         f"{' and '.join(tr.name for tr in trains)}: they meet the {shaft} at "
                         "fixed angles only")
        factors = {p.name: float(getattr(p, "floor_factor", 1.0)) for p in passes}
        tables, reliability = _gear_tables(model, labels, train_of, gearset, gaps, factors,
                                           unseen)
    return PhasingResult(tables, labels, model, fixed, fixed_reason, reliability, relative, notes,
                         dict(train_of), {nm: v[1] for nm, v in all_labels.items()},
                         None if gaps is None else np.asarray(gaps, dtype=float))


def _encoder_trains(encoders, kin: Kinematics, notes: list) -> list:
    """Angle trains of the encoders (:func:`meshphase.kinematics.trains.encoder_train`), their edges
    cleaned (:func:`meshphase.kinematics.encoder.clean_edges`, counts in ``notes``); an encoder that
    cannot observe the mesh angle (a differential, a held shaft) is named in ``notes``."""
    out = []
    for name, shaft, ppr, times, sigma in encoders or ():
        ppr = as_positive_int(ppr, f"encoder {name!r} pulses_per_rev")
        if kin.fixed is None:
            notes.append(f"differential rig: encoder {name} on the {shaft} shaft does not fix the "
                         "mesh angle (no held member); it is not used")
            continue
        try:
            per_rev = shaft_cycles(kin, shaft)
        except ValueError as exc:
            notes.append(f"encoder {name}: {exc}; it is not used")
            continue
        edges = clean_edges(np.asarray(times, dtype=float))
        pieces = split_at_gaps(edges)
        notes.append(f"encoder {name} ({shaft} shaft, {ppr} pulses per turn, "
                     f"{per_rev / ppr:.4g} mesh cycles per pulse): {edges.summary()}"
                     + (f"; counted anew after {len(pieces) - 1} gap(s) of more than "
                        f"{MAX_GAP_PULSES} pulses" if len(pieces) > 1 else ""))
        if edges.n_extra or edges.n_missing:
            warnings.warn(f"encoder {name}: {edges.n_extra} extra edge(s) dropped (glitches), "
                          f"{edges.n_missing} missing edge(s) counted", DataQualityWarning,
                          stacklevel=3)
        for q, piece in enumerate(pieces):
            if len(piece) >= 2:
                out.append(encoder_train(piece, per_rev / ppr, sigma=sigma,
                                         name=name if q == 0 else f"{name} [{q + 1}]"))
    return out


def _held_from_data(passes, gearset, tach: np.ndarray, speeds, resolution, given: tuple) -> tuple:
    """(held member, reason) from the data: mesh cycles per carrier turn, counted over one
    tacho interval on the busiest gauge's pass pattern (which pulse is planet 1 does not
    matter for a count), with the nominal ``speeds`` (:func:`meshphase.kinematics.shafts.held_member`);
    ``given`` when the count cannot be made."""
    psi = gearset.angles
    p0 = max(passes, key=lambda p: p.times.size)
    o0 = pass_order(gearset.direction, p0.gear)
    pl0, inf0 = assign_planets_by_pattern(p0.times, psi, o0)
    ok0 = pl0 >= 0
    if np.count_nonzero(ok0) < 2:
        return given
    z0 = gearset.z_sun if p0.gear == "sun" else gearset.z_ring
    tr0 = gauge_train(p0.name, p0.gear, p0.times[ok0], pl0[ok0].astype(int),
                      inf0["position"][ok0].astype(np.int64), planet_fractions(psi, o0), z0)
    ratio = mesh_cycles_per_carrier_turn(tr0, tach)
    if not math.isfinite(ratio):
        return given
    return held_member(gearset.z_sun, gearset.z_ring, speeds, resolution=resolution,
                       mesh_rate=ratio, carrier_rate=1.0)


@dataclass(frozen=True)
class _HeldGauges:
    """What names planet 1 of a gauge on the held member: the held member, the tacho edges
    [s], the key's carrier-frame angle [rad], the gauges' ground angles [rad] and the
    carrier's sense (+1 counter-clockwise)."""

    fixed: str | None
    tacho: np.ndarray | None
    key_angle: float | None
    mounts: dict
    carrier_sense: int

    def applies(self, p: GaugePasses, planet: np.ndarray) -> bool:
        return (p.gear == self.fixed and p.name in self.mounts and self.key_angle is not None
                and self.tacho is not None and self.tacho.size >= 2 and bool(np.any(planet >= 0)))


def _label_gauges(passes, gearset, held: _HeldGauges, notes: list,
                  shifts: dict | None = None) -> tuple[dict, dict, list]:
    """Planet labels of every gauge, ring gauges first (their loads may name the sun's
    planets): by the pass pattern, then by the tacho for a gauge on the held member; a main
    gauge whose gear has an entry in ``shifts`` takes planet 1 from it (:func:`_pinned`).

    Returns (labels of each gear's main gauge, {channel: (labels, fractions, passes)} of
    every gauge, gears whose labels are relative)."""
    psi = gearset.angles
    n = gearset.n_planets
    labels: dict = {}
    all_labels: dict = {}
    relative: list = []
    ring_load = None
    for p in sorted(passes, key=lambda p: (p.gear != "ring", not p.main)):
        order = pass_order(gearset.direction, p.gear)
        frac = planet_fractions(psi, order)
        ref = ring_load if (p.gear == "sun" and p.main) else None
        pl, inf = assign_planets_by_pattern(p.times, psi, order, amplitudes=np.abs(p.amplitude),
                                            reference_amplitudes=ref)
        pos = inf["position"]
        decided = {"pattern": "pattern", "amplitude": "amplitude"}.get(inf["shift_decided_by"],
                                                                         "first pulse")
        if inf.get("ambiguous"):
            decided = "first pulse"
        caution = ""
        if ref is not None or (p.gear == "sun" and p.main and "ring" in labels):
            # the loads as the ring gauge sees them against the sun's once the load variation
            # with the carrier's phase is divided out
            pl0, inf0 = assign_planets_by_pattern(p.times, psi, order)
            pl, pos, decided, caution = sun_by_loads(p, pl0, inf0["position"],
                                                      (pl, pos, decided), labels["ring"],
                                                      gearset, notes)
        if held.applies(p, pl):
            vote = relabel_by_tacho(p.times, pl, pos, held.tacho, psi, held.mounts[p.name],
                                    pass_order=order, carrier_sense=held.carrier_sense,
                                    key_angle=held.key_angle)
            pl, pos = vote.planet, vote.position
            if vote.accepted:
                decided, caution = "tacho", ""
            elif vote.compared:
                notes.append(f"{p.name}: the tacho and the pass pattern disagree on planet 1 "
                             f"({vote.agree} of {vote.compared} passes agree); labels "
                             "left relative")
        if p.main and p.gear not in labels and p.gear in (shifts or {}):
            pl, pos, decided, caution = _pinned(p, pl, pos, decided, shifts[p.gear], gearset,
                                                notes)
        lab = GaugeLabels(p.name, p.times, p.amplitude, p.sigma, pl, pos, decided,
                          int(inf.get("n_unassigned", 0)), caution)
        all_labels[p.name] = (lab, frac, p)
        if p.main and p.gear not in labels:
            labels[p.gear] = lab
            if decided == "first pulse" or caution:
                relative.append(p.gear)
            if p.gear == "ring" and np.any(pl >= 0):
                ring_load = ring_loads(lab, n)
    return labels, all_labels, relative


def _pinned(p: GaugePasses, pl, pos, decided: str, shift: int, gearset, notes: list) -> tuple:
    """(planet, position, "scene", "") of a main gauge whose planet 1 the scene fixes
    ``shift`` places along its pass order from its first pulse; a note when the labels the
    data gave (``pl``, ``pos``, named by ``decided``) put planet 1 elsewhere."""
    n = gearset.n_planets
    order = pass_order(gearset.direction, p.gear)
    seq = np.argsort(planet_fractions(gearset.angles, order), kind="stable")
    pl0, inf0 = assign_planets_by_pattern(p.times, gearset.angles, order)
    new_pl, new_pos = shift_labels(pl0, inf0["position"], seq, int(shift) % n)
    ok = (new_pl >= 0) & (pl >= 0)
    if decided != "first pulse" and np.any(ok):
        d = int(np.mod(pos[ok][0] - new_pos[ok][0], n))
        if d:
            by = {"amplitude": "loads", "pattern": "pass pattern"}.get(decided, decided)
            notes.append(f"{p.name}: the scene's {p.gear}_shift = {shift} puts planet 1 {d} "
                         f"place(s) from where the {by} name(s) it; the scene's is used")
    return new_pl, new_pos, "scene", ""


def _gauge_trains(all_labels: dict, gearset) -> tuple[list, dict]:
    """The angle train of every gauge with two or more labelled passes
    (:func:`meshphase.kinematics.trains.gauge_train`), as a list and by channel."""
    trains, train_of = [], {}
    for name, (lab, frac, p) in all_labels.items():
        ok = lab.planet >= 0
        if np.count_nonzero(ok) < 2:
            continue
        z = gearset.z_sun if p.gear == "sun" else gearset.z_ring
        sig = None if p.sigma is None else np.asarray(p.sigma)[ok]
        tr = gauge_train(name, p.gear, p.times[ok], lab.planet[ok].astype(int),
                         lab.position[ok].astype(np.int64), frac, z, sigma=sig,
                         order=pass_order(gearset.direction, p.gear))
        trains.append(tr)
        train_of[name] = tr
    return trains, train_of


def _gear_tables(model: AngleModel, labels: dict, train_of: dict, gearset, gaps,
                 factors=None, unseen=()) -> tuple[dict, dict]:
    """Per gear with a main-gauge train: its phasing table from the angle model
    (:func:`phasing_from_model`), its timing floor times the gauge's floor factor (``factors``
    by channel, :attr:`GaugePasses.floor_factor`: both passes of a row are the gauge's), and
    its reliability (:func:`phasing_reliability`)."""
    n = gearset.n_planets
    tables: dict = {}
    reliability: dict = {}
    for gear, lab in labels.items():
        tr = train_of.get(lab.channel)
        if tr is None:
            continue
        z = gearset.z_sun if gear == "sun" else gearset.z_ring
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ProcessingWarning)
            tab = phasing_from_model(model, tr, z, n, gauge=gear, gaps=gaps)
        factor = (factors or {}).get(lab.channel, 1.0)
        if tab.timing_floor is not None and factor != 1.0:
            tab.timing_floor = tab.timing_floor * factor
        tables[gear] = tab
        reliability[gear] = {**phasing_reliability(model, tr, tab, unseen), "floor_factor": float(factor)}
    return tables, reliability
