"""Heavy third-party libraries, imported on first use: the one place the library layers take
scipy from.

A :class:`LazyModule` stands for a module by name and imports it the first time one of its
attributes is read, so that importing a module of the package that uses scipy loads no scipy
(``meshphase --help``, ``info`` and ``process`` start without it). The proxies below are the
scipy submodules the package uses; a module takes its proxy by name
(``from ..runtime.lazy import linalg``) and calls through it (``linalg.qr(...)``).

A run loads the scipy modules of its stages (:data:`PROCESSING_SCIPY`, :func:`load_all`)
before it holds the loaded BLAS libraries to one thread: scipy.linalg brings a BLAS of its
own, which a limit set before it loads would not reach.
"""

from __future__ import annotations

import importlib
import types

__all__ = ["LazyModule", "lazy_module", "is_loaded", "load_all", "PROCESSING_SCIPY", "fft", "interpolate", "io", "linalg", "ndimage", "optimize",
           "signal", "special", "stats"]


class LazyModule(types.ModuleType):
    """A module imported the first time one of its attributes is read.

    Creating one imports nothing and does not look the module up (no ``find_spec``): a module
    that is not installed fails on first use, not at creation. Each attribute read is cached
    on the proxy, so later reads of it are plain attribute look-ups. The proxy adds no public
    attribute of its own (every name is the module's): :func:`is_loaded` and :func:`load_all`
    ask and load it from outside. Dunder names
    (``__wrapped__``, ``__path__`` ...) read before the module is loaded raise AttributeError
    rather than import it: tools that probe module globals (doctest, ``inspect.unwrap``) do
    not load the library.

    Parameters
    ----------
    name : str
        The module's absolute dotted name, e.g. ``"scipy.linalg"``.

    Raises
    ------
    ImportError
        On the first attribute read, when the module does not import; the message names it.
    AttributeError
        On an attribute read the loaded module does not have.
    """

    def __init__(self, name: str):
        if not isinstance(name, str) or not name or name.startswith("."):
            raise ValueError(f"a lazy module needs an absolute module name, got {name!r}")
        super().__init__(name)
        self.__dict__["_lazy_module"] = None

    def _lazy_load(self) -> types.ModuleType:
        """Import the module (once) and return it; ImportError naming it when it does not
        import."""
        module = self.__dict__["_lazy_module"]
        if module is None:
            name = self.__dict__["__name__"]
            try:
                module = importlib.import_module(name)
            except ImportError as exc:
                raise ImportError(f"{name} is needed here and does not import: {exc}",
                                  name=name) from exc
            self.__dict__["_lazy_module"] = module
        return module

    def __getattr__(self, attr: str):
        if attr.startswith("__") and attr.endswith("__") and not is_loaded(self):
            raise AttributeError(attr)
        value = getattr(self._lazy_load(), attr)
        self.__dict__[attr] = value
        return value

    def __dir__(self):
        return dir(self._lazy_load())

    def __repr__(self) -> str:
        state = "loaded" if is_loaded(self) else "not loaded"
        return f"<lazy module {self.__dict__['__name__']!r} ({state})>"


def lazy_module(name: str) -> LazyModule:
    """A proxy for the module ``name`` that imports it on first attribute read.

    Parameters
    ----------
    name : str
        The module's absolute dotted name, e.g. ``"scipy.optimize"``.

    Returns
    -------
    LazyModule
        The proxy; nothing is imported yet.

    Raises
    ------
    ValueError
        ``name`` empty, relative or not a string.
    """
    return LazyModule(name)


def is_loaded(proxy: LazyModule) -> bool:
    """Whether the proxy's module has been imported through it.

    Parameters
    ----------
    proxy : LazyModule

    Returns
    -------
    bool

    Raises
    ------
    TypeError
        ``proxy`` is not a :class:`LazyModule`.
    """
    if not isinstance(proxy, LazyModule):
        raise TypeError(f"is_loaded takes a LazyModule proxy, got {type(proxy).__name__}")
    return proxy.__dict__["_lazy_module"] is not None


#: scipy.fft (the spectra and the matched filters' correlations)
fft = lazy_module("scipy.fft")
#: scipy.interpolate (BSpline, PchipInterpolator)
interpolate = lazy_module("scipy.interpolate")
#: scipy.io (loadmat: MATLAB MAT-files v5/v7, meshphase.io.matlab)
io = lazy_module("scipy.io")
#: scipy.linalg (least-squares and QR of the smoother and the angle designs)
linalg = lazy_module("scipy.linalg")
#: scipy.ndimage (running filters and labelled runs)
ndimage = lazy_module("scipy.ndimage")
#: scipy.optimize (least_squares, brentq, approx_fprime, OptimizeResult)
optimize = lazy_module("scipy.optimize")
#: scipy.signal (the reference filters when numba is not installed; imports scipy.stats)
signal = lazy_module("scipy.signal")
#: scipy.special (the normal quantiles and error functions of the tolerance models)
special = lazy_module("scipy.special")
#: scipy.stats (the tolerance Monte Carlo's quasi-random sampler, qmc)
stats = lazy_module("scipy.stats")

#: The scipy submodules the processing stages use: loaded (:func:`load_all`) before a run
#: holds BLAS to one thread and before a campaign's fork server forks (scipy.signal and
#: scipy.stats are not among them: ``meshphase process`` needs neither)
PROCESSING_SCIPY = (fft, interpolate, linalg, ndimage, optimize, special)


def load_all(proxies=PROCESSING_SCIPY) -> None:
    """Import the modules of the given proxies now (each once).

    Parameters
    ----------
    proxies : iterable of LazyModule
        The proxies to load; empty: nothing to do.

    Raises
    ------
    TypeError
        An item that is not a :class:`LazyModule`.
    ImportError
        A module that does not import; the message names it.
    """
    proxies = tuple(proxies)
    for p in proxies:
        if not isinstance(p, LazyModule):
            raise TypeError(f"load_all takes LazyModule proxies, got {type(p).__name__}")
    for p in proxies:
        p._lazy_load()
