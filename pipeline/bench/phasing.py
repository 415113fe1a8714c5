"""Measured phasing against synthetic truth on a real rig's conditions: error against run time.

The accuracy matrix of the measured-phasing issue: the seed 000 Table 1 gearset on the seed's
rig (Z 25/87/29, four planets, held ring, sun 18.19 r/min, 5120 Hz, 0.2 mm shaft hole errors,
white noise, hum, drift; scenarios ``rig_*`` of :mod:`meshphase.synthetic.scenarios`) under 1 % and 3 %
speed ripple at the carrier rate, 1 % at the sun rate, +-10 % ramps, both senses, three
unequally spaced planets, five planets, with and without the carrier tacho, at 20 and 10 dB,
over 2 and 10 minutes.

Per case and gauge: the per-pass RMS phasing error against the truth [mesh cycles] (every
measured pass against the true mesh angle turned between its two pulses,
:func:`meshphase.compare.predict.truth_comparison`), the floor the two onsets' timing bounds set (RMS
of the per-pass timing floor), their ratio, the target ``max(2e-3, 1.3 x floor)``, the
calibration of the per-pass uncertainty (RMS of error / sigma, share inside 1.96 sigma), the
planet-label match, whether the run flagged the phasing unreliable, the angle model chosen,
and the wall time of the processing (load to compare, not the generation). Measured, never
asserted here (tests/test_phasing_accuracy.py asserts).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np

from ..runtime.log import logger

__all__ = ["PhasingCase", "matrix_cases", "run_case", "phasing_rows", "markdown_table",
           "pooled_calibration", "error_vs_runtime_figure", "PHASING_COLUMNS", "TARGET_ABS",
           "TARGET_FLOOR_RATIO"]

#: accuracy target: per-pass RMS <= max(TARGET_ABS, TARGET_FLOOR_RATIO x floor) [mesh cycles]
TARGET_ABS = 2e-3
TARGET_FLOOR_RATIO = 1.3

PHASING_COLUMNS = ("case", "gauge", "n", "rms", "floor", "ratio", "target", "ok", "z_rms",
                   "coverage95", "label_match", "reliable", "model", "process_s")


@dataclasses.dataclass(frozen=True)
class PhasingCase:
    """One cell of the matrix.

    Attributes
    ----------
    scenario : str
        A ``rig_*`` scenario of :mod:`meshphase.synthetic.scenarios`.
    tacho : bool
        Keep the carrier tacho channel.
    snr_db : float or None
        White-noise SNR [dB] (20 log10 peak / noise RMS); None keeps the scenario's
        artefacts as they are.
    minutes : float
        Record length [min]; a ramp keeps its total speed change over the record.
    """

    scenario: str
    tacho: bool = True
    snr_db: float | None = 20.0
    minutes: float = 2.0

    @property
    def name(self) -> str:
        snr = "" if self.snr_db is None else f" {self.snr_db:g}dB"
        return f"{self.scenario}{'' if self.tacho else ' no-tacho'}{snr} {self.minutes:g}min"


_BASE = ("rig_steady", "rig_ripple1", "rig_ripple3", "rig_ripple_sun", "rig_ramp_up",
         "rig_ramp_down", "rig_ccw", "rig_3planets", "rig_5planets")


def matrix_cases(quick: bool = False) -> list[PhasingCase]:
    """The matrix: every condition at 20 dB over 2 min with the tacho; without it for the
    ripple, ramp and planet-layout cases; at 10 dB; over 10 min. ``quick``: three cells."""
    if quick:
        return [PhasingCase("rig_ripple1", minutes=1.0), PhasingCase("rig_ripple3", minutes=1.0),
                PhasingCase("rig_ripple1", tacho=False, minutes=1.0)]
    cases = [PhasingCase(s) for s in _BASE]
    cases += [PhasingCase(s, tacho=False) for s in ("rig_ripple1", "rig_ripple3", "rig_ramp_up",
                                                     "rig_ccw", "rig_3planets", "rig_5planets")]
    cases += [PhasingCase(s, snr_db=10.0) for s in ("rig_ripple1", "rig_ripple3", "rig_5planets")]
    cases += [PhasingCase(s, minutes=10.0) for s in ("rig_ripple1", "rig_ripple3", "rig_ramp_up")]
    cases += [PhasingCase("rig_ripple1", tacho=False, snr_db=10.0, minutes=10.0)]
    return cases


def case_config(case: PhasingCase):
    """The scenario's :class:`meshphase.synthetic.config.SynthConfig` changed as the case says."""
    from meshphase.synthetic.scenarios import get_scenario

    cfg = get_scenario(case.scenario)
    dur = 60.0 * case.minutes
    changes = {"duration": dur}
    if case.snr_db is not None:
        changes["artefacts"] = dataclasses.replace(cfg.artefacts, snr_db=case.snr_db)
    if not case.tacho:
        changes["tacho"] = None
    if cfg.speed.ramp_rate:
        # the same total speed change over the record, whatever its length
        sp = cfg.speed
        changes["speed"] = dataclasses.replace(sp, ramp_rate=sp.ramp_rate * cfg.duration / dur)
    return cfg.with_(**changes)


def run_case(case: PhasingCase, *, seed: int = 0, results=("phasing", "compare"),
             channels=()) -> dict:
    """Generate the case, run the scene stages on it, compare with the truth.

    ``channels``: the scene's ``[[channels]]`` entries (dicts, :mod:`meshphase.io.channels`),
    none by default (the generator's own channel kinds).

    Returns
    -------
    dict
        ``case``, ``ctx`` (the RunContext), ``process_s`` (wall time of the stages [s]),
        ``gauges``: {gear: row dict with the :data:`PHASING_COLUMNS` values}.
    """
    from ..compare.predict import truth_comparison
    from ..run.scene import Scene
    from ..run.stages import run_scene

    cfg = case_config(case)
    scene = Scene(path=None, name=case.name, results=list(results),
                  channels=[dict(c) for c in channels],
                  input={"synthetic": case.scenario, "minutes": case.minutes, "seed": seed,
                         "config": cfg})
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ctx = run_scene(scene)
    wall = time.perf_counter() - t
    rows = {}
    ph = ctx.phasing
    truth = ctx.load.truth if ctx.load is not None else None
    if ph is not None and truth is not None:
        model = ph.model
        for gear, tab in ph.tables.items():
            lab = ph.labels[gear]
            ch, times, pl = lab.channel, lab.times, lab.planet
            tc = truth_comparison(tab, truth, ch, times=times, planets=pl) if len(tab) else None
            if tc is None:
                continue
            floor = tc["floor_rms"]
            target = max(TARGET_ABS, TARGET_FLOOR_RATIO * floor) if math.isfinite(floor) else TARGET_ABS
            rows[gear] = {"case": case.name, "gauge": gear, "n": tc["n"], "rms": tc["rms"],
                          "floor": floor, "ratio": tc["rms"] / floor if floor > 0 else float("nan"),
                          "target": target, "ok": bool(tc["rms"] <= target),
                          "z_rms": tc["z_rms"], "coverage95": tc["coverage95"],
                          # a gauge whose planets cannot be named (declared relative in the
                          # run's summary) has no label to match: said, not scored as 0
                          "label_match": ("relative" if gear in (ph.labels_relative or ())
                                          else tc["label_match"]),
                          "reliable": bool((ph.reliability or {}).get(gear, {}).get("reliable", False)),
                          "model": model.terms if model is not None else "",
                          "process_s": wall, "errors": tc["errors"],
                          "sigma": np.asarray(tab.uncertainty)}
    return {"case": case, "ctx": ctx, "process_s": wall, "gauges": rows}


def phasing_rows(cases, *, seed: int = 0) -> list[dict]:
    """Table rows (one per case and gauge, :data:`PHASING_COLUMNS`) of :func:`run_case`, each
    with ``z`` (the per-pass error / sigma values, for the pooled calibration)."""
    out = []
    for case in cases:
        res = run_case(case, seed=seed)
        for gear in ("sun", "ring"):
            r = res["gauges"].get(gear)
            if r is not None:
                row = {k: r[k] for k in PHASING_COLUMNS}
                z = r["errors"] / r["sigma"]
                row["z"] = z[np.isfinite(z)].tolist()
                out.append(row)
        logger.info("phasing bench: %s done in %.1f s", case.name, res["process_s"])
    return out


def pooled_calibration(rows) -> dict:
    """RMS of error / sigma and the share inside 1.96 sigma over every pass of ``rows``."""
    z = np.concatenate([np.asarray(r.get("z", []), dtype=float) for r in rows]) if rows else np.empty(0)
    return {"n": int(z.size), "z_rms": float(np.sqrt(np.mean(z ** 2))) if z.size else float("nan"),
            "coverage95": float(np.mean(np.abs(z) <= 1.96)) if z.size else float("nan"),
            "n_ok": int(sum(bool(r["ok"]) for r in rows)), "n_rows": len(rows)}


def error_vs_runtime_figure(rows, path) -> None:
    """Scatter of error / target against processing time, one point per case and gauge
    (matplotlib through meshphase.report.figures, the one plotting module)."""
    from ..report.figures import error_vs_runtime

    curves = {}
    for r in rows:
        key = r["gauge"]
        xs, ys = curves.setdefault(key, ([], []))
        xs.append(float(r["process_s"]))
        ys.append(float(r["rms"] / r["target"]))
    srt = {k: (np.asarray(x)[np.argsort(x)], np.asarray(y)[np.argsort(x)]) for k, (x, y) in curves.items()}
    fig = error_vs_runtime(srt,
                           xlabel="processing wall time [s]",
                           ylabel="per-pass RMS error / target [-]",
                           title="measured phasing: error against run time (target = 1)")
    fig.savefig(path, dpi=90)


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float):
        if v == 0.0:
            return "0"
        return "-" if not math.isfinite(v) else (f"{v:.2e}" if abs(v) < 0.01 or abs(v) >= 1e3 else f"{v:.3g}")
    return str(v)


def markdown_table(rows, columns=None) -> str:
    """The rows as a Markdown table (``columns``: the keys shown, in order; default the
    matrix's)."""
    head = tuple(columns) if columns is not None else (
        "case", "gauge", "n", "rms", "floor", "ratio", "target", "ok", "z_rms", "coverage95",
        "label_match", "reliable", "process_s", "model")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        lines.append("| " + " | ".join(_fmt(r[k]) for k in head) + " |")
    return "\n".join(lines) + "\n"
