"""The run's machinery, below everything else: worker threads, the C heap, the numba kernel
cache and the package logger.

Holds no science and no file formats. May import only the standard library, numpy and the
package's root helpers (:mod:`meshphase.errors`, :mod:`meshphase.validate`); every other
package may import it.
"""
