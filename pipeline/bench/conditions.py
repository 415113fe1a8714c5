"""Measured phasing on the conditions where it was once confident and wrong: the accuracy table.

Each condition (:data:`CONDITIONS`) is a synthetic scenario of the seed 000 rig (Z 25/87/29,
four planets, held ring, sun 18.19 r/min, 0.2 mm shaft hole errors, 20 dB; the adversarial
scenarios of :mod:`meshphase.synthetic.scenarios`), run through the scene stages with one or
more seeds (:func:`meshphase.bench.phasing.run_case`), optionally with scene channel entries
(a wiring condition). Per condition, seed and gauge the row gives the per-pass RMS error of
the measured phasing against the truth [mesh cycles], the RMS timing floor of the passes, the
target ``max(TARGET_ABS, TARGET_FLOOR_RATIO x floor)``, the calibration of the per-pass sigma
(RMS of error / sigma, share of passes with ``|error| <= 1.96 sigma``), the share of passes
whose planet label is the truth's ("relative" where the run names the planets relative to
the first pulse), the run's verdict
("ok", or "unreliable" with its causes), the number of warnings of the run, and whether the
row meets the goal: within the target, or flagged unreliable with RMS(error / sigma) <=
:data:`FLAGGED_Z_MAX`. A run that gives no phasing for a gauge has a row saying so (``n`` 0,
verdict "none" with the run's first message naming the gauge); it meets the goal when such a
message exists. Measured, never asserted.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from ..runtime.log import logger
from ..validate import as_int, as_positive
from .phasing import PhasingCase, markdown_table, pooled_calibration, run_case

__all__ = ["Condition", "CONDITIONS", "QUICK_CONDITIONS", "CONDITION_COLUMNS", "FLAGGED_Z_MAX",
           "condition_rows", "conditions_markdown", "run_conditions"]

#: largest RMS(error / sigma) of a row flagged unreliable that still meets the goal [-]
FLAGGED_Z_MAX = 1.5

#: Columns of the accuracy table (conditions.json rows, the CSV and the Markdown).
CONDITION_COLUMNS = ("condition", "scenario", "seed", "gauge", "n", "rms", "floor", "target",
                     "within_target", "z_rms", "coverage95", "label_match", "verdict", "meets",
                     "n_warnings", "process_s")


@dataclasses.dataclass(frozen=True)
class Condition:
    """One row group of the accuracy table.

    Attributes
    ----------
    name : str
        What the condition is, as printed.
    scenario : str
        A scenario of :mod:`meshphase.synthetic.scenarios` (its artefacts kept as they are).
    seeds : tuple of int
        Generator seeds, one run each.
    channels : tuple of tuple
        Scene ``[[channels]]`` entries as ``((key, value), ...)`` tuples (empty: none).
    minutes : float
        Record length [min].
    """

    name: str
    scenario: str
    seeds: tuple = (0,)
    channels: tuple = ()
    minutes: float = 2.0

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"condition name must be a non-empty string, got {self.name!r}")
        seeds = tuple(as_int(s, f"condition {self.name!r} seed") for s in self.seeds)
        if not seeds or any(s < 0 for s in seeds):
            raise ValueError(f"condition {self.name!r}: seeds must be one or more integers >= 0, "
                             f"got {self.seeds!r}")
        object.__setattr__(self, "seeds", seeds)
        object.__setattr__(self, "minutes",
                           as_positive(self.minutes, f"condition {self.name!r} minutes"))

    @property
    def case(self) -> PhasingCase:
        """The bench case: the scenario with its own artefacts and tacho."""
        return PhasingCase(self.scenario, snr_db=None, minutes=float(self.minutes))


#: The issue's conditions (the encoder row waits for the encoder channel kind).
CONDITIONS = (
    Condition("1 % ripple at the planet spin rate", "rig_ripple_planet", (0, 1, 2)),
    Condition("the same with a 60-pulse sun-shaft encoder", "rig_ripple_planet_encoder", (0, 1, 2)),
    Condition("1 % planet-rate ripple, Z 25/85/30, 5 planets", "rig_5planets_ripple_planet"),
    Condition("sun 120 r/min, 1 % carrier ripple", "rig_fast_ripple1", (0, 1, 2)),
    Condition("pulse amplitude +-25 % once per carrier turn", "rig_load_ripple"),
    Condition("gauge channels in µε", "rig_microstrain"),
    Condition("both gauges mapped as sun by a glob", "rig_steady",
              channels=((("name", "[sr]*"), ("kind", "sun"), ("gear", "sun")),)),
    Condition("clean slow rig", "rig_clean"),
)

#: One short row: the planet-rate ripple over half a minute (a smoke run).
QUICK_CONDITIONS = (Condition("1 % ripple at the planet spin rate", "rig_ripple_planet",
                              minutes=0.5),)


def _verdict(ctx, gear: str) -> tuple[bool, str]:
    """(reliable, "ok" or "unreliable: causes") of a gauge's phasing in the run."""
    rel = ((ctx.phasing.reliability or {}) if ctx.phasing is not None else {}).get(gear, {})
    if rel.get("reliable", False):
        return True, "ok"
    reasons = "; ".join(str(r) for r in rel.get("reasons", ())) or "no reason given"
    return False, f"unreliable: {reasons}"


def condition_rows(conditions=None) -> list[dict]:
    """Rows (:data:`CONDITION_COLUMNS`, plus ``z``: the per-pass error / sigma values) of
    every condition, seed and gauge (``conditions``: default :data:`CONDITIONS`)."""
    out = []
    for cond in CONDITIONS if conditions is None else conditions:
        if not isinstance(cond, Condition):
            raise TypeError(f"conditions must hold Condition entries, got {cond!r}")
        for seed in cond.seeds:
            res = run_case(cond.case, seed=seed, channels=[dict(c) for c in cond.channels])
            ctx = res["ctx"]
            n_warn = len(ctx.messages)
            base = {"condition": cond.name, "scenario": cond.scenario, "seed": seed,
                    "n_warnings": n_warn, "process_s": res["process_s"]}
            for gear in ("sun", "ring"):
                r = res["gauges"].get(gear)
                if r is None:
                    # no phasing for this gauge: no number is no wrong answer when a message
                    # of the run names the gauge; silence is a failure of its own
                    why = next((m for m in ctx.messages if gear in m), None)
                    out.append({**base, "gauge": gear, "n": 0, "rms": math.nan, "floor": math.nan,
                                "target": math.nan, "within_target": False, "z_rms": math.nan,
                                "coverage95": math.nan, "label_match": "",
                                "verdict": f"none: {why or 'no phasing, no message naming the gauge'}",
                                "meets": why is not None, "z": []})
                    continue
                reliable, verdict = _verdict(ctx, gear)
                z = r["errors"] / r["sigma"]
                z = z[np.isfinite(z)]
                meets = bool(r["ok"] or (not reliable and r["z_rms"] <= FLAGGED_Z_MAX))
                out.append({**base, "gauge": gear, "n": r["n"], "rms": r["rms"],
                            "floor": r["floor"], "target": r["target"], "within_target": r["ok"],
                            "z_rms": r["z_rms"], "coverage95": r["coverage95"],
                            "label_match": r["label_match"], "verdict": verdict,
                            "meets": meets, "z": z.tolist()})
            logger.info("accuracy table: %s seed %d done in %.1f s", cond.name, seed,
                        res["process_s"])
    return out


def conditions_markdown(rows) -> str:
    """The table as Markdown with the pooled calibration and the count of rows meeting the
    goal underneath."""
    cal = pooled_calibration([{**r, "ok": r["meets"]} for r in rows])
    return (markdown_table(rows, CONDITION_COLUMNS)
            + f"\nPooled over {cal['n']} passes: RMS(error/sigma) {cal['z_rms']:.2f}, coverage95 "
              f"{cal['coverage95']:.3f}; {cal['n_ok']} of {cal['n_rows']} rows meet the goal "
              f"(within target, or flagged unreliable with RMS(error/sigma) <= "
              f"{FLAGGED_Z_MAX:g}).\n")


def run_conditions(out_dir, conditions=None) -> dict:
    """Run the accuracy table into ``out_dir``: ``conditions.json`` (rows without the per-pass
    values, the pooled calibration), ``conditions.csv`` and ``conditions.md``.

    ``conditions``: the :class:`Condition` entries (default :data:`CONDITIONS`).

    Returns
    -------
    dict
        ``rows``, ``pooled`` (:func:`meshphase.bench.phasing.pooled_calibration` over the
        rows, ``n_ok`` counting the rows that meet the goal), ``markdown`` and ``files``.
    """
    from ..run.table_csv import write_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = condition_rows(CONDITIONS if conditions is None else conditions)
    pooled = pooled_calibration([{**r, "ok": r["meets"]} for r in rows])
    md = conditions_markdown(rows)
    plain = [{k: r[k] for k in CONDITION_COLUMNS} for r in rows]
    files = {"json": out / "conditions.json", "csv": out / "conditions.csv",
             "md": out / "conditions.md"}
    files["json"].write_text(json.dumps({"rows": plain, "pooled": pooled}, indent=2,
                                        default=float, allow_nan=True), encoding="utf-8")
    write_csv(plain, files["csv"], columns=CONDITION_COLUMNS)
    files["md"].write_text(md, encoding="utf-8")
    return {"rows": rows, "pooled": pooled, "markdown": md,
            "files": {k: str(v) for k, v in files.items()}}
