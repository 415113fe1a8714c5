"""Strain from bridge volts: the Wheatstone-bridge strain equations, per channel.

A rig that logs the bridge's output voltage instead of strain names, per ``[[channels]]``
entry of the scene, the bridge configuration, the gauge factor, the excitation voltage and,
where the configuration uses them, Poisson's ratio and the lead and gauge resistances
(``data_schemas/scene.md``, "Strain from bridge volts"). The samples are converted when the
recording is loaded, before conditioning, and the conversion is recorded in the recording's
history.

The equations are National Instruments' (the seven configurations of NI-DAQmx, named as
there): NI, "Measuring Strain with Strain Gages" (white paper 3642); NI-DAQmx Help, "Strain
Gage Configurations" (quarter-bridge I/II, half-bridge I/II, full-bridge I/II/III); NI
SCC-SG Series User Guide (370419), "Strain Equations"; Keysight BenchVue DAQ help, "Strain
Equations" (quarter, half and full bending: the same forms). With the bridge's output
``V_out``, its unstrained output ``V_init`` and the excitation ``V_ex``, the voltage ratio is

    V_r = (V_out - V_init) / V_ex                                                    [V/V]

and, with gauge factor GF, Poisson's ratio nu, lead resistance R_L and gauge resistance R_g,

    quarter_I, quarter_II  strain = -4 V_r / (GF (1 + 2 V_r)) * (1 + R_L/R_g)
    half_I                 strain = -4 V_r / (GF ((1 + nu) - 2 V_r (nu - 1))) * (1 + R_L/R_g)
    half_II                strain = -2 V_r / GF * (1 + R_L/R_g)
    full_I                 strain = -V_r / GF
    full_II                strain = -2 V_r / (GF (nu + 1))
    full_III               strain = -2 V_r / (GF ((nu + 1) - V_r (nu - 1)))

(NI's sign convention, with their wiring; a bridge wired the other way round gives the
strain negated: a negative ``gain`` flips the volts back). The full bridges carry no lead
term in NI's equations (remote sensing compensates the leads), so a lead resistance is
refused there. ``quarter``, ``half`` and ``full`` are the bending forms
quarter_I, half_II and full_I.

The initial offset ``V_init`` is the mean of ``V_out`` over a named window of the recording
(``null_window_s``, the rig at rest), i.e. the mean of the ratio over that window is
subtracted (NI-DAQmx's "offset nulling"); without a window, V_init = 0.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from ..recording import Recording
from ..validate import as_float

__all__ = ["BRIDGE_TYPES", "BridgeConfig", "strain_from_ratio", "ratio_from_strain",
           "strain_from_volts", "volts_from_strain", "null_ratio", "bridge_recording",
           "window_means", "initial_volts", "convert_block", "bridge_history", "strain_spec"]

#: bridge configuration -> (uses Poisson's ratio, has the lead-resistance term)
BRIDGE_TYPES: dict[str, tuple[bool, bool]] = {
    "quarter_I": (False, True),
    "quarter_II": (False, True),
    "half_I": (True, True),
    "half_II": (False, True),
    "full_I": (False, False),
    "full_II": (True, False),
    "full_III": (True, False),
}
#: the plain names: the bending forms (Keysight's "Quarter/Half/Full Bridge Bending")
_ALIASES = {"quarter": "quarter_I", "half": "half_II", "full": "full_I"}


@dataclass(frozen=True)
class BridgeConfig:
    """One channel's bridge, checked.

    Parameters
    ----------
    bridge : str
        One of :data:`BRIDGE_TYPES`, or ``quarter``/``half``/``full`` (quarter_I, half_II,
        full_I).
    gauge_factor : float
        GF [-], > 0.
    excitation : float
        Excitation voltage V_ex [V], > 0.
    poisson : float, optional
        Poisson's ratio nu [-] of the gauged material, 0 <= nu < 0.5 (half_I, full_II,
        full_III only, where it is required).
    lead_resistance : float
        Lead resistance R_L [ohm], >= 0 (quarter and half bridges only).
    gauge_resistance : float, optional
        Nominal gauge resistance R_g [ohm], > 0; required when ``lead_resistance`` > 0.
    null_window : tuple of float, optional
        (start, stop) [s] on the recording's time axis: V_init is the mean output there.
    """

    bridge: str
    gauge_factor: float
    excitation: float
    poisson: float | None = None
    lead_resistance: float = 0.0
    gauge_resistance: float | None = None
    null_window: tuple | None = None

    def __post_init__(self):
        b = _ALIASES.get(self.bridge, self.bridge)
        if b not in BRIDGE_TYPES:
            raise ValueError(f"bridge {self.bridge!r} is not a known configuration; known: "
                             f"{', '.join(BRIDGE_TYPES)} (and quarter, half, full)")
        object.__setattr__(self, "bridge", b)
        gf = as_float(self.gauge_factor, "gauge_factor")
        if not gf > 0:
            raise ValueError(f"gauge_factor = {gf:g}: a gauge factor is > 0 (metal foil: about 2)")
        ex = as_float(self.excitation, "excitation voltage")
        if not ex > 0:
            raise ValueError(f"excitation = {ex:g} V: the bridge excitation is > 0 V")
        object.__setattr__(self, "gauge_factor", gf)
        object.__setattr__(self, "excitation", ex)
        uses_nu, has_lead = BRIDGE_TYPES[b]
        self._check_poisson(b, uses_nu)
        self._check_leads(b, has_lead)
        if self.null_window is not None:
            w = tuple(as_float(x, "null_window") for x in self.null_window)
            if len(w) != 2 or not w[1] > w[0]:
                raise ValueError(f"null_window = {list(self.null_window)} s: give [start, stop] "
                                 "with stop after start")
            object.__setattr__(self, "null_window", w)

    def _check_poisson(self, b: str, uses_nu: bool) -> None:
        if uses_nu and self.poisson is None:
            raise ValueError(f"bridge {b} needs Poisson's ratio (poisson, e.g. 0.3 for steel)")
        if not uses_nu and self.poisson is not None:
            raise ValueError(f"bridge {b} does not use Poisson's ratio (only half_I, full_II, "
                             "full_III do); leave poisson out")
        if self.poisson is not None:
            nu = as_float(self.poisson, "poisson")
            if not 0.0 <= nu < 0.5:
                raise ValueError(f"poisson = {nu:g}: Poisson's ratio of a solid lies in 0 .. 0.5")
            object.__setattr__(self, "poisson", nu)

    def _check_leads(self, b: str, has_lead: bool) -> None:
        rl = as_float(self.lead_resistance, "lead_resistance")
        if rl < 0:
            raise ValueError(f"lead_resistance = {rl:g} ohm is negative")
        if rl > 0 and not has_lead:
            raise ValueError(f"bridge {b} has no lead-resistance term (a full bridge's leads are "
                             "compensated by remote sensing in NI's equations); leave lead_ohm out")
        object.__setattr__(self, "lead_resistance", rl)
        if self.gauge_resistance is not None:
            rg = as_float(self.gauge_resistance, "gauge_resistance")
            if not rg > 0:
                raise ValueError(f"gauge_resistance = {rg:g} ohm: a gauge's resistance is > 0 "
                                 "(120, 350 or 1000 ohm usually)")
            object.__setattr__(self, "gauge_resistance", rg)
        elif rl > 0:
            raise ValueError("lead_resistance needs the gauge's nominal resistance "
                             "(gauge_ohm, e.g. 350) for the factor 1 + R_L/R_g")

    @property
    def lead_factor(self) -> float:
        """1 + R_L/R_g [-]: the lead-resistance desensitisation of quarter and half bridges."""
        if not self.lead_resistance:
            return 1.0
        return 1.0 + self.lead_resistance / self.gauge_resistance

    def to_dict(self) -> dict:
        """The configuration with SI units in the key names (for the history)."""
        return {"bridge": self.bridge, "gauge_factor": self.gauge_factor,
                "excitation_V": self.excitation, "poisson": self.poisson,
                "lead_ohm": self.lead_resistance, "gauge_ohm": self.gauge_resistance,
                "null_window_s": None if self.null_window is None else list(self.null_window)}


def _config(cfg) -> BridgeConfig:
    if not isinstance(cfg, BridgeConfig):
        raise TypeError(f"cfg must be a BridgeConfig, got {type(cfg).__name__}")
    return cfg


def strain_from_ratio(vr, cfg: BridgeConfig) -> np.ndarray:
    """Strain [m/m] from the voltage ratio V_r = (V_out - V_init)/V_ex [V/V].

    Parameters
    ----------
    vr : array_like
        Voltage ratio [V/V], any shape (NaN stays NaN).
    cfg : BridgeConfig

    Returns
    -------
    numpy.ndarray
        Strain [m/m], float64, the shape of ``vr`` (NI's equations, module docstring).
    """
    cfg = _config(cfg)
    vr = np.asarray(vr, dtype=np.float64)
    gf, b = cfg.gauge_factor, cfg.bridge
    nu = cfg.poisson
    with np.errstate(divide="ignore", invalid="ignore"):
        if b in ("quarter_I", "quarter_II"):
            e = -4.0 * vr / (gf * (1.0 + 2.0 * vr))
        elif b == "half_I":
            e = -4.0 * vr / (gf * ((1.0 + nu) - 2.0 * vr * (nu - 1.0)))
        elif b == "half_II":
            e = -2.0 * vr / gf
        elif b == "full_I":
            e = -vr / gf
        elif b == "full_II":
            e = -2.0 * vr / (gf * (nu + 1.0))
        else:  # full_III
            e = -2.0 * vr / (gf * ((nu + 1.0) - vr * (nu - 1.0)))
    return e * cfg.lead_factor


def ratio_from_strain(strain, cfg: BridgeConfig) -> np.ndarray:
    """Voltage ratio V_r [V/V] that the bridge gives at ``strain`` [m/m]: the inverse of
    :func:`strain_from_ratio` (solved for V_r by hand from the same equations).

    Parameters
    ----------
    strain : array_like
        Strain [m/m], any shape.
    cfg : BridgeConfig

    Returns
    -------
    numpy.ndarray
        V_r [V/V], float64.
    """
    cfg = _config(cfg)
    x = np.asarray(strain, dtype=np.float64) / cfg.lead_factor * cfg.gauge_factor  # GF e
    b, nu = cfg.bridge, cfg.poisson
    with np.errstate(divide="ignore", invalid="ignore"):
        if b in ("quarter_I", "quarter_II"):
            return -x / (4.0 + 2.0 * x)
        if b == "half_I":
            return -x * (1.0 + nu) / (4.0 - 2.0 * x * (nu - 1.0))
        if b == "half_II":
            return -x / 2.0
        if b == "full_I":
            return -x
        if b == "full_II":
            return -x * (nu + 1.0) / 2.0
        return -x * (nu + 1.0) / (2.0 - x * (nu - 1.0))   # full_III


def strain_from_volts(volts, cfg: BridgeConfig, v_init: float = 0.0) -> np.ndarray:
    """Strain [m/m] from the bridge output ``volts`` [V] with the unstrained output
    ``v_init`` [V]: V_r = (volts - v_init)/V_ex, then :func:`strain_from_ratio`."""
    cfg = _config(cfg)
    v_init = as_float(v_init, "v_init")
    return strain_from_ratio((np.asarray(volts, dtype=np.float64) - v_init) / cfg.excitation, cfg)


def volts_from_strain(strain, cfg: BridgeConfig, v_init: float = 0.0) -> np.ndarray:
    """Bridge output [V] at ``strain`` [m/m]: V_init + V_ex V_r (inverse of
    :func:`strain_from_volts`)."""
    cfg = _config(cfg)
    v_init = as_float(v_init, "v_init")
    return v_init + cfg.excitation * ratio_from_strain(strain, cfg)


def null_ratio(volts, excitation: float) -> float:
    """The mean voltage ratio mean(V_out)/V_ex [V/V] of the samples ``volts`` [V] of a null
    window (non-finite samples left out); ValueError when none is finite."""
    v = np.asarray(volts, dtype=np.float64).ravel()
    ex = as_float(excitation, "excitation")
    if not ex > 0:
        raise ValueError(f"excitation = {ex:g} V: the bridge excitation is > 0 V")
    ok = np.isfinite(v)
    if not ok.any():
        raise ValueError("the null window holds no finite sample")
    return float(v[ok].mean() / ex)


def _window_columns(t0: float, fs: float, n: int, window) -> tuple[int, int]:
    """Sample range [i0, i1) of ``window`` [s] in a recording of ``n`` samples from ``t0``;
    ValueError when the window is not inside it."""
    t_end = t0 + n / fs
    w0, w1 = window
    if w0 < t0 - 0.5 / fs or w1 > t_end + 0.5 / fs:
        raise ValueError(f"null_window_s [{w0:g}, {w1:g}] s is not inside the recording, which "
                         f"runs {t0:g} .. {t_end:g} s")
    i0 = max(0, math.ceil((w0 - t0) * fs - 1e-6))
    i1 = min(n, math.ceil((w1 - t0) * fs - 1e-6))
    if i1 <= i0:
        raise ValueError(f"null_window_s [{w0:g}, {w1:g}] s holds no sample (fs {fs:g} Hz)")
    return i0, i1


def window_means(blocks: Iterator, t0: float, fs: float, n: int, windows: dict) -> dict:
    """Mean of each column over its time window, from consecutive blocks.

    Parameters
    ----------
    blocks : iterator of (int, ndarray)
        (first sample, samples x channels) as :meth:`meshphase.recording.BlockSource.blocks`
        gives them; read only up to the last window's end.
    t0, fs, n : float, float, int
        Time of sample 0 [s], sample rate [Hz], number of samples.
    windows : dict of int to (float, float)
        Column -> (start, stop) [s].

    Returns
    -------
    dict of int to float
        Column -> mean of its finite samples in the window (NaN when none is finite).
    """
    if not windows:
        return {}
    ranges = {j: _window_columns(t0, fs, n, w) for j, w in windows.items()}
    sums = {j: 0.0 for j in ranges}
    counts = {j: 0 for j in ranges}
    last = max(i1 for _, i1 in ranges.values())
    for a, data in blocks:
        b = a + data.shape[0]
        for j, (i0, i1) in ranges.items():
            lo, hi = max(a, i0), min(b, i1)
            if hi > lo:
                x = np.asarray(data[lo - a:hi - a, j], dtype=np.float64)
                ok = np.isfinite(x)
                sums[j] += float(x[ok].sum())
                counts[j] += int(ok.sum())
        if b >= last:
            break
    return {j: sums[j] / counts[j] if counts[j] else math.nan for j in ranges}


def convert_block(data: np.ndarray, conversions: dict) -> np.ndarray:
    """``data`` with each column j of ``conversions`` {j: (cfg, v_init)} in strain [m/m]
    (a copy in the block's dtype)."""
    out = np.array(data, copy=True)
    for j, (cfg, v_init) in conversions.items():
        out[:, j] = strain_from_volts(data[:, j], cfg, v_init)
    return out


def initial_volts(blocks, t0, fs, n, configs: dict) -> dict:
    """{column: V_init [V]} of the configs with a null window (0 for the others)."""
    windows = {j: c.null_window for j, c in configs.items() if c.null_window is not None}
    means = window_means(blocks, t0, fs, n, windows)
    for j, m in means.items():
        if not math.isfinite(m):
            raise ValueError(f"null_window_s {list(windows[j])} s of column {j} holds no "
                             "finite sample")
    return {j: means.get(j, 0.0) for j in configs}


def bridge_history(names, configs: dict, v_init: dict) -> dict:
    """The ``bridge_strain`` history entry: {channel: its bridge, V_init [V] and initial
    ratio [V/V]} (``names``: channel names by column; ``configs``, ``v_init`` by column)."""
    return {names[j]: dict(c.to_dict(), v_init_V=v_init[j],
                           initial_ratio_V_per_V=v_init[j] / c.excitation)
            for j, c in configs.items()}


def bridge_recording(rec, configs: dict):
    """A Recording whose bridge channels are in strain [m/m] (units "m/m").

    Parameters
    ----------
    rec : meshphase.Recording
        Bridge channels in volts [V].
    configs : dict of str to BridgeConfig
        Channel name -> its bridge.

    Returns
    -------
    meshphase.Recording
        The converted samples, with a ``bridge_strain`` history step naming each channel's
        bridge, its V_init [V] and initial ratio [V/V].
    """
    if not isinstance(rec, Recording):
        raise TypeError(f"rec must be a Recording, got {type(rec).__name__}")
    if not configs:
        return rec
    cols = {rec.index(name): _config(c) for name, c in configs.items()}
    data = rec.data
    v_init = initial_volts(iter([(0, data)]), rec.t0, rec.fs, rec.n_samples, cols)
    out = convert_block(data, {j: (c, v_init[j]) for j, c in cols.items()})
    specs = [strain_spec(s) if j in cols else s for j, s in enumerate(rec.channels)]
    return Recording(out, rec.fs, specs, rec.t0, rec.start_datetime, rec.meta, rec.history).with_history(
        "bridge_strain", channels=bridge_history(rec.names, cols, v_init))


def strain_spec(spec):
    """``spec`` (a ChannelSpec) with units "m/m"."""
    return dataclasses.replace(spec, units="m/m")
