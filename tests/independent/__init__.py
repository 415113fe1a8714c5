"""Independent reference rig for meshphase (imports neither ``pipeline`` nor ``synthetic``).

See :mod:`independent.rig` (``tests/independent/rig.py``).
"""
