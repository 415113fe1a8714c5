"""Bridge channels converted to strain as a recording is streamed: a block source.

:class:`BridgeSource` wraps any :class:`meshphase.run.stream.BlockSource` and converts the
bridge channels of every block it reads with :func:`meshphase.io.bridge.convert_block`, after
reading each channel's unstrained output over its null window once
(:func:`meshphase.io.bridge.initial_volts`). The equations and their sources:
:mod:`meshphase.io.bridge`.
"""

from __future__ import annotations

from meshphase.io.bridge import BridgeConfig, bridge_history, convert_block, initial_volts, strain_spec
from meshphase.run.stream import BlockSource, StreamedRecording

__all__ = ["BridgeSource"]


class BridgeSource(BlockSource):
    """A block source (:class:`meshphase.run.stream.BlockSource`) whose bridge channels come out
    in strain [m/m]: the source's blocks converted as they are read.

    V_init of each channel with a null window is read once, when this source is made, from
    ``null_source`` (the whole recording, so that a window outside an analysis window
    ``start_s``/``stop_s`` still reads); every other attribute is the wrapped source's.

    Parameters
    ----------
    source : BlockSource
        Bridge channels in volts [V] (gains applied).
    configs : dict of str to BridgeConfig
        Channel name -> its bridge.
    null_source : BlockSource, optional
        The whole recording, for the null windows (default ``source``).
    """

    def __init__(self, source, configs: dict, null_source=None):
        h = source.header
        self.source = source
        bad = [n for n, c in configs.items() if not isinstance(c, BridgeConfig)]
        if bad or not configs:
            raise TypeError(f"configs must map channel names to BridgeConfig, got {configs!r}")
        cols = {h.index(name): c for name, c in configs.items()}
        ns = source if null_source is None else null_source
        nh = ns.header
        self.v_init = initial_volts(ns.blocks(1 << 16), nh.t0, nh.fs, nh.n_samples, cols)
        self.conversions = {j: (c, self.v_init[j]) for j, c in cols.items()}
        specs = tuple(strain_spec(s) if j in cols else s for j, s in enumerate(h.channels))
        self._header = StreamedRecording(h.fs, h.n_samples, specs, h.t0, h.start_datetime, h.meta,
                                         h.history, h.dtype).with_history(
            "bridge_strain", channels=bridge_history(h.names, cols, self.v_init))

    @property
    def header(self) -> StreamedRecording:
        """The wrapped source's header with the bridge channels in "m/m" and the
        ``bridge_strain`` step in its history (its dtype follows the wrapped source's)."""
        self._header.dtype = self.source.header.dtype
        return self._header

    @property
    def label(self) -> str:
        return self.source.label

    def __getattr__(self, name):
        if name == "source":   # not set yet (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.source, name)  # warn_nonfinite, fmt, path ... of the wrapped source

    def blocks(self, n_block: int):
        """The wrapped source's blocks, bridge columns in strain [m/m]."""
        for a, data in self.source.blocks(n_block):
            yield a, convert_block(data, self.conversions)
