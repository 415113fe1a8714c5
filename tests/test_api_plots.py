"""Result.plot and Recording.plot draw what they say (artists counted), _repr_html_ shows
channels / status and per-planet phasing, and neither loads matplotlib or pandas early."""

import subprocess
import sys

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.container import ErrorbarContainer  # noqa: E402

import meshphase  # noqa: E402
from meshphase.io import write  # noqa: E402
from meshphase.api.result import Result  # noqa: E402
from meshphase.recording import ChannelSpec, Recording  # noqa: E402
from meshphase.report.notebook import plot_recording  # noqa: E402
from meshphase.run.context import RunContext  # noqa: E402
from meshphase.run.scene import Scene  # noqa: E402

#: the demo rig's gearset as a scene's [gearset] table (mm); its teeth need profile shift
GEARSET = {"z_sun": 25, "z_ring": 87, "z_planet": 29, "n_planets": 4, "carrier_radius_mm": 112.5,
           "face_width_mm": 40, "direction": "cw", "profile_shift": True}


@pytest.fixture(scope="module")
def rec():
    from meshphase.synthetic import generate

    return generate("rig_ripple1", duration=60.0, seed=1)[0]


@pytest.fixture(scope="module")
def res(rec, tmp_path_factory):
    """A file processed with a dict gearset (no tolerances: no band)."""
    path = write(rec, tmp_path_factory.mktemp("rec") / "rig.h5")
    return meshphase.process(path, GEARSET)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _vlines(ax) -> list:
    return [c for c in ax.collections if isinstance(c, LineCollection)]


# ----------------------------------------------------------------------------- Result.plot
def test_plot_phasing(res):
    fig = res.plot("phasing")
    ph = res.phasing
    assert len(fig.axes) == 2
    for ax, gauge in zip(fig.axes, ("sun", "ring")):
        planets = ph[ph["gauge"] == gauge]["planet"].tolist()
        bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
        assert len(bars) == len(planets) == 3                    # one per measured planet
        dotted = [ln for ln in ax.lines if ln.get_linestyle() == ":"]
        assert len(dotted) == 3                                  # the ideal of each planet
        assert sorted(ln.get_ydata()[0] for ln in dotted) == [0.25, 0.5, 0.75]
        model = [ln for ln in ax.lines if ln.get_linestyle() == "-" and ln.get_marker() in
                 ("None", None, "")]
        assert len(model) == 3                                   # the identified model
        n = sum(len(b.lines[0].get_xdata()) for b in bars)
        assert n == len(res.context.phasing.tables[gauge])       # every pass drawn
        assert "mesh cycles" in ax.get_ylabel()
    assert fig.axes[-1].get_xlabel() == "time [s]"


def test_plot_one_gauge_into_given_axes(res):
    fig, ax = plt.subplots()
    out = res.plot("phasing", gauge="ring", ax=ax)
    assert out is fig and len(fig.axes) == 1
    assert len([c for c in ax.containers if isinstance(c, ErrorbarContainer)]) == 3
    with pytest.raises(ValueError, match="ax= draws one panel"):
        res.plot("phasing", ax=ax)


def test_plot_onsets(res):
    fig = res.plot("onsets")
    assert len(fig.axes) == 2
    for ax in fig.axes:
        assert len(ax.lines) == 1                                # the conditioned signal
        marks = _vlines(ax)
        assert len(marks) == 4                                   # one colour per planet
        assert {t.get_text() for t in ax.get_legend().get_texts()} == {
            f"planet {p}" for p in range(1, 5)}
        assert "µε" in ax.get_ylabel()


def test_plot_load_sharing(res):
    fig = res.plot("load_sharing")
    ax = fig.axes[0]
    bars = ax.patches
    assert len(bars) == 4
    np.testing.assert_allclose([b.get_height() for b in bars],
                               res.context.load_sharing.sharing.factors)


def test_plot_residuals(res):
    fig = res.plot("residuals", gauge="sun")
    ax, = fig.axes
    pts = [ln for ln in ax.lines if ln.get_marker() == "o"]
    assert len(pts) == 3
    y = np.concatenate([ln.get_ydata() for ln in pts])
    assert y.size == len(res.context.phasing.tables["sun"])
    assert np.all(np.abs(y) < 0.5)
    assert "model" in ax.get_ylabel()


def test_result_plot_bad_input(res):
    with pytest.raises(ValueError, match="kind must be one of"):
        res.plot("histogram")
    with pytest.raises(ValueError, match="kind must be one of"):
        res.plot(None)
    with pytest.raises(ValueError, match="gauge must be"):
        res.plot("phasing", gauge="planet")


def test_result_plot_of_an_empty_run():
    r = Result(RunContext(Scene(path=None, name="empty", results=[])))
    for kind in ("phasing", "onsets", "load_sharing", "residuals"):
        with pytest.raises(ValueError, match="nothing to plot"):
            r.plot(kind)


# ----------------------------------------------------------------------------- plot_recording
def test_plot_recording_with_result_onsets(rec, res):
    fig = plot_recording(rec, channels=["sun", "ring"], start=0.0, stop=10.0, onsets=res)
    assert len(fig.axes) == 2
    for ax, ch in zip(fig.axes, ("sun", "ring")):
        assert len(ax.lines) == 1
        x = ax.lines[0].get_xdata()
        assert x[0] >= 0.0 and x[-1] < 10.0
        lab = next(v for v in res.context.phasing.labels.values() if v.channel == ch)
        n_in = np.count_nonzero((lab.times >= x[0]) & (lab.times <= x[-1]))
        assert sum(len(c.get_segments()) for c in _vlines(ax)) == n_in > 0


def test_plot_recording_with_times_and_decimation(rec):
    times = np.array([1.0, 2.0, 3.0, 50.0])
    fig = plot_recording(rec, "sun", start=0.0, stop=5.0, onsets=times, max_points=1000)
    ax, = fig.axes
    assert len(ax.lines[0].get_xdata()) <= 1000
    marks = _vlines(ax)
    assert len(marks) == 1 and len(marks[0].get_segments()) == 3    # 50 s is outside
    fig2 = plot_recording(rec, start=0.0, stop=1.0)
    assert len(fig2.axes) == rec.n_channels and not any(_vlines(a) for a in fig2.axes)


def test_plot_recording_dict_onsets_and_axes(rec):
    fig, ax = plt.subplots()
    out = plot_recording(rec, "ring", 0.0, 2.0, {"ring": ([0.5, 1.5], [1, 2])}, ax=ax)
    assert out is fig
    assert len(_vlines(ax)) == 2                                 # planets 1 and 2


def test_plot_recording_empty_and_bad_input(rec):
    empty = Recording(np.empty((0, 1)), 100.0, ["x"])
    with pytest.raises(ValueError, match="empty"):
        plot_recording(empty)
    with pytest.raises(ValueError, match="no channel named"):
        plot_recording(rec, channels="nope")
    with pytest.raises(ValueError, match="outside the recording"):
        plot_recording(rec, start=1000.0, stop=1001.0)
    with pytest.raises(TypeError, match="onsets must be"):
        plot_recording(rec, "sun", 0.0, 1.0, onsets="soon")
    fig, ax = plt.subplots()
    with pytest.raises(ValueError, match="ax= draws one panel"):
        plot_recording(rec, start=0.0, stop=1.0, ax=ax)
    with pytest.raises(ValueError, match="max_points"):
        plot_recording(rec, "sun", 0.0, 1.0, max_points=1)
    with pytest.raises(TypeError, match="Recording"):
        plot_recording(rec.data)
    assert not hasattr(rec, "plot")        # plotting lives in the report, not on the Recording


def test_plot_channels_empty_and_bad_input():
    from meshphase.report.notebook import plot_channels

    spec = [ChannelSpec("x", kind="sun")]
    with pytest.raises(ValueError, match="must be samples x channels"):
        plot_channels([], np.empty((0, 1)), spec)
    with pytest.raises(ValueError, match="must be samples x channels"):
        plot_channels([0.0, 1.0], np.zeros((2, 2)), spec)
    with pytest.raises(ValueError, match="must be samples x channels"):
        plot_channels([0.0, 1.0], np.zeros(2), spec)
    fig = plot_channels([0.0, 1.0], np.array([[1e-6], [2e-6]]), spec)
    np.testing.assert_allclose(fig.axes[0].lines[0].get_ydata(), [1.0, 2.0])   # microstrain


# ----------------------------------------------------------------------------- HTML
def test_recording_repr_html(rec):
    h = rec._repr_html_()
    assert "5120 Hz" in h and "60 s" in h and "307200 samples" in h
    for c in rec.channels:
        assert f"<td style='padding:0 .6em'>{c.name}</td>" in h
    assert h.count("<tr>") == 1 + rec.n_channels


def test_recording_repr_html_escapes_and_empty():
    r = Recording(np.zeros((0, 1)), 10.0, [ChannelSpec("<b>x</b>", kind="sun", tooth=3)])
    h = r._repr_html_()
    assert "&lt;b&gt;x&lt;/b&gt;" in h and "<b>x</b>" not in h
    assert "0 samples" in h and ">tooth<" in h


def test_result_repr_html(res):
    h = res._repr_html_()
    assert "meshphase result: ok" in h
    assert "gearset Z 25/87/29, 4 planets" in h
    assert "Measured phasing per planet" in h and "Load sharing" in h
    # header + 6 planet rows (3 per gauge); header + 4 load-sharing rows
    assert h.count("<tr>") == (1 + 6) + (1 + 4)


def test_html_table_bad_input():
    from meshphase.html_repr import html_table
    from meshphase.api.result import run_html

    assert "<tbody></tbody>" in html_table([], ["a"])
    with pytest.raises(TypeError, match="rows must be"):
        html_table({"a": 1}, ["a"])
    with pytest.raises(ValueError, match="columns is empty"):
        html_table([{"a": 1}], [])
    assert "meshphase result: ok" in run_html(
        RunContext(Scene(path=None, name="e", results=[])), {"status": "ok"})


def test_repr_html_loads_neither_matplotlib_nor_pandas():
    code = ("import sys, numpy as np, meshphase; "
            "r = meshphase.Recording(np.zeros((10, 1)), 10.0, ['x']); r._repr_html_(); "
            "bad = [m for m in ('matplotlib', 'pandas') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
