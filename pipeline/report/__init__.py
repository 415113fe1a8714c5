"""Reports: the only subpackage that imports matplotlib.

- :mod:`.html`     static self-contained HTML (embedded PNG figures, tables)
- :mod:`.figures`  the report's figures
- :mod:`.notebook` plots for notebooks (:func:`plot_recording`)
"""

from meshphase.report.html import Report, Section
from meshphase.report.notebook import plot_recording

__all__ = ["Report", "Section", "plot_recording"]
