"""Reports: the only subpackage that imports matplotlib.

- :mod:`.html`     static self-contained HTML (embedded PNG figures, tables)
- :mod:`.figures`  the report's figures
- :mod:`.notebook` plots for notebooks (:func:`meshphase.report.notebook.plot_recording`;
                   imported on its own: it loads matplotlib.pyplot)
"""

from .html import Report, Section

__all__ = ["Report", "Section"]
