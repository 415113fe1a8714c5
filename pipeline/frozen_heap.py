"""Importing this module collects the garbage and freezes the heap (:func:`gc.freeze`).

A campaign's local workers fork from a server that has imported what their tasks need
(:func:`meshphase.cluster.worker_server`, with :func:`meshphase.campaign_job.worker_modules`,
of which this module is the last). Such a server can only import modules before it forks,
so this module does its work when it is imported. It does what the documentation of
:func:`gc.freeze` advises before a ``fork()`` without ``exec()``: the objects the imports made
(about 190 000) move to the collector's permanent generation. A worker's collections then
never walk them, and so never write to, and copy, the pages they share with the server.

Measured (``meshphase bench campaign``, its first-figure rows: a forked child draws one figure
of the combined report twice; medians of 6 children per figure): without this module the
child's first figure took 0.14-0.15 s longer than its second, a full collection walking every
inherited object; with it, 0.035-0.066 s longer (0.025-0.032 s in two earlier runs).

Remote workers import it when they connect (:func:`meshphase.campaign_job.warm_up`): their
modules' objects stay alive for the worker's life anyway. Nothing else imports it.
"""

from __future__ import annotations

import gc

__all__ = ["FROZEN_OBJECTS"]

gc.collect()
gc.freeze()
#: Objects in the permanent generation once this module was imported [-].
FROZEN_OBJECTS = gc.get_freeze_count()
