"""The version of meshphase (the one place it is written besides ``pyproject.toml``), kept in a
module of its own so the readers, writers and output folders that stamp it import nothing else
of the package."""

__version__ = "0.1.0"
