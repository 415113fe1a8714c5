"""Member speeds, the identification's combinations and the report's verdict on recordings of
the independent rig (tests/independent/rig.py): a held ring (sun 18.19 r/min, the Table 2
case 1 hole errors), a held carrier whose ring turns (sun 18.19 r/min, no tacho) and a held
sun whose ring turns (carrier 1.06 r/min), processed through a scene as a user would."""

import json
import math
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from meshphase.run.scene import parse_scene
from meshphase.run.stages import run_scene, write_outputs

from . import rig as R
from .test_meshphase_on_rig import _errors, scene_text

#: a steady 1-minute record: the angle model's mean mesh frequency is its end-to-end mesh
#: angle (~350 cycles, known to ~1e-3 cycles) over the time, so 1e-5 relative is ~30x the
#: error measured (4e-7 for the held ring, 1e-6 for the star)
REL = 1e-5


def _run(tmp: Path, name: str, minutes: float = 1.0, **config):
    p = tmp / f"{name}.tdms"
    truth = R.make_rig_tdms(p, minutes=minutes, seed=3, **config)
    scene = tmp / f"{name}.toml"
    scene.write_text(scene_text(truth, p).replace('results = ["phasing", "compare"]',
                                                   'results = ["phasing", "compare", "identify"]'),
                     encoding="utf-8")
    return run_scene(parse_scene(scene.read_text(encoding="utf-8"), scene)), truth


@pytest.fixture(scope="module")
def held(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("speeds_held")
    ctx, truth = _run(tmp, "held", fixed="ring", sun_rpm=18.19, errors=_errors(4))
    out = tmp / "out"
    out.mkdir()
    write_outputs(ctx, out)
    return ctx, truth, out


class _Summary(HTMLParser):
    """The text of the paragraphs with class "verdict" inside the section titled Summary."""

    def __init__(self):
        super().__init__()
        self.section, self.in_h2, self.in_verdict = None, False, False
        self.verdicts = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "h2":
            self.in_h2 = True
        elif tag == "p" and a.get("class") == "verdict" and self.section == "Summary":
            self.in_verdict = True
            self.verdicts.append("")

    def handle_endtag(self, tag):
        if tag == "h2":
            self.in_h2 = False
        elif tag == "p":
            self.in_verdict = False

    def handle_data(self, data):
        if self.in_h2:
            self.section = data.strip()
        elif self.in_verdict:
            self.verdicts[-1] += data


def test_held_ring_speeds(held):
    ctx, truth, _ = held
    sp = ctx.phasing.member_speeds
    assert sp["held"] == "ring" and sp["ring"] == 0.0
    assert sp["sun"] == pytest.approx(truth.speeds["sun_rpm"], rel=REL)
    assert sp["carrier"] == pytest.approx(truth.speeds["carrier_rpm"], rel=REL)
    # the rig's planet_rel_rad_s is the spin relative to the carrier
    assert sp["planet_relative"] == pytest.approx(truth.speeds["planet_rel_rad_s"] * 60 / (2 * math.pi),
                                                  rel=REL)


def test_star_ring_turns(tmp_path):
    ctx, truth = _run(tmp_path, "star", fixed="carrier", sun_rpm=18.19, tacho=False)
    sp = ctx.phasing.member_speeds
    assert sp["held"] is None and sp["carrier"] == 0.0
    assert sp["ring"] == pytest.approx(truth.speeds["ring_rpm"], rel=REL)     # -5.227 r/min
    assert sp["sun"] == pytest.approx(truth.speeds["sun_rpm"], rel=REL)
    assert "the ring turns at -5.227 r/min" in sp["text"]


def test_held_sun_carrier_1_06_ring_turns(tmp_path):
    # the sun held, the carrier driven at 1.06 r/min (3 min: 13 sun-gauge passes): the ring
    # turns at 1.3646 r/min. The slow mesh (0.44 Hz) leaves the ring gauge without usable
    # pulses; the sun gauge's passes alone give the mesh frequency
    ctx, truth = _run(tmp_path, "sun_held", fixed="sun", carrier_rpm=1.06, minutes=3.0)
    sp = ctx.phasing.member_speeds
    assert sp["held"] == "sun" and sp["sun"] == 0.0
    assert sp["carrier"] == pytest.approx(truth.speeds["carrier_rpm"], rel=REL)
    assert sp["ring"] == pytest.approx(truth.speeds["ring_rpm"], rel=REL)
    assert sp["text"].startswith("sun held; sun 0 r/min, carrier 1.06 r/min, ring 1.365 r/min")


def test_report_summary_opens_with_the_verdict(held):
    ctx, truth, out = held
    summary = json.loads((out / "summary.json").read_text())
    ident = summary["identify"]
    parser = _Summary()
    parser.feed((out / "report.html").read_text(encoding="utf-8"))
    assert len(parser.verdicts) == 1
    text = parser.verdicts[0]
    assert text == summary["verdict"]
    assert f"from {ident['rms_before']:.3g} to {ident['rms_after']:.3g} mesh cycles" in text
    assert f"determine {ident['rank']} combination(s) of the 12 offset components" in text
    best = ident["combinations"][0]
    assert f"{best['estimate'] * 1e3:.4g} mm (95 % interval {best['ci95'][0] * 1e3:.4g} to" in text
    assert "Member speeds: ring held; sun 18.19 r/min, carrier 4.06 r/min, ring 0 r/min" in text
    assert summary["member_speeds_rpm"]["sun"] == pytest.approx(18.19, rel=REL)


def test_combinations_file_matches_the_summary(held):
    _, _, out = held
    summary = json.loads((out / "summary.json").read_text())
    combos = summary["identify"]["combinations"]
    df = pd.read_csv(out / "identified_combinations.csv")
    assert len(df) == len(combos) == summary["identify"]["rank"] > 0
    assert list(df["combination"]) == list(range(1, len(combos) + 1))
    assert df["std_m"].is_monotonic_increasing
    assert (df["ci95_lo_m"] < df["estimate_m"]).all() and (df["estimate_m"] < df["ci95_hi_m"]).all()
    coef = df[[c for c in df.columns if c.startswith("coef_")]].to_numpy()
    assert abs((coef ** 2).sum(axis=1) - 1.0).max() < 1e-9
    errors = pd.read_csv(out / "identified_errors.csv")
    blind = errors.loc[~errors["identifiable"]]
    assert blind["identified_by"].notna().all()


@pytest.mark.slow
def test_suggested_second_ring_gauge_on_the_rig(tmp_path):
    # Two recordings of the same rig motion (2 min, held ring, planet offsets only), the
    # ring gauge at its usual angle and a quarter turn further. With one ring gauge the
    # planets are not identifiable one by one and the suggestion is that second gauge;
    # fitting the sun gauge and both ring gauges identifies every planet, with standard
    # errors as predicted (measured 3.46e-5 against 3.35e-5 m; bound a factor 1.5).
    # Measured but not asserted: the estimates of the newly determined (weakest) direction
    # lie 0.2-0.3 mm from the rig's truth, several standard errors: the rig's recordings
    # carry a systematic misfit there that the statistical prediction does not include.
    from meshphase.compare.identify import identify_errors

    err = {"e_planet": (0.2e-3, 0.1e-3, 0.3e-3, 0.15e-3), "kappa_planet": (0.3, 1.5, 2.9, 4.4)}
    base = R.make_rig_config(minutes=2.0).ring_gauge_angle
    runs = [_run(tmp_path, f"g{k}", fixed="ring", sun_rpm=18.19, errors=err,
                 ring_gauge_angle=base + k * math.pi / 2)[0] for k in (0, 1)]
    one = runs[0].identify.identification
    sugg = {s["gear"]: s for s in one.suggestions}
    for n in range(1, 5):
        assert sugg[f"planet{n}"]["option"] == "add a second ring gauge a quarter turn from the first"
    tabs = [runs[0].phasing.tables["sun"], runs[0].phasing.tables["ring"],
            runs[1].phasing.tables["ring"]]
    both = identify_errors(tabs, runs[0].gearset)
    planets = [r for r in both.table if r["gear"].startswith("planet")]
    assert all(r["identifiable"] for r in planets)
    for r in planets:
        pred = sugg[r["gear"]]["predicted_std"]
        got = max(both.parameters[f"{r['gear']}_x"][1], both.parameters[f"{r['gear']}_y"][1])
        assert pred / 1.5 < got < pred * 1.5, (r["gear"], pred, got)
