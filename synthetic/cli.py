"""Implementation of ``meshphase synth SCENARIO OUT [--minutes M] [--seed N] [--format F]``.

:func:`cli_synth` generates a named scenario and writes the recording in any writable
format of :mod:`meshphase.io` (the format from ``format`` or the suffix:
:func:`meshphase.io.format_for_write`) plus the ground-truth sidecar (``OUT.truth.json``),
block by block (flat memory): TDMS as :func:`meshphase.io.tdms_write.write_tdms` lays it
out (one float64 segment per generated block, the file named after OUT), the other formats
through :func:`meshphase.io.write_blocks`.
"""

from __future__ import annotations

from pathlib import Path

from meshphase.io import format_for_write, write_blocks
from meshphase.io.tdms_write import write_tdms
from meshphase.runtime.log import logger
from meshphase.validate import as_positive

from meshphase.synthetic.generate import generate_blocks
from meshphase.synthetic.truth import truth_path_for

__all__ = ["cli_synth"]


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
        (.h5/.hdf5, .mcap, .csv, .tdms, or a registered format's).
    minutes : float, optional
        Duration [min] (default: the scenario's).
    seed : int, optional
        Random seed (recorded in the sidecar); None draws fresh entropy.
    format : str, optional
        A writable format of :data:`meshphase.io.FORMATS` (``"hdf5"``, ``"mcap"``,
        ``"csv"``, ``"tdms"`` ...).
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
    fmt = format_for_write(out, format)
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
    if fmt == "tdms":   # one segment per generated block, the file property name = OUT's stem
        write_tdms(iter(stream), out, n_samples=stream.n_samples, overwrite=overwrite)
    else:
        write_blocks(stream, (blk.data for blk in stream), out, format=fmt,
                     dtype=stream.dtype, overwrite=overwrite)
    stream.truth.write(truth_path, overwrite=overwrite)
    logger.info("synth %s: wrote %s (%s, %d samples x %d channels) and %s", scenario, out, fmt,
                stream.n_samples, len(stream.channels), truth_path)
    return out, truth_path
