"""Unit tests of the fixes the fault corpus led to (issue 10, items 1-3): the output checks of
:func:`meshphase.io.base.atomic_path`, file names on read() errors, npTDMS log records as
warnings, each CLI warning line once, ``run`` of a scene without results.
"""

from __future__ import annotations

import errno
import logging
import os
import stat
import warnings

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.cli import main
from meshphase.errors import FormatWarning
from meshphase.run.exits import _load_error, recording_read_errors
from meshphase.run.state import FailureKind, StageFailure
from meshphase.io.base import atomic_path
from meshphase.recording import ChannelSpec, Recording


def _rec(n=200):
    data = np.random.default_rng(0).standard_normal((n, 2)) * 1e-5
    return Recording(data, 5120.0, [ChannelSpec("sun", kind="sun"), ChannelSpec("ring", kind="ring")])


# --------------------------------------------------------------------------- atomic_path
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_overwrite_refuses_a_fifo_and_leaves_it(tmp_path):
    fifo = tmp_path / "out.h5"
    os.mkfifo(fifo)
    with pytest.raises(FileExistsError, match="is a FIFO .*overwrite replaces regular files only"):
        pio.write(_rec(), fifo, overwrite=True)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.h5"]       # no temporary file


def test_overwrite_refuses_a_device_node(tmp_path):
    dev = tmp_path / "null.h5"
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))             # a private /dev/null
    except (PermissionError, AttributeError, OSError) as exc:
        pytest.skip(f"cannot create a device node here ({exc})")
    with pytest.raises(FileExistsError, match="is a device"):
        pio.write(_rec(), dev, overwrite=True)
    assert stat.S_ISCHR(os.lstat(dev).st_mode)


def test_overwrite_replaces_a_symlink_not_its_target(tmp_path):
    target = tmp_path / "target.txt"
    target.write_text("keep me")
    link = tmp_path / "out.h5"
    link.symlink_to(target)
    pio.write(_rec(), link, overwrite=True)
    assert target.read_text() == "keep me" and not link.is_symlink()
    assert pio.read(link) == _rec()


def test_parent_that_is_a_file_is_named_as_such(tmp_path):
    blocker = tmp_path / "plain"
    blocker.write_text("x")
    with pytest.raises(NotADirectoryError) as err:
        with atomic_path(blocker / "out.h5"):
            pytest.fail("the body must not run")
    assert err.value.errno == errno.ENOTDIR and f"{blocker} is a file, not a folder" in str(err.value)
    assert err.value.filename == str(blocker / "out.h5")


def test_missing_folder_and_loop_in_the_parent(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        with atomic_path(tmp_path / "nowhere" / "out.h5"):
            pass
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(OSError) as err:
        with atomic_path(tmp_path / "a" / "out.h5"):
            pass
    assert err.value.errno == errno.ELOOP and err.value.filename == str(tmp_path / "a" / "out.h5")


def test_name_too_long_is_refused_before_writing(tmp_path):
    long = tmp_path / ("x" * 300 + ".h5")
    with pytest.raises(OSError) as err:
        with atomic_path(long):
            pytest.fail("the body must not run")
    assert err.value.errno == errno.ENAMETOOLONG and "the name has 303 bytes" in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_existing_directory_and_file_without_overwrite(tmp_path):
    (tmp_path / "d.h5").mkdir()
    with pytest.raises(IsADirectoryError):
        with atomic_path(tmp_path / "d.h5", overwrite=True):
            pass
    (tmp_path / "f.h5").write_bytes(b"old")
    with pytest.raises(FileExistsError, match="pass overwrite=True"):
        with atomic_path(tmp_path / "f.h5"):
            pass
    assert (tmp_path / "f.h5").read_bytes() == b"old"


# --------------------------------------------------------------------------- read() errors
def test_read_error_without_file_name_gets_the_path(tmp_path):
    path = tmp_path / "rec.h5"
    with pytest.raises(OSError) as err:
        with recording_read_errors(path):
            raise OSError(errno.EIO, os.strerror(errno.EIO))
    assert err.value.errno == errno.EIO and err.value.filename == str(path)
    with pytest.raises(PermissionError) as err:                      # names a file already
        with recording_read_errors(path):
            raise PermissionError(errno.EACCES, "Permission denied", "/elsewhere")
    assert err.value.filename == "/elsewhere"


@pytest.mark.skipif(not os.path.exists("/proc/self/mem"), reason="Linux /proc only")
def test_detect_format_names_a_file_whose_read_fails():
    with pytest.raises(OSError) as err:
        pio.detect_format("/proc/self/mem")                        # open works, read(): EIO
    assert err.value.filename == "/proc/self/mem"


def test_load_error_text():
    def failed(exc):
        return StageFailure.raised("load", exc)

    assert _load_error(failed(PermissionError(13, "Permission denied", "/x/a.h5"))) == "/x/a.h5: Permission denied"
    assert _load_error(StageFailure("load", FailureKind.RAISED, "/a.csv: line 2: bad", "CorruptFileError")) \
        == "/a.csv: line 2: bad"
    assert _load_error(failed(RuntimeError("odd"))) == "RuntimeError: odd"
    assert _load_error(StageFailure("load", FailureKind.RAISED)) == ""


# --------------------------------------------------------------------------- npTDMS log records
def test_nptdms_log_records_become_one_format_warning(tmp_path, tdms_writer):
    path = tdms_writer(tmp_path / "v.tdms")
    blob = bytearray(path.read_bytes())
    blob[8] ^= 0x01                                     # first lead-in: version 4713, others 4712
    path.write_bytes(bytes(blob))
    seen = []

    class Grab(logging.Handler):
        def emit(self, record):
            seen.append(record)

    grab = Grab()
    logging.getLogger().addHandler(grab)
    try:
        with pytest.warns(FormatWarning, match=rf"{path.name}: npTDMS: Segment version mismatch") as rec:
            pio.read_info(path)
    finally:
        logging.getLogger().removeHandler(grab)
    assert len([w for w in rec if "npTDMS" in str(w.message)]) == 1
    assert not [r for r in seen if r.name.startswith("nptdms")]     # nothing reached a handler


def test_nptdms_log_records_are_dropped_when_the_read_fails(tmp_path, tdms_writer):
    """The third segment's raw-data offset grown by 256 bytes: npTDMS logs "Data size ... is
    not a multiple of the chunk size" and reads on, the reader's wf_samples check fails.
    The error says it all: no warning line besides it."""
    import struct

    path = tdms_writer(tmp_path / "offset.tdms")
    blob = bytearray(path.read_bytes())
    pos = 0
    for _ in range(2):                                   # to the third lead-in
        pos += 28 + struct.unpack_from("<Q", blob, pos + 12)[0]
    blob[pos + 21] ^= 0x01                               # raw-data offset += 256
    path.write_bytes(bytes(blob))
    from nptdms import TdmsFile

    seen = []

    class Grab(logging.Handler):
        def emit(self, record):
            seen.append(record.getMessage())

    lg = logging.getLogger("nptdms.tdms_segment")
    grab = Grab()
    lg.addHandler(grab)
    try:
        TdmsFile.read_metadata(str(path))               # npTDMS alone does complain
    finally:
        lg.removeHandler(grab)
    assert any("not a multiple of the chunk size" in m for m in seen)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                  # any warning would fail here
        with pytest.raises(pio.CorruptFileError, match="wf_samples"):
            pio.read(path)


@pytest.fixture
def tdms_writer():
    from meshphase.synthetic.tdms_export import write_tdms

    def make(path):
        rec = _rec(1000)
        return write_tdms(list(rec.blocks(50 / 5120.0 * 4)), path, n_samples=rec.n_samples)
    return make


# --------------------------------------------------------------------------- CLI
def test_each_warning_line_once(tmp_path, capsys):
    """A plain CSV column without units warns in read_info and again in every block read:
    the command shows the line once."""
    p = tmp_path / "plain.csv"
    rows = "".join(f"{i / 100},{i * 1e-6},{-i * 1e-6}\n" for i in range(400))
    p.write_text("time [s],sun,ring [m/m]\n" + rows)
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = lambda m, c, f, ln, file=None, line=None: print(
            warnings.formatwarning(m, c, f, ln, line), end="", file=__import__("sys").stderr)
        assert main(["-q", "info", str(p)]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("meshphase info: warning: FormatWarning: ") and "'sun'" in err[0]


@pytest.mark.parametrize("text", ["", "# a comment only\n", 'name = "gearset only"\n[gearset]\nz_sun = 25\n'
                                  'z_ring = 87\nz_planet = 31\nn_planets = 4\ncarrier_radius_mm = 112.5\n'])
def test_run_refuses_a_scene_without_results(tmp_path, capsys, text):
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    assert main(["-q", "run", str(scene), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    # one line naming the file and the key, and what a scene needs (the scene checks' wording)
    assert len(err) == 1 and str(scene) in err[0] and "[results]" in err[0]
    assert "nothing to run" in err[0] or "no results requested" in err[0]
    assert not (tmp_path / "o").exists()


def test_run_bad_input_types():
    with pytest.raises(SystemExit) as exc:          # argparse: the scene argument is required
        main(["run"])
    assert exc.value.code == 2
