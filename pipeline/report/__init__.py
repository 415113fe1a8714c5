"""Reports: the only subpackage that imports matplotlib.

- :mod:`.html`     static self-contained HTML (embedded PNG figures, tables)
- :mod:`.figures`  the report's figures
"""

from meshphase.report.html import Report, Section

__all__ = ["Report", "Section"]
