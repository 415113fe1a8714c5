"""HDF5 files of other tools with any channel count and shape: 2-D datasets of 100 and 1000
channels, N-D datasets (one channel per index over the non-sample axes), the samples-axis
rule and its ambiguity error."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

import meshphase.io as pio
from meshphase.errors import FormatWarning
from meshphase.io import hdf5
from meshphase.io.base import RecordingFileError


@pytest.mark.parametrize("n_ch", [100, 1000])
@pytest.mark.parametrize("orient", ["samples x channels", "channels x samples"])
def test_2d_dataset_of_many_channels_reads_every_channel(tmp_path, n_ch, orient):
    rng = np.random.default_rng(n_ch)
    x = rng.normal(size=(2048, n_ch)).astype(np.float32)
    path = tmp_path / "wide.h5"
    with h5py.File(path, "w") as f:
        d = f.create_dataset("daq/data", data=x if orient.startswith("samples") else x.T, chunks=True)
        d.attrs["sample_rate"] = 1024.0
        d.attrs["channel_names"] = [f"SG{i:04d}" for i in range(n_ch)]
    info = pio.read_info(path)
    assert info.n_samples == 2048 and len(info.channels) == n_ch and info.fs == 1024.0
    assert info.names[0] == "SG0000" and info.names[-1] == f"SG{n_ch - 1:04d}"
    assert set(info.meta["hdf5"]["datasets"]) == {"daq/data"}     # the dataset's attributes once
    rec = pio.read(path)
    assert rec.data.dtype == np.float32
    np.testing.assert_array_equal(rec.data, x)
    part = hdf5.read(path, ["SG0042", "SG0003"], 100, 900)
    np.testing.assert_array_equal(part.data, x[100:900, [42, 3]])
    blocks = list(hdf5.iter_blocks(path, 500, 0))
    np.testing.assert_array_equal(np.concatenate([b.data for b in blocks]), x)


def test_2d_dataset_read_in_pieces_matches(tmp_path, monkeypatch):
    # a window bigger than one piece is read piece by piece, each column copied out
    monkeypatch.setattr(hdf5, "_PIECE_BYTES", 100 * 8 * 7)         # 7 rows of 100 float64 a piece
    x = np.arange(1000 * 100, dtype=float).reshape(1000, 100)
    path = tmp_path / "p.h5"
    with h5py.File(path, "w") as f:
        f["m"] = x
        f["m"].attrs["fs"] = 10.0
    rec = hdf5.read(path, ["m_99", "m_0", "m_50"], 3, 998)
    np.testing.assert_array_equal(rec.data, x[3:998, [99, 0, 50]])


def test_3d_dataset_is_one_channel_per_index(tmp_path):
    # (samples, a, b) -> channels name[i,j]; the samples axis is the longest, or the one an
    # attribute names
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4000, 2, 3))
    path = tmp_path / "cube.h5"
    with h5py.File(path, "w") as f:
        f["cube"] = x
        f["cube"].attrs["fs"] = 2000.0
        f["moved"] = np.moveaxis(x, 0, 2)[:, :, :10]                  # (2, 3, 10): shorter, skipped
    with pytest.warns(FormatWarning, match="skipped dataset.*moved"):
        rec = pio.read(path)
    assert rec.names == ["cube[0,0]", "cube[0,1]", "cube[0,2]", "cube[1,0]", "cube[1,1]", "cube[1,2]"]
    np.testing.assert_array_equal(rec.data, x.reshape(4000, 6))
    part = pio.read(path, ["cube[1,2]"], start=0.5, stop=1.0)
    np.testing.assert_array_equal(part.data[:, 0], x[1000:2000, 1, 2])
    with h5py.File(path, "w") as f:
        f["cube"] = np.moveaxis(x, 0, 1)                               # (2, 4000, 3)
        f["cube"].attrs["time_axis"] = 1
        f["cube"].attrs["fs"] = 2000.0
    rec = pio.read(path)
    np.testing.assert_array_equal(rec.data, x.reshape(4000, 6))


def test_samples_axis_attribute_wins_over_the_longer_axis(tmp_path):
    x = np.arange(30.0).reshape(3, 10)
    path = tmp_path / "a.h5"
    with h5py.File(path, "w") as f:
        f["m"] = x
        f["m"].attrs["sample_axis"] = 0                                # 3 samples of 10 channels
    rec = pio.read(path, fs=1.0)
    assert rec.n_samples == 3 and rec.n_channels == 10
    np.testing.assert_array_equal(rec.data, x)


@pytest.mark.parametrize("value", [2, -1, "rows", 1.5])
def test_bad_samples_axis_attribute_is_named(tmp_path, value):
    path = tmp_path / "bad.h5"
    with h5py.File(path, "w") as f:
        f["m"] = np.zeros((3, 10))
        f["m"].attrs["time_axis"] = value
    with pytest.raises(RecordingFileError, match=r"attribute time_axis = .* of dataset /m \(shape \(3, 10\)\) "
                                                  r"is not an axis 0 to 1"):
        pio.read_info(path, fs=1.0)


def test_cube_with_tied_longest_axes_is_ambiguous(tmp_path):
    path = tmp_path / "tie.h5"
    with h5py.File(path, "w") as f:
        f["cube"] = np.zeros((50, 50, 4))
    with pytest.raises(RecordingFileError, match=r"dataset /cube of shape \(50, 50, 4\).*ambiguous.*time_axis"):
        pio.read_info(path, fs=1.0)


def test_file_with_no_numeric_dataset_is_refused(tmp_path):
    path = tmp_path / "empty.h5"
    with h5py.File(path, "w") as f:
        f["empty"] = np.zeros((0, 5))
    with pytest.raises(RecordingFileError, match="no 1-D numeric dataset"):
        pio.read_info(path, fs=1.0)
