"""Smoke run of the processing benchmark (meshphase.bench.processing): outputs and columns
only; numbers are measured, never asserted (see processing_bench.md of a full run)."""

import json

import numpy as np
import pytest

from meshphase.bench.processing import (ACCURACY_COLUMNS, THROUGHPUT_COLUMNS, PulseShape,
                                        match_onsets, pulse_scenario, pulse_train,
                                        run_processing_bench)


def test_quick_bench_writes_tables(tmp_path):
    res = run_processing_bench(tmp_path / "out", quick=True, rng=1)
    j = tmp_path / "out" / "processing_bench.json"
    md = tmp_path / "out" / "processing_bench.md"
    assert j.is_file() and md.is_file()
    data = json.loads(j.read_text())
    assert data["accuracy"] and data["throughput"]
    from meshphase.bench.conditions import CONDITION_COLUMNS

    assert data["conditions"] and all(set(CONDITION_COLUMNS) <= set(r) for r in data["conditions"])
    for row in data["accuracy"]:
        assert set(ACCURACY_COLUMNS) <= set(row)
    for row in data["throughput"]:
        assert set(THROUGHPUT_COLUMNS) <= set(row)
    settings = {r["setting"] for r in data["accuracy"]}
    assert settings == {"coarse", "refine_once", "refine_block", "refine_auto", "refine_oracle"}
    assert all(r["crb_samples"] > 0 for r in data["accuracy"])
    assert {r["stage"] for r in data["throughput"]} >= {
        "onsets.detect_onsets", "onsets.detect_onsets relearn=block", "condition.detect_hum",
        "welch detrend=linear (scipy)", "welch detrend=detrend_linear",
        "iir.sosfiltfilt engine=scipy"}
    for r in data["throughput"]:
        if r["stage"].startswith("iir.sosfiltfilt") and "scipy" not in r["stage"]:
            # the same arithmetic as scipy's
            assert r["max_diff"] <= 1e-12
    text = md.read_text()
    assert "| " + " | ".join(ACCURACY_COLUMNS) + " |" in text
    assert "| " + " | ".join(THROUGHPUT_COLUMNS) + " |" in text
    assert "| " + " | ".join(CONDITION_COLUMNS) + " |" in text
    from meshphase.bench.startup import STARTUP_COLUMNS

    assert [r["what"] for r in data["startup"]][:2] == ["python -c pass", "import meshphase"]
    assert "| " + " | ".join(STARTUP_COLUMNS) + " |" in text
    assert res["files"]["json"] == str(j)


def test_pulse_generator_truth():
    fs = 5120.0
    sh = PulseShape(100 / fs)
    # sin^2 lobe: FWHM T_c / 2, half-rise T_c / 4 after contact start
    assert sh.fwhm == pytest.approx(0.5 * 1.6 * 100 / fs)
    assert sh.rise_time(0.5) == pytest.approx(0.25 * 1.6 * 100 / fs)
    x = pulse_train(2000, fs, [500 / fs], [2.0], sh)
    assert x.max() == pytest.approx(2.0, rel=1e-3)
    assert np.argmax(x) == 500 + 80
    assert x[:400].tolist() == [0.0] * 400
    bl = PulseShape(2.5 / fs, bandlimit=0.45, fs=fs)
    assert 0 < bl.rise_time(0.5) < bl.fwhm
    x, truth = pulse_scenario(20000, fs, sh, 600 / fs, snr_db=20.0, rng=0)
    assert truth["onset"].size == truth["crb"].size > 20
    assert truth["sigma"] == pytest.approx(0.1)
    assert pulse_train(0, fs, [], 1.0, sh).shape == (0,)
    with pytest.raises(ValueError, match="bandlimit"):
        PulseShape(1e-3, bandlimit=0.6, fs=fs)


def test_pulse_rows_in_chunks_equal_all_at_once(monkeypatch):
    """The generator works on the pulse rows a chunk at a time (bounded memory: 2^24 samples
    of 2-sample pulses took 16 GB at once); added in pulse order, the train and the bounds
    are the same bit for bit as one chunk's."""
    import meshphase.bench.processing as bp

    fs = 5120.0
    sh = PulseShape(2.5 / fs, bandlimit=0.45, fs=fs)      # overlapping rows: 258 samples each
    whole = pulse_scenario(6000, fs, sh, 15 / fs, snr_db=20.0, rng=3)
    monkeypatch.setattr(bp, "_PULSE_ROW_SAMPLES", 1000)  # 3 rows per chunk
    assert len(bp._pulse_chunks(whole[1]["crb"].size, 258)) > 100
    parts = pulse_scenario(6000, fs, sh, 15 / fs, snr_db=20.0, rng=3)
    assert np.array_equal(parts[0], whole[0])
    assert np.array_equal(parts[1]["crb"], whole[1]["crb"])
    assert bp._pulse_chunks(0, 258) == []
    assert bp._pulse_chunks(5, 10 ** 9) == [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)]


def test_match_onsets_one_to_one():
    it, idt = match_onsets([1.0, 1.05, 3.0], [1.02, 2.0, 3.01], 0.1)
    assert it.tolist() == [0, 2] and idt.tolist() == [0, 2]
    it, idt = match_onsets([1.0, 1.03], [1.02, 1.033], 0.1)     # both want 1.03
    assert it.tolist() == [1] and idt.tolist() == [1]
    e1, e2 = match_onsets([], [1.0], 0.1)
    assert e1.size == e2.size == 0
