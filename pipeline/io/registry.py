"""The format registry: one declared :class:`FormatSpec` per recording-file format.

A format is a module implementing the reader protocol (:mod:`meshphase.io.base` says what
each function does): ``sniff(head) -> bool``, ``read_info(path, **options)``,
``read(path, channels, i0, i1, **options)``, optionally ``iter_blocks(path, n_block,
n_overlap, channels, **options)``, and, for a writable format, ``write(recording, path,
**options)`` and ``write_blocks(header, blocks, path, dtype=..., **options)``. The module
declares what it is and can do once, as a :class:`FormatSpec` named ``FORMAT``; everything
else (:data:`meshphase.io.FORMATS`, format detection, the suffix table of
:func:`meshphase.io.write`, the ``--format`` choices of the command line, the scene's
per-format options, the checksum pass of streamed reads) is derived from the specs.

The built-in formats are listed here by module (``hdf5``, ``mcap``, ``tdms``, ``lvm``, ``csv``,
``matlab``) and
imported when first needed, so ``import meshphase.io`` loads no format library. Other
formats come from

* :func:`register_format` (a spec whose ``module`` is importable), or
* an installed distribution's entry point in the group ``meshphase.formats`` whose object
  is a :class:`FormatSpec` (read once, on the first look at the registry).

Detection asks the formats in the order of :func:`format_names` (the built-ins, then the
others in the order they came), a ``catch_all`` format (CSV: any delimited text) after all
the others.
"""

from __future__ import annotations

import importlib
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Iterator, Mapping

from ..errors import FormatWarning

__all__ = ["FormatSpec", "register_format", "unregister_format", "format_names", "get_spec", "get_format",
           "format_of_suffix", "writable_formats", "sniff_order", "FormatChoices", "ENTRY_POINT_GROUP", "BUILTIN_FORMATS"]

#: Entry-point group of third-party format plugins (each object a :class:`FormatSpec`).
ENTRY_POINT_GROUP = "meshphase.formats"
#: The built-in formats: name -> module declaring ``FORMAT`` (detection asks the formats with
#: magic bytes or a first line of their own first, CSV, the catch-all, last; the HDF5 reader
#: declines a MATLAB 7.3 file, an HDF5 file with MATLAB's header text in its user block,
#: which goes to ``matlab``).
BUILTIN_FORMATS = MappingProxyType({"hdf5": "meshphase.io.hdf5", "mcap": "meshphase.io.mcap",
                                    "tdms": "meshphase.io.tdms", "lvm": "meshphase.io.lvm",
                                    "csv": "meshphase.io.csv", "matlab": "meshphase.io.matlab"})


def _as_option_types(value, what: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise TypeError(f"{what} must be a mapping of option name -> type, got {type(value).__name__}")
    for k, t in value.items():
        types = t if isinstance(t, tuple) else (t,)
        if not isinstance(k, str) or not k.isidentifier() or not types \
                or not all(isinstance(x, type) for x in types):
            raise TypeError(f"{what}: {k!r} -> {t!r} is no option name -> type (or tuple of types)")
    return MappingProxyType(dict(value))


@dataclass(frozen=True, eq=False)
class FormatSpec:
    """What a recording-file format is and can do, declared once by its module.

    Parameters
    ----------
    name : str
        Lower-case identifier (``"hdf5"``): the ``format=`` of :func:`meshphase.io.read`,
        :func:`~meshphase.io.write` and the ``--format`` of the command line.
    module : str
        Dotted path of the module implementing the reader protocol (``sniff``,
        ``read_info``, ``read``; ``iter_blocks`` optional; ``write`` when ``writable``,
        ``write_blocks`` when ``streaming_write``). Imported on first use.
    suffixes : tuple of str
        Lower-case file suffixes with the dot (``(".h5", ".hdf5")``); the first is the
        usual one. The suffix names the format of a file to write; a file read is
        recognised by its content (``sniff``).
    writable : bool
        :func:`meshphase.io.write` writes it (the module has ``write``).
    streaming_write : bool
        :func:`meshphase.io.write_blocks` writes it block by block in flat memory (the
        module has ``write_blocks``); implies ``writable``.
    random_access : bool
        ``read`` of a window costs what the window holds (chunked storage); a format
        without it is streamed from the start to reach a window.
    checksums : bool
        The files store checksums that ``verify=True`` (the default of every read) checks
        and ``verify=False`` skips; a streamed source checks them in its first pass only.
    rate_option : bool
        A file may state no sample rate; ``fs=`` [Hz] (a read option) gives it then, as the
        scene's ``[input] fs_Hz`` does.
    catch_all : bool
        ``sniff`` accepts broad content (any delimited text): asked after every other format.
    read_options : mapping of str to type or tuple of types
        Options of ``read_info``/``read``/``iter_blocks`` besides ``verify`` (which every
        format takes), with their types (None is always allowed: the default).
    write_options : mapping of str to type or tuple of types
        Options of ``write``/``write_blocks`` besides ``dtype``.
    read_libraries : tuple of str
        The third-party libraries the reader imports on first use (a campaign's workers
        import them ahead of the fork).
    description : str
        One line for listings.
    """

    name: str
    module: str
    suffixes: tuple = ()
    writable: bool = False
    streaming_write: bool = False
    random_access: bool = False
    checksums: bool = False
    rate_option: bool = False
    catch_all: bool = False
    read_options: Mapping = field(default_factory=dict)
    write_options: Mapping = field(default_factory=dict)
    read_libraries: tuple = ()
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier() or self.name != self.name.lower():
            raise ValueError(f"format name must be a lower-case identifier, got {self.name!r}")
        if not isinstance(self.module, str) or not all(p.isidentifier() for p in self.module.split(".")):
            raise ValueError(f"format {self.name!r}: module must be a dotted module path, got {self.module!r}")
        suffixes = tuple(self.suffixes) if isinstance(self.suffixes, (tuple, list)) else None
        if suffixes is None or not all(isinstance(s, str) and len(s) > 1 and s.startswith(".")
                                       and s == s.lower() for s in suffixes):
            raise ValueError(f"format {self.name!r}: suffixes must be lower-case '.xyz' strings, "
                             f"got {self.suffixes!r}")
        object.__setattr__(self, "suffixes", suffixes)
        for flag in ("writable", "streaming_write", "random_access", "checksums", "rate_option", "catch_all"):
            if not isinstance(getattr(self, flag), bool):
                raise TypeError(f"format {self.name!r}: {flag} must be a bool, got {getattr(self, flag)!r}")
        if self.streaming_write and not self.writable:
            raise ValueError(f"format {self.name!r}: streaming_write needs writable")
        read_options = _as_option_types(self.read_options, f"format {self.name!r}: read_options")
        write_options = _as_option_types(self.write_options, f"format {self.name!r}: write_options")
        if "verify" in read_options:
            raise ValueError(f"format {self.name!r}: verify is every format's option; leave it out "
                             "of read_options")
        if self.rate_option and "fs" not in read_options:
            raise ValueError(f"format {self.name!r}: rate_option needs the read option fs")
        if write_options and not self.writable:
            raise ValueError(f"format {self.name!r}: write_options of a format that is not writable")
        object.__setattr__(self, "read_options", read_options)
        object.__setattr__(self, "write_options", write_options)
        if not isinstance(self.read_libraries, tuple) or not all(isinstance(x, str) for x in self.read_libraries):
            raise TypeError(f"format {self.name!r}: read_libraries must be a tuple of str, "
                            f"got {self.read_libraries!r}")
        if not isinstance(self.description, str):
            raise TypeError(f"format {self.name!r}: description must be a str, got {self.description!r}")

    def load(self) -> ModuleType:
        """The module implementing the format (imported on the first call)."""
        return importlib.import_module(self.module)


_lock = threading.RLock()
_specs: dict[str, FormatSpec] = {}          # loaded specs, by name
_order: list[str] = list(BUILTIN_FORMATS)   # every known name, built-ins first
_plugins_read = False


def _read_entry_points() -> None:
    """Register the specs of the ``meshphase.formats`` entry points (once; a broken plugin
    is skipped with a FormatWarning naming it)."""
    global _plugins_read
    with _lock:
        if _plugins_read:
            return
        _plugins_read = True
        from importlib.metadata import entry_points  # the scan of installed distributions: once

        for ep in entry_points(group=ENTRY_POINT_GROUP):
            try:
                spec = ep.load()
                if not isinstance(spec, FormatSpec):
                    raise TypeError(f"its object is a {type(spec).__name__}, not a FormatSpec")
                if spec.name in _order:
                    raise ValueError(f"format {spec.name!r} is registered already")
                _register(spec)
            except Exception as exc:  # noqa: BLE001 (a third party's plugin must not break reading)
                warnings.warn(f"format plugin {ep.name!r} ({ep.value}) skipped: {exc}", FormatWarning,
                              stacklevel=2)


def _register(spec: FormatSpec) -> None:
    _specs[spec.name] = spec
    if spec.name not in _order:
        _order.append(spec.name)


def register_format(spec: FormatSpec, *, replace: bool = False) -> FormatSpec:
    """Add a format to the registry (detection, :func:`meshphase.io.read`, the CLI).

    Parameters
    ----------
    spec : FormatSpec
    replace : bool
        Replace a registered plugin of the same name (default False: ValueError). A
        built-in format is never replaced.

    Returns
    -------
    FormatSpec
        ``spec``.
    """
    if not isinstance(spec, FormatSpec):
        raise TypeError(f"spec must be a FormatSpec, got {type(spec).__name__}")
    _read_entry_points()
    with _lock:
        if spec.name in BUILTIN_FORMATS:
            raise ValueError(f"format {spec.name!r} is built in; a plugin needs another name")
        if spec.name in _order and not replace:
            raise ValueError(f"format {spec.name!r} is registered already (replace=True replaces it)")
        _register(spec)
    return spec


def unregister_format(name: str) -> None:
    """Remove a format added by :func:`register_format` or an entry point (ValueError for a
    built-in or unknown name)."""
    with _lock:
        if name in BUILTIN_FORMATS:
            raise ValueError(f"format {name!r} is built in and stays")
        if name not in _order:
            raise ValueError(f"unknown format {name!r}; supported formats: {', '.join(_order)}")
        _order.remove(name)
        _specs.pop(name, None)


def format_names() -> tuple[str, ...]:
    """Names of the registered formats: the built-ins, then the others in the order they came."""
    _read_entry_points()
    return tuple(_order)


def get_spec(name: str) -> FormatSpec:
    """The :class:`FormatSpec` of format ``name`` (ValueError listing the formats when unknown).

    A built-in's module is imported here, on the first call."""
    spec = _specs.get(name)
    if spec is not None:
        return spec
    names = format_names()
    if not isinstance(name, str) or name not in names:
        raise ValueError(f"unknown format {name!r}; supported formats: {', '.join(names)}")
    with _lock:
        if name not in _specs:
            module = importlib.import_module(BUILTIN_FORMATS[name])
            spec = getattr(module, "FORMAT", None)
            if not isinstance(spec, FormatSpec) or spec.name != name:
                raise TypeError(f"{BUILTIN_FORMATS[name]}.FORMAT must be the FormatSpec of {name!r}, "
                                f"got {spec!r}")
            _specs[name] = spec
    return _specs[name]


def get_format(name: str) -> ModuleType:
    """The module implementing format ``name`` (its reader and writer functions)."""
    return get_spec(name).load()


def sniff_order() -> Iterator[FormatSpec]:
    """The specs in the order detection asks them: :func:`format_names`, catch-all ones last.

    Specs load one by one as the iteration reaches them."""
    last = []
    for name in format_names():
        spec = get_spec(name)
        if spec.catch_all:
            last.append(spec)
        else:
            yield spec
    yield from last


def format_of_suffix(path) -> str | None:
    """The format whose suffixes hold ``path``'s suffix (any case); None when none does."""
    suffix = Path(path).suffix.lower()
    if not suffix:
        return None
    return next((name for name in format_names() if suffix in get_spec(name).suffixes), None)


def writable_formats() -> tuple[str, ...]:
    """Names of the formats :func:`meshphase.io.write` writes."""
    return tuple(name for name in format_names() if get_spec(name).writable)


class FormatChoices:
    """The format names as argparse ``choices``, read from the registry when used (a plugin
    registered after the parser was built is a choice too, and building the parser loads
    no format module).

    Parameters
    ----------
    writable : bool
        Only the writable formats (default: every format).
    """

    def __init__(self, writable: bool = False):
        self.writable = bool(writable)

    def _names(self) -> tuple[str, ...]:
        return writable_formats() if self.writable else format_names()

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __iter__(self):
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())

    def __repr__(self) -> str:
        return f"FormatChoices({', '.join(self._names())})"
