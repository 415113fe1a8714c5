"""Recordings whose every requested result comes out empty: the exit status and ``status``
follow from the results (:func:`meshphase.run.exits.run_status`), on the command and in the
Python API alike.

Each case changes a copy of 30 s of the seed rig (the shortest recording whose sun and ring
gauges both give passes: the clean copy is ``ok``, so a case's status is its fault's) with
h5py: a channel zeroed, constant, NaN or scaled, isolated +inf samples, a wrong ``fs``
attribute. The CLI runs in-process (:func:`meshphase.cli.main`), about a second per case.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from seed_rig_toml import SEED_RIG_GEARSET

import meshphase
import meshphase.io
from meshphase.cli import main
from meshphase.run.exits import EXIT_ERROR, EXIT_OK, EXIT_PARTIAL


def _scale(channels, factor):
    def edit(f):
        for c in channels:
            d = f[f"channels/{c}"]
            d[...] = d[...] * factor
    return edit


def _set(channel, value):
    def edit(f):
        d = f[f"channels/{channel}"]
        d[...] = np.full(d.shape, value)
    return edit


def _inf_ring(f):
    d = f["channels/ring"]
    x = d[...]
    x[np.random.default_rng(1).choice(x.size, x.size // 1000, replace=False)] = np.inf  # 0.1 %
    d[...] = x


def _fs(f):
    f.attrs["fs"] = 5e6


#: case -> (edit of the HDF5 file, exit code, status, {missing result: text its cause holds})
CASES = {
    "clean": (None, EXIT_OK, "ok", {}),
    "sun-all-zero": (_set("sun", 0.0), EXIT_PARTIAL, "partial", {"phasing": "sun gauge: no measured pass"}),
    "sun-constant": (_set("sun", 1e-4), EXIT_PARTIAL, "partial", {"phasing": "sun gauge: no measured pass"}),
    # the ring's passes go too: their planet-1 reference lies across the sun's gap
    "sun-all-nan": (_set("sun", np.nan), EXIT_PARTIAL, "partial",
                    {"phasing": "channel 'sun' has 1 run(s) of NaN/inf samples",
                     "compare": "no gauge"}),
    "gauges-times-1e-310": (_scale(("sun", "ring"), 1e-310), EXIT_PARTIAL, "partial",
                            {"phasing": "no usable pulse", "load_sharing": "no planet's factor",
                             "compare": "no gauge with measured phasing"}),
    "gauges-times-1e300": (_scale(("sun", "ring"), 1e300), EXIT_PARTIAL, "partial",
                           {"phasing": "their squares overflow float64",
                            "load_sharing": "no planet's factor", "compare": "no gauge"}),
    "ring-0.1%-inf": (_inf_ring, EXIT_PARTIAL, "partial",
                      {"phasing": "ring gauge: no measured pass", "load_sharing": "no planet's factor"}),
    "fs-5e6-on-5120-Hz": (_fs, EXIT_PARTIAL, "partial",
                          {"phasing": "no measured pass", "load_sharing": "no planet's factor",
                           "compare": "no gauge"}),
}


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """30 s of the seed rig as HDF5, its gearset file, and one changed copy per case."""
    from meshphase.synthetic import generate

    d = tmp_path_factory.mktemp("exit_corpus")
    rec, _ = generate("seed_rig", duration=30.0, seed=0)
    clean = Path(meshphase.io.write(rec, d / "clean.h5"))
    gearset = d / "gearset.toml"
    gearset.write_text('name = "seed rig gearset"\n' + SEED_RIG_GEARSET, encoding="utf-8")
    files = {}
    for name, (edit, *_rest) in CASES.items():
        if edit is None:
            files[name] = clean
            continue
        files[name] = d / f"{name}.h5"
        shutil.copy(clean, files[name])
        with h5py.File(files[name], "a") as f:
            edit(f)
    return {"files": files, "gearset": gearset}


@pytest.mark.parametrize("case", list(CASES))
def test_cli_status_follows_the_results(rig, case, tmp_path, capsys):
    _edit, code, status, causes = CASES[case]
    out = tmp_path / "o"
    assert main(["-q", "process", str(rig["files"][case]), "--gearset", str(rig["gearset"]),
                 "--out", str(out)]) == code
    cap = capsys.readouterr()
    summ = json.loads((out / "summary.json").read_text())
    assert summ["status"] == status
    missing = {}
    for m in summ["missing_results"]:
        missing.setdefault(m["result"], []).append(m["cause"])
    assert set(missing) == set(causes)
    for result, text in causes.items():
        assert any(text in c for c in missing[result]), (result, missing[result])
    # one "partial" line per missing result on stderr, and no raw numpy warning
    assert len(re.findall(r"^meshphase process: partial: ", cap.err, re.M)) == len(summ["missing_results"])
    assert "RuntimeWarning" not in cap.err


@pytest.mark.parametrize("case", list(CASES))
def test_api_status_is_the_clis(rig, case):
    _edit, _code, status, causes = CASES[case]
    res = meshphase.process(rig["files"][case], rig["gearset"])
    assert res.status == status
    assert res.summary()["status"] == status


def test_all_nan_recording_is_nothing_usable(rig, tmp_path, capsys):
    path = tmp_path / "all-nan.h5"
    shutil.copy(rig["files"]["clean"], path)
    with h5py.File(path, "a") as f:
        for c in ("sun", "ring", "tacho"):
            _set(c, np.nan)(f)
    out = tmp_path / "o"
    assert main(["-q", "process", str(path), "--gearset", str(rig["gearset"]), "--out", str(out)]) == EXIT_ERROR
    err = [ln for ln in capsys.readouterr().err.splitlines() if ": error: " in ln]
    assert len(err) == 1 and "nothing usable in the recording" in err[0] and "all-nan.h5" in err[0]
    assert "sun: all 153600 samples NaN/inf" in err[0] and "ring: all 153600 samples NaN/inf" in err[0]
    assert not out.exists()                     # exit 1: nothing written
    with pytest.raises(meshphase.ProcessingFailed, match="nothing usable in the recording"):
        meshphase.process(path, rig["gearset"])


def test_tdms_bit_flips_that_remove_every_sun_pass_are_partial(tmp_path, capsys):
    """Four single bit flips in the sun channel's TDMS raw data (the exponent's top bit: four
    samples of ~1e302) leave no sun pass: exit 3 naming the channel, on the CLI and the API."""
    from meshphase.synthetic import generate
    from meshphase.synthetic.tdms_export import write_tdms

    rec, _ = generate("seed_rig", duration=30.0, seed=0)
    clean = write_tdms(list(rec.blocks(1.0)), tmp_path / "clean.tdms", n_samples=rec.n_samples)
    raw = bytearray(Path(clean).read_bytes())
    sun = rec.data[:, rec.names.index("sun")]
    flipped = 0
    nonzero = np.flatnonzero(sun)
    for k in nonzero[:: nonzero.size // 16]:                  # spread over the 30 s
        at = raw.find(sun[k].tobytes())
        if at < 0 or raw.find(sun[k].tobytes(), at + 1) >= 0:  # the value's bytes, once only
            continue
        raw[at + 7] ^= 0x40
        flipped += 1
        if flipped == 4:
            break
    assert flipped == 4
    path = tmp_path / "flipped.tdms"
    path.write_bytes(bytes(raw))
    gearset = tmp_path / "gearset.toml"
    gearset.write_text('name = "seed rig gearset"\n' + SEED_RIG_GEARSET, encoding="utf-8")
    out = tmp_path / "o"
    assert main(["-q", "process", str(path), "--gearset", str(gearset), "--out", str(out)]) == EXIT_PARTIAL
    summ = json.loads((out / "summary.json").read_text())
    causes = [m["cause"] for m in summ["missing_results"] if m["result"] == "phasing"]
    assert summ["status"] == "partial" and len(causes) == 1
    assert causes[0].startswith("sun gauge: no measured pass") and "channel 'sun'" in causes[0]
    assert "RuntimeWarning" not in capsys.readouterr().err
    assert meshphase.process(path, gearset).status == "partial"


def test_every_gauge_constant_is_nothing_usable(rig, tmp_path, capsys):
    path = tmp_path / "flat.h5"
    shutil.copy(rig["files"]["clean"], path)
    with h5py.File(path, "a") as f:
        _set("sun", 0.0)(f)
        _set("ring", 2e-5)(f)
    assert main(["-q", "process", str(path), "--gearset", str(rig["gearset"]),
                 "--out", str(tmp_path / "o")]) == EXIT_ERROR
    err = [ln for ln in capsys.readouterr().err.splitlines() if ": error: " in ln]
    assert len(err) == 1 and "sun: constant 0; ring: constant 2e-05" in err[0]
    assert not (tmp_path / "o").exists()
