"""Generation speed (run with ``-m bench``): samples per second per channel, linear in duration.

Measured, not asserted beyond sanity: the numbers are printed (``-s``) and the cost must grow
linearly with the duration (events are computed once, samples block by block).
"""

import time

import numpy as np
import pytest

from meshphase.synthetic import generate_blocks


def _rate(name, duration, block=None, repeat=3):
    """Best of ``repeat`` runs (the reference machine is shared): samples/s, gauge-channel
    samples/s, seconds. The plan (events, truth) is included; it is O(events)."""
    best = None
    for _ in range(repeat):
        t = time.perf_counter()
        stream = generate_blocks(name, duration=duration, seed=0, block=block)
        n_gauges = sum(1 for c in stream.channels if c.kind != "tacho")
        n = 0
        for rec in stream:
            n += rec.n_samples
        dt = time.perf_counter() - t
        best = dt if best is None else min(best, dt)
    return n / best, n * n_gauges / best, best


@pytest.mark.bench
@pytest.mark.parametrize("name, duration", [("seed_rig", 600.0), ("table1_high_speed", 60.0),
                                            ("noisy", 600.0), ("rig_realistic", 600.0),
                                            ("facewidth_offcentre", 300.0),
                                            # pulses rendered in angle (shaft-locked ripple)
                                            ("rig_ripple1", 600.0), ("rig_ripple_sun", 600.0)])
def test_generation_rate(name, duration):
    _rate(name, duration / 10, repeat=1)   # warm caches
    s, gs, dt = _rate(name, duration)
    print(f"\n{name}: {s / 1e6:.1f} MSamples/s per channel-set, {gs / 1e6:.1f} MSamples/s "
          f"gauge-channel samples ({dt:.2f} s for {duration} s)")
    s2, _, dt2 = _rate(name, 2 * duration)
    # linear in duration (a fixed plan cost of O(events) makes the ratio a little below 2)
    assert 1.3 < dt2 / dt < 2.8
    assert gs > 2e6


@pytest.mark.bench
def test_one_hour_rate():
    s, gs, dt = _rate("one_hour", 3600.0, block=60.0, repeat=1)
    print(f"\none_hour: {dt:.1f} s, {gs / 1e6:.1f} MSamples/s per gauge channel")
    assert np.isfinite(gs) and gs > 2e6
