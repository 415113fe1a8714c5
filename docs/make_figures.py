"""Draw the figures of the method page (docs/method.md) with the package's own plots.

A one-minute synthetic recording of the demo's rig (``rig_ripple1``: seed 000 Table 1
teeth, 1 % drive ripple at the carrier rate, 20 dB noise, hum, drift, shaft hole errors,
carrier tacho) is processed with the demo scene, and :meth:`meshphase.Result.plot` draws
each view into ``docs/figures/``. Run from the repository root::

    python3 docs/make_figures.py

The PNGs are committed; each stays small (80 dpi, < 200 kB).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import meshphase  # noqa: E402
from meshphase.io import write  # noqa: E402
from meshphase.run.demo import demo_scene_path  # noqa: E402
from meshphase.synthetic import generate  # noqa: E402

OUT = Path(__file__).resolve().parent / "figures"
DPI = 80
#: figure file -> Result.plot kind
VIEWS = {"onsets.png": "onsets", "phasing.png": "phasing", "residuals.png": "residuals",
         "load_sharing.png": "load_sharing"}


def main() -> int:
    """Generate the recording, process it, write one PNG per view; print each file's size."""
    OUT.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        rec, _truth = generate("rig_ripple1", duration=60.0, seed=1)
        path = Path(tmp) / "rig.h5"
        write(rec, path)
        res = meshphase.process(meshphase.read(path), demo_scene_path(tmp), tolerance=True)
    for name, kind in VIEWS.items():
        fig = res.plot(kind)
        fig.savefig(OUT / name, dpi=DPI)
        plt.close(fig)
        print(f"{name}: {(OUT / name).stat().st_size / 1e3:.0f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
