"""Campaigns: one scene, many recordings, one Dask job (``meshphase campaign``), on a local
cluster or an existing scheduler, with completion markers to resume from and one report over all
recordings; a cluster of separate ``dask scheduler`` / ``dask worker`` processes
(:mod:`~meshphase.campaign.processes`, for the tests and the bench of a campaign on a real
cluster: docs/cluster.md).

May import :mod:`meshphase.run` and everything below it; only the command line and the bench
import it.
"""
