"""Typed description of a synthetic recording: gearset, speeds, gauges, artefacts.

A :class:`SynthConfig` is everything :func:`meshphase.synthetic.generate.generate` needs; the named
scenarios (:mod:`meshphase.synthetic.scenarios`) are functions returning one. Every field is SI
(m, rad, rad/s, s, Hz, strain m/m) and is validated on construction (ValueError / TypeError
naming the field). ``to_dict`` / ``from_dict`` give a JSON-friendly round trip, which is how
the configuration travels in the ground-truth sidecar.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from meshphase.models.bearing import seed_case
from meshphase.models.gearset import Gearset, Speeds
from meshphase.models.mesh_phasing import ShaftHoleErrors
from meshphase.models.tilt import solve_tilt
from meshphase.models.tolerance import ToleranceBand, Tolerances
from meshphase.validate import (as_choice, as_finite_array, as_float, as_int, as_nonnegative,
                                as_positive, as_positive_int)

from meshphase.synthetic.kinematics import SpeedProfile

__all__ = ["GaugeConfig", "TachoConfig", "EncoderConfig", "TiltSource", "Artefacts", "SynthConfig",
           "LoadModulation", "load_factor", "STRAIN_UNITS", "errors_to_dict", "errors_from_dict"]

GEARS = ("sun", "ring")
DTYPES = ("float64", "float32")
#: Strain units a gauge channel can be written in: unit string -> samples per m/m [-]
#: (micro sign U+00B5 and Greek mu U+03BC both spell microstrain).
STRAIN_UNITS = {"m/m": 1.0, "mm/m": 1e3, "%": 1e2, "µε": 1e6, "με": 1e6,
                "µm/m": 1e6, "um/m": 1e6}


@dataclass(frozen=True)
class GaugeConfig:
    """One tooth-root strain gauge.

    Parameters
    ----------
    name : str
        Channel name.
    gear : {"sun", "ring"}
        Gear carrying the gauge.
    tooth : int
        Index j of the gauged tooth [-]; its centre line points at
        ``angle0 + 2 pi j / Z`` at t = 0 (``angle0`` = ``SynthConfig.sun_angle0`` or
        ``ring_angle0``) [rad].
    face_position : float, optional
        Axial position across the face from its centre [m]. None: a plain "sun"/"ring" gauge
        that reads the face-averaged load; a value makes it a "facewidth" channel weighted by
        the load distribution w(z) (spec section 7).
    amplitude : float
        Peak strain of a pulse at equal load sharing and centred load [m/m] (> 0).
    contact_ratio : float
        Contact ratio eps [-] in [1, 3]: the tensile lobe lasts eps mesh periods.
    side_lobe : float
        Compressive lobe depth before normalisation [-], in [0, 1).
    skew : float, optional
        Moment-arm asymmetry [-] in (-1, 1). Default: +0.2 on the sun (driving gear, contact
        moves root -> tip), -0.2 on the ring (driven).
    units : str
        Unit string of the channel's samples, a key of :data:`STRAIN_UNITS` ("m/m", "mm/m",
        "%", "µε", ...): the samples are the strain [m/m] times that unit's scale, and the
        string is the channel's units in the Recording and in every file written from it.
        Every other strain of the config (amplitude, noise, ADC range, clip level) stays in
        m/m.
    """

    name: str
    gear: str
    tooth: int = 0
    face_position: float | None = None
    amplitude: float = 150e-6
    contact_ratio: float = 1.6
    side_lobe: float = 0.25
    skew: float | None = None
    units: str = "m/m"

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"gauge name must be a non-empty string, got {self.name!r}")
        as_choice(self.gear, "gear", GEARS)
        tooth = as_int(self.tooth, f"gauge {self.name!r} tooth")
        if tooth < 0:
            raise ValueError(f"gauge {self.name!r}: tooth must be a non-negative integer, got {tooth!r}")
        object.__setattr__(self, "tooth", tooth)
        if self.face_position is not None:
            object.__setattr__(self, "face_position", as_float(self.face_position, "face_position"))
        object.__setattr__(self, "amplitude", as_positive(self.amplitude, "amplitude"))
        eps = as_float(self.contact_ratio, "contact_ratio")
        if not 1.0 <= eps <= 3.0:
            raise ValueError(f"gauge {self.name!r}: contact_ratio must be in [1, 3], got {eps!r}")
        object.__setattr__(self, "contact_ratio", eps)
        sl = as_nonnegative(self.side_lobe, "side_lobe")
        if sl >= 1.0:
            raise ValueError(f"gauge {self.name!r}: side_lobe must be in [0, 1), got {sl!r}")
        object.__setattr__(self, "side_lobe", sl)
        sk = (0.2 if self.gear == "sun" else -0.2) if self.skew is None else as_float(self.skew, "skew")
        if abs(sk) >= 1.0:
            raise ValueError(f"gauge {self.name!r}: skew must be in (-1, 1), got {sk!r}")
        object.__setattr__(self, "skew", sk)
        if not isinstance(self.units, str) or self.units not in STRAIN_UNITS:
            raise ValueError(f"gauge {self.name!r}: units must be one of {sorted(STRAIN_UNITS)}, "
                             f"got {self.units!r}")

    @property
    def unit_scale(self) -> float:
        """Samples per m/m of strain in this gauge's ``units`` [-]."""
        return STRAIN_UNITS[self.units]

    @property
    def kind(self) -> str:
        """Channel kind: "facewidth" with a face position, else the gear."""
        return "facewidth" if self.face_position is not None else self.gear

    def to_dict(self) -> dict:
        return {"name": self.name, "gear": self.gear, "tooth": self.tooth,
                "face_position": self.face_position, "amplitude": self.amplitude,
                "contact_ratio": self.contact_ratio, "side_lobe": self.side_lobe, "skew": self.skew,
                "units": self.units}


@dataclass(frozen=True)
class TachoConfig:
    """Carrier once-per-revolution tacho channel.

    Parameters
    ----------
    name : str
        Channel name.
    angle : float, optional
        Carrier angle (ground frame, carrier frame = ground frame at t = 0) at which the key
        reaches the probe [rad]. None: a quarter of the planet spacing of carrier rotation
        before planet 1 reaches the first ring gauge (with a fixed ring this puts planet 1's
        ring pass right after every tacho pulse).
    width : float
        Key width [rev] of carrier rotation (the pulse stays high that long), in (0, 0.5).
    level : float
        High level [V].
    """

    name: str = "tacho"
    angle: float | None = None
    width: float = 0.01
    level: float = 5.0

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"tacho name must be a non-empty string, got {self.name!r}")
        if self.angle is not None:
            object.__setattr__(self, "angle", as_float(self.angle, "tacho angle"))
        w = as_positive(self.width, "tacho width")
        if w >= 0.5:
            raise ValueError(f"tacho width must be in (0, 0.5) rev, got {w!r}")
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "level", as_positive(self.level, "tacho level"))

    def to_dict(self) -> dict:
        return {"name": self.name, "angle": self.angle, "width": self.width, "level": self.level}


@dataclass(frozen=True)
class EncoderConfig:
    """A shaft encoder (or multi-pulse tacho): ``pulses_per_rev`` pulses per turn of a shaft.

    Parameters
    ----------
    name : str
        Channel name.
    shaft : {"sun", "input", "carrier", "ring"}
        The shaft it sits on ("input" is the sun); it must turn.
    pulses_per_rev : int
        Pulses per revolution [-].
    angle : float
        Absolute shaft angle at which pulse 0 rises [rad]; pulse k rises
        ``2 pi k / pulses_per_rev`` further on, in the shaft's sense of rotation.
    duty : float
        Fraction of a pulse period at the high level [-], in (0, 1).
    level : float
        High level [V].
    missing : float
        Probability that a pulse is missing (neither of its edges recorded) [-], in [0, 1).
    extra : float
        Probability per pulse of a glitch: a short extra pulse in the low part of the
        period, ``glitch`` of a period long [-], in [0, 1).
    glitch : float
        Length of a glitch [pulse periods], in (0, 0.2].
    """

    name: str = "encoder"
    shaft: str = "sun"
    pulses_per_rev: int = 60
    angle: float = 0.0
    duty: float = 0.5
    level: float = 5.0
    missing: float = 0.0
    extra: float = 0.0
    glitch: float = 0.02

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise ValueError(f"encoder name must be a non-empty string, got {self.name!r}")
        as_choice(self.shaft, "encoder shaft", ("sun", "input", "carrier", "ring"))
        ppr = as_int(self.pulses_per_rev, "encoder pulses_per_rev")
        if ppr < 1:
            raise ValueError(f"encoder pulses_per_rev must be a positive integer, got {ppr!r}")
        object.__setattr__(self, "pulses_per_rev", ppr)
        object.__setattr__(self, "angle", as_float(self.angle, "encoder angle"))
        # (lower bound open?, upper bound, upper bound open?) of each fraction
        ranges = {"duty": (True, 1.0, True), "missing": (False, 1.0, True),
                  "extra": (False, 1.0, True), "glitch": (True, 0.2, False)}
        for k, (lo_open, hi, hi_open) in ranges.items():
            v = as_nonnegative(getattr(self, k), f"encoder {k}")
            if (lo_open and v == 0.0) or (v >= hi if hi_open else v > hi):
                raise ValueError(f"encoder {k} must be in {'(' if lo_open else '['}0, {hi:g}"
                                 f"{')' if hi_open else ']'}, got {v!r}")
            object.__setattr__(self, k, v)
        object.__setattr__(self, "level", as_positive(self.level, "encoder level"))

    @property
    def member(self) -> str:
        """The gear member of the shaft ("input" is the sun)."""
        return "sun" if self.shaft == "input" else self.shaft

    def to_dict(self) -> dict:
        return {"name": self.name, "shaft": self.shaft, "pulses_per_rev": self.pulses_per_rev,
                "angle": self.angle, "duty": self.duty, "level": self.level,
                "missing": self.missing, "extra": self.extra, "glitch": self.glitch}


@dataclass(frozen=True)
class TiltSource:
    """Load centroid offsets from the coupled bearing tilt solve (spec section 5).

    :func:`meshphase.models.tilt.solve_tilt` on the planet geometry of a seed 001 case, with the
    gearset's face width; the converged (Z_S, Z_R) apply to every planet.

    Parameters
    ----------
    case : {"1", "2-A", "2-B"}
        Seed 001 case giving the planet geometry (:func:`meshphase.models.bearing.seed_case`).
    k_tilt : float
        Needle-bearing tilting stiffness k_t [N·m/rad], > 0.
    input_torque : float, optional
        Sun input torque [N·m]; default the case's.
    c_g : float
        Mesh stiffness per unit face width [N/m^2] (ISO 6336 default 20e9).
    """

    case: str = "1"
    k_tilt: float = 8.8e4
    input_torque: float | None = None
    c_g: float = 20e9

    def __post_init__(self):
        as_choice(self.case, "tilt case", ("1", "2-A", "2-B"))
        object.__setattr__(self, "k_tilt", as_positive(self.k_tilt, "k_tilt"))
        if self.input_torque is not None:
            object.__setattr__(self, "input_torque", as_positive(self.input_torque, "input_torque"))
        object.__setattr__(self, "c_g", as_positive(self.c_g, "c_g"))

    def solve(self, face_width: float):
        """The TiltSolution for face width ``face_width`` [m]."""
        c = seed_case(self.case)
        torque = c.input_torque if self.input_torque is None else self.input_torque
        return solve_tilt(c.geometry, torque, k_tilt_Nm_per_rad=self.k_tilt, c_g=self.c_g,
                          face_width=face_width)

    def to_dict(self) -> dict:
        return {"case": self.case, "k_tilt": self.k_tilt, "input_torque": self.input_torque,
                "c_g": self.c_g}


@dataclass(frozen=True)
class Artefacts:
    """Acquisition artefacts; each is off unless set (see :mod:`meshphase.synthetic.artefacts`).

    Parameters
    ----------
    snr_db : float, optional
        Broadband noise: 20 log10(nominal pulse peak / noise RMS) [dB] per gauge. None: none.
    pink_fraction : float
        Share of the noise power in the 1/f part [-], in [0, 1].
    pink_fmin : float
        Lowest frequency of the 1/f band [Hz].
    drift_amplitude : float
        Final thermal drift D [m/m] (0: none).
    drift_time_constant : float
        Thermal time constant T_th [s].
    hum_amplitude : float
        Mains hum fundamental amplitude [m/m] (0: none).
    hum_frequency : float
        Mains frequency [Hz]: 50 or 60.
    hum_harmonics : tuple of float
        Relative weights of harmonics 1, 2, 3, ... [-].
    adc_bits : int, optional
        ADC resolution [bit] (24 or 16 typically). Needs ``adc_range``.
    adc_range : float, optional
        ADC input range +-R [m/m].
    clip_level : float, optional
        Amplifier saturation level [m/m].
    gap_rate : float
        Rate of acquisition gaps [1/s].
    gap_length : float
        Mean gap length [s].
    dropout_rate : float
        Rate of single dropped samples [1/s].
    gain_error : float or mapping, optional
        Constant relative gauge gain error [-]: one value for every gauge, or per channel name.
    gain_error_std : float
        Standard deviation of a random per-gauge gain error [-] (added to ``gain_error``).
    """

    snr_db: float | None = None
    pink_fraction: float = 0.0
    pink_fmin: float = 0.05
    drift_amplitude: float = 0.0
    drift_time_constant: float = 900.0
    hum_amplitude: float = 0.0
    hum_frequency: float = 50.0
    hum_harmonics: tuple = (1.0, 0.0, 0.25)
    adc_bits: int | None = None
    adc_range: float | None = None
    clip_level: float | None = None
    gap_rate: float = 0.0
    gap_length: float = 0.05
    dropout_rate: float = 0.0
    gain_error: float | Mapping | None = None
    gain_error_std: float = 0.0

    def __post_init__(self):
        if self.snr_db is not None:
            object.__setattr__(self, "snr_db", as_float(self.snr_db, "snr_db"))
        pf = as_nonnegative(self.pink_fraction, "pink_fraction")
        if pf > 1.0:
            raise ValueError(f"pink_fraction must be in [0, 1], got {pf!r}")
        object.__setattr__(self, "pink_fraction", pf)
        object.__setattr__(self, "pink_fmin", as_positive(self.pink_fmin, "pink_fmin"))
        object.__setattr__(self, "drift_amplitude", as_float(self.drift_amplitude, "drift_amplitude"))
        object.__setattr__(self, "drift_time_constant", as_positive(self.drift_time_constant, "drift_time_constant"))
        object.__setattr__(self, "hum_amplitude", as_nonnegative(self.hum_amplitude, "hum_amplitude"))
        object.__setattr__(self, "hum_frequency", as_positive(self.hum_frequency, "hum_frequency"))
        h = tuple(float(x) for x in as_finite_array(self.hum_harmonics, "hum_harmonics", ndim=1))
        object.__setattr__(self, "hum_harmonics", h)
        if self.adc_bits is not None:
            b = as_positive_int(self.adc_bits, "adc_bits")
            if not 2 <= b <= 32:
                raise ValueError(f"adc_bits must be in [2, 32], got {b!r}")
            object.__setattr__(self, "adc_bits", b)
            if self.adc_range is None:
                raise ValueError("adc_bits needs adc_range (the ADC input range +-R [m/m])")
        if self.adc_range is not None:
            object.__setattr__(self, "adc_range", as_positive(self.adc_range, "adc_range"))
        if self.clip_level is not None:
            object.__setattr__(self, "clip_level", as_positive(self.clip_level, "clip_level"))
        object.__setattr__(self, "gap_rate", as_nonnegative(self.gap_rate, "gap_rate"))
        object.__setattr__(self, "gap_length", as_positive(self.gap_length, "gap_length"))
        object.__setattr__(self, "dropout_rate", as_nonnegative(self.dropout_rate, "dropout_rate"))
        ge = self.gain_error
        if ge is not None:
            if isinstance(ge, Mapping):
                ge = {str(k): as_float(v, f"gain_error[{k!r}]") for k, v in ge.items()}
                for k, v in ge.items():
                    if v <= -1.0:
                        raise ValueError(f"gain_error[{k!r}] must be > -1, got {v!r}")
            else:
                ge = as_float(ge, "gain_error")
                if ge <= -1.0:
                    raise ValueError(f"gain_error must be > -1, got {ge!r}")
            object.__setattr__(self, "gain_error", ge)
        object.__setattr__(self, "gain_error_std", as_nonnegative(self.gain_error_std, "gain_error_std"))

    @property
    def any(self) -> bool:
        """True when at least one artefact is switched on."""
        return bool(self.snr_db is not None or self.drift_amplitude or self.hum_amplitude
                    or self.adc_bits or self.clip_level or self.gap_rate or self.dropout_rate
                    or self.gain_error or self.gain_error_std)

    def to_dict(self) -> dict:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["hum_harmonics"] = list(self.hum_harmonics)
        if isinstance(self.gain_error, Mapping):
            d["gain_error"] = dict(self.gain_error)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Artefacts":
        d = dict(d)
        if "hum_harmonics" in d:
            d["hum_harmonics"] = tuple(d["hum_harmonics"])
        return cls(**d)


@dataclass(frozen=True)
class LoadModulation:
    """One term of a load modulation common to every planet, locked to the carrier angle.

    Every pulse amplitude is multiplied by ``1 + sum_k a_k cos(m_k theta_c + phi_k)``, with
    ``theta_c = w_c tau`` the carrier's absolute rotation angle at the engagement [rad]
    (carrier frame = ground frame at t = 0): a torque ripple once (m = 1) or m times per
    carrier turn, the same for every planet's mesh at a given carrier angle.

    Parameters
    ----------
    amplitude : float
        Relative amplitude a [-], >= 0; the amplitudes of all terms must sum below 1 so that
        every pulse keeps a positive amplitude.
    order : int
        Harmonic m of the carrier's rotation [-], >= 1.
    phase : float
        Phase phi [rad] at theta_c = 0.
    """

    amplitude: float
    order: int = 1
    phase: float = 0.0

    def __post_init__(self):
        a = as_nonnegative(self.amplitude, "load modulation amplitude")
        if a >= 1.0:
            raise ValueError(f"load modulation amplitude must be in [0, 1) (a relative "
                             f"amplitude [-]), got {a!r}")
        object.__setattr__(self, "amplitude", a)
        m = as_int(self.order, "load modulation order")
        if m < 1:
            raise ValueError(f"load modulation order must be an integer >= 1 (harmonic of the "
                             f"carrier's rotation), got {m!r}")
        object.__setattr__(self, "order", m)
        object.__setattr__(self, "phase", as_float(self.phase, "load modulation phase"))

    def to_dict(self) -> dict:
        return {"amplitude": self.amplitude, "order": self.order, "phase": self.phase}

    @classmethod
    def from_any(cls, d) -> "LoadModulation":
        """From a LoadModulation, a dict (keys of :meth:`to_dict`) or a tuple ``(amplitude[,
        order[, phase]])``."""
        if isinstance(d, LoadModulation):
            return d
        if isinstance(d, dict):
            unknown = sorted(set(d) - {"amplitude", "order", "phase"})
            if unknown or "amplitude" not in d:
                raise ValueError(f"load modulation needs 'amplitude' (and optionally 'order', "
                                 f"'phase'), got keys {sorted(d)}")
            return cls(**d)
        if isinstance(d, (tuple, list)) and 1 <= len(d) <= 3:
            return cls(*d)
        raise TypeError("a load modulation term must be a LoadModulation, a dict or (amplitude[, "
                        f"order[, phase]]), got {d!r}")


def load_factor(terms, carrier_angle) -> np.ndarray:
    """Common load factor ``1 + sum a cos(m theta_c + phi)`` [-] of :class:`LoadModulation`
    terms at carrier angles ``carrier_angle`` [rad] (1 without terms)."""
    th = np.asarray(carrier_angle, dtype=np.float64)
    out = np.ones(th.shape)
    for t in terms:
        out += t.amplitude * np.cos(t.order * th + t.phase)
    return out


_ERR_FIELDS = ("e_sun", "kappa_sun", "e_ring", "kappa_ring", "e_planet", "kappa_planet")


def errors_to_dict(errors) -> dict | None:
    """JSON-friendly form of ShaftHoleErrors or Tolerances (SI units), or None."""
    if errors is None:
        return None
    if isinstance(errors, ShaftHoleErrors):
        return {"type": "ShaftHoleErrors",
                **{k: np.asarray(getattr(errors, k)).tolist() for k in _ERR_FIELDS}}
    if isinstance(errors, Tolerances):
        return {"type": "Tolerances", **errors.to_dict()}
    raise TypeError(f"errors must be ShaftHoleErrors, Tolerances or None, got {type(errors).__name__}")


def errors_from_dict(d: dict | None):
    """Inverse of :func:`errors_to_dict`."""
    if d is None:
        return None
    d = dict(d)
    kind = d.pop("type", "ShaftHoleErrors")
    if kind == "ShaftHoleErrors":
        return ShaftHoleErrors(**{k: np.asarray(d[k], dtype=float) for k in _ERR_FIELDS if k in d})
    if kind == "Tolerances":
        return Tolerances(**{k: ToleranceBand(**v) for k, v in d.items()})
    raise ValueError(f"unknown errors type {kind!r}; expected ShaftHoleErrors or Tolerances")


def _tuple_or_scalar(v):
    return tuple(v) if isinstance(v, (list, tuple)) else v


def _per_planet(value, name, n, *, positive=False):
    arr = as_finite_array(value, name)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have one value per planet ({n}), got shape {arr.shape}")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} must be > 0, got {arr.tolist()!r}")
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class SynthConfig:
    """Everything that defines a synthetic recording.

    Parameters
    ----------
    name : str
        Scenario name (recorded in the truth).
    gearset : Gearset
        Tooth counts, planet angles [rad], carrier radius [m], direction, face width [m].
    speeds : Speeds
        Nominal absolute speeds [rad/s]. ``gearset.direction`` must match them: "cw"
        (clockwise planets) exactly when the sun turns counter-clockwise relative to the
        carrier, w_sc > 0.
    fs : float
        Sample rate [Hz].
    duration : float
        Default duration [s].
    gauges : tuple of GaugeConfig
        Strain gauges (names unique, not clashing with the tacho).
    errors : ShaftHoleErrors or Tolerances, optional
        Shaft hole position errors (one realisation), or tolerance bands from which one
        realisation is drawn with the recording's seed.
    load_sharing : sequence of float, optional
        Planet load sharing factors LS_n [-] (mean 1, spec section 6); None: equal sharing.
    centroid_sun, centroid_ring : float or sequence of float
        Load centroid offsets Z_S, Z_R of each planet's sun and ring mesh [m] (spec
        sections 4, 7); need ``gearset.face_width`` when non-zero or when face-width gauges
        exist.
    tilt : TiltSource, optional
        Take Z_S, Z_R from the coupled tilt solve instead (then leave the centroids at 0).
    load_modulation : tuple of LoadModulation
        Load modulation common to every planet, locked to the carrier angle (a torque ripple;
        :class:`LoadModulation`, or dicts / tuples ``(amplitude[, order[, phase]])``): every
        pulse amplitude times :func:`load_factor` at the engagement's carrier angle.
    speed : SpeedProfile
        Speed fluctuation: ramp, ripple at fixed frequencies and ripple locked to a member's
        rotation angle (:class:`meshphase.synthetic.kinematics.ShaftRipple`).
    artefacts : Artefacts
        Noise, drift, hum, ADC, clipping, gaps, gain error.
    tacho : TachoConfig, optional
        Carrier once-per-revolution channel.
    encoder : EncoderConfig, optional
        A shaft encoder channel (after the tacho).
    sun_angle0 : float
        Direction of sun tooth 0 in the carrier frame at t = 0 [rad].
    ring_angle0 : float, optional
        Direction of ring tooth 0 in the carrier frame at t = 0 [rad]. None: a quarter of the
        planet spacing after planet 1 in the carrier's sense of rotation.
    t0 : float
        Time of the first sample on the recording's axis [s].
    start_datetime : str, optional
        Wall-clock time of the first sample (ISO 8601).
    dtype : {"float64", "float32"}
        Sample type of the generated Recording.
    description : str
        What the scenario is for.
    """

    name: str
    gearset: Gearset
    speeds: Speeds
    fs: float
    duration: float
    gauges: tuple
    errors: ShaftHoleErrors | Tolerances | None = None
    load_sharing: tuple | None = None
    centroid_sun: float | tuple = 0.0
    centroid_ring: float | tuple = 0.0
    tilt: TiltSource | None = None
    load_modulation: tuple = ()
    speed: SpeedProfile = field(default_factory=SpeedProfile)
    artefacts: Artefacts = field(default_factory=Artefacts)
    tacho: TachoConfig | None = None
    sun_angle0: float = 0.3
    ring_angle0: float | None = None
    t0: float = 0.0
    start_datetime: str | None = None
    dtype: str = "float64"
    description: str = ""
    encoder: EncoderConfig | None = None

    def __post_init__(self):
        self._check_types_and_speeds()
        object.__setattr__(self, "fs", as_positive(self.fs, "fs"))
        object.__setattr__(self, "duration", as_positive(self.duration, "duration"))
        self._check_channels()
        self._check_errors()
        self._check_loads()
        object.__setattr__(self, "sun_angle0", as_float(self.sun_angle0, "sun_angle0"))
        if self.ring_angle0 is not None:
            object.__setattr__(self, "ring_angle0", as_float(self.ring_angle0, "ring_angle0"))
        object.__setattr__(self, "t0", as_float(self.t0, "t0"))
        as_choice(self.dtype, "dtype", DTYPES)
        if self.artefacts.snr_db is not None and self.artefacts.pink_fraction > 0 \
                and self.artefacts.pink_fmin >= self.fs / 20.0:
            raise ValueError(f"pink_fmin must be below fs / 20 = {self.fs / 20.0!r} Hz, got "
                             f"{self.artefacts.pink_fmin!r}")

    def _check_types_and_speeds(self) -> None:
        """Name, the parts' types, and a gearset direction that the speeds agree with."""
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.gearset, Gearset):
            raise TypeError(f"gearset must be a Gearset, got {type(self.gearset).__name__}")
        if not isinstance(self.speeds, Speeds):
            raise TypeError(f"speeds must be a Speeds, got {type(self.speeds).__name__}")
        g, sp = self.gearset, self.speeds
        if not isinstance(self.speed, SpeedProfile):
            raise TypeError(f"speed must be a SpeedProfile, got {type(self.speed).__name__}")
        if not isinstance(self.artefacts, Artefacts):
            raise TypeError(f"artefacts must be an Artefacts, got {type(self.artefacts).__name__}")
        if sp.w_sc == 0.0:
            raise ValueError("speeds: the sun must turn relative to the carrier (w_sc != 0), got "
                             f"sun={sp.sun!r}, carrier={sp.carrier!r} rad/s")
        want = "cw" if sp.w_sc > 0 else "ccw"
        if g.direction != want:
            raise ValueError(f"gearset.direction={g.direction!r} contradicts the speeds: w_sc = "
                             f"{sp.w_sc!r} rad/s turns the planets {'clockwise' if want == 'cw' else 'counter-clockwise'} "
                             f"(direction={want!r})")

    def _check_channels(self) -> None:
        """Gauges and tacho: types, unique names, existing teeth, gain errors of known gauges,
        a turning carrier for a tacho (``gauges`` stored as a tuple)."""
        g, sp = self.gearset, self.speeds
        gauges = tuple(self.gauges)
        if not all(isinstance(x, GaugeConfig) for x in gauges):
            raise TypeError("gauges must be GaugeConfig instances")
        object.__setattr__(self, "gauges", gauges)
        if self.tacho is not None and not isinstance(self.tacho, TachoConfig):
            raise TypeError(f"tacho must be a TachoConfig or None, got {type(self.tacho).__name__}")
        if self.encoder is not None and not isinstance(self.encoder, EncoderConfig):
            raise TypeError(f"encoder must be an EncoderConfig or None, got "
                            f"{type(self.encoder).__name__}")
        names = [x.name for x in gauges] + ([self.tacho.name] if self.tacho else []) + (
            [self.encoder.name] if self.encoder else [])
        if not names:
            raise ValueError("a synthetic recording needs at least one gauge or a tacho")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"duplicate channel name(s) {dup}")
        for x in gauges:
            z = g.z_sun if x.gear == "sun" else g.z_ring
            if x.tooth >= z:
                raise ValueError(f"gauge {x.name!r}: tooth {x.tooth} does not exist on the {x.gear} "
                                 f"(Z = {z}, teeth 0..{z - 1})")
        ge = self.artefacts.gain_error
        if isinstance(ge, Mapping):
            unknown = sorted(set(ge) - {x.name for x in gauges})
            if unknown:
                raise ValueError(f"artefacts.gain_error names unknown gauge(s) {unknown}; gauges: "
                                 f"{[x.name for x in gauges]}")
        if self.tacho is not None and sp.carrier == 0.0:
            raise ValueError("a carrier tacho needs a turning carrier (speeds.carrier != 0)")
        if self.encoder is not None and getattr(sp, self.encoder.member) == 0.0:
            raise ValueError(f"encoder {self.encoder.name!r}: the {self.encoder.shaft} shaft does "
                             f"not turn (speeds.{self.encoder.member} = 0)")

    def _check_errors(self) -> None:
        """``errors``: None, bands, or one realisation of the shaft hole errors."""
        g = self.gearset
        if self.errors is not None and not isinstance(self.errors, (ShaftHoleErrors, Tolerances)):
            raise TypeError(f"errors must be ShaftHoleErrors, Tolerances or None, got {type(self.errors).__name__}")
        if isinstance(self.errors, ShaftHoleErrors) and self.errors.sample_shape(g.n_planets) != ():
            raise ValueError("errors must be one realisation (no sample dimensions), got sample shape "
                             f"{self.errors.sample_shape(g.n_planets)}")

    def _check_loads(self) -> None:
        """Load sharing (mean 1) and centroid offsets [m] per planet (stored as tuples), the
        tilt solve, the load modulation terms (stored as a tuple), and the face width [m] that
        centroids and face-width gauges need."""
        g, gauges = self.gearset, self.gauges
        n = g.n_planets
        if self.load_sharing is not None:
            ls = _per_planet(self.load_sharing, "load_sharing", n, positive=True)
            if abs(sum(ls) / n - 1.0) > 1e-9:
                raise ValueError(f"load_sharing factors must average 1 (LS_n = N eps_n / sum eps), "
                                 f"got mean {sum(ls) / n!r}")
            object.__setattr__(self, "load_sharing", ls)
        zs = _per_planet(self.centroid_sun, "centroid_sun", n)
        zr = _per_planet(self.centroid_ring, "centroid_ring", n)
        object.__setattr__(self, "centroid_sun", zs)
        object.__setattr__(self, "centroid_ring", zr)
        has_face = any(x.face_position is not None for x in gauges)
        if self.tilt is not None:
            if not isinstance(self.tilt, TiltSource):
                raise TypeError(f"tilt must be a TiltSource or None, got {type(self.tilt).__name__}")
            if any(zs) or any(zr):
                raise ValueError("give centroid offsets or a tilt solve (tilt=), not both")
            if g.face_width is None:
                raise ValueError("a tilt solve needs gearset.face_width [m]")
        if isinstance(self.load_modulation, (LoadModulation, dict)):
            raise TypeError("load_modulation must be a sequence of terms, got a single "
                            f"{type(self.load_modulation).__name__}; wrap it in a tuple")
        try:
            raw = tuple(self.load_modulation)
        except TypeError:
            raise TypeError(f"load_modulation must be a sequence of LoadModulation terms, got "
                            f"{self.load_modulation!r}") from None
        terms = tuple(LoadModulation.from_any(t) for t in raw)
        total = sum(t.amplitude for t in terms)
        if total >= 1.0:
            raise ValueError(f"load_modulation amplitudes sum to {total!r}: a pulse amplitude "
                             f"could reach 0 or below (the sum must stay < 1)")
        object.__setattr__(self, "load_modulation", terms)
        if (has_face or any(zs) or any(zr)) and g.face_width is None:
            raise ValueError("face-width gauges and centroid offsets need gearset.face_width [m]")
        if g.face_width is not None:
            b = g.face_width
            for nm, z in (("centroid_sun", zs), ("centroid_ring", zr)):
                if any(abs(v) >= 0.5 * b for v in z):
                    raise ValueError(f"{nm} must satisfy |Z| < b/2 = {0.5 * b!r} m, got {z!r}")
            for x in gauges:
                if x.face_position is not None and abs(x.face_position) > 0.5 * b:
                    raise ValueError(f"gauge {x.name!r}: face_position must be within the face "
                                     f"(|z| <= {0.5 * b!r} m), got {x.face_position!r}")

    # ------------------------------------------------------------------ derived values
    @property
    def ring_tooth0_angle(self) -> float:
        """Direction of ring tooth 0 at t = 0 [rad] (resolving the default)."""
        if self.ring_angle0 is not None:
            return self.ring_angle0
        psi1 = self.gearset.angles[0]
        sgn = 1.0 if self.speeds.carrier >= 0 else -1.0
        return psi1 + sgn * math.pi / (2.0 * self.gearset.n_planets)

    def tooth_angle(self, gauge: GaugeConfig) -> float:
        """Direction of the gauged tooth's centre line at t = 0, carrier frame [rad]."""
        if gauge.gear == "sun":
            return self.sun_angle0 + 2.0 * math.pi * gauge.tooth / self.gearset.z_sun
        return self.ring_tooth0_angle + 2.0 * math.pi * gauge.tooth / self.gearset.z_ring

    def tacho_angle(self) -> float:
        """Carrier angle of the tacho key [rad] (resolving the default)."""
        if self.tacho is None or self.tacho.angle is not None:
            return 0.0 if self.tacho is None else self.tacho.angle
        ring = [x for x in self.gauges if x.gear == "ring"]
        theta_r = self.tooth_angle(ring[0]) if ring else self.ring_tooth0_angle
        # fixed ring: planet 1 meets the ring tooth when the carrier angle is theta_r - psi_1
        sgn = 1.0 if self.speeds.carrier > 0 else -1.0
        return theta_r - self.gearset.angles[0] - sgn * math.pi / (2.0 * self.gearset.n_planets)

    def with_(self, **changes) -> "SynthConfig":
        """A copy with fields replaced (validated again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict:
        """JSON-friendly dict of every field (SI units)."""
        return {
            "name": self.name, "description": self.description,
            "gearset": self.gearset.to_dict(), "speeds": self.speeds.to_dict(),
            "fs": self.fs, "duration": self.duration,
            "gauges": [x.to_dict() for x in self.gauges],
            "errors": errors_to_dict(self.errors),
            "load_sharing": None if self.load_sharing is None else list(self.load_sharing),
            "centroid_sun": list(self.centroid_sun), "centroid_ring": list(self.centroid_ring),
            "tilt": None if self.tilt is None else self.tilt.to_dict(),
            "load_modulation": [t.to_dict() for t in self.load_modulation],
            "speed": self.speed.to_dict(), "artefacts": self.artefacts.to_dict(),
            "tacho": None if self.tacho is None else self.tacho.to_dict(),
            "sun_angle0": self.sun_angle0, "ring_angle0": self.ring_angle0, "t0": self.t0,
            "start_datetime": self.start_datetime, "dtype": self.dtype,
            "encoder": None if self.encoder is None else self.encoder.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "SynthConfig":
        """Inverse of :meth:`to_dict`."""
        d = dict(d)
        return cls(
            name=d["name"], description=d.get("description", ""),
            gearset=Gearset.from_dict(d["gearset"]), speeds=Speeds(**d["speeds"]),
            fs=d["fs"], duration=d["duration"],
            gauges=tuple(GaugeConfig(**x) for x in d["gauges"]),
            errors=errors_from_dict(d.get("errors")),
            load_sharing=None if d.get("load_sharing") is None else tuple(d["load_sharing"]),
            centroid_sun=_tuple_or_scalar(d.get("centroid_sun", 0.0)),
            centroid_ring=_tuple_or_scalar(d.get("centroid_ring", 0.0)),
            tilt=None if d.get("tilt") is None else TiltSource(**d["tilt"]),
            load_modulation=tuple(d.get("load_modulation", ())),
            speed=SpeedProfile.from_dict(d.get("speed", {})),
            artefacts=Artefacts.from_dict(d.get("artefacts", {})),
            tacho=None if d.get("tacho") is None else TachoConfig(**d["tacho"]),
            sun_angle0=d.get("sun_angle0", 0.3), ring_angle0=d.get("ring_angle0"),
            t0=d.get("t0", 0.0), start_datetime=d.get("start_datetime"),
            dtype=d.get("dtype", "float64"),
            encoder=None if d.get("encoder") is None else EncoderConfig(**d["encoder"]),
        )
