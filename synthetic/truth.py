"""Ground truth of a synthetic recording, and its JSON sidecar file.

Everything downstream (onsets, phasing, load sharing, centroids) is judged against this.

Definitions
-----------
Engagement time
    The instant the gauged tooth's centre line crosses the line of centres from the gauged
    gear's actual pitch centre to the actual centre of the planet, i.e. the middle of the
    tooth's contact with that planet (:mod:`meshphase.synthetic.kinematics`). Times are on the
    recording's time axis (``t0 + i / fs``) [s]; ``tau`` is the engagement's angle time.
Pulse position (angle, not time)
    A pulse is a function of the gauged gear's rotation angle relative to the carrier
    (:mod:`meshphase.synthetic.gauges`): the tensile lobe spans ``contact_ratio`` mesh periods *of angle*
    centred on the engagement, its maximum lies ``pulse[name]["peak_offset"]`` mesh periods of
    angle after it, and the support is ``pulse[name]["support"]`` mesh periods of angle either
    side. One mesh period of angle is ``2 pi / Z`` of relative rotation, i.e. angle time
    ``pulse[name]["nominal_mesh_period"]`` = ``2 pi / (Z |w_rel|)`` [s]; in time it lasts the
    local mesh period (``events[name].mesh_period`` at the engagement), and it stretches with
    the speed within the pulse. A feature ``x`` mesh periods of angle after the engagement
    therefore sits at ``t(tau_e + x * nominal_mesh_period)``, which
    :meth:`GroundTruth.event_angle_times` evaluates exactly (``~ t_e + x * mesh_period`` to
    first order). A detector reporting another feature of the pulse sees a constant offset in
    mesh periods of angle, which is expected.
Planet numbers
    1-based, planet 1 = ``gearset.planet_angles[0]`` (as in the papers and
    :class:`meshphase.kinematics.phasing.PassTable`).
Pass
    One relative revolution of the gauged gear starting at its engagement with planet 1; the
    pass holds the following engagement of every other planet before planet 1 comes again.
    Passes cut by the start or end of the recording are left out.
True phasing per pass (``gamma``)
    ``gamma_jn = frac(Z_j |w_jc| (tau_n - tau_1) / 2 pi)`` with ``tau`` the angle time of the
    engagements (rotation angles are ``w tau``; see kinematics): the mesh cycles the gauged
    gear turns, relative to the carrier, from meeting planet 1 to meeting planet n. At
    constant speed this is exactly spec section 3's ``frac((t_n - t_1) / T_j)`` with the
    nominal mesh period; under speed fluctuation it is what a measurement that rebuilds the
    local angle from the pulse train (or the tacho) should find. It is counted forward in time
    for both gears, which reproduces Parker's signs of spec section 1 (ring included: for
    clockwise planets gamma_rn = frac(-Z_r psi_n / 2 pi)); spec section 3 writes the ring case
    with a minus sign, which holds when t_n - t_1 is counted backwards. Values within 1e-9 of a
    whole cycle are stored as 0.
Model phasing (``gamma_model``)
    :func:`meshphase.models.mesh_phasing.time_varying_phasing` evaluated at the angle time of
    planet n's engagement: the instantaneous model value. It differs from ``gamma`` by the
    change of the errors' geometry during the pass (of the order of Dev).
SNR
    ``20 log10(A / sigma)``, A the gauge's nominal pulse peak strain, sigma the RMS of the
    broadband noise (white + 1/f): ``noise_rms[name]`` = sigma [m/m].
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshphase.io.base import atomic_path
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.synthetic.config import SynthConfig, errors_from_dict

__all__ = ["GroundTruth", "EventTable", "PassTruth", "truth_path_for", "ENGAGEMENT_DEFINITION",
           "TRUTH_FORMAT"]

TRUTH_FORMAT = "meshphase-synthetic-truth/1"

ENGAGEMENT_DEFINITION = (
    "engagement time = instant the gauged tooth's centre line crosses the line of centres "
    "(actual gear pitch centre -> actual planet centre), i.e. the middle of the tooth's contact "
    "with that planet; the pulse is a function of the gauged gear's angle: its tensile lobe "
    "spans contact_ratio mesh periods of angle centred on it and its peak lies "
    "pulse[channel].peak_offset mesh periods of angle after it; times on the recording axis "
    "t0 + i/fs [s]; planets 1-based")


def truth_path_for(recording_path) -> Path:
    """Sidecar path of a recording file: the file name plus ``.truth.json``."""
    p = Path(recording_path)
    return p.with_name(p.name + ".truth.json")


def _arr(x, dtype=float):
    return np.asarray(x, dtype=dtype)


@dataclass
class EventTable:
    """Engagements of one gauge channel, sorted by time.

    Attributes
    ----------
    time : ndarray
        Engagement times on the recording axis [s].
    planet : ndarray of int
        Planet number, 1-based.
    revolution : ndarray of int
        Relative revolution index k of the gauged gear [-].
    tau : ndarray
        Angle time of the engagement [s] (relative to the first sample).
    mesh_period : ndarray
        Local mesh period [s].
    amplitude : ndarray
        True peak strain of the pulse [m/m] (load sharing, face load and the common load
        modulation included; the gauge gain error is not: see ``GroundTruth.gain_errors``;
        a channel written in other units holds it times ``extra["gauge_units"]`` scale).
    """

    time: np.ndarray
    planet: np.ndarray
    revolution: np.ndarray
    tau: np.ndarray
    mesh_period: np.ndarray
    amplitude: np.ndarray

    _FIELDS = ("time", "planet", "revolution", "tau", "mesh_period", "amplitude")

    def __len__(self) -> int:
        return int(np.asarray(self.time).size)

    def to_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)).tolist() for k in self._FIELDS}

    @classmethod
    def from_dict(cls, d: dict) -> "EventTable":
        return cls(time=_arr(d["time"]), planet=_arr(d["planet"], np.int64),
                   revolution=_arr(d["revolution"], np.int64), tau=_arr(d["tau"]),
                   mesh_period=_arr(d["mesh_period"]), amplitude=_arr(d["amplitude"]))


@dataclass
class PassTruth:
    """True phasing per pass of one gauge channel: one row per planet 2..N per pass.

    Attributes
    ----------
    pass_index : ndarray of int
        Pass number (0 = first complete pass in the recording).
    planet : ndarray of int
        Planet number n, 1-based (2..N).
    time : ndarray
        Engagement time of planet n in this pass [s] (recording axis).
    time_planet1 : ndarray
        Engagement time of planet 1 opening the pass [s].
    gamma : ndarray
        True phasing from the engagement angles [-], in [0, 1).
    gamma_model : ndarray
        Model phasing at planet n's engagement [-], in [0, 1).
    """

    pass_index: np.ndarray
    planet: np.ndarray
    time: np.ndarray
    time_planet1: np.ndarray
    gamma: np.ndarray
    gamma_model: np.ndarray

    _FIELDS = ("pass_index", "planet", "time", "time_planet1", "gamma", "gamma_model")

    def __len__(self) -> int:
        return int(np.asarray(self.time).size)

    def to_dict(self) -> dict:
        return {k: np.asarray(getattr(self, k)).tolist() for k in self._FIELDS}

    @classmethod
    def from_dict(cls, d: dict) -> "PassTruth":
        return cls(pass_index=_arr(d["pass_index"], np.int64), planet=_arr(d["planet"], np.int64),
                   time=_arr(d["time"]), time_planet1=_arr(d["time_planet1"]),
                   gamma=_arr(d["gamma"]), gamma_model=_arr(d["gamma_model"]))

    def for_planet(self, n: int) -> "PassTruth":
        """Rows of planet ``n`` (1-based)."""
        m = np.asarray(self.planet) == n
        return PassTruth(*(np.asarray(getattr(self, k))[m] for k in self._FIELDS))


@dataclass
class GroundTruth:
    """Everything that went into a synthetic recording.

    Attributes
    ----------
    scenario : str
        Scenario (config) name.
    seed : int
        Seed of the random generator (``SeedSequence`` entropy); the same seed and config
        give the same samples.
    fs : float
        Sample rate [Hz].
    t0 : float
        Time of the first sample [s].
    n_samples : int
        Samples per channel.
    config : dict
        The full :class:`meshphase.synthetic.config.SynthConfig` (``to_dict``): gearset, nominal
        speeds, gauges, artefacts, speed profile, tacho.
    errors : dict or None
        The shaft hole error realisation used (ShaftHoleErrors fields, SI), drawn from the
        tolerance bands with the seed when the config gives bands.
    events : dict of str to EventTable
        Engagements per gauge channel.
    passes : dict of str to PassTruth
        True phasing per pass per gauge channel.
    ideal_phasing : dict
        ``{"sun": [...], "ring": [...]}`` Parker's gamma_sn, gamma_rn [-].
    load_sharing : ndarray, shape (N,)
        Planet load sharing factors LS_n [-].
    centroid_sun, centroid_ring : ndarray, shape (N,)
        Load centroid offsets Z_S, Z_R per planet [m].
    tacho_times : ndarray
        Tacho rising edges (key reaches the probe) [s]; empty without a tacho.
    tacho_stop_times : ndarray
        Tacho falling edges [s].
    gain_errors : dict of str to float
        Relative gain error of each gauge channel [-] (recorded = (1 + g) * strain).
    noise_rms : dict of str to float
        Broadband noise RMS per gauge channel [m/m] (0 without noise).
    hum_phases : dict of str to list
        Phase of each hum harmonic per channel [rad].
    gaps : ndarray of int, shape (k, 2)
        ``[start, stop)`` sample ranges lost (NaN in every channel).
    pulse : dict of str to dict
        Per gauge: ``contact_ratio``, ``side_lobe``, ``skew``; ``peak_offset`` and ``support``
        (half-width) in mesh periods of the gauged gear's angle relative to the carrier;
        ``domain`` ("angle"); ``nominal_mesh_period``: one mesh period of angle in angle time,
        ``2 pi / (Z |w_rel|)`` [s]; ``angle_map``: degree and fit error [mesh periods] of the
        renderer's per-pulse polynomial (degree 1, error 0 at constant speed).
    engagement_definition : str
        :data:`ENGAGEMENT_DEFINITION`.
    extra : dict
        Anything else (generator version, speed factor range...).
    """

    scenario: str
    seed: int
    fs: float
    t0: float
    n_samples: int
    config: dict
    errors: dict | None
    events: dict
    passes: dict
    ideal_phasing: dict
    load_sharing: np.ndarray
    centroid_sun: np.ndarray
    centroid_ring: np.ndarray
    tacho_times: np.ndarray
    tacho_stop_times: np.ndarray
    gain_errors: dict
    noise_rms: dict
    hum_phases: dict
    gaps: np.ndarray
    pulse: dict
    engagement_definition: str = ENGAGEMENT_DEFINITION
    extra: dict = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Duration n_samples / fs [s]."""
        return self.n_samples / self.fs

    def to_dict(self) -> dict:
        """JSON-friendly dict (arrays as lists; floats round-trip exactly)."""
        return {
            "format": TRUTH_FORMAT, "scenario": self.scenario, "seed": int(self.seed),
            "fs": self.fs, "t0": self.t0, "n_samples": int(self.n_samples),
            "duration": self.duration,
            "engagement_definition": self.engagement_definition,
            "config": self.config, "errors": self.errors,
            "events": {k: v.to_dict() for k, v in self.events.items()},
            "passes": {k: v.to_dict() for k, v in self.passes.items()},
            "ideal_phasing": self.ideal_phasing,
            "load_sharing": np.asarray(self.load_sharing).tolist(),
            "centroid_sun": np.asarray(self.centroid_sun).tolist(),
            "centroid_ring": np.asarray(self.centroid_ring).tolist(),
            "tacho_times": np.asarray(self.tacho_times).tolist(),
            "tacho_stop_times": np.asarray(self.tacho_stop_times).tolist(),
            "gain_errors": dict(self.gain_errors), "noise_rms": dict(self.noise_rms),
            "hum_phases": {k: list(v) for k, v in self.hum_phases.items()},
            "gaps": np.asarray(self.gaps, dtype=np.int64).reshape(-1, 2).tolist(),
            "pulse": self.pulse, "extra": self.extra,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "GroundTruth":
        """Inverse of :meth:`to_dict`; ValueError for another format."""
        if d.get("format") != TRUTH_FORMAT:
            raise ValueError(f"not a meshphase synthetic truth (format {d.get('format')!r}, "
                             f"expected {TRUTH_FORMAT!r})")
        return cls(
            scenario=d["scenario"], seed=int(d["seed"]), fs=float(d["fs"]), t0=float(d["t0"]),
            n_samples=int(d["n_samples"]), config=d["config"], errors=d.get("errors"),
            events={k: EventTable.from_dict(v) for k, v in d["events"].items()},
            passes={k: PassTruth.from_dict(v) for k, v in d["passes"].items()},
            ideal_phasing=d["ideal_phasing"], load_sharing=_arr(d["load_sharing"]),
            centroid_sun=_arr(d["centroid_sun"]), centroid_ring=_arr(d["centroid_ring"]),
            tacho_times=_arr(d["tacho_times"]), tacho_stop_times=_arr(d["tacho_stop_times"]),
            gain_errors={k: float(v) for k, v in d["gain_errors"].items()},
            noise_rms={k: float(v) for k, v in d["noise_rms"].items()},
            hum_phases={k: [float(x) for x in v] for k, v in d["hum_phases"].items()},
            gaps=_arr(d["gaps"], np.int64).reshape(-1, 2), pulse=d["pulse"],
            engagement_definition=d.get("engagement_definition", ENGAGEMENT_DEFINITION),
            extra=d.get("extra", {}),
        )

    def write(self, path, *, overwrite: bool = False) -> Path:
        """Write the sidecar JSON to ``path`` (atomically); FileExistsError unless overwrite."""
        path = Path(path)
        text = json.dumps(self.to_dict(), allow_nan=False, separators=(",", ":"))
        with atomic_path(path, overwrite=overwrite) as tmp:
            tmp.write_text(text, encoding="utf-8")
        return path

    @classmethod
    def read(cls, path) -> "GroundTruth":
        """Read a sidecar written by :meth:`write` (or the sidecar of a recording path)."""
        path = Path(path)
        if not path.name.endswith(".truth.json") and truth_path_for(path).exists():
            path = truth_path_for(path)
        with open(path, encoding="utf-8") as fh:
            d = json.load(fh)
        return cls.from_dict(d)

    def speed_clock(self):
        """The recording's :class:`~meshphase.synthetic.kinematics.SpeedClock` (speed profile bound to the
        nominal speeds, both from ``config``): ``tau(t)`` and ``t(tau)`` with t from the first
        sample [s]."""
        cfg = SynthConfig.from_dict(self.config)
        return cfg.speed.clock(cfg.speeds)

    def shaft_hole_errors(self) -> ShaftHoleErrors | None:
        """The shaft hole errors put in (``errors`` as :class:`ShaftHoleErrors`), None
        without (:class:`meshphase.compare.truth.RecordingTruth`)."""
        return errors_from_dict(self.errors) if isinstance(self.errors, dict) else self.errors

    def tacho_geometry(self) -> tuple:
        """(key angle [rad] or None, {gauge channel: ground angle [rad]}) of the generator
        (:class:`meshphase.compare.truth.RecordingTruth`).

        Its key reaches the probe at carrier angle ``cfg.tacho_angle()``, so the edge fires
        at theta_c = -key_angle; a held member's gauge sits still, its direction at t = 0 is
        its ground angle. The key angle is None without a tacho in the configuration.
        """
        cfg = SynthConfig.from_dict(self.config)
        key = -cfg.tacho_angle() if cfg.tacho is not None else None
        return key, {g.name: cfg.tooth_angle(g) for g in cfg.gauges}

    def event_angle_times(self, channel: str, offset) -> np.ndarray:
        """Times [s] (recording axis) at which the gauged gear has turned ``offset`` mesh
        periods of angle past each engagement of ``channel``.

        ``offset = pulse[channel]["peak_offset"]`` gives the pulse maxima, ``+-support`` the
        ends of the pulse support, 0 the engagement times themselves.

        Parameters
        ----------
        channel : str
            Gauge channel name.
        offset : float or array_like
            Angle after the engagement [mesh periods]; broadcast against the events.
        """
        if channel not in self.events:
            raise ValueError(f"no gauge channel {channel!r} in the truth; channels: {sorted(self.events)}")
        ev = self.events[channel]
        tau = np.asarray(ev.tau, dtype=float) + np.asarray(offset, dtype=float) * float(
            self.pulse[channel]["nominal_mesh_period"])
        return self.t0 + self.speed_clock().time_of(tau)

    def gamma_table(self, channel: str) -> PassTruth:
        """True phasing per pass of ``channel`` (ValueError naming the channels if unknown)."""
        if channel not in self.passes:
            raise ValueError(f"no gauge channel {channel!r} in the truth; channels: {sorted(self.passes)}")
        return self.passes[channel]

    def __eq__(self, other) -> bool:
        if not isinstance(other, GroundTruth):
            return NotImplemented
        return json.dumps(self.to_dict(), sort_keys=True) == json.dumps(other.to_dict(), sort_keys=True)

    __hash__ = None
