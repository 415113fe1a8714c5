"""Generate synthetic rig recordings, whole or block by block, with their ground truth.

:func:`generate` returns one :class:`~meshphase.recording.Recording` and its
:class:`~meshphase.synthetic.truth.GroundTruth`; :func:`generate_blocks` returns a
:class:`SyntheticStream` that yields the same samples as consecutive Recordings of a given
block length, with flat memory (the one-hour scenarios). The same seed gives the same samples
bit for bit, whichever way the recording is cut.

How a block is made
-------------------
1. Up front (cheap: events, not samples): the shaft hole error realisation, the exact
   engagement times of every gauged tooth (:mod:`meshphase.synthetic.kinematics`), the pulse
   amplitudes from load sharing and the face-width load (:mod:`meshphase.synthetic.gauges`), the tacho
   edges, the gain errors, hum phases and gaps (:mod:`meshphase.synthetic.artefacts`), and the truth.
2. Per block and channel: the pulses of the events whose support meets the block are
   scattered into the buffer from a tabulated pulse shape (work proportional to the pulse
   samples, not events x samples); then only the artefacts the scenario asks for are added,
   in the order of :mod:`meshphase.synthetic.artefacts`.

One :class:`~meshphase.synthetic.kinematics.SpeedClock` (the speed profile bound to the nominal speeds)
gives the engagements, the tacho edges, the pulses and the truth, so they share one angle
time ``tau``. Pulses last a fixed angle of the gauged gear (:mod:`meshphase.synthetic.gauges`): at
constant speed they are rendered linear in time, otherwise through
:func:`~meshphase.synthetic.gauges.angle_pulse_map` (a per-event polynomial in the sample offset that
follows ``tau(t)`` to 1e-9 mesh periods).

Channels appear in the order of ``config.gauges``, then the tacho, then the encoder. Samples
are in physical units with ``ChannelSpec.gain = 1``: a gauge's strain in its ``units`` (m/m
unless the gauge says "µε", "mm/m", "%", ...: every artefact is made in m/m and the channel
scaled last), the tacho and the encoder in V. The truth stays in SI (amplitudes, noise RMS
[m/m]); its ``extra["gauge_units"]`` gives each gauge's unit string and scale.
"""

from __future__ import annotations

import math
import sys
from typing import Iterator

import numpy as np
from tqdm import tqdm

from meshphase.runtime.log import logger
from meshphase.models.mesh_phasing import ShaftHoleErrors, ideal_phasing, time_varying_phasing
from meshphase.models.tolerance import Tolerances
from meshphase.recording import ChannelSpec, Recording
from meshphase.validate import as_int, as_positive

from meshphase.synthetic import artefacts as art
from meshphase.synthetic.config import SynthConfig, errors_to_dict, load_factor
from meshphase.synthetic.gauges import (AnglePulses, PulseTable, angle_pulse_map, face_load_factor, pulse_peak_offset, render_angle_pulses,
                                        render_box, render_pulses)
from meshphase.synthetic.kinematics import EngagementEvents, engagement_events, event_times_for_angles, gauge_rates
from meshphase.synthetic.scenarios import get_scenario
from meshphase.synthetic.truth import EventTable, GroundTruth, PassTruth

__all__ = ["generate", "generate_blocks", "SyntheticStream", "resolve_seed", "resolve_config",
           "draw_errors", "GENERATOR_VERSION"]

GENERATOR_VERSION = "2"
TWO_PI = 2.0 * math.pi
_SNAP = 1e-9
_DEFAULT_BLOCK_SAMPLES = 1 << 20
#: Sub-block for per-sample work [samples] (temporaries stay cache-resident).
_SUB = 1 << 15


# ----------------------------------------------------------------------------- inputs

def resolve_seed(seed=None, rng=None) -> int:
    """The integer seed to record: from ``seed`` (int), or drawn from ``rng``.

    Parameters
    ----------
    seed : int, optional
        Non-negative integer seed.
    rng : int, numpy.random.Generator or numpy.random.SeedSequence, optional
        Alternative source: an int is a seed; a Generator gives one 63-bit draw (so the
        recording stays reproducible from the recorded seed). None for both: fresh entropy.
    """
    if seed is not None and rng is not None:
        raise ValueError("give seed or rng, not both")
    src = seed if seed is not None else rng
    if src is None:
        return int(np.random.SeedSequence().entropy % (1 << 63))
    if isinstance(src, np.random.Generator):
        return int(src.integers(0, 1 << 63))
    if isinstance(src, np.random.SeedSequence):
        return int(np.random.default_rng(src).integers(0, 1 << 63))
    s = as_int(src, "seed")
    if s < 0:
        raise ValueError(f"seed must be >= 0, got {s!r}")
    return s


def resolve_config(scenario_or_config) -> SynthConfig:
    """A :class:`SynthConfig` from a config or a scenario name (ValueError listing names)."""
    if isinstance(scenario_or_config, SynthConfig):
        return scenario_or_config
    if isinstance(scenario_or_config, str):
        return get_scenario(scenario_or_config)
    raise TypeError(f"scenario_or_config must be a scenario name or a SynthConfig, got "
                    f"{type(scenario_or_config).__name__}")


def draw_errors(tolerances: Tolerances, n_planets: int, seed: int) -> ShaftHoleErrors:
    """One realisation of the shaft hole errors from tolerance bands, with the seed's
    ``errors`` stream (a negative radial error is stored as |e| with the angle turned by pi,
    as the Monte Carlo does)."""
    rng = art.stream_rng(seed, "errors")
    cols = tolerances.columns(n_planets)
    u = rng.random(len(cols))
    vals = {"e_planet": np.zeros(n_planets), "kappa_planet": np.zeros(n_planets)}
    for (name, n, band), ui in zip(cols, u):
        v = float(band.ppf(np.array([ui]))[0]) if band.is_random else band.mean
        if n is None:
            vals[name] = v
        else:
            vals[name][n] = v
    for e, k in (("e_sun", "kappa_sun"), ("e_ring", "kappa_ring")):
        if vals[e] < 0:
            vals[e], vals[k] = -vals[e], vals[k] + math.pi
    neg = vals["e_planet"] < 0
    vals["e_planet"][neg] *= -1.0
    vals["kappa_planet"][neg] += math.pi
    return ShaftHoleErrors(**vals)


def _frac(x):
    x = np.asarray(x, dtype=np.float64)
    out = x - np.floor(x)
    near = np.abs(x - np.rint(x)) <= _SNAP
    out = np.where(near, 0.0, out)
    return np.where(out >= 1.0, 0.0, out)


# ----------------------------------------------------------------------------- the plan

class _Channel:
    __slots__ = ("spec", "gauge", "pos", "per", "amp", "table", "gain", "sigma", "hum_phases",
                 "reach", "angle", "scale")


def _planet_loads(cfg: SynthConfig) -> tuple:
    """(load sharing [-], sun and ring centroid offsets [m] per planet, tilt solve summary
    or None): the centroids from the coupled tilt solve when the config asks for it."""
    g, n_p = cfg.gearset, cfg.gearset.n_planets
    ls = np.ones(n_p) if cfg.load_sharing is None else np.asarray(cfg.load_sharing)
    zs = np.asarray(cfg.centroid_sun)
    zr = np.asarray(cfg.centroid_ring)
    tilt_info = None
    if cfg.tilt is not None:
        sol = cfg.tilt.solve(g.face_width)
        zs = np.full(n_p, float(sol.z_s))
        zr = np.full(n_p, float(sol.z_r))
        tilt_info = {"z_s": float(sol.z_s), "z_r": float(sol.z_r),
                     "residual": float(np.max(sol.residual)),
                     "converged": bool(np.all(sol.converged)),
                     "face_width": g.face_width}
    return ls, zs, zr, tilt_info


def _pulse_amplitudes(cfg: SynthConfig, gauge, ev: EngagementEvents, loads: tuple) -> np.ndarray:
    """Pulse amplitude of each event [m/m]: nominal x load sharing x face load factor x the
    common load modulation at the engagement's carrier angle ``w_c tau``."""
    ls, zs, zr, _ = loads
    fac = np.ones(cfg.gearset.n_planets)
    if gauge.face_position is not None:
        cz = zs if gauge.gear == "sun" else zr
        fac = face_load_factor(gauge.face_position, cz, cfg.gearset.face_width)
    amp_planet = gauge.amplitude * ls * fac
    if not len(ev):
        return np.empty(0)
    return amp_planet[ev.planet - 1] * load_factor(cfg.load_modulation, cfg.speeds.carrier * ev.tau)


def _gain_error(gauge, a, draw) -> float:
    """The gauge's relative gain error [-]: the configured one plus its random draw."""
    ge = 0.0
    if isinstance(a.gain_error, dict):
        ge = a.gain_error.get(gauge.name, 0.0)
    elif a.gain_error is not None:
        ge = a.gain_error
    ge = float(ge + draw)
    if ge <= -1.0:
        raise ValueError(f"gauge {gauge.name!r}: drawn gain error {ge!r} <= -1 (gain_error_std too large)")
    return ge


class _Plan:
    """Everything computed before the first sample: events, amplitudes, artefact draws, truth."""

    def __init__(self, cfg: SynthConfig, duration: float, seed: int):
        self.cfg = cfg
        self.seed = seed
        self.fs = cfg.fs
        self.n_samples = int(round(duration * cfg.fs))
        if self.n_samples < 1:
            raise ValueError(f"duration {duration!r} s gives no sample at fs = {cfg.fs!r} Hz")
        dur = self.n_samples / self.fs
        cfg.speed.check(dur)
        #: the speed profile bound to the nominal speeds: one angle time for everything
        self.clock = cfg.speed.clock(cfg.speeds)
        self.dtype = np.dtype(cfg.dtype)
        # errors realisation
        if isinstance(cfg.errors, Tolerances):
            self.errors = draw_errors(cfg.errors, cfg.gearset.n_planets, seed)
        else:
            self.errors = cfg.errors
        loads = _planet_loads(cfg)
        gauge_truth = self._gauge_channels(dur, loads)
        tacho_times = self._tacho_channel(dur)
        enc_truth = self._encoder_channel(dur)
        a = cfg.artefacts
        self.hum = (art.HumSource(self.fs, a.hum_amplitude, a.hum_frequency, a.hum_harmonics)
                    if a.hum_amplitude else None)
        # gaps
        self.gaps = art.draw_gaps(art.stream_rng(seed, "gaps"), self.n_samples, self.fs,
                                  a.gap_rate, a.gap_length, a.dropout_rate)
        self.specs = tuple([c.spec for c in self.channels] + ([self.tacho_spec] if self.tacho else [])
                           + ([self.encoder_spec] if self.encoder else []))
        self.meta = {
            "source": "synthetic", "scenario": cfg.name, "seed": seed,
            "generator": f"synthetic/{GENERATOR_VERSION}",
            "gearset": cfg.gearset.to_dict(), "speeds_nominal": cfg.speeds.to_dict(),
        }
        self.history = [{"step": "meshphase.synthetic.generate", "scenario": cfg.name, "seed": seed,
                         "generator": GENERATOR_VERSION}]
        self.truth = self._truth(dur, loads, gauge_truth, tacho_times)
        if enc_truth is not None:
            self.truth.extra["encoder"] = enc_truth

    def _gauge_channels(self, dur: float, loads: tuple) -> dict:
        """The gauge channels (events, amplitudes, gains, pulse maps, noise and hum draws);
        returns their truth by kind (events, passes, pulse, gain errors, noise, hum phases)."""
        cfg, a = self.cfg, self.cfg.artefacts
        # artefact draws (independent streams so switching one does not move the others)
        setup = art.stream_rng(self.seed, "setup", 0)
        gain_rand = setup.standard_normal(len(cfg.gauges)) * a.gain_error_std
        hum_rng = art.stream_rng(self.seed, "setup", 1)
        n_harm = len(a.hum_harmonics)
        s_min = cfg.speed.bounds(dur)[0]
        self.channels: list[_Channel] = []
        truth = {k: {} for k in ("events", "passes", "pulse", "gain_errors", "noise_rms",
                                 "hum_phases")}
        for gi, gauge in enumerate(cfg.gauges):
            ch = _Channel()
            ch.gauge = gauge
            ch.scale = gauge.unit_scale                     # samples per m/m, at the end
            ch.spec = ChannelSpec(
                gauge.name, kind=gauge.kind, units=gauge.units, gain=1.0, gear=gauge.gear,
                tooth=gauge.tooth, face_position=gauge.face_position,
                description=f"synthetic {gauge.gear} tooth-root strain gauge, tooth {gauge.tooth}")
            ch.table = PulseTable(gauge.contact_ratio, gauge.side_lobe, gauge.skew)
            w, z = gauge_rates(cfg.gearset, cfg.speeds, gauge.gear)
            t_mesh_max = TWO_PI / (z * abs(w) * s_min)
            margin = ch.table.half * t_mesh_max + 2.0 / self.fs
            ev = engagement_events(cfg.gearset, cfg.speeds, gauge.gear, cfg.tooth_angle(gauge),
                                   -margin, dur + margin, errors=self.errors, profile=self.clock)
            amp = _pulse_amplitudes(cfg, gauge, ev, loads)
            ge = _gain_error(gauge, a, gain_rand[gi])
            ch.gain = 1.0 + ge
            ch.pos = ev.time * self.fs
            ch.per = ev.mesh_period * self.fs
            ch.amp = amp * ch.gain
            ch.reach = ch.table.half * float(ch.per.max()) + 1.0 if ch.per.size else 0.0
            t_angle = TWO_PI / (z * abs(w))                 # one mesh period of angle [s]
            ch.angle = None
            map_info = {"degree": 1, "fit_error": 0.0}
            if not self.clock.is_constant:
                # the pulse lasts a fixed angle: follow tau(t) within every pulse
                ch.angle = angle_pulse_map(ev.tau, t_angle, self.clock.tau, self.clock.time_of,
                                           self.fs, ch.table)
                map_info = {"degree": ch.angle.degree, "fit_error": ch.angle.fit_error}
            ch.sigma = gauge.amplitude / 10.0 ** (a.snr_db / 20.0) if a.snr_db is not None else 0.0
            ch.hum_phases = hum_rng.uniform(0.0, TWO_PI, n_harm)
            self.channels.append(ch)
            self._gauge_truth(truth, ch, ev, amp, dur, (w, z, t_angle), map_info, ge)
        return truth

    def _gauge_truth(self, truth: dict, ch: _Channel, ev: EngagementEvents, amp: np.ndarray,
                     dur: float, rates: tuple, map_info: dict, ge: float) -> None:
        """A gauge's events and passes inside the recording, its pulse, gain error, noise and
        hum phases into ``truth`` (``rates``: its relative speed [rad/s], tooth count and
        mesh period of angle time [s])."""
        cfg, gauge = self.cfg, ch.gauge
        w, z, t_angle = rates
        inside = (ev.time >= 0.0) & (ev.time < dur)
        evt = EngagementEvents(ev.time[inside], ev.tau[inside], ev.planet[inside],
                               ev.revolution[inside], ev.mesh_period[inside])
        truth["events"][gauge.name] = EventTable(
            time=cfg.t0 + evt.time, planet=evt.planet, revolution=evt.revolution,
            tau=evt.tau, mesh_period=evt.mesh_period, amplitude=amp[inside])
        truth["passes"][gauge.name] = self._passes(evt, gauge.gear, w, z, self.errors)
        truth["pulse"][gauge.name] = {
            "contact_ratio": gauge.contact_ratio, "side_lobe": gauge.side_lobe,
            "skew": gauge.skew, "support": ch.table.half,
            "peak_offset": pulse_peak_offset(gauge.contact_ratio, gauge.side_lobe, gauge.skew),
            "domain": "angle", "nominal_mesh_period": t_angle, "angle_map": map_info}
        truth["gain_errors"][gauge.name] = ge
        truth["noise_rms"][gauge.name] = ch.sigma
        truth["hum_phases"][gauge.name] = ch.hum_phases.tolist() if cfg.artefacts.hum_amplitude else []

    def _tacho_channel(self, dur: float) -> tuple[np.ndarray, np.ndarray]:
        """The carrier tacho's pulses (``self.tacho``) and spec; returns the start and stop
        times of its pulses inside the recording [s] (empty without a tacho)."""
        cfg = self.cfg
        self.tacho = None
        if cfg.tacho is None:
            return np.empty(0), np.empty(0)
        tc = cfg.tacho
        t_rev = TWO_PI / (abs(cfg.speeds.carrier) * cfg.speed.bounds(dur)[0])
        st, sp_ = event_times_for_angles(cfg.speeds.carrier, cfg.tacho_angle(),
                                         -tc.width * t_rev - 2.0 / self.fs, dur, width=tc.width,
                                         profile=self.clock)
        self.tacho = (st * self.fs, sp_ * self.fs, tc.level)
        self.tacho_spec = ChannelSpec(tc.name, kind="tacho", units="V", gain=1.0, gear="carrier",
                                      description="synthetic carrier once-per-revolution tacho")
        keep = (st >= 0.0) & (st < dur)
        return cfg.t0 + st[keep], cfg.t0 + sp_[keep]

    def _encoder_channel(self, dur: float) -> dict | None:
        """The encoder's pulses (``self.encoder``: rising and falling edges [samples], level)
        and spec, missing pulses left out and glitches added; returns its truth: every true
        rising edge inside the recording [s], which of them are missing, the glitches' rising
        edges [s] (None without an encoder)."""
        cfg = self.cfg
        self.encoder = None
        ec = cfg.encoder
        if ec is None:
            return None
        ppr = ec.pulses_per_rev
        w = getattr(cfg.speeds, ec.member)
        # pulse k rises where the shaft angle passes angle + 2 pi k / ppr: the marks of a
        # member turning ppr times as fast past ppr * angle; a pulse lasts ``duty`` of a period
        t_pulse = TWO_PI / (abs(w) * ppr * cfg.speed.bounds(dur)[0])
        st, sp_ = event_times_for_angles(w * ppr, ec.angle * ppr, -t_pulse - 2.0 / self.fs, dur,
                                         width=ec.duty, profile=self.clock)
        rng = art.stream_rng(self.seed, "setup", 90)
        gone = rng.random(st.size) < ec.missing
        glitch = rng.random(st.size) < ec.extra
        # a glitch sits at a random place in the low part of its period (after the fall)
        period = np.diff(st, append=st[-1] + (st[-1] - st[-2] if st.size > 1 else t_pulse))
        room = (1.0 - ec.duty - 2.0 * ec.glitch) * period
        g0 = sp_ + ec.glitch * period + rng.random(st.size) * np.maximum(room, 0.0)
        g0, g1 = g0[glitch], (g0 + ec.glitch * period)[glitch]
        a = np.concatenate([st[~gone], g0])
        b = np.concatenate([sp_[~gone], g1])
        order = np.argsort(a)
        self.encoder = (a[order] * self.fs, b[order] * self.fs, ec.level)
        self.encoder_spec = ChannelSpec(ec.name, kind="encoder", units="V", gain=1.0,
                                        shaft=ec.shaft, pulses_per_rev=ppr,
                                        description=f"synthetic {ec.shaft}-shaft encoder, "
                                                    f"{ppr} pulses per revolution")
        inside = (st >= 0.0) & (st < dur)
        g_in = (g0 >= 0.0) & (g0 < dur)
        return {"channel": ec.name, "shaft": ec.shaft, "pulses_per_rev": ppr,
                "rising_edges": (cfg.t0 + st[inside]).tolist(),
                "missing": np.flatnonzero(gone[inside]).tolist(),
                "glitch_edges": (cfg.t0 + g0[g_in]).tolist()}

    def _truth(self, dur: float, loads: tuple, gauge_truth: dict, tacho_times: tuple) -> GroundTruth:
        """The recording's ground truth."""
        cfg, clock, errors = self.cfg, self.clock, self.errors
        ls, zs, zr, tilt_info = loads
        gam_ideal_s, gam_ideal_r = ideal_phasing(cfg.gearset)
        s_grid = clock.factor(np.linspace(0.0, dur, 1001))
        return GroundTruth(
            scenario=cfg.name, seed=self.seed, fs=self.fs, t0=cfg.t0, n_samples=self.n_samples,
            config=cfg.to_dict(), errors=errors_to_dict(errors) if isinstance(errors, ShaftHoleErrors) else None,
            events=gauge_truth["events"], passes=gauge_truth["passes"],
            ideal_phasing={"sun": gam_ideal_s.tolist(), "ring": gam_ideal_r.tolist()},
            load_sharing=ls.copy(), centroid_sun=zs.copy(), centroid_ring=zr.copy(),
            tacho_times=tacho_times[0], tacho_stop_times=tacho_times[1],
            gain_errors=gauge_truth["gain_errors"], noise_rms=gauge_truth["noise_rms"],
            hum_phases=gauge_truth["hum_phases"], gaps=self.gaps, pulse=gauge_truth["pulse"],
            extra={"generator": GENERATOR_VERSION,
                   "speed_factor_range": [float(s_grid.min()), float(s_grid.max())],
                   "speed_clock_panels": clock.n_panels,
                   "tacho_angle": cfg.tacho_angle() if cfg.tacho else None,
                   "tilt_solution": tilt_info,
                   "tooth_angles": {x.name: cfg.tooth_angle(x) for x in cfg.gauges},
                   "gauge_units": {x.name: {"units": x.units, "scale": x.unit_scale}
                                   for x in cfg.gauges},
                   "channels": [c.name for c in self.specs]})

    def _passes(self, ev: EngagementEvents, gear: str, w: float, z: int, errors) -> PassTruth:
        cfg = self.cfg
        n_p = cfg.gearset.n_planets
        empty = PassTruth(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0), np.empty(0),
                          np.empty(0), np.empty(0))
        p1 = np.flatnonzero(ev.planet == 1)
        if p1.size == 0 or n_p < 2:
            return empty
        j = np.searchsorted(ev.time[p1], ev.time, side="right") - 1
        other = (ev.planet != 1) & (j >= 0)
        if not np.any(other):
            return empty
        jj = j[other]
        # complete passes: every other planet exactly once
        counts = np.bincount(jj, minlength=p1.size)
        complete = counts == n_p - 1
        sel = np.flatnonzero(other)[complete[jj]]
        if sel.size == 0:
            return empty
        jsel = j[sel]
        tau1 = ev.tau[p1][jsel]
        gamma = _frac(z * abs(w) * (ev.tau[sel] - tau1) / TWO_PI)
        gs, gr = time_varying_phasing(ev.tau[sel], cfg.gearset, cfg.speeds, errors)
        gm = (gs if gear == "sun" else gr)[np.arange(sel.size), ev.planet[sel] - 1]
        # renumber passes from 0
        _, pass_idx = np.unique(jsel, return_inverse=True)
        return PassTruth(pass_index=pass_idx.astype(np.int64), planet=ev.planet[sel].astype(np.int64),
                         time=cfg.t0 + ev.time[sel], time_planet1=cfg.t0 + ev.time[p1][jsel],
                         gamma=gamma, gamma_model=np.asarray(gm, dtype=np.float64))

    # ------------------------------------------------------------------ rendering
    def noise_sources(self) -> list:
        a = self.cfg.artefacts
        return [art.NoiseSource(self.seed, i, self.fs, ch.sigma, a.pink_fraction, a.pink_fmin)
                if ch.sigma > 0 else None for i, ch in enumerate(self.channels)]

    def render(self, i0: int, n: int, noise: list, out: np.ndarray | None = None) -> np.ndarray:
        """Samples i0 <= i < i0 + n of every channel, shape (n_channels, n) (into ``out``).

        Per-sample work runs on sub-blocks of :data:`_SUB` samples so that every temporary
        stays small and cache-resident (fresh large temporaries cost page faults here).
        """
        a = self.cfg.artefacts
        n_ch = len(self.specs)
        if out is None:
            buf = np.zeros((n_ch, n), dtype=self.dtype)
        else:
            buf = out
            buf.fill(0.0)
        f64 = self.dtype == np.float64
        scratch = None if f64 else np.zeros(min(n, _SUB))
        for s in range(0, n, _SUB):
            e = min(n, s + _SUB)
            j0, j1 = i0 + s, i0 + e                 # absolute sample range
            drift = None
            if a.drift_amplitude:
                drift = art.drift((j0 + np.arange(e - s, dtype=np.float64)) / self.fs,
                                  a.drift_amplitude, a.drift_time_constant)
            for c, ch in enumerate(self.channels):
                work = buf[c, s:e] if f64 else scratch[:e - s]
                if not f64:
                    work.fill(0.0)
                if ch.angle is not None:
                    ap = ch.angle
                    if len(ap):
                        lo = int(np.searchsorted(ap.first, j0 - ap.width, side="right"))
                        hi = int(np.searchsorted(ap.first, j1, side="left"))
                        if hi > lo:
                            sub = AnglePulses(ap.first[lo:hi], ap.count[lo:hi], ap.width,
                                              ap.coef[lo:hi], ap.degree, ap.fit_error)
                            render_angle_pulses(work, j0, sub, ch.amp[lo:hi], ch.table)
                elif ch.pos.size:
                    lo = int(np.searchsorted(ch.pos, j0 - ch.reach, side="left"))
                    hi = int(np.searchsorted(ch.pos, j1 + ch.reach, side="right"))
                    if hi > lo:
                        render_pulses(work, j0, ch.pos[lo:hi], ch.per[lo:hi], ch.amp[lo:hi],
                                      ch.table)
                if drift is not None:
                    work += drift
                if noise[c] is not None:
                    noise[c].add_to(work, j0)
                if self.hum is not None:
                    self.hum.add_to(work, j0, ch.hum_phases)
                if a.clip_level is not None:
                    art.clip(work, a.clip_level)
                if a.adc_bits is not None:
                    art.quantise(work, a.adc_bits, a.adc_range)
                if ch.scale != 1.0:
                    work *= ch.scale
                if not f64:
                    buf[c, s:e] = work
            boxes = [self.tacho, self.encoder]
            for row, box in zip(range(len(self.channels), n_ch), [b for b in boxes if b is not None]):
                st, sp_, level = box
                lo = int(np.searchsorted(sp_, j0 - 1.0, side="left"))
                hi = int(np.searchsorted(st, j1 + 1.0, side="right"))
                if hi > lo:
                    w = buf[row, s:e] if f64 else scratch[:e - s]
                    if not f64:
                        w.fill(0.0)
                    render_box(w, j0, st[lo:hi], sp_[lo:hi], level)
                    if not f64:
                        buf[row, s:e] = w
        if self.gaps.size:
            art.apply_gaps(buf.T, i0, self.gaps)
        return buf

    def recording(self, i0: int, buf: np.ndarray) -> Recording:
        return Recording(buf.T, self.fs, self.specs, t0=self.cfg.t0 + i0 / self.fs,
                         start_datetime=self.cfg.start_datetime, meta=self.meta,
                         history=self.history)


# ----------------------------------------------------------------------------- public API

def _progress_callback(progress, total: int, desc: str):
    """(update(n), close()) for progress=None/False, True (tqdm bar) or a callable(done, total)."""
    if progress is None or progress is False:
        return (lambda n: None), (lambda: None)
    if progress is True:
        bar = tqdm(total=total, desc=desc, unit="S", unit_scale=True, file=sys.stderr, leave=False)
        return bar.update, bar.close
    if callable(progress):
        state = {"done": 0}

        def upd(n):
            state["done"] += n
            progress(state["done"], total)
        return upd, (lambda: None)
    raise TypeError(f"progress must be None, a bool or a callable(done, total), got {progress!r}")


class SyntheticStream:
    """A synthetic recording produced block by block (flat memory).

    Iterating yields consecutive :class:`Recording` blocks of ``block_samples`` samples (the
    last one shorter); their samples equal those of :func:`generate` with the same seed. The
    ground truth of the whole recording is available before iterating (``truth``).

    Attributes
    ----------
    truth : GroundTruth
    fs : float
        Sample rate [Hz].
    n_samples : int
        Total samples per channel.
    channels : tuple of ChannelSpec
    block_samples : int
        Samples per block.
    dtype : numpy dtype
        Sample type of the blocks.
    """

    def __init__(self, plan: _Plan, block_samples: int, progress=None):
        self._plan = plan
        self.truth = plan.truth
        self.fs = plan.fs
        self.n_samples = plan.n_samples
        self.channels = plan.specs
        self.block_samples = int(block_samples)
        self.progress = progress
        self.meta = plan.meta
        self.history = plan.history
        self.t0 = plan.cfg.t0
        self.start_datetime = plan.cfg.start_datetime
        self.dtype = plan.dtype

    def __len__(self) -> int:
        return -(-self.n_samples // self.block_samples)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.channels]

    def _blocks(self, out=None):
        plan = self._plan
        noise = plan.noise_sources()
        upd, close = _progress_callback(self.progress, self.n_samples, f"synth {plan.cfg.name}")
        try:
            for i0 in range(0, self.n_samples, self.block_samples):
                n = min(self.block_samples, self.n_samples - i0)
                buf = plan.render(i0, n, noise, None if out is None else out[:, i0:i0 + n])
                upd(n)
                yield i0, buf
        finally:
            close()

    def __iter__(self) -> Iterator[Recording]:
        for i0, buf in self._blocks():
            yield self._plan.recording(i0, buf)

    def collect(self) -> Recording:
        """All blocks in one Recording, rendered straight into one output array."""
        plan = self._plan
        out = np.empty((len(self.channels), self.n_samples), dtype=plan.dtype)
        for _ in self._blocks(out):
            pass
        return plan.recording(0, out)


def _plan(scenario_or_config, duration, seed, rng) -> _Plan:
    cfg = resolve_config(scenario_or_config)
    dur = cfg.duration if duration is None else as_positive(duration, "duration")
    s = resolve_seed(seed, rng)
    plan = _Plan(cfg, dur, s)
    logger.info("synthetic %s: %d samples x %d channels at %g Hz, seed %d", cfg.name,
                plan.n_samples, len(plan.specs), plan.fs, s)
    return plan


def generate_blocks(scenario_or_config, *, duration: float | None = None, block: float | None = None,
                    seed: int | None = None, rng=None, progress=None) -> SyntheticStream:
    """A synthetic recording as a stream of Recording blocks, with its ground truth.

    Parameters
    ----------
    scenario_or_config : str or SynthConfig
        Scenario name (:data:`meshphase.synthetic.scenarios.SCENARIOS`) or a config.
    duration : float, optional
        Duration [s] (default: the scenario's).
    block : float, optional
        Block length [s] (default 2**20 samples).
    seed : int, optional
        Seed of the random generator (recorded in the truth); None draws fresh entropy.
    rng : int, Generator or SeedSequence, optional
        Alternative to ``seed`` (see :func:`resolve_seed`).
    progress : None, bool or callable(done, total)
        Progress bar (True: tqdm on stderr) or callback in samples.

    Returns
    -------
    SyntheticStream
    """
    plan = _plan(scenario_or_config, duration, seed, rng)
    if block is None:
        nb = _DEFAULT_BLOCK_SAMPLES
    else:
        nb = max(1, int(round(as_positive(block, "block") * plan.fs)))
    return SyntheticStream(plan, nb, progress)


def generate(scenario_or_config, *, duration: float | None = None, seed: int | None = None,
             rng=None, progress=None) -> tuple[Recording, GroundTruth]:
    """Generate a synthetic recording and its ground truth.

    Parameters
    ----------
    scenario_or_config : str or SynthConfig
        Scenario name (:data:`meshphase.synthetic.scenarios.SCENARIOS`) or a config.
    duration : float, optional
        Duration [s] (default: the scenario's).
    seed : int, optional
        Seed of the random generator, recorded in the truth; None draws fresh entropy.
    rng : int, Generator or SeedSequence, optional
        Alternative to ``seed`` (see :func:`resolve_seed`).
    progress : None, bool or callable(done, total)
        Progress bar (True: tqdm on stderr) or callback in samples.

    Returns
    -------
    recording : Recording
        Samples x channels in physical units (strain in each gauge's units, m/m by default;
        tacho [V]); NaN over gaps.
    truth : GroundTruth
        Engagement times, planets, true phasing per pass, load sharing, centroids, all
        parameters and the seed.
    """
    plan = _plan(scenario_or_config, duration, seed, rng)
    stream = SyntheticStream(plan, _DEFAULT_BLOCK_SAMPLES, progress)
    return stream.collect(), plan.truth
