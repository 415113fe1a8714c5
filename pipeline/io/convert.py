"""Streamed conversion of a recording file to another format (``meshphase convert``).

Each block read is written at once, so memory stays at one block plus the writer's chunk
buffer whatever the length; the output is published atomically when complete
(:func:`meshphase.io.write_blocks`). Read errors name the source file
(:func:`meshphase.io.base.recording_read_errors`), write errors the output.
"""

from __future__ import annotations

import contextlib
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, ContextManager

import numpy as np

from ..recording import Recording
from ..validate import as_positive_int
from . import detect_format, format_for_write, iter_blocks, read_info, write_blocks
from .base import recording_read_errors

__all__ = ["convert", "Converted", "CONVERT_BLOCK_SAMPLES"]

#: samples per channel per block: 2**18 is 16 MB of 8 float64 channels
CONVERT_BLOCK_SAMPLES = 2 ** 18


@dataclass(frozen=True)
class Converted:
    """What :func:`convert` wrote.

    Attributes
    ----------
    path : Path
        The output file.
    source_format, format : str
        Format of the source and of the output.
    n_samples, n_channels : int
        Samples per channel and channels written.
    """

    path: Path
    source_format: str
    format: str
    n_samples: int
    n_channels: int


def convert(src, dst, *, format: str | None = None, overwrite: bool = False,
            block_samples: int = CONVERT_BLOCK_SAMPLES,
            progress: Callable[[int, str], ContextManager] | None = None,
            read_options: dict | None = None, **options) -> Converted:
    """Convert recording file ``src`` to ``dst``, streamed block by block.

    Parameters
    ----------
    src, dst : str or Path
        Source recording (format recognised by content) and output file.
    format : str, optional
        A writable format of :data:`meshphase.io.FORMATS` (``hdf5``, ``mcap``, ``csv``,
        ``tdms`` ...); default from ``dst``'s suffix.
    overwrite : bool
        Replace an existing ``dst`` (atomically); otherwise FileExistsError.
    block_samples : int
        Samples per channel per block read and written [-].
    progress : callable, optional
        ``progress(total_samples, description)`` returning a context manager with an
        ``update(n_samples)`` method (a tqdm bar fits); None: no progress.
    read_options : dict, optional
        Read options of the source's format (``topics=``, ``fs=`` ...: :func:`meshphase.io.read`).
    **options
        Write options of the output format (e.g. ``compression="gzip"`` for HDF5).

    Returns
    -------
    Converted
        The written path, both formats, samples and channels. The samples keep their stored
        dtype (float32 stays float32); the history gains a ``convert`` step naming the source.
    """
    block_samples = as_positive_int(block_samples, "block_samples")
    src, dst = Path(src), Path(dst)
    with recording_read_errors(src):
        fmt = detect_format(src)
        info = read_info(src, format=fmt, **(read_options or {}))
    history = Recording(np.empty((0, len(info.channels))), info.fs, info.channels,
                        history=info.history).with_history(
        "convert", source=str(src), source_format=fmt).history
    header = dataclasses.replace(info, history=history)
    blocks = iter_blocks(src, block_samples / info.fs, format=fmt, **(read_options or {}))
    with recording_read_errors(src):
        first = next(blocks, None)
    dtype = first.data.dtype if first is not None else np.dtype(np.float64)
    out_format = format_for_write(dst, format)

    def data():
        bar_cm = (progress(info.n_samples, f"{fmt} -> {out_format}") if progress is not None
                  else contextlib.nullcontext())
        with bar_cm as bar, recording_read_errors(src):
            for block in ([first] if first is not None else []):
                yield block.data
                if bar is not None:
                    bar.update(block.n_samples)
            for block in blocks:
                yield block.data
                if bar is not None:
                    bar.update(block.n_samples)

    out = write_blocks(header, data(), dst, format=format, dtype=dtype, overwrite=overwrite,
                       **options)
    return Converted(path=Path(out), source_format=fmt, format=out_format,
                     n_samples=int(info.n_samples), n_channels=len(info.channels))
