"""meshphase.io.convert: the streamed conversion behind ``meshphase convert``."""

from __future__ import annotations

import numpy as np
import pytest

from meshphase.io import RecordingFileError, convert, read, write
from meshphase.recording import ChannelSpec, Recording


def _rec(n=5000, dtype=np.float64) -> Recording:
    rng = np.random.default_rng(3)
    data = rng.standard_normal((n, 2)).astype(dtype)
    return Recording(data, 5120.0, [ChannelSpec("sun_0", kind="sun"),
                                    ChannelSpec("ring_0", kind="ring")], t0=1.5)


@pytest.mark.parametrize("suffix", [".mcap", ".csv", ".h5"])
def test_convert_streams_every_block_and_names_the_source(tmp_path, suffix):
    rec = _rec()
    src = write(rec, tmp_path / "a.h5")
    bars = []

    class Bar:
        def __init__(self, total, desc):
            self.total, self.desc, self.n = total, desc, 0
            bars.append(self)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def update(self, n):
            self.n += n

    done = convert(src, tmp_path / f"b{suffix}", overwrite=True, block_samples=1024,
                   progress=Bar)
    back = read(done.path)
    np.testing.assert_array_equal(back.data, rec.data)      # lossless: repr-exact CSV too
    assert back.fs == rec.fs and back.t0 == rec.t0
    assert (done.source_format, done.n_samples, done.n_channels) == ("hdf5", 5000, 2)
    assert back.history[-1]["step"] == "convert" and back.history[-1]["source"] == str(src)
    assert len(bars) == 1 and bars[0].n == bars[0].total == 5000     # every block counted


def test_convert_keeps_float32(tmp_path):
    src = write(_rec(dtype=np.float32), tmp_path / "a.h5")
    done = convert(src, tmp_path / "b.mcap")
    assert read(done.path).data.dtype == np.float32


def test_convert_empty_recording(tmp_path):
    src = write(_rec(n=0), tmp_path / "empty.h5")
    done = convert(src, tmp_path / "empty.mcap")
    assert done.n_samples == 0 and read(done.path).n_samples == 0


def test_convert_bad_input(tmp_path):
    src = write(_rec(), tmp_path / "a.h5")
    with pytest.raises(FileExistsError):
        convert(src, src)                                   # never over an existing file
    with pytest.raises(ValueError, match="block_samples"):
        convert(src, tmp_path / "b.mcap", block_samples=0)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 64)     # HDF5 magic, nothing behind it
    with pytest.raises(RecordingFileError, match="junk.h5"):
        convert(junk, tmp_path / "c.mcap")
    with pytest.raises(FileNotFoundError):
        convert(tmp_path / "missing.h5", tmp_path / "d.mcap")
