"""Importing this module draws one small figure of the combined campaign report.

A campaign's local workers fork from a server that has imported what their tasks need
(:func:`meshphase.cluster.worker_server`, with :func:`meshphase.campaign_job.worker_modules`).
Such a server can only import modules before it forks, so this module does its work when it
is imported: it draws :func:`meshphase.report.campaign_report.wall_times_across_recordings`
for two made-up recordings to PNG, in memory. After that matplotlib has imported what it loads
on first use (the Agg canvas, Pillow's PNG writer, the legend and text modules), it has read
its font and filled its text caches. Every forked worker inherits all of it.

Measured (2-core machine, 6 forks per figure, each child drawing one real figure of an
8-recording campaign twice): the first figure took 0.138 s longer than the second in a
child of a server without this module, 0.009-0.020 s longer with it. The drawing here takes
0.17-0.18 s, once, in the server, which starts while the campaign checks its scene. Every
worker draws figures of the combined report after its recordings
(:func:`meshphase.campaign_job.draw_figures`), so a campaign on one or two local workers
ends about 0.12 s sooner.

Remote workers import it too, when they connect (:func:`meshphase.campaign_job.warm_up`).
Nothing else imports it.
"""

from __future__ import annotations

import time

from .campaign_report import figure_png, wall_times_across_recordings

__all__ = ["WARM_UP_S", "WARM_UP_PNG_BYTES", "draw_warm_up_figure"]


def draw_warm_up_figure() -> bytes:
    """One small figure of the combined report, drawn to PNG: its bars, labels and layout.

    Returns
    -------
    bytes
        The PNG.
    """
    return figure_png(wall_times_across_recordings, ["rec_a", "rec_b"], [1.0, 2.0], ["ok", "failed"])


_t = time.perf_counter()
#: The size of the figure drawn on import [bytes].
WARM_UP_PNG_BYTES = len(draw_warm_up_figure())
#: What drawing it took on import [s].
WARM_UP_S = time.perf_counter() - _t
del _t
