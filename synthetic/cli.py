"""Implementation of ``meshphase synth SCENARIO OUT [--minutes M] [--seed N] [--format F]``.

:func:`cli_synth` generates a named scenario and writes the recording in any of the four
formats plus the ground-truth sidecar (``OUT.truth.json``). TDMS is written block by block
(flat memory, :mod:`meshphase.synthetic.tdms_export`); HDF5, MCAP and CSV through
``meshphase.io.write_blocks``, block by block as well.
"""

from __future__ import annotations

from pathlib import Path

from meshphase.runtime.log import logger
from meshphase.validate import as_positive

from meshphase.synthetic.generate import generate_blocks
from meshphase.synthetic.truth import truth_path_for

__all__ = ["cli_synth", "FORMATS", "format_for_path"]

#: Output formats of ``meshphase synth``.
FORMATS = ("hdf5", "mcap", "csv", "tdms")
_SUFFIXES = {".h5": "hdf5", ".hdf5": "hdf5", ".hdf": "hdf5", ".mcap": "mcap", ".csv": "csv",
             ".tdms": "tdms"}


def format_for_path(path, format: str | None = None) -> str:
    """Output format from ``format`` or the file suffix (ValueError listing the choices)."""
    if format is not None:
        if format not in FORMATS:
            raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {format!r}")
        return format
    suffix = Path(path).suffix.lower()
    if suffix in _SUFFIXES:
        return _SUFFIXES[suffix]
    raise ValueError(f"{path}: cannot tell the format from suffix {suffix!r}; use one of "
                     f"{', '.join(sorted(_SUFFIXES))} or pass format= one of {', '.join(FORMATS)}")


def cli_synth(scenario: str, out, minutes: float | None = None, seed: int | None = None,
              format: str | None = None, overwrite: bool = False,
              progress: bool = True) -> tuple[Path, Path]:
    """Generate scenario ``scenario`` and write it to ``out`` plus its truth sidecar.

    Parameters
    ----------
    scenario : str
        Scenario name (:func:`meshphase.synthetic.scenarios.list_scenarios`).
    out : str or Path
        Output recording file; the format comes from ``format`` or the suffix
        (.h5/.hdf5, .mcap, .csv, .tdms).
    minutes : float, optional
        Duration [min] (default: the scenario's).
    seed : int, optional
        Random seed (recorded in the sidecar); None draws fresh entropy.
    format : {"hdf5", "mcap", "csv", "tdms"}, optional
    overwrite : bool
        Replace existing output files (default False: FileExistsError before any work).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    (Path, Path)
        The recording file and its truth sidecar (``<out>.truth.json``).
    """
    out = Path(out)
    fmt = format_for_path(out, format)
    truth_path = truth_path_for(out)
    if not overwrite:
        for p in (out, truth_path):
            if p.exists():
                raise FileExistsError(f"{p}: exists; pass overwrite=True (--overwrite) to replace it")
    if not out.parent.exists():
        raise FileNotFoundError(f"{out}: directory {out.parent} does not exist")
    duration = None if minutes is None else 60.0 * as_positive(minutes, "minutes")
    # default blocks of 2**20 samples: also the TDMS segment length
    stream = generate_blocks(scenario, duration=duration, seed=seed, progress=bool(progress))
    if fmt == "tdms":
        from meshphase.synthetic.tdms_export import write_tdms

        write_tdms(iter(stream), out, n_samples=stream.n_samples, overwrite=overwrite)
    else:
        from meshphase.io import write_blocks

        # block by block too: flat memory whatever the duration
        write_blocks(stream, (blk.data for blk in stream), out, format=fmt,
                     dtype=stream.dtype, overwrite=overwrite)
    stream.truth.write(truth_path, overwrite=overwrite)
    logger.info("synth %s: wrote %s (%s, %d samples x %d channels) and %s", scenario, out, fmt,
                stream.n_samples, len(stream.channels), truth_path)
    return out, truth_path
