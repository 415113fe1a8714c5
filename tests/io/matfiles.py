"""MAT-files for the tests, written the way MATLAB writes them.

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
