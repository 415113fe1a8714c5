"""Recording, ChannelSpec and the quality array functions."""

from __future__ import annotations

import datetime as dt
import json
import sys

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from meshphase.signal.quality import (FlatRuns, chance_min_run, channel_quality, clipped_runs,
                                      dropout_runs, equal_runs, find_runs, flat_runs, nonfinite_runs,
                                      outside_runs, plateau_runs, quantisation_step)
from meshphase.recording import CHANNEL_KINDS, ChannelSpec, Recording, sample_index


def _rec(n=100, n_ch=3, fs=100.0, t0=0.0, dtype=np.float64, **kw):
    data = np.arange(n * n_ch, dtype=dtype).reshape(n, n_ch)
    specs = [ChannelSpec("sun_1", "sun"), ChannelSpec("ring_1", "ring"), ChannelSpec("tacho", "tacho", "V")][:n_ch]
    specs += [ChannelSpec(f"x{j}") for j in range(n_ch - len(specs))]
    return Recording(data, fs, specs, t0=t0, **kw)


# ---------------------------------------------------------------------------- ChannelSpec
def test_channel_spec_defaults_and_gear_from_kind():
    s = ChannelSpec("a")
    assert (s.kind, s.units, s.gain, s.gear, s.tooth, s.face_position, s.description) == \
        ("other", "m/m", 1.0, None, None, None, "")
    assert ChannelSpec("s", "sun").gear == "sun" and ChannelSpec("r", "ring").gear == "ring"
    assert ChannelSpec("f", "facewidth").gear is None
    assert ChannelSpec("t", "ring", gear="planet").gear == "planet"
    assert set(CHANNEL_KINDS) == {"sun", "ring", "facewidth", "tacho", "encoder", "other"}


def test_channel_spec_normalises_numbers():
    s = ChannelSpec("a", gain=2, tooth=np.int64(4), face_position=np.float32(0.5))
    assert type(s.gain) is float and s.tooth == 4 and type(s.tooth) is int and type(s.face_position) is float


@pytest.mark.parametrize("kw, exc, match", [
    ({"name": ""}, ValueError, "non-empty"),
    ({"name": "   "}, ValueError, "non-empty"),
    ({"name": 3}, ValueError, "non-empty"),
    ({"name": "a", "kind": "planet"}, ValueError, "kind must be one of"),
    ({"name": "a", "units": 1}, TypeError, "units must be a string"),
    ({"name": "a", "gain": 0.0}, ValueError, "gain must be non-zero"),
    ({"name": "a", "gain": float("nan")}, ValueError, "gain must be finite"),
    ({"name": "a", "gain": "1"}, TypeError, "gain must be a real number"),
    ({"name": "a", "tooth": -1}, ValueError, "tooth must be a non-negative integer"),
    ({"name": "a", "tooth": 1.5}, ValueError, "tooth must be a non-negative integer"),
    ({"name": "a", "tooth": True}, ValueError, "tooth must be a non-negative integer"),
    ({"name": "a", "face_position": "left"}, TypeError, "face_position must be a real number"),
])
def test_channel_spec_bad_input(kw, exc, match):
    with pytest.raises(exc, match=match):
        ChannelSpec(**kw)


def test_channel_spec_dict_round_trip_and_unknown_keys():
    s = ChannelSpec("fw", "facewidth", "m/m", 0.5, "planet", 3, -0.01, "left")
    assert ChannelSpec.from_dict(s.to_dict()) == s
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['colour'\]"):
        ChannelSpec.from_dict({"name": "a", "colour": "red"})
    with pytest.raises(TypeError):
        ChannelSpec.from_dict({})           # name missing


# ---------------------------------------------------------------------------- construction
def test_construction_normalises_data_and_channels():
    r = Recording(np.arange(5), 10.0, ["a"])
    assert r.data.shape == (5, 1) and r.data.dtype == np.float64
    f32 = np.zeros((4, 2), np.float32)
    r = Recording(f32, 10.0, [ChannelSpec("a"), {"name": "b", "kind": "ring"}])
    assert r.data is f32 and r.data.dtype == np.float32
    assert r.channels[1].kind == "ring" and isinstance(r.channels, tuple)
    assert Recording(f32, 10.0, ["a", "b"], copy=True).data is not f32
    r = Recording(np.zeros((2, 1)), 1.0, ["a"], start_datetime=dt.datetime(2024, 1, 2, tzinfo=dt.timezone.utc))
    assert r.start_datetime == "2024-01-02T00:00:00+00:00"


@pytest.mark.parametrize("args, kw, exc, match", [
    ((np.zeros((3, 2, 2)), 10.0, ["a", "b"]), {}, ValueError, "must be 2-D"),
    ((np.array(["a", "b"]), 10.0, ["a"]), {}, TypeError, "must be numeric"),
    ((np.zeros((3, 2)), 0.0, ["a", "b"]), {}, ValueError, "fs must be > 0"),
    ((np.zeros((3, 2)), -1.0, ["a", "b"]), {}, ValueError, "fs must be > 0"),
    ((np.zeros((3, 2)), float("inf"), ["a", "b"]), {}, ValueError, "fs must be finite"),
    ((np.zeros((3, 2)), "fast", ["a", "b"]), {}, TypeError, "fs must be a real number"),
    ((np.zeros((3, 2)), True, ["a", "b"]), {}, TypeError, "fs must be a real number"),
    ((np.zeros((3, 2)), 10.0, ["a"]), {}, ValueError, r"2 channel column\(s\) but 1 channel spec"),
    ((np.zeros((3, 2)), 10.0, ["a", "a"]), {}, ValueError, r"duplicate channel name\(s\) \['a'\]"),
    ((np.zeros((3, 2)), 10.0, ["a", 5]), {}, TypeError, "channels must be ChannelSpec, dict or str"),
    ((np.zeros((3, 1)), 10.0, ["a"]), {"t0": float("nan")}, ValueError, "t0 must be finite"),
    ((np.zeros((3, 1)), 10.0, ["a"]), {"start_datetime": 12}, TypeError, "start_datetime must be"),
])
def test_construction_bad_input(args, kw, exc, match):
    with pytest.raises(exc, match=match):
        Recording(*args, **kw)


def test_empty_recording():
    r = Recording(np.empty((0, 2)), 50.0, ["a", "b"])
    assert (r.n_samples, r.n_channels, r.duration, len(r)) == (0, 2, 0.0, 0)
    assert r.times().shape == (0,) and list(r.blocks(1.0)) == []
    assert r.slice_time(0.0, 1.0).n_samples == 0
    assert r.to_dataframe().shape == (0, 2)
    assert r.quality()[0]["n_samples"] == 0
    z = Recording(np.empty((5, 0)), 50.0, [])
    assert z.n_channels == 0 and z.names == [] and z.n_samples == 5


# ---------------------------------------------------------------------------- properties, equality
def test_basic_properties_and_times():
    r = _rec(n=200, fs=50.0, t0=-1.0)
    assert (r.n_samples, r.n_channels, r.duration, r.dt, r.t_end) == (200, 3, 4.0, 0.02, 3.0)
    assert r.names == ["sun_1", "ring_1", "tacho"]
    np.testing.assert_array_equal(r.times(), -1.0 + np.arange(200) / 50.0)
    assert "200 samples x 3 channels at 50 Hz" in repr(r)


def test_equality_is_exact_and_nan_aware():
    a = _rec()
    a.data[3, 1] = np.nan
    b = a.copy()
    assert a == b and a is not b and a.data is not b.data
    b.data[0, 0] += 1e-12
    assert a != b
    assert a != _rec(dtype=np.float32)                 # dtype matters
    assert a != Recording(a.data, a.fs, a.channels, meta={"x": 1})
    assert a != Recording(a.data, a.fs, a.channels, t0=1.0)
    assert a != Recording(a.data, a.fs, a.channels, history=[{"step": "s"}])
    assert (a == 5) is False


def test_copy_is_deep():
    a = Recording(np.zeros((3, 1)), 1.0, ["a"], meta={"g": {"z": 1}}, history=[{"step": "x"}])
    b = a.copy()
    b.meta["g"]["z"] = 2
    b.history[0]["step"] = "y"
    b.data[0, 0] = 9
    assert a.meta["g"]["z"] == 1 and a.history[0]["step"] == "x" and a.data[0, 0] == 0


# ---------------------------------------------------------------------------- channels
def test_channel_access_and_selection():
    r = _rec()
    assert r.index("ring_1") == 1 and r.spec("tacho").units == "V"
    np.testing.assert_array_equal(r.channel("tacho"), r.data[:, 2])
    assert [c.name for c in r.by_kind("sun")] == ["sun_1"] and r.by_kind("facewidth") == []
    s = r.select(["tacho", 0])
    assert s.names == ["tacho", "sun_1"]
    np.testing.assert_array_equal(s.data, r.data[:, [2, 0]])
    assert r.select(-1).names == ["tacho"] and r.select("ring_1").names == ["ring_1"]
    assert r.select(None) is r
    assert r.select([0, 1, 2]).data is r.data


@pytest.mark.parametrize("call, exc, match", [
    (lambda r: r.index("nope"), ValueError, r"no channel named 'nope'; channels are \['sun_1'"),
    (lambda r: r.by_kind("gear"), ValueError, "kind must be one of"),
    (lambda r: r.select(["sun_1", "sun_1"]), ValueError, "repeats a channel"),
    (lambda r: r.select([]), ValueError, "selection is empty"),
    (lambda r: r.select([3]), ValueError, "out of range"),
    (lambda r: r.select([True]), TypeError, "names or indices"),
    (lambda r: r.select([1.0]), TypeError, "names or indices"),
])
def test_channel_access_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call(_rec())


# ---------------------------------------------------------------------------- time
def test_slice_time_is_half_open_and_a_view():
    r = _rec(n=100, fs=10.0, t0=1.0)
    s = r.slice_time(2.0, 3.0)
    np.testing.assert_array_equal(s.times(), 2.0 + np.arange(10) / 10.0)
    assert s.t0 == 2.0 and np.shares_memory(s.data, r.data)
    assert r.slice_time(2.0, 2.05).n_samples == 1
    assert r.slice_time(0.0, 1.05).n_samples == 1          # clipped at the start
    assert r.slice_time(10.5, 100.0).n_samples == 5        # clipped at the end
    assert r.slice_time().n_samples == 100


@pytest.mark.parametrize("start, stop, match", [(11.0, 12.0, "outside the recording"),
                                                (-5.0, 1.0, "outside the recording"),
                                                (3.0, 2.0, "before start")])
def test_window_outside_the_recording(start, stop, match):
    with pytest.raises(ValueError, match=match):
        _rec(n=100, fs=10.0, t0=1.0).slice_time(start, stop)


def test_sample_index_rounding():
    fs, t0 = 5120.0, 0.3
    for i in [0, 1, 7, 5119, 123456]:
        assert sample_index(t0 + i / fs, t0, fs, 10**6) == i
    assert sample_index(t0 + 0.5 / fs, t0, fs, 100) == 1
    assert sample_index(-10.0, t0, fs, 100) == 0 and sample_index(10.0, t0, fs, 100) == 100


@settings(max_examples=100, deadline=None)
@given(n=st.integers(1, 500), fs=st.floats(0.5, 1e5), t0=st.floats(-1e3, 1e3),
       a=st.floats(0, 1), b=st.floats(0, 1))
@example(n=100, fs=2480.0, t0=1.0, a=0.0, b=1e-08)   # stop on the tolerance's edge: skipped
def test_slice_time_selects_exactly_the_half_open_window(n, fs, t0, a, b):
    r = Recording(np.zeros((n, 1)), fs, ["x"], t0=t0)
    start = t0 + min(a, b) * r.duration * 0.999
    stop = t0 + max(a, b) * r.duration
    if stop <= start:
        return
    # a time 1e-6 samples after a sample instant is the edge of sample_index's documented
    # tolerance: which side it falls on is rounding (in this reference as in the code), so
    # windows with an end within 1e-9 samples of that edge assert nothing
    for x in ((start - t0) * fs, (stop - t0) * fs):
        if abs((x - 1e-6) - round(x - 1e-6)) < 1e-9:
            return
    i0, i1 = r.sample_range(start, stop)
    t = r.times()
    inside = np.flatnonzero((t >= start - 1e-6 / fs) & (t < stop - 1e-6 / fs))
    assert (i0, i1) == ((inside[0], inside[-1] + 1) if inside.size else (i0, i0))


def test_blocks_with_overlap():
    r = _rec(n=105, fs=10.0)
    blocks = list(r.blocks(2.0, 0.5))
    assert [b.n_samples for b in blocks] == [25, 25, 25, 25, 25, 5]
    assert [b.t0 for b in blocks] == [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    np.testing.assert_array_equal(blocks[1].data, r.data[20:45])
    assert all(np.shares_memory(b.data, r.data) for b in blocks)
    np.testing.assert_array_equal(np.concatenate([b.data[:20] for b in blocks]), r.data)


@settings(max_examples=100, deadline=None)
@given(n=st.integers(0, 300), block=st.integers(1, 120), overlap=st.integers(0, 150))
def test_blocks_cover_every_sample_once_plus_overlap(n, block, overlap):
    r = Recording(np.arange(n, dtype=float), 100.0, ["x"])
    blocks = list(r.blocks(block / 100.0, overlap / 100.0))
    assert len(blocks) == -(-n // block)
    for k, b in enumerate(blocks):
        np.testing.assert_array_equal(b.data[:, 0], np.arange(k * block, min(n, (k + 1) * block + overlap)))


@pytest.mark.parametrize("block, overlap, match", [(0.0, 0.0, "block must be > 0"), (-1.0, 0.0, "block must be > 0"),
                                                   (1.0, -0.1, "overlap must be >= 0"),
                                                   ("1", 0.0, "block must be a real number")])
def test_blocks_bad_input(block, overlap, match):
    with pytest.raises((ValueError, TypeError), match=match):
        list(_rec().blocks(block, overlap))


# ---------------------------------------------------------------------------- conversions
def test_to_dataframe():
    r = _rec(n=5, fs=4.0, t0=1.0)
    df = r.to_dataframe()
    assert list(df.columns) == r.names and df.index.name == "time_s"
    np.testing.assert_array_equal(df.index.to_numpy(), r.times())
    np.testing.assert_array_equal(df.to_numpy(), r.data)
    assert df.attrs["fs"] == 4.0 and df.attrs["units"]["tacho"] == "V"
    assert r.to_dataframe(time_index=False).index.tolist() == [0, 1, 2, 3, 4]


def test_to_xarray_labels_time_channels_and_header():
    xr = pytest.importorskip("xarray")
    specs = [ChannelSpec("sun_1", "sun", tooth=3, gain=2.0),
             ChannelSpec("fw_a", "facewidth", gear="ring", face_position=-0.004),
             ChannelSpec("tacho", "tacho", "V")]
    data = np.arange(15, dtype=np.float32).reshape(5, 3)
    r = Recording(data, 4.0, specs, t0=1.0, start_datetime="2024-05-01T10:00:00+00:00",
                  meta={"rig": "B2", "z": [1, 2], "bad": float("nan")})
    da = r.to_xarray()
    assert isinstance(da, xr.DataArray) and da.dims == ("time", "channel") and da.name == "samples"
    assert da.dtype == np.float32
    np.testing.assert_array_equal(da.to_numpy(), data)
    np.testing.assert_array_equal(da["time"].to_numpy(), r.times())
    assert da["time"].attrs["units"] == "s" and da["face_position"].attrs["units"] == "m"
    assert list(da["channel"].to_numpy()) == ["sun_1", "fw_a", "tacho"]
    assert list(da["kind"].to_numpy()) == ["sun", "facewidth", "tacho"]
    assert list(da["units"].to_numpy()) == ["m/m", "m/m", "V"]
    assert list(da["gear"].to_numpy()) == ["sun", "ring", ""]
    np.testing.assert_array_equal(da["gain"].to_numpy(), [2.0, 1.0, 1.0])
    np.testing.assert_array_equal(da["tooth"].to_numpy(), [3.0, np.nan, np.nan])
    np.testing.assert_array_equal(da["face_position"].to_numpy(), [np.nan, -0.004, np.nan])
    assert da.attrs["fs"] == 4.0 and da.attrs["t0"] == 1.0
    assert da.attrs["start_datetime"] == "2024-05-01T10:00:00+00:00"
    assert json.loads(da.attrs["meta"]) == {"rig": "B2", "z": [1, 2], "bad": None}
    assert float(da.sel(channel="fw_a", time=1.5)) == 7.0       # sample 2 at t0 + 2 / fs


def test_to_xarray_of_an_empty_recording():
    pytest.importorskip("xarray")
    da = _rec(n=0).to_xarray()
    assert da.shape == (0, 3) and da["time"].size == 0
    assert da.attrs["start_datetime"] == "" and json.loads(da.attrs["meta"]) == {}


def test_to_xarray_without_xarray_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)            # import xarray raises ImportError
    with pytest.raises(ImportError, match=r"pip install \"meshphase\[xarray\]\""):
        _rec(n=3).to_xarray()


def test_header_history_and_replace_data():
    r = _rec(n=4, meta={"rig": "B2"})
    h = r.header()
    assert h["fs"] == r.fs and h["n_samples"] == 4 and h["channels"][0]["name"] == "sun_1" and h["meta"] == {"rig": "B2"}
    r2 = r.with_history("filter", band=np.array([1.0, 2.0]), order=np.int64(4))
    assert r.history == [] and r2.history[0]["step"] == "filter"
    assert r2.history[0]["band"] == [1.0, 2.0] and type(r2.history[0]["order"]) is int
    r3 = r.replace_data(np.ones((4, 3)), step="ones")
    assert r3.data.sum() == 12 and r3.history[-1]["step"] == "ones" and r3.channels == r.channels
    with pytest.raises(ValueError, match="shape"):
        r.replace_data(np.ones((3, 3)))


# ---------------------------------------------------------------------------- quality
def test_find_runs_and_nonfinite_runs():
    np.testing.assert_array_equal(find_runs([0, 1, 1, 0, 1]), [[1, 3], [4, 5]])
    assert find_runs([]).shape == (0, 2) and find_runs([False, False]).shape == (0, 2)
    np.testing.assert_array_equal(find_runs([True, True]), [[0, 2]])
    np.testing.assert_array_equal(nonfinite_runs([1, np.nan, np.inf, 2, -np.inf]), [[1, 3], [4, 5]])
    assert nonfinite_runs(np.array([])).shape == (0, 2)
    with pytest.raises(ValueError, match="1-D"):
        find_runs(np.zeros((2, 2), bool))
    with pytest.raises(ValueError, match="1-D"):
        nonfinite_runs(np.zeros((2, 2)))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.booleans(), max_size=200))
def test_find_runs_reconstructs_the_mask(mask):
    runs = find_runs(mask)
    out = np.zeros(len(mask), bool)
    for a, b in runs:
        assert b > a
        out[a:b] = True
    np.testing.assert_array_equal(out, np.asarray(mask, bool))
    assert np.all(runs[1:, 0] > runs[:-1, 1]) if len(runs) > 1 else True


def test_clipped_runs():
    x = np.array([0.0, 1.0, 5.0, 5.0, 5.0, 2.0, -3.0, -3.0, 0.0, 5.0, 5.0])
    np.testing.assert_array_equal(clipped_runs(x), [[2, 5]])
    np.testing.assert_array_equal(clipped_runs(x, min_run=2), [[2, 5], [6, 8], [9, 11]])
    assert clipped_runs(np.ones(10)).shape == (0, 2)                 # constant: nothing to clip
    assert clipped_runs(np.full(5, np.nan)).shape == (0, 2)
    assert clipped_runs(np.array([])).shape == (0, 2)
    with pytest.raises(ValueError, match="min_run"):
        clipped_runs(x, min_run=1)


def test_channel_quality_summary():
    x = np.array([1.0, np.nan, np.nan, 3.0, np.inf, -1.0])
    q = channel_quality(x)
    assert (q["n_samples"], q["n_nonfinite"], q["longest_nonfinite_run"]) == (6, 3, 2)
    assert q["nonfinite_runs"] == [[1, 3], [4, 5]] and (q["min"], q["max"]) == (-1.0, 3.0)
    assert q["rms"] == pytest.approx(np.sqrt((1 + 9 + 1) / 3))
    e = channel_quality(np.array([]))
    assert e["n_samples"] == 0 and np.isnan(e["rms"]) and e["nonfinite_runs"] == []
    r = Recording(np.column_stack([x, np.zeros(6)]), 1.0, ["a", "b"])
    assert [q["channel"] for q in r.quality()] == ["a", "b"] and r.quality()[1]["n_nonfinite"] == 0


# ---------------------------------------------------------------------------- flat runs
def _planted(seed, spec, gap_range=(20, 60)):
    """White float64 noise (never repeats a value) with planted runs of exactly equal
    samples: ``spec`` = [(length, kind)], kind "zero" (DAQ writes 0.0), "hold" (the sample
    before the run is held) or "value" (an arbitrary value). Returns (x, [start, stop) rows)."""
    rng = np.random.default_rng(seed)
    total = sum(L for L, _ in spec) + (len(spec) + 1) * gap_range[1] + 1
    x = 5.0 + rng.standard_normal(total)
    pos, runs = 0, []
    for L, kind in spec:
        pos += int(rng.integers(*gap_range))
        v = {"zero": 0.0, "hold": x[pos], "value": float(rng.normal(5.0, 3.0))}[kind]
        x[pos:pos + L] = v                       # "hold": x[pos] is the held sample itself
        runs.append([pos, pos + L])
        pos += L
    return x[:pos + gap_range[0]], runs


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1),
       spec=st.lists(st.tuples(st.integers(2, 40), st.sampled_from(["zero", "hold", "value"])),
                     max_size=8),
       floor=st.integers(2, 6))
def test_flat_runs_find_exactly_the_planted_runs_above_the_threshold(seed, spec, floor):
    x, planted = _planted(seed, spec)
    fr = flat_runs(x, min_run=floor, clip_min_run=floor)
    assert fr.min_run == fr.clip_min_run >= floor
    found = sorted(fr.dropout_runs.tolist() + fr.clipped_runs.tolist())
    assert found == [r for r in planted if r[1] - r[0] >= fr.min_run]
    # the threshold is the chance model's: noise never repeats, so p only counts the
    # planted runs themselves (upper Poisson bound over the runs of the array)
    n_runs = x.size - sum(r[1] - r[0] - 1 for r in planted)
    c = len(planted)
    p = (c + 2 * np.sqrt(c) + 3) / n_runs
    assert fr.p_equal == pytest.approx(p)
    assert fr.min_run == max(floor, chance_min_run(min(p, 1.0), x.size))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1),
       spec=st.lists(st.tuples(st.integers(2, 40), st.sampled_from(["zero", "hold", "value"])),
                     max_size=8),
       min_run=st.integers(2, 10))
def test_equal_runs_are_the_planted_runs(seed, spec, min_run):
    x, planted = _planted(seed, spec, gap_range=(1, 30))
    assert equal_runs(x, min_run=min_run).tolist() == [r for r in planted if r[1] - r[0] >= min_run]


def test_chance_min_run_is_the_smallest_improbable_length():
    # smallest L with n p^(L-1) < false_alarm: 1000 * 0.5**20 = 9.5e-4 < 1e-3 <= 1000 * 0.5**19
    assert chance_min_run(0.5, 1000, 1e-3) == 21
    for p, n in ((0.1, 3_000_000), (0.8, 307_200), (1e-4, 10**7)):
        L = chance_min_run(p, n)
        assert n * p ** (L - 1) < 1e-3 <= n * p ** (L - 2) or L == 2
    assert chance_min_run(0.0, 10**9) == 2
    assert chance_min_run(1e-9, 100) == 2                 # n p < false_alarm: even pairs are rare
    assert chance_min_run(1.0, 500) == 501                # every run is as likely as any
    assert chance_min_run(0.5, 0) == 2                    # empty channel
    with pytest.raises(ValueError, match="p"):
        chance_min_run(1.5, 100)
    with pytest.raises(TypeError, match="p"):
        chance_min_run("0.5", 100)
    with pytest.raises(ValueError, match="n"):
        chance_min_run(0.5, -1)
    with pytest.raises(TypeError, match="n"):
        chance_min_run(0.5, 10.5)
    with pytest.raises(ValueError, match="false_alarm"):
        chance_min_run(0.5, 100, 0.0)
    with pytest.raises(ValueError, match="false_alarm"):
        chance_min_run(0.5, 100, 1.0)


def test_quantisation_step():
    rng = np.random.default_rng(3)
    lsb = 2.0 * 140e-6 / 2**16                            # 16-bit over +-140 um/m
    x = np.rint(rng.normal(0.0, 20 * lsb, 50_000) / lsb) * lsb
    assert quantisation_step(x) == pytest.approx(lsb, rel=1e-9)
    assert quantisation_step(np.rint(rng.normal(0, 20, 5000)).astype(np.int16)) == 1.0
    assert quantisation_step(rng.normal(size=5000)) == 0.0           # continuous
    assert quantisation_step(np.array([])) == 0.0
    assert quantisation_step(np.full(100, np.nan)) == 0.0
    assert quantisation_step(np.ones(100)) == 0.0                     # no step to see
    with pytest.raises(ValueError, match="1-D"):
        quantisation_step(np.zeros((3, 3)))
    with pytest.raises(TypeError, match="numeric"):
        quantisation_step(np.array(["a", "b"]))


def test_equal_runs_small_cases_and_bad_input():
    x = np.array([1.0, 2, 2, 2, 3, np.nan, np.nan, 4, 4, np.inf, np.inf, np.inf, 5])
    assert equal_runs(x).tolist() == [[1, 4], [7, 9]]       # NaN and inf never form runs
    assert equal_runs(x, min_run=3).tolist() == [[1, 4]]
    assert equal_runs(np.array([])).shape == (0, 2)
    assert equal_runs(np.array([7.0])).shape == (0, 2)
    with pytest.raises(ValueError, match="min_run"):
        equal_runs(x, min_run=1)
    with pytest.raises(TypeError, match="min_run"):
        equal_runs(x, min_run=2.5)
    with pytest.raises(ValueError, match="1-D"):
        equal_runs(np.zeros((2, 2)))
    with pytest.raises(TypeError, match="numeric"):
        equal_runs(["a", "b"])


def test_flat_runs_empty_degenerate_and_bad_input():
    for x in (np.array([]), np.array([1.0]), np.full(50, np.nan)):
        fr = flat_runs(x)
        assert isinstance(fr, FlatRuns)
        assert fr.dropout_runs.shape == fr.clipped_runs.shape == (0, 2)
        assert dropout_runs(x).shape == plateau_runs(x).shape == (0, 2)
    # a constant channel has one run and no statistics to call it improbable: p = 1
    fr = flat_runs(np.zeros(10_000))
    assert fr.dropout_runs.shape == (0, 2) and fr.p_equal == 1.0
    spec = [(30, "zero"), (25, "hold"), (3, "value")]
    x, planted = _planted(1, spec)
    assert dropout_runs(x).tolist() == planted[:2]
    # ~200 samples holding 3 runs: p ~ 0.06 and a 3-sample run is no evidence (threshold 6)
    assert flat_runs(x, min_run=3).min_run == 6 and dropout_runs(x, min_run=3).tolist() == planted[:2]
    # ~150000 samples: n p^2 < 1e-3, a 3-sample run of exactly equal floats is a fault (the
    # arbitrary value, a few sigma above the noise and no jump away, reads as a clipped spike)
    x, planted = _planted(1, spec, gap_range=(40_000, 60_000))
    fr = flat_runs(x, min_run=3)
    assert fr.min_run == 3 and fr.dropout_runs.tolist()[:2] == planted[:2]
    assert sorted(fr.dropout_runs.tolist() + fr.clipped_runs.tolist()) == planted
    with pytest.raises(ValueError, match="false_alarm"):
        flat_runs(x, false_alarm=0.0)
    with pytest.raises(TypeError, match="false_alarm"):
        flat_runs(x, false_alarm="1e-3")
    with pytest.raises(ValueError, match="min_run"):
        flat_runs(x, min_run=1)
    with pytest.raises(ValueError, match="clip_min_run"):
        plateau_runs(x, clip_min_run=0)
    with pytest.raises(TypeError, match="min_run"):
        dropout_runs(x, min_run=None)
    with pytest.raises(ValueError, match="1-D"):
        flat_runs(np.zeros((4, 4)))
    with pytest.raises(TypeError, match="numeric"):
        flat_runs(np.array(["x"] * 10))


def test_flat_runs_tell_a_clip_from_a_dropout():
    # sin^2 pulses in white noise (20 dB), one clipped at 60 % of its peak (a one-polarity
    # gain-stage clip), one with its top zeroed, one whose rising flank is held
    rng = np.random.default_rng(4)
    n, w = 6000, 400
    t = np.arange(w)
    pulse = np.sin(np.pi * t / w) ** 2
    x = 0.1 * rng.standard_normal(n) + 0.3
    for s in (500, 2000, 3500, 5000):
        x[s:s + w] += pulse
    clip = x[500:900] > 0.9
    x[500:900] = np.minimum(x[500:900], 0.9)
    x[2150:2250] = 0.0
    x[3550:3650] = x[3549]
    fr = flat_runs(x)
    first, last = 500 + np.flatnonzero(clip)[[0, -1]]
    assert fr.clipped_runs.tolist() == [[first, last + 1]]
    assert fr.dropout_runs.tolist() == [[2150, 2250], [3549, 3650]]    # held: from its source
    # the other polarity: the same, mirrored
    fr = flat_runs(-x)
    assert fr.clipped_runs.tolist() == [[first, last + 1]]
    assert fr.dropout_runs.tolist() == [[2150, 2250], [3549, 3650]]
    # a dropout inside a clipped plateau stays a dropout, the plateau on either side a clip
    # (a step into another flat run is no jump; runs at other levels do not join a cluster)
    y = x.copy()
    y[5000:5400] = np.minimum(y[5000:5400], 0.9)
    c5 = 5000 + np.flatnonzero(y[5000:5400] == 0.9)[[0, -1]]
    y[5190:5210] = 0.0
    fr = flat_runs(y)
    assert fr.dropout_runs.tolist() == [[2150, 2250], [3549, 3650], [5190, 5210]]
    assert fr.clipped_runs.tolist() == [[first, last + 1], [c5[0], 5190], [5210, c5[1] + 1]]


def test_channel_quality_lists_dropouts_and_skips_a_tacho():
    x, planted = _planted(2, [(40, "zero"), (60, "hold")])
    q = channel_quality(x)
    assert q["dropout_runs"] == planted and q["n_dropout_runs"] == 2
    assert q["n_dropout_samples"] == 100 and q["longest_dropout_run"] == 60
    assert q["dropout_min_run"] >= 4 and q["n_clipped_runs"] == 0
    # a tacho sits on two levels by design: its flat runs are not dropouts
    tacho = np.where(np.arange(20_000) % 5000 < 100, 5.0, 0.0)
    assert channel_quality(tacho, kind="tacho")["n_dropout_runs"] == 0
    assert channel_quality(tacho, kind="tacho")["dropout_min_run"] is None
    assert channel_quality(tacho, kind="tacho")["clipped_runs"] == clipped_runs(tacho).tolist()
    assert channel_quality(tacho) == channel_quality(tacho, kind="tacho")   # recognised as such
    assert channel_quality(x, kind="sun") == q
    e = channel_quality(np.array([]))
    assert e["dropout_runs"] == [] and e["n_dropout_runs"] == 0 and e["longest_dropout_run"] == 0
    with pytest.raises(TypeError, match="kind"):
        channel_quality(x, kind=3)
    r = Recording(np.column_stack([x, tacho[:x.size]]), 1000.0,
                  [ChannelSpec("g", kind="sun"), ChannelSpec("t", kind="tacho", units="V")])
    rq = r.quality()
    assert rq[0]["dropout_runs"] == planted and rq[1]["dropout_runs"] == []


def test_outside_runs():
    runs = np.array([[0, 5], [10, 20], [30, 33]])
    assert outside_runs(runs, [[0, 6], [29, 40]]).tolist() == [[10, 20]]
    assert outside_runs(runs, [[11, 20]]).tolist() == runs.tolist()     # not contained
    assert outside_runs(runs, np.empty((0, 2), np.int64)).tolist() == runs.tolist()
    assert outside_runs([], [[0, 5]]).shape == (0, 2)
    with pytest.raises(ValueError, match="runs"):
        outside_runs(np.array([1, 2, 3]), [[0, 1]])
    with pytest.raises(TypeError, match="cover"):
        outside_runs(runs, [[0.5, 2.0]])
