"""cli_synth in the four formats and the TDMS writer."""

import datetime as dt
import warnings

import numpy as np
import pytest

from meshphase.errors import DataQualityWarning
from meshphase.io import read
from meshphase.recording import Recording
from meshphase.synthetic import GroundTruth, cli_synth, generate, generate_blocks
from meshphase.io import format_for_write
from meshphase.synthetic.tdms_export import write_tdms


@pytest.mark.parametrize("suffix", [".h5", ".mcap", ".csv", ".tdms"])
def test_cli_synth_writes_recording_and_truth(tmp_path, suffix):
    out = tmp_path / f"rec{suffix}"
    path, tpath = cli_synth("gaps", out, minutes=0.2, seed=8, progress=False)
    assert path == out and tpath == tmp_path / f"rec{suffix}.truth.json"
    ref, truth = generate("gaps", duration=12.0, seed=8)
    with warnings.catch_warnings():
        # the readers announce the NaN runs of the gaps (their job, not under test here)
        warnings.simplefilter("ignore", DataQualityWarning)
        rec = read(path)
    assert rec.names == ref.names and rec.fs == ref.fs and rec.n_samples == ref.n_samples
    assert [c.kind for c in rec.channels] == [c.kind for c in ref.channels]
    if suffix == ".csv":     # text: 17 significant digits round trip, NaN kept
        np.testing.assert_allclose(rec.data, ref.data, rtol=1e-15, atol=0, equal_nan=True)
    else:
        assert np.array_equal(rec.data, ref.data, equal_nan=True)
    assert GroundTruth.read(tpath) == truth


def test_cli_synth_refuses_to_overwrite_and_bad_format(tmp_path):
    out = tmp_path / "a.tdms"
    cli_synth("seed_rig", out, minutes=0.05, seed=1, progress=False)
    with pytest.raises(FileExistsError):
        cli_synth("seed_rig", out, minutes=0.05, seed=1, progress=False)
    cli_synth("seed_rig", out, minutes=0.05, seed=2, progress=False, overwrite=True)
    assert GroundTruth.read(out).seed == 2
    with pytest.raises(ValueError, match="suffix"):
        cli_synth("seed_rig", tmp_path / "a.xyz", minutes=0.05, progress=False)
    with pytest.raises(ValueError, match="format"):
        cli_synth("seed_rig", tmp_path / "a.h5", format="wav", progress=False)
    with pytest.raises(FileNotFoundError):
        cli_synth("seed_rig", tmp_path / "missing" / "a.h5", minutes=0.05, progress=False)
    with pytest.raises(ValueError, match="minutes"):
        cli_synth("seed_rig", tmp_path / "b.h5", minutes=-1.0, progress=False)
    with pytest.raises(ValueError, match="unknown scenario"):
        cli_synth("nope", tmp_path / "c.h5", minutes=0.05, progress=False)
    assert format_for_write("x.HDF5") == "hdf5" and format_for_write("x.bin", "mcap") == "mcap"


def test_cli_synth_progress_bar(tmp_path, capsys):
    cli_synth("seed_rig", tmp_path / "p.h5", minutes=0.05, seed=1, progress=True)
    assert (tmp_path / "p.h5").exists()


def test_write_tdms_properties_and_blocks(tmp_path):
    from nptdms import TdmsFile

    stream = generate_blocks("facewidth_offcentre", duration=3.0, seed=2, block=0.7)
    p = write_tdms(iter(stream), tmp_path / "f.tdms", n_samples=stream.n_samples)
    f = TdmsFile.read(p)
    grp = f["meshphase"]
    ch = grp["ring_fw2"]
    assert ch.properties["wf_increment"] == pytest.approx(1 / 5120.0)
    assert ch.properties["unit_string"] == "m/m"
    assert ch.properties["meshphase_kind"] == "facewidth"
    assert ch.properties["meshphase_face_position"] == pytest.approx(-0.008)
    assert ch.properties["wf_start_time"] == np.datetime64("1904-01-01T00:00:00")
    assert grp["tacho"].properties["unit_string"] == "V"
    assert len(ch) == stream.n_samples
    whole, _ = generate("facewidth_offcentre", duration=3.0, seed=2)
    rec = read(p)
    assert np.array_equal(rec.data, whole.data)
    assert rec.spec("ring_fw2").face_position == pytest.approx(-0.008)
    assert rec.spec("ring_fw2").tooth == 10 and rec.spec("ring_fw2").gear == "ring"


def test_write_tdms_start_time_and_errors(tmp_path):
    rec = Recording(np.arange(10.0), 100.0, ["sun"],
                    start_datetime=dt.datetime(2024, 5, 1, 12, 0, tzinfo=dt.timezone.utc))
    p = write_tdms(rec, tmp_path / "a.tdms")
    back = read(p)
    assert back.start_datetime.startswith("2024-05-01T12:00:00")
    with pytest.raises(ValueError, match="no blocks"):
        write_tdms([], tmp_path / "b.tdms")
    assert not (tmp_path / "b.tdms").exists()
    other = Recording(np.arange(10.0), 100.0, ["sun"], t0=5.0)
    with pytest.raises(ValueError, match="consecutive"):
        write_tdms([rec, other], tmp_path / "c.tdms")
    with pytest.raises(TypeError, match="Recordings"):
        write_tdms([np.zeros(3)], tmp_path / "d.tdms")
    with pytest.raises(ValueError, match="group"):
        write_tdms(rec, tmp_path / "e.tdms", group="")
    with pytest.raises(FileExistsError):
        write_tdms(rec, p)
