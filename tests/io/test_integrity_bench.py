"""Cost of the integrity checks on 10 min x 8 channels x 5120 Hz float64 (24.6 MSamples).

Measured, not asserted (``-m bench``): MCAP read with and without the CRC checks, HDF5 write
and read with and without fletcher32. Prints GS/s (wall, best of ``REPEATS``) and the
process CPU time, so a loaded machine shows up as wall >> CPU. Run with ``-s`` to see the
table: ``python -m pytest -m bench -s tests/io/test_integrity_bench.py``.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import meshphase.io as pio
from meshphase.io import hdf5, mcap
from meshphase.io.mcap import header as mheader
from meshphase.recording import ChannelSpec, Recording

pytestmark = [pytest.mark.bench, pytest.mark.timeout(1800)]

FS = 5120.0
N = int(600 * FS)
N_CH = 8
REPEATS = 5


@pytest.fixture(scope="module")
def rec():
    data = np.random.default_rng(0).standard_normal((N, N_CH)) * 1e-5
    return Recording(data, FS, [ChannelSpec(name=f"sun_{j}", kind="sun", units="m/m") for j in range(N_CH)])


def _best(fn, repeats=REPEATS, before=None):
    wall, cpu = np.inf, np.inf
    for _ in range(repeats):
        if before is not None:
            before()
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
        del out
    return wall, cpu


def _row(what, wall, cpu, base=None):
    gs = N * N_CH / wall / 1e9
    ratio = "" if base is None else f"  ratio {base / wall:5.2f} (wall)"
    print(f"{what:<46} {gs:6.3f} GS/s  wall {wall:6.3f} s  cpu {cpu:6.3f} s{ratio}")


def test_mcap_crc_cost(rec, tmp_path):
    for comp in ("none", "lz4"):
        p = pio.write(rec, tmp_path / f"r_{comp}.mcap", compression=comp)
        assert pio.read(p) == rec
        off = _best(lambda: mcap.read(p, verify=False))
        on = _best(lambda: mcap.read(p, verify=True))
        first = _best(lambda: mcap.read(p, verify=True), before=mheader._VERIFIED.clear)
        opened = _best(lambda: mcap.read_info(p, verify=True), before=mheader._VERIFIED.clear)
        print()
        _row(f"MCAP {comp:4} read, verify=False", *off)
        _row(f"MCAP {comp:4} read, verify=True (file checked)", *on, base=off[0])
        _row(f"MCAP {comp:4} read, verify=True (first open)", *first, base=off[0])
        print(f"MCAP {comp:4} open-time check (summary + data-section CRC): {opened[0] * 1e3:.1f} ms")


def test_hdf5_fletcher32_cost(rec, tmp_path):
    k = [0]

    def write(fletcher32):
        k[0] += 1
        return pio.write(rec, tmp_path / f"w{k[0]}.h5", fletcher32=fletcher32)

    def write_raw(fletcher32):  # the format writer alone: no temporary file, no fsync
        k[0] += 1
        return hdf5.write(rec, tmp_path / f"raw{k[0]}.h5", fletcher32=fletcher32)

    w_off = _best(lambda: write(False))
    w_on = _best(lambda: write(True))
    raw_off = _best(lambda: write_raw(False))
    raw_on = _best(lambda: write_raw(True))
    p_off = pio.write(rec, tmp_path / "off.h5", fletcher32=False)
    p_on = pio.write(rec, tmp_path / "on.h5", fletcher32=True)
    r_off = _best(lambda: hdf5.read(p_off))
    r_on = _best(lambda: hdf5.read(p_on))
    r_skip = _best(lambda: hdf5.read(p_on, verify=False))
    print()
    _row("HDF5 write (registry: fsync), no fletcher32", *w_off)
    _row("HDF5 write (registry: fsync), fletcher32", *w_on, base=w_off[0])
    _row("HDF5 write (no fsync), no fletcher32", *raw_off)
    _row("HDF5 write (no fsync), fletcher32", *raw_on, base=raw_off[0])
    _row("HDF5 read, no fletcher32", *r_off)
    _row("HDF5 read, fletcher32 checked", *r_on, base=r_off[0])
    _row("HDF5 read, fletcher32 file, verify=False", *r_skip, base=r_off[0])
