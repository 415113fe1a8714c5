"""The run's machinery, below everything else: worker threads, the C heap, the numba kernel
cache, the package logger and the proxies through which the package imports scipy on first use
(:mod:`.lazy`).

Holds no science and no file formats. May import only the standard library, numpy and the
package's root helpers (:mod:`meshphase.errors`, :mod:`meshphase.validate`), and scipy only
through :mod:`.lazy`'s proxies; every other package may import it.
"""
