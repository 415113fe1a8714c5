"""Write synthetic recordings as NI TDMS files (npTDMS ``TdmsWriter``), block by block.

``meshphase.io`` reads TDMS but does not write it (real TDMS files come from NI DAQ
hardware); synthetic TDMS files are written here, laid out the way an NI rig writes them so
that they exercise the same reader path (``pipeline/io/tdms.py``,
``data_schemas/tdms_mapping.md``):

* one group (default ``"meshphase"``), one float64 channel per recording channel, in order;
* per channel: ``wf_increment`` = 1 / fs [s], ``wf_start_offset`` = t0 [s],
  ``wf_start_time`` (the recording's ``start_datetime``, UTC; the LabVIEW zero time
  1904-01-01 when it has none, which the reader takes as "not set"), ``wf_samples``,
  ``unit_string``, ``NI_ChannelName``, ``meshphase_kind``, ``meshphase_gear``,
  ``meshphase_tooth``, ``meshphase_face_position`` [m], ``meshphase_description``;
* file properties: ``name``, ``meshphase_meta`` and ``meshphase_history`` (JSON text);
* one segment per block (blocks of >= 1e5 samples keep the per-segment overhead of the
  reader negligible), so memory stays flat however long the recording.
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Iterable

import numpy as np

from meshphase.io.base import atomic_path
from meshphase.recording import Recording

__all__ = ["write_tdms", "LABVIEW_ZERO"]

#: TDMS timestamp zero (LabVIEW epoch): "start time not set".
LABVIEW_ZERO = np.datetime64("1904-01-01T00:00:00", "us")


def _start_time(start_datetime: str | None) -> np.datetime64:
    if start_datetime is None:
        return LABVIEW_ZERO
    d = _dt.datetime.fromisoformat(start_datetime)
    if d.tzinfo is not None:
        d = d.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    return np.datetime64(d, "us")


def _channel_props(rec: Recording, n_total: int) -> list[dict]:
    out = []
    for spec in rec.channels:
        p = {
            "wf_increment": 1.0 / rec.fs,
            "wf_start_offset": float(rec.t0),
            "wf_start_time": _start_time(rec.start_datetime),
            "wf_samples": int(n_total),
            "unit_string": spec.units,
            "NI_ChannelName": spec.name,
            "meshphase_kind": spec.kind,
            "meshphase_description": spec.description,
        }
        if spec.gear is not None:
            p["meshphase_gear"] = spec.gear
        if spec.tooth is not None:
            p["meshphase_tooth"] = int(spec.tooth)
        if spec.face_position is not None:
            p["meshphase_face_position"] = float(spec.face_position)
        if spec.gain != 1.0:
            p["meshphase_gain"] = float(spec.gain)
        out.append(p)
    return out


def write_tdms(blocks: Recording | Iterable[Recording], path, *, n_samples: int | None = None,
               group: str = "meshphase", overwrite: bool = False) -> Path:
    """Write a recording, or consecutive blocks of one, to an NI TDMS file (atomically).

    Parameters
    ----------
    blocks : Recording or iterable of Recording
        The recording, or its consecutive blocks (same channels and fs; each block's t0 must
        continue the previous one); each block becomes one TDMS segment.
    path : str or Path
        Output file (``.tdms``).
    n_samples : int, optional
        Total samples per channel, written as ``wf_samples`` (default: the first block's).
    group : str
        TDMS group name.
    overwrite : bool
        Replace an existing file (default False: FileExistsError).

    Returns
    -------
    Path
    """
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    if isinstance(blocks, Recording):
        blocks = [blocks]
    if not isinstance(group, str) or not group:
        raise ValueError(f"group must be a non-empty string, got {group!r}")
    path = Path(path)
    with atomic_path(path, overwrite=overwrite) as tmp:
        with TdmsWriter(str(tmp)) as w:
            first = None
            expect_t = None
            for rec in blocks:
                if not isinstance(rec, Recording):
                    raise TypeError(f"blocks must be Recordings, got {type(rec).__name__}")
                if first is None:
                    first = rec
                    total = rec.n_samples if n_samples is None else int(n_samples)
                    props = _channel_props(rec, total)
                    objs = [RootObject(properties={
                                "name": path.stem,
                                "meshphase_meta": json.dumps(rec.meta, default=str),
                                "meshphase_history": json.dumps(rec.history, default=str)}),
                            GroupObject(group, properties={})]
                    for j, spec in enumerate(rec.channels):
                        objs.append(ChannelObject(group, spec.name,
                                                  np.ascontiguousarray(rec.data[:, j], dtype=np.float64),
                                                  properties=props[j]))
                    w.write_segment(objs)
                else:
                    if rec.names != first.names or rec.fs != first.fs:
                        raise ValueError(f"block at t0={rec.t0!r} s has channels {rec.names} at "
                                         f"{rec.fs!r} Hz, the first block {first.names} at {first.fs!r} Hz")
                    if abs(rec.t0 - expect_t) > 0.5 / rec.fs:
                        raise ValueError(f"block starts at t0={rec.t0!r} s, expected {expect_t!r} s "
                                         "(blocks must be consecutive)")
                    w.write_segment([ChannelObject(group, spec.name,
                                                   np.ascontiguousarray(rec.data[:, j], dtype=np.float64))
                                     for j, spec in enumerate(rec.channels)])
                expect_t = rec.t0 + rec.n_samples / rec.fs
            if first is None:
                raise ValueError("no blocks to write")
    return path
