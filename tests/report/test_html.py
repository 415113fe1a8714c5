"""The static HTML report builder: self-contained, escaped, figures embedded."""

import base64
import re

import numpy as np
import pandas as pd
import pytest

from meshphase.report import Report
from meshphase.report import figures


def test_report_is_self_contained_and_escaped(tmp_path):
    rep = Report("Validation <rig>", "scene x")
    s = rep.section("Phasing & more")
    s.text("a < b").table(pd.DataFrame({"planet": [1, 2], "gamma": [0.25, float("nan")]}))
    s.figure(figures.load_sharing_bars([1.1, 0.9, 1.0], [1.08, 0.92, 1.0]), caption="LS")
    out = rep.write(tmp_path / "r.html")
    html = out.read_text()
    assert "Validation &lt;rig&gt;" in html and "a &lt; b" in html and "Phasing &amp; more" in html
    # no external resources: every src is a data: URI
    assert all(src.startswith("data:image/png;base64,") for src in re.findall(r'src="([^"]+)"', html))
    png = base64.b64decode(re.search(r'base64,([^"]+)"', html).group(1))
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert "<td class=''>–</td>" in html  # NaN shown as a dash, not "nan"


def test_empty_table_and_long_table(tmp_path):
    rep = Report("t")
    rep.section("empty").table([], columns=["a", "b"])
    rep.section("long").table([{"a": i} for i in range(250)], max_rows=10)
    html = rep.to_html()
    assert "240 more row(s)" in html


@pytest.mark.parametrize("fn, args", [
    (figures.signal_with_onsets, (np.linspace(0, 1, 100), np.sin(np.linspace(0, 9, 100)) * 1e-6,
                                  [0.2, 0.5], [1, 2])),
    (figures.residual_histograms, ({"sun": np.random.default_rng(0).normal(size=100), "ring": []},)),
    (figures.error_vs_runtime, ({"a": ([0.1, 1, 10], [1, 0.3, 0.1])},)),
    (figures.stage_times, (["read", "onsets"], [0.1, 0.5], ["", "1e-3 cycles"])),
    (figures.bearing_moments_bars, (["sun", "ring"], {"model": [96, -105.8], "GSAM": [90, -100]})),
    (figures.quality_overview, ([{"channel": "a", "n_nonfinite": 3, "n_clipped_runs": 1}],)),
])
def test_figures_render(fn, args):
    from meshphase.report.html import figure_to_png

    png = figure_to_png(fn(*args))
    assert png[:4] == b"\x89PNG" and len(png) > 2000


def test_phasing_over_time_with_band_and_model():
    from meshphase.report.html import figure_to_png

    df = pd.DataFrame({"time_s": [0, 1, 2, 0, 1, 2], "planet": [2, 2, 2, 3, 3, 3],
                       "gamma": [0.24, 0.26, 0.99, 0.5, 0.51, 0.49], "uncertainty": [0.01] * 6})
    fig = figures.phasing_over_time({"sun": df}, predicted={"sun": {2: ([0, 2], [0.25, 0.25])}},
                                    bands={"sun": {2: (0.2, 0.3)}}, ideal={"sun": {2: 0.25, 3: 0.5}})
    assert figure_to_png(fig)[:4] == b"\x89PNG"


def test_phasing_over_time_takes_plain_columns_as_a_dataframe():
    """The validation report hands it a pass table's columns (no pandas): the same figure,
    pixel for pixel, as from the DataFrame of the same columns; NaN uncertainty draws no
    bar in either."""
    from meshphase.report.html import figure_to_png

    cols = {"time_s": np.array([0.0, 1.0, 2.0, 0.5, 1.5, 2.5]), "planet": np.array([3, 2, 2, 3, 2, 3]),
            "gamma": np.array([0.49, 0.24, 0.99, 0.5, 0.26, 0.51]),
            "uncertainty": np.array([0.01, np.nan, 0.02, 0.01, 0.01, np.nan])}
    kw = dict(bands={"sun": {2: (0.2, 0.3)}}, ideal={"sun": {2: 0.25, 3: 0.5}})
    a = figure_to_png(figures.phasing_over_time({"sun": cols}, **kw))
    b = figure_to_png(figures.phasing_over_time({"sun": pd.DataFrame(cols)}, **kw))
    assert a == b
