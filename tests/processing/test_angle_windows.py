"""meshphase.kinematics.angle_windows: the angle model of long records in bounded memory.

Truth: exact engagement instants from meshphase.synthetic.kinematics (tests/processing/test_angles.py's
``trains_from_truth``), timing jitter 20 us with its sigma given, so the per-pass error
against truth and the reported uncertainty can be compared directly.
"""

from __future__ import annotations

import json
import tracemalloc

import numpy as np
import pytest

from meshphase.kinematics.angle_windows import WindowedAngleModel, fit_angle_windows
from meshphase.kinematics.angles import fit_angle_model
from meshphase.kinematics.shafts import kinematics
from meshphase.jsonable import to_jsonable
from meshphase.models.tolerance import table2_case
from meshphase.synthetic.kinematics import ShaftRipple, SpeedProfile

from test_angles import per_pass_error, rig, trains_from_truth  # tests/processing, on sys.path

KIN = kinematics(25, 87, 29, fixed="ring")


@pytest.fixture(scope="module")
def long_record():
    # 20 min of the seed rig: 1 % carrier-locked ripple, 10 % ramp, a 2 % speed drift with a
    # 10-min period (what a long test-rig run does), Table 2 case 1 hole errors
    g, sp = rig()
    dur = 1200.0
    prof = SpeedProfile(ramp_rate=0.1 / dur, ripple=((0.02, 1.0 / 600.0, 0.1),),
                        shaft=(ShaftRipple("carrier", 0.01, 1, 0.4),))
    trains, ev = trains_from_truth(g, sp, prof, dur, errors=table2_case(1)[2], jitter=2e-5,
                                   sigma=2e-5)
    return trains, ev


@pytest.fixture(scope="module")
def windowed(long_record):
    return fit_angle_windows(long_record[0], KIN, 4, max_obs=1500)


def test_short_record_is_the_whole_fit_exactly(long_record):
    trains, _ = long_record
    short = [t for t in trains]
    m1 = fit_angle_windows(short, KIN, 4, max_obs=10 ** 6)
    m2 = fit_angle_model(short, KIN, 4)
    assert type(m1) is type(m2) and not isinstance(m1, WindowedAngleModel)
    t = np.linspace(10.0, 1100.0, 50)
    assert np.array_equal(m1.mesh_angle(t), m2.mesh_angle(t))


def test_windows_follow_the_truth_as_well_as_the_whole_fit(long_record, windowed):
    """Per-pass error against truth with windows no worse than 1.1x the whole-record fit's
    (measured: 0.69x / 0.68x: a window's linear ripple modulation follows a slow drift
    better), and the reported uncertainty stays calibrated: RMS(error / sigma) in [0.5, 1.5]
    (measured 0.68 / 1.07)."""
    trains, ev = long_record
    whole = fit_angle_model(trains, KIN, 4)
    win = windowed
    assert isinstance(win, WindowedAngleModel) and len(win.windows) >= 2
    assert win.converged
    for tr in trains[:2]:
        e_w, tab_w = per_pass_error(win, tr, ev, 4)
        e_a, tab_a = per_pass_error(whole, tr, ev, 4)
        assert len(tab_w) == len(tab_a)
        rms_w, rms_a = (float(np.sqrt(np.mean(e ** 2))) for e in (e_w, e_a))
        assert rms_w <= 1.1 * rms_a, (tr.name, rms_w, rms_a)
        z = float(np.sqrt(np.mean((e_w / tab_w.uncertainty) ** 2)))
        assert 0.5 <= z <= 1.5, (tr.name, z)


def test_angle_and_rate_are_continuous_across_the_stitches(long_record, windowed):
    trains, _ = long_record
    win = windowed
    h = win.margin
    for b in win.bounds:
        # across the blend's ends and its middle the angle moves by rate x dt, no jump:
        # a step would show as a residual of the size of the stitch misfit (~1e-3 cycles)
        for tb in (b - h, b, b + h):
            t = tb + np.array([-1e-3, 1e-3])
            a = win.mesh_angle(t)
            r = win.mesh_rate(np.array([tb]))[0]
            assert abs((a[1] - a[0]) - r * 2e-3) < 1e-7
    # dA/dt is the derivative of A (central differences, 1e-4 relative)
    t = np.linspace(trains[0].times[5], trains[0].times[-5], 400)
    d = (win.mesh_angle(t + 1e-3) - win.mesh_angle(t - 1e-3)) / 2e-3
    assert np.allclose(d, win.mesh_rate(t), rtol=1e-4)
    assert np.all(win.stitch_rms < 1e-2)


def test_per_train_views_cover_every_observation_once(long_record, windowed):
    trains, _ = long_record
    win = windowed
    for tr in trains:
        t, r = win.residuals(tr.name)
        om = win.outlier_mask(tr.name)
        assert om.shape == (len(tr),)
        assert np.array_equal(t, tr.times)          # each pass from exactly one core
        fit = win.train(tr.name)
        assert fit.n + fit.n_outliers == len(tr)
    json.dumps(to_jsonable(win.summary()), allow_nan=False)
    assert len(win.summary()["windows"]) == len(win.windows)


def test_memory_is_bounded_by_the_window_not_the_record():
    """Peak traced memory of the fit for 10 and 30 min of the seed rig in windows of 1000
    observations: the 30-min fit may take at most 1.5x the 10-min one (the trains and the
    windows' kept results grow; the working Jacobian does not). A whole-record fit grows
    about 3x over the same step."""
    g, sp = rig()
    peaks = []
    for dur in (600.0, 1800.0):
        trains, _ = trains_from_truth(g, sp, SpeedProfile(shaft=(ShaftRipple("carrier", 0.01, 1, 0.4),)),
                                      dur, jitter=2e-5, sigma=2e-5)
        trains = trains[:2] * 3 + trains[2:]
        trains = [type(t)(**{**vars(t), "name": f"{t.name}{i}"}) for i, t in enumerate(trains)]
        tracemalloc.start()
        fit_angle_windows(trains, KIN, 4, max_obs=1000)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < 1.5 * peaks[0], peaks


def test_empty_and_bad_input():
    g, sp = rig()
    with pytest.raises(ValueError, match="gauge train"):
        fit_angle_windows([], KIN, 4)
    with pytest.raises(TypeError, match="PassTrain"):
        fit_angle_windows([object()], KIN, 4)
    trains, _ = trains_from_truth(g, sp, SpeedProfile(), 60.0)
    for bad in (0, 99, 1.5, True, "x"):
        with pytest.raises(ValueError, match="max_obs"):
            fit_angle_windows(trains, KIN, 4, max_obs=bad)
    with pytest.raises(ValueError, match="n_planets"):
        fit_angle_windows(trains, KIN, 0)



def test_windows_on_threads_equal_the_serial_fit(long_record, windowed):
    """The windows are fitted side by side on the run's threads; each window is fitted
    whole on one thread, so the model is the serial one bit for bit, and progress still
    counts every window once, in order."""
    from meshphase.runtime.threads import threads_limited

    trains, _ = long_record
    seen = []
    with threads_limited(1):
        serial = fit_angle_windows(trains, KIN, 4, max_obs=1500,
                                   progress=lambda k, n: seen.append((k, n)))
    assert isinstance(serial, WindowedAngleModel)
    k = len(serial.windows)
    assert seen == [(j + 1, k) for j in range(k)]
    t = np.linspace(*serial.t_span, 2001)
    for threaded in (windowed,):             # fitted with the default (2+ threads here)
        np.testing.assert_array_equal(threaded.mesh_angle(t), serial.mesh_angle(t))
        np.testing.assert_array_equal(threaded.mesh_rate(t), serial.mesh_rate(t))
        assert threaded.terms == serial.terms and threaded.selection == serial.selection
    with threads_limited(2):
        again = fit_angle_windows(trains, KIN, 4, max_obs=1500)
    np.testing.assert_array_equal(again.mesh_angle(t), serial.mesh_angle(t))


def test_a_failing_window_names_itself_on_threads(long_record, monkeypatch):
    """A window whose fit raises is named in the error (the first such window, in time
    order), whether the windows ran on one thread or two."""
    import meshphase.kinematics.angle_windows as aw
    from meshphase.runtime.threads import threads_limited

    trains, _ = long_record
    calls = []
    orig = aw.fit_angle_model

    def failing(subs, *a, **k):
        calls.append(1)
        if subs[0].times[0] > 300.0:
            raise ValueError("too few passes")
        return orig(subs, *a, **k)

    monkeypatch.setattr(aw, "fit_angle_model", failing)
    for n in (1, 2):
        with threads_limited(n), pytest.raises(ValueError, match=r"angle model window \d+ of \d+"):
            fit_angle_windows(trains, KIN, 4, max_obs=1500)


def test_a_window_warning_reaches_the_caller_from_a_worker_thread(long_record, monkeypatch):
    """A window fit's ProcessingWarning (a fit that did not converge) is raised on a worker
    thread; the run collects warnings with catch_warnings in the calling thread, so it must
    arrive there (once per window that warns)."""
    import warnings

    import meshphase.kinematics.angle_windows as aw
    from meshphase.errors import ProcessingWarning
    from meshphase.runtime.threads import threads_limited

    trains, _ = long_record
    orig = aw.fit_angle_model

    def warning(subs, *a, **k):
        warnings.warn(f"window at {subs[0].times[0]:.0f} s did not converge", ProcessingWarning)
        return orig(subs, *a, **k)

    monkeypatch.setattr(aw, "fit_angle_model", warning)
    with threads_limited(2), warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ProcessingWarning)
        model = fit_angle_windows(trains, KIN, 4, max_obs=1500)
    mine = [w for w in caught if issubclass(w.category, ProcessingWarning)]
    assert len(mine) == len(model.windows) >= 2


def test_windowed_model_choice_comes_from_each_pairs_window():
    # 4 min of the planet-rate ripple passes (test_angles: a common ripple and equal planet
    # terms the gauges cannot tell apart) in windows of 300 observations: each pair's
    # spread is its own window's, a competitor named in several windows is reported once,
    # and the spread still covers the error (RMS(error / sigma) <= 1.5, as for one fit)
    from test_angles import _planet_rate_ripple_trains

    trains, ev, kin = _planet_rate_ripple_trains(False, 240.0)
    win = fit_angle_windows(trains, kin, 4, max_obs=300)
    assert isinstance(win, WindowedAngleModel) and len(win.windows) >= 2
    err, tab = per_pass_error(win, trains[0], ev, 4)
    assert float(np.sqrt(np.mean((err / tab.uncertainty) ** 2))) <= 1.5
    keys = [(c["words"], c["versus"], c["inseparable"]) for c in tab.competitors]
    assert len(keys) == len(set(keys)) and any(k[2] for k in keys)
    assert sum(c["n"] for c in tab.competitors if c["inseparable"]) == len(tab)
    spread, _ = win.choice_spread(tab.time, tab.ref_time)
    k = np.searchsorted(win.bounds, 0.5 * (tab.time + tab.ref_time), side="right")
    assert len(set(k.tolist())) >= 2
    for j, w in enumerate(win.windows):
        m = k == j
        if np.any(m):
            assert np.array_equal(spread[m], w.choice_spread(tab.time[m], tab.ref_time[m])[0])
    spread, info = win.choice_spread([], [])
    assert spread.shape == (0,) and info == []
    with pytest.raises(ValueError, match="one shape"):
        win.choice_spread(tab.time[:3], tab.ref_time[:2])
