"""MATLAB MAT-files: v5 (scipy.io.savemat, plain and compressed) and v7.3 (laid out as
MATLAB's ``save -v7.3`` writes them, as cited below) for each
recognised layout; detection beside HDF5; the lazy v7.3 reads; the errors.

v5: ``scipy.io.savemat``. v7.3: h5py, laid out as MATLAB's ``save -v7.3`` lays them out
(hdf5storage's "Storage Format" page and MathWorks' MAT-file version notes describe it): a
512-byte user block whose first 116 bytes are the header text ``MATLAB 7.3 MAT-file,
Platform: ..., Created on: ... HDF5 schema 1.00 .`` padded with spaces, then 8 zero bytes
(subsystem offset), the version 0x0200 and the endian indicator ``IM``; every variable a
dataset (or, for a struct, a group) with a ``MATLAB_class`` attribute; arrays stored
column-major, so a MATLAB ``m x n`` array is an HDF5 dataset of shape ``(n, m)`` (an N x 1
vector: ``(1, N)``); text as uint16 UTF-16 code units (class ``char``,
``MATLAB_int_decode`` 2); a cell array as a dataset of object references into ``/#refs#``;
a struct as a group with its field names in ``MATLAB_fields``; gzip-compressed chunks.
"""

from __future__ import annotations

import itertools

import h5py
import numpy as np
import pytest
import scipy.io as sio

import meshphase.io as pio
from meshphase.cli import main
from meshphase.errors import FormatWarning
from meshphase.io import matlab
from meshphase.io.base import CorruptFileError, RecordingFileError
from meshphase.recording import Recording


# ---------------------------------------------------------------------------- MATLAB's v7.3 layout
HEADER = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Feb 07 02:29:00 2014 HDF5 schema 1.00 ."
_CLASS = {np.dtype(np.float64): "double", np.dtype(np.float32): "single", np.dtype(np.int16): "int16",
          np.dtype(np.int32): "int32", np.dtype(np.uint8): "uint8", np.dtype(np.int64): "int64"}


def _cls(obj, name: str) -> None:
    obj.attrs["MATLAB_class"] = np.bytes_(name)


def _char(group, name: str, text: str):
    codes = np.array([ord(c) for c in text], dtype=np.uint16).reshape(-1, 1)   # 1 x L -> (L, 1)
    if not text:
        ds = group.create_dataset(name, data=np.array([0, 0], dtype=np.uint64))
        ds.attrs["MATLAB_empty"] = np.uint8(1)
    else:
        ds = group.create_dataset(name, data=codes)
    _cls(ds, "char")
    ds.attrs["MATLAB_int_decode"] = np.int32(2)
    return ds


def _write(f, group, name: str, value, counter) -> None:
    if isinstance(value, dict):
        g = group.create_group(name)
        _cls(g, "struct")
        vl = h5py.vlen_dtype(np.dtype("S1"))
        fields = np.empty(len(value), dtype=vl)
        for i, k in enumerate(value):
            fields[i] = np.array([c.encode("ascii") for c in k], dtype="S1")
        g.attrs.create("MATLAB_fields", fields, dtype=vl)
        for k, v in value.items():
            _write(f, g, k, v, counter)
        return
    if isinstance(value, str):
        _char(group, name, value)
        return
    if isinstance(value, list):                                   # a 1 x K cellstr
        refs = f.require_group("#refs#")
        out = np.empty((len(value), 1), dtype=h5py.ref_dtype)     # 1 x K -> (K, 1)
        for i, s in enumerate(value):
            out[i, 0] = _char(refs, f"r{next(counter)}", s).ref
        ds = group.create_dataset(name, data=out, dtype=h5py.ref_dtype)
        _cls(ds, "cell")
        return
    a = np.asarray(value)
    if a.ndim == 0:
        a = a.reshape(1, 1)
    elif a.ndim == 1:
        a = a.reshape(-1, 1)                                      # MATLAB's column vector N x 1
    data = a.T                                                    # column-major: (n, m)
    kw = {"compression": "gzip", "chunks": True} if a.size > 64 else {}
    ds = group.create_dataset(name, data=data, **kw)
    _cls(ds, "logical" if a.dtype == bool else _CLASS[a.dtype])


def write_v73(path, variables: dict) -> None:
    """A MATLAB 7.3 MAT-file of ``variables``: name -> ndarray (MATLAB orientation; a 1-D
    array is an N x 1 column vector), float (1 x 1), str (char), list of str (cellstr),
    dict (struct)."""
    counter = itertools.count()
    with h5py.File(path, "w", userblock_size=512) as f:
        for k, v in variables.items():
            _write(f, f, k, v, counter)
    with open(path, "r+b") as fh:
        fh.write(HEADER.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02" + b"IM")


FS = 2560.0
N = 3000
VERSIONS = ["v5", "v5 compressed", "v7.3"]


def _save(path, variables: dict, version: str):
    if version == "v7.3":
        write_v73(path, variables)
    else:
        sio.savemat(path, variables, do_compression=version.endswith("compressed"))
    return path


@pytest.fixture(scope="module")
def x():
    return np.random.default_rng(42).normal(size=(N, 3))


def _t(t0=0.0):
    return t0 + np.arange(N) / FS


LAYOUTS = {
    # (a) one variable per channel, a time vector (starting at 2 s) and a units struct
    "vectors + t": lambda x: ({"t": _t(2.0), "sun_T3": x[:, 0], "ring_1": x[:, 1], "tacho": x[:, 2],
                               "units": {"sun_T3": "ue", "tacho": "V"}},
                              {"sun_T3": 0, "ring_1": 1, "tacho": 2}, 2.0, {"sun_T3": "ue", "tacho": "V"}),
    "vectors + Fs": lambda x: ({"Fs": FS, "sun_T3": x[:, 0], "ring_1": x[:, 1]},
                               {"sun_T3": 0, "ring_1": 1}, 0.0, {}),
    "vectors + dt": lambda x: ({"dt": 1 / FS, "sun_T3": x[:, 0]}, {"sun_T3": 0}, 0.0, {}),
    # (b) one matrix with names, samples x channels or channels x samples
    "matrix samples x channels": lambda x: ({"data": x, "channel_names": ["sun_T3", "ring_1", "tacho"],
                                             "units": ["ue", "ue", "V"], "fs": FS},
                                            {"sun_T3": 0, "ring_1": 1, "tacho": 2}, 0.0,
                                            {"sun_T3": "ue", "ring_1": "ue", "tacho": "V"}),
    "matrix channels x samples": lambda x: ({"M": np.ascontiguousarray(x.T), "names": ["sun_T3", "ring_1", "tacho"],
                                             "SampleRate": FS},
                                            {"sun_T3": 0, "ring_1": 1, "tacho": 2}, 0.0, {}),
    "matrix with a time column": lambda x: ({"log": np.c_[_t(1.5), x[:, :2]], "names": ["Time", "sun", "ring"]},
                                            {"sun": 0, "ring": 1}, 1.5, {}),
    # (c) a struct of channels, its rate and units struct
    "struct": lambda x: ({"data": {"fs": FS, "sun_T3": x[:, 0], "ring_1": x[:, 1],
                                   "units": {"sun_T3": "ue"}}},
                         {"sun_T3": 0, "ring_1": 1}, 0.0, {"sun_T3": "ue"}),
    "nested struct": lambda x: ({"rec": {"fs": FS, "strain": {"sun_T3": x[:, 0], "ring_1": x[:, 1]},
                                         "speed": {"tacho": x[:, 2]}}},
                                {"sun_T3": 0, "ring_1": 1, "tacho": 2}, 0.0, {}),
    "struct per channel": lambda x: ({"sun_T3": {"values": x[:, 0], "fs": FS, "units": "ue"},
                                      "ring_1": {"data": x[:, 1], "dt": 1 / FS, "units": "V"},
                                      "tacho": {"y": x[:, 2], "time": _t(), "unit": "V"}},
                                     {"sun_T3": 0, "ring_1": 1, "tacho": 2}, 0.0,
                                     {"sun_T3": "ue", "ring_1": "V", "tacho": "V"}),
}


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_layouts_read_as_channels(tmp_path, x, version, layout):
    variables, cols, t0, units = LAYOUTS[layout](x)
    path = _save(tmp_path / "rec.mat", variables, version)
    assert pio.detect_format(path) == "matlab"
    info = pio.read_info(path)
    assert info.format == "matlab" and info.fs == FS and info.n_samples == N
    assert info.t0 == pytest.approx(t0, abs=1e-12) and sorted(info.names) == sorted(cols)
    assert {c.name: c.units for c in info.channels} == {nm: units.get(nm, "") for nm in cols}
    rec = pio.read(path)
    for nm, j in cols.items():
        np.testing.assert_array_equal(rec.data[:, rec.names.index(nm)], x[:, j])
    assert rec.history[-1]["step"] == "read_matlab" and rec.meta["matlab"]["version"] == ("7.3" if version == "v7.3" else "5")
    first = list(cols)[0]
    win = pio.read(path, [first], start=t0 + 0.25, stop=t0 + 0.5)
    np.testing.assert_array_equal(win.data[:, 0], x[640:1280, cols[first]])
    assert win.t0 == pytest.approx(t0 + 0.25)
    blocks = list(pio.iter_blocks(path, 0.5, 0.0))
    np.testing.assert_array_equal(np.concatenate([b.data for b in blocks]), rec.data)


@pytest.mark.parametrize("version", VERSIONS)
def test_kinds_come_from_the_names_and_single_stays_float32(tmp_path, x, version):
    path = _save(tmp_path / "k.mat", {"fs": FS, "sun_T3": x[:, 0].astype(np.float32),
                                      "ring_1": x[:, 1].astype(np.float32)}, version)
    rec = pio.read(path)
    assert {c.name: c.kind for c in rec.channels} == {"sun_T3": "sun", "ring_1": "ring"}
    assert rec.data.dtype == np.float32


@pytest.mark.parametrize("version", VERSIONS)
def test_integer_counts_read_as_float64(tmp_path, version):
    counts = (np.arange(N) % 700 - 350).astype(np.int16)
    rec = pio.read(_save(tmp_path / "i.mat", {"fs": FS, "raw": counts}, version))
    assert rec.data.dtype == np.float64
    np.testing.assert_array_equal(rec.data[:, 0], counts.astype(float))


# ---------------------------------------------------------------------------- detection
def test_v73_goes_to_matlab_and_our_hdf5_to_hdf5(tmp_path, x):
    mat = _save(tmp_path / "rec.mat", {"fs": FS, "sun_T3": x[:, 0]}, "v7.3")
    disguised = tmp_path / "rec.h5"
    disguised.write_bytes(mat.read_bytes())
    assert pio.detect_format(mat) == pio.detect_format(disguised) == "matlab"
    assert h5py.is_hdf5(mat)                                 # it is HDF5 underneath
    ours = pio.write(Recording(x[:, :1], FS, ["sun_T3"]), tmp_path / "ours.h5")
    assert pio.detect_format(ours) == "hdf5"
    assert pio.format_of_suffix("a.MAT") == "matlab" and "matlab" in pio.FORMATS
    assert not pio.get_spec("matlab").writable
    with pytest.raises(ValueError, match="format 'matlab' is read-only"):
        pio.write(Recording(x[:, :1], FS, ["sun_T3"]), tmp_path / "back.mat")


@pytest.mark.parametrize("head, version", [
    (b"MATLAB 5.0 MAT-file, Platform: GLNXA64" + b" " * 80, "5"),
    (b"MATLAB 7.3 MAT-file, Platform: GLNXA64" + b" " * 80, "7.3"),
    (b"", None), (b"MATLAB", None), (b"\x89HDF\r\n\x1a\n" + b"\0" * 600, None),
    (b"time,sun\n0,1\n", None), (bytes(64), None)])
def test_mat_version_and_sniff(head, version):
    assert matlab.mat_version(head) == version
    assert matlab.sniff(head) is (version is not None)


def test_v4_file_is_recognised_and_refused_saying_how_to_save_it(tmp_path):
    path = tmp_path / "old.mat"
    sio.savemat(path, {"x": np.arange(10.0)}, format="4")
    assert matlab.mat_version(path.read_bytes()[:64]) == "4" and pio.detect_format(path) == "matlab"
    with pytest.raises(RecordingFileError, match=r"v4 MAT-file.*'-v7'"):
        pio.read(path)


# ---------------------------------------------------------------------------- v7.3 is read lazily
class _Spy:
    """Records the selections h5py's Dataset.__getitem__ is asked for, by dataset name."""

    def __init__(self, monkeypatch):
        self.calls = []
        orig = h5py.Dataset.__getitem__
        spy = self

        def getitem(ds, args, *rest, **kw):
            spy.calls.append((ds.name, args))
            return orig(ds, args, *rest, **kw)

        monkeypatch.setattr(h5py.Dataset, "__getitem__", getitem)
        monkeypatch.setattr(h5py.Dataset, "read_direct", lambda *a, **k: pytest.fail("read_direct used"))

    def of(self, name):
        return [a for n, a in self.calls if n == name]


def test_v73_read_info_reads_no_channel_and_a_window_only_its_slice(tmp_path, x, monkeypatch):
    path = _save(tmp_path / "lazy.mat", {"data": x, "channel_names": ["sun_T3", "ring_1", "tacho"],
                                         "fs": FS}, "v7.3")
    matlab._LAYOUTS.clear()
    spy = _Spy(monkeypatch)
    info = pio.read_info(path)
    assert info.names == ["sun_T3", "ring_1", "tacho"]
    assert spy.of("/data") == [] and spy.of("/fs")               # the rate read, no sample
    spy.calls.clear()
    rec = pio.read(path, ["ring_1"], start=0.5, stop=0.75)
    assert spy.of("/data") == [(1, slice(1280, 1920))]          # MATLAB's column 2 is HDF5 row 1
    np.testing.assert_array_equal(rec.data[:, 0], x[1280:1920, 1])


def test_v73_time_vector_is_read_once_for_the_header(tmp_path, x, monkeypatch):
    path = _save(tmp_path / "t.mat", {"t": _t(), "sun_T3": x[:, 0]}, "v7.3")
    matlab._LAYOUTS.clear()
    spy = _Spy(monkeypatch)
    pio.read(path, start=0.0, stop=0.1)
    assert len(spy.of("/t")) == 1 and spy.of("/sun_T3") == [(0, slice(0, 256))]   # N x 1 is HDF5 (1, N)


# ---------------------------------------------------------------------------- rates
@pytest.mark.parametrize("version", VERSIONS)
def test_no_rate_needs_fs_and_fs_gives_it(tmp_path, x, version):
    path = _save(tmp_path / "norate.mat", {"sun_T3": x[:, 0], "ring_1": x[:, 1]}, version)
    with pytest.raises(RecordingFileError, match=r"no sample rate.*fs_Hz"):
        pio.read_info(path)
    rec = pio.read(path, fs=FS)
    assert rec.fs == FS and rec.history[-1]["fs_from"] == "given"


def test_fs_given_overrides_the_files_rate_with_a_warning(tmp_path, x):
    path = _save(tmp_path / "r.mat", {"fs": FS, "sun_T3": x[:, 0]}, "v5")
    with pytest.warns(FormatWarning, match=r"fs=1000.0 Hz given overrides the file's 2560.0 Hz"):
        assert pio.read_info(path, fs=1000.0).fs == 1000.0


@pytest.mark.parametrize("version", VERSIONS)
def test_time_vector_off_the_grid_is_named(tmp_path, x, version):
    t = _t()
    t[1000] += 0.5 / FS                                          # a sample half an interval late
    path = _save(tmp_path / "gap.mat", {"t": t, "sun_T3": x[:, 0]}, version)
    with pytest.raises(RecordingFileError, match=r"non-uniform time in time vector 't' at sample 1000"):
        pio.read_info(path)


def test_rates_that_disagree_are_refused(tmp_path, x):
    path = _save(tmp_path / "two.mat", {"sun_T3": {"values": x[:, 0], "fs": FS},
                                        "ring_1": {"values": x[:, 1], "fs": 2 * FS}}, "v5")
    with pytest.raises(RecordingFileError, match="different sample rates"):
        pio.read_info(path)


def test_time_vector_and_rate_that_disagree_are_refused(tmp_path, x):
    path = _save(tmp_path / "tf.mat", {"t": _t(), "fs": 1000.0, "sun_T3": x[:, 0]}, "v7.3")
    with pytest.raises(RecordingFileError, match=r"time vector 't' gives 2560.0 Hz, fs says 1000.0 Hz"):
        pio.read_info(path)


@pytest.mark.parametrize("bad", [0.0, -5.0])
def test_non_positive_rate_is_named(tmp_path, x, bad):
    path = _save(tmp_path / "neg.mat", {"fs": bad, "sun_T3": x[:, 0]}, "v5")
    with pytest.raises(RecordingFileError, match=r"variable fs = .* is not a positive rate"):
        pio.read_info(path)


# ---------------------------------------------------------------------------- what is not read
@pytest.mark.parametrize("version", VERSIONS)
def test_unrecognised_layout_lists_the_variables(tmp_path, version):
    path = _save(tmp_path / "odd.mat", {"operator": "K. Lee", "fs": FS, "flags": np.array([[1.0]])}, version)
    with pytest.raises(RecordingFileError, match=r"no channels found.*Variables: (?=.*operator \(1x6 char\))"
                                                 r"(?=.*fs \(1x1 double\))(?=.*flags \(1x1 double\))"):
        pio.read_info(path)


@pytest.mark.parametrize("version", VERSIONS)
def test_empty_mat_file_says_it_has_no_variables(tmp_path, version):
    path = _save(tmp_path / "empty.mat", {}, version)
    with pytest.raises(RecordingFileError, match="no channels found.*Variables: no variables"):
        pio.read_info(path)


def test_zero_byte_mat_file_is_empty(tmp_path):
    path = tmp_path / "zero.mat"
    path.write_bytes(b"")
    with pytest.raises(RecordingFileError, match=r"file is empty \(0 bytes\)"):
        pio.read(path)


@pytest.mark.parametrize("version", VERSIONS)
def test_square_matrix_without_names_is_ambiguous(tmp_path, version):
    path = _save(tmp_path / "sq.mat", {"M": np.ones((50, 50)), "fs": FS}, version)
    with pytest.raises(RecordingFileError, match=r"M \(50x50 double\) is square"):
        pio.read_info(path)


def test_matrix_without_names_takes_the_longer_axis_as_samples(tmp_path, x):
    rec = pio.read(_save(tmp_path / "m.mat", {"M": x.T.copy(), "fs": FS}, "v7.3"))
    assert rec.names == ["M_1", "M_2", "M_3"]
    np.testing.assert_array_equal(rec.data, x)


def test_names_that_fit_neither_axis_are_named(tmp_path, x):
    path = _save(tmp_path / "n.mat", {"M": x, "names": ["a", "b"], "fs": FS}, "v5")
    with pytest.raises(RecordingFileError, match=r"2 channel names for M \(3000x3 double\)"):
        pio.read_info(path)


def test_several_matrices_are_listed(tmp_path, x):
    path = _save(tmp_path / "mm.mat", {"A": x, "B": x[:, :2], "fs": FS}, "v5")
    with pytest.raises(RecordingFileError, match=r"several matrices.*A \(3000x3 double\), B \(3000x2 double\)"):
        pio.read_info(path)


def test_shorter_vectors_and_matrices_beside_channels_are_skipped_with_a_warning(tmp_path, x):
    path = _save(tmp_path / "s.mat", {"fs": FS, "sun_T3": x[:, 0], "calib": np.arange(5.0),
                                      "image": np.ones((4, 4))}, "v5")
    with pytest.warns(FormatWarning, match=r"not read as channels.*calib.*image"):
        rec = pio.read(path)
    assert rec.names == ["sun_T3"]


@pytest.mark.parametrize("version, values, shown", [
    ("v5", np.ones(N) + 1j, r"z \(3000x?\d* complex\)"),           # scipy reads logical back as uint8
    ("v7.3", np.ones(N, dtype=bool), r"z \(3000x1 logical\)")])
def test_non_numeric_only_is_refused(tmp_path, version, values, shown):
    path = _save(tmp_path / "nn.mat", {"z": values, "note": ["a", "b"]}, version)
    with pytest.raises(RecordingFileError, match=r"no channels found.*" + shown):
        pio.read_info(path)


@pytest.mark.parametrize("version", VERSIONS)
def test_truncated_file_is_a_corrupt_file_error(tmp_path, x, version):
    path = _save(tmp_path / "cut.mat", {"fs": FS, "sun_T3": x[:, 0], "ring_1": x[:, 1]}, version)
    path.write_bytes(path.read_bytes()[:2000])
    with pytest.raises(CorruptFileError, match="cut.mat"):
        pio.read(path)


@pytest.mark.parametrize("bad", [dict(fs=0.0), dict(fs="fast"), dict(verify="yes")])
def test_bad_options_are_refused(tmp_path, x, bad):
    path = _save(tmp_path / "o.mat", {"fs": FS, "sun_T3": x[:, 0]}, "v5")
    with pytest.raises((TypeError, ValueError)):
        pio.read_info(path, **bad)


def test_unknown_channel_and_window_outside_are_refused(tmp_path, x):
    path = _save(tmp_path / "w.mat", {"fs": FS, "sun_T3": x[:, 0]}, "v7.3")
    with pytest.raises(ValueError, match="nope"):
        matlab.read(path, ["nope"])
    with pytest.raises(ValueError, match=r"sample range \[0, 9999\) outside"):
        matlab.read(path, None, 0, 9999)


# ---------------------------------------------------------------------------- the command line
def test_meshphase_info_shows_a_mat_file(tmp_path, x, capsys):
    path = _save(tmp_path / "rig.mat", LAYOUTS["struct"](x)[0], "v7.3")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "format    matlab" in out and "sun_T3" in out and "2560 Hz" in out


# ---------------------------------------------------------------------------- the declaration
def test_declared_options_match_the_functions_and_no_other_format_is_imported():
    import ast
    import inspect

    spec = pio.get_spec("matlab")
    assert spec.load() is matlab and matlab.FORMAT is spec and spec.rate_option and not spec.checksums
    for fn in (matlab.read_info, matlab.read, matlab.iter_blocks):
        kw = {p.name for p in inspect.signature(fn).parameters.values() if p.kind is p.KEYWORD_ONLY}
        assert kw == set(spec.read_options) | {"verify"}, fn
    tree = ast.parse(inspect.getsource(matlab))
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert not imported & {"hdf5", "csv", "tdms", "mcap"}, imported
