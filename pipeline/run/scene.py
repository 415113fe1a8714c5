"""Scenes: a TOML file -> a typed, SI-unit config -> the stages its results need.

One module of about 1,300 lines on purpose: it walks one schema table by table, each table's
parser beside its checks, and every error names the key and the line of the file; the stage
graph it plans from is declared in :mod:`meshphase.run.declare`.

A scene names the gearset, the gauges, the inputs (a recording file or a synthetic
scenario), the tolerances and the results wanted (``data_schemas/scene.schema.json``,
documented in ``data_schemas/scene.md``). It is validated up front; errors name the key and
the line of the scene file (what is checked: ``data_schemas/scene.md``, "What is checked before
anything runs"; the gearset itself with :mod:`meshphase.models.assembly`, and the scene against
the recording's header with :func:`check_recording`). :func:`plan` turns the requested results into the ordered list of
stages that must run, and nothing else: a bearing-moment scene opens no recording, a scene
without tolerances runs no Monte Carlo, a scene without face-width gauges does no centroid
work. The stages are declared in :mod:`meshphase.run.declare` (:data:`STAGES` and
:data:`RESULTS` come from there) and run by :mod:`meshphase.run.stages`.
"""

from __future__ import annotations

import math
import os
import re
import stat
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshphase.data_schemas import schema_errors

from .. import io
from ..io.bridge import BridgeConfig
from ..io.sources import scenario_config, scenario_names
from ..io.channels import (GAUGE_KINDS, ChannelMapError, apply_channel_overrides, check_gauges,
                           is_glob, map_channels)
from ..errors import DeprecatedNameWarning, SceneWarning
from ..models.assembly import (CLEARANCE_ATOL, assemblable_planet_counts, coaxiality_error,
                               max_equal_planets, tip_clearance)
from ..models.gearset import Gearset, Speeds, rpm_to_rad_s
from ..models.mesh_phasing import assembly_check
from ..kinematics.shafts import typed_resolution
from ..recording import Recording
from ..io.units import parse_unit
from ..runtime.registry import DEFAULT_ONSET_DETECTOR, ONSET_DETECTORS
from .declare import gearset_stages, recording_stages, result_stages, stage_graph

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "scene_schema_errors", "plan",
           "check_recording", "read_options", "with_recording", "output_folder", "READ_KEYS",
           "CSV_KEYS", "STAGES", "RESULTS", "LIMITS"]

#: stage -> the stages it needs (a DAG; the flow runs one way), from the stage registry
STAGES: dict[str, tuple[str, ...]] = stage_graph()

#: result name -> stages that produce it, from the stage registry
RESULTS: dict[str, tuple[str, ...]] = result_stages()

_NEEDS_RECORDING = recording_stages()


def _file_state(path) -> str:
    """``"file"`` for a regular file, else why it is not one (never raises)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return "no such recording file"
    except OSError as e:  # ELOOP, ENAMETOOLONG, ENOTDIR, EACCES on a parent
        return f"the recording cannot be reached ({e.strerror or e})"
    if not stat.S_ISREG(st.st_mode):
        return "not a regular file (a folder, FIFO or device)"
    return "file"


class SceneError(ValueError):
    """A scene file that does not validate; the message names the file, key and line."""

    def __init__(self, path, key: str, problem: str, line: int | None = None):
        self.path, self.key, self.problem, self.line = str(path), key, problem, line
        where = f"{path}" + (f", line {line}" if line else "")
        super().__init__(f"{where}: [{key}] {problem}" if key else f"{where}: {problem}")


@dataclass
class Scene:
    """A validated scene, SI units inside.

    Attributes
    ----------
    path : Path or None
        The scene file (relative paths in it resolve against its folder).
    name : str
    results : list of str
    gearset : Gearset or None
    speeds : Speeds or None
        Nominal speeds [rad/s] (a hint, never used for measured phasing).
    channels : list of dict
        The ``[[channels]]`` entries (:mod:`meshphase.io.channels`): ``name`` (exact or glob) or
        ``regex``, ``kind``, ``gear``, ``tooth``, ``face_position`` [m], ``gain``,
        ``mount_angle`` [rad], ``bridge`` (a :class:`meshphase.io.bridge.BridgeConfig`).
    input : dict
        ``recording`` (Path) or ``synthetic`` (scenario name) with ``minutes``, ``seed``,
        ``start``/``stop`` [s], or ``memory`` (a Recording given in code: :func:`meshphase.process`); ``mcap``: the format options mapping an MCAP file of
        another tool (``topics``, ``fs``, ``max_jitter``, ``stamp``); ``csv``: the reader
        options of a delimited-text file (``header_row``, ``skip_rows``, ``decimal``,
        ``delimiter``); ``fs_Hz`` [Hz]; ``options``: format options given beside the scene
        (the command line's), over the others (:func:`read_options`).
    processing : dict
    tolerances : dict or None
        Bands in SI ([m], [rad] or "uniform"), ``samples``, ``sampler``, ``window`` [s], ``seed``.
    bearing : dict or None
        ``case``, ``input_torque`` [N·m], ``z_s``/``z_r`` [m], ``k_tilt`` [N·m/rad] list (from
        ``k_tilt_Nm_per_rad`` or ``k_tilt_Nmm_per_rad``), ``c_g`` [N/m^2], double-pinion
        included-angle sweeps ``double_pinion_included_angle_sp``/``_rp`` [rad] (old keys
        ``double_pinion_beta_deg``/``_gamma_deg`` still read, with a DeprecatedNameWarning).
    output : Path or None
        The ``output`` key, absolute: relative to the current directory (:func:`output_folder`).
    raw : dict
        The parsed TOML as written.
    speeds_resolution : dict or None
        Uncertainty of the typed sun and carrier speeds [rad/s] (half a unit in the last
        typed digit): what "zero" means for a Willis ring speed.
    fixed : {"ring", "sun", "none"} or None
        The held member as the scene states it (None: decided from speeds and tacho).
    tacho : dict
        ``key_angle`` [rad] (carrier-frame angle of the key from planet 1), ``channel``.
    mounts : dict of str to float
        Ground angle of each gauge on a held member [rad], from its channel's
        ``mount_angle_deg``.
    labels : dict of str to int
        ``[labels]``: per gear ("sun", "ring") the places along its pass order from the
        first pulse to planet 1 [-] (:func:`meshphase.kinematics.phasing.measure_phasing`
        ``label_shifts``).
    profile_shift : bool
        ``[gearset] profile_shift``: the gears are profile shifted, so Z_r = Z_s + 2 Z_p need
        not hold (coaxiality is then not checked).
    onset_detector : str
        ``[onsets] detector``: the registered onset detector of the gauges
        (:mod:`meshphase.onsets.detector`), default ``"matched"``.
    text : str
        The scene file's text (for the line numbers of errors found later, e.g. by
        :func:`plan`); empty for a scene built in code.
    """

    path: Path | None
    name: str
    results: list[str]
    gearset: Gearset | None = None
    speeds: Speeds | None = None
    channels: list[dict] = field(default_factory=list)
    input: dict = field(default_factory=dict)
    processing: dict = field(default_factory=dict)
    tolerances: dict | None = None
    bearing: dict | None = None
    output: Path | None = None
    raw: dict = field(default_factory=dict)
    speeds_resolution: dict | None = None
    fixed: str | None = None
    tacho: dict = field(default_factory=dict)
    mounts: dict = field(default_factory=dict)
    labels: dict = field(default_factory=dict)
    profile_shift: bool = False
    onset_detector: str = DEFAULT_ONSET_DETECTOR
    text: str = field(default="", repr=False, compare=False)

    @property
    def has_recording_input(self) -> bool:
        return bool(self.input.get("recording") or self.input.get("synthetic")
                    or self.input.get("memory") is not None)


_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\-]+)\s*\]\]?\s*(#.*)?$")
_KEYLINE = re.compile(r"^\s*([A-Za-z0-9_\-]+)\s*=")


def _line_of(text: str, keys: list) -> int | None:
    """Best-effort line number (1-based) of a key path in TOML text.

    ``keys`` is a path as jsonschema gives it (strings and array indices, indices also as digit
    strings): ``["gearset", "z_sun"]``, ``["channels", 1, "tooth"]`` (the second ``[[channels]]``
    table), ``["results", 1]`` (the ``results`` line), ``["foo"]`` (a ``foo = `` line or a
    ``[foo]`` header). Falls back to the table header when the key itself is not written.
    """
    if not text or not keys:
        return None
    keys = [int(k) if isinstance(k, str) and k.isdigit() else k for k in keys]
    lines = text.splitlines()
    # sections: (table name, array-of-tables index, header line or None, first body line, end)
    sections, counts = [], {}
    cur = ["", None, None, 0]
    for i, ln in enumerate(lines):
        m = _HEADER.match(ln)
        if m:
            sections.append((*cur, i))
            name = m.group(2)
            idx = None
            if m.group(1) == "[[":
                idx = counts.get(name, 0)
                counts[name] = idx + 1
            cur = [name, idx, i + 1, i + 1]
    sections.append((*cur, len(lines)))

    def find_key(sec, key):
        for i in range(sec[3], sec[4]):
            m = _KEYLINE.match(lines[i])
            if m and m.group(1) == key:
                return i + 1
        return None

    head, rest = keys[0], keys[1:]
    if not isinstance(head, str):
        return None
    ln = find_key(sections[0], head)      # a top-level key (arrays: the key's line)
    if ln is not None:
        return ln
    tabs = [s for s in sections[1:] if s[0] == head]
    if not tabs:
        return None
    tab = tabs[0]
    if rest and isinstance(rest[0], int):
        tab = next((s for s in tabs if s[1] == rest[0]), tab)
        rest = rest[1:]
    sub = next((k for k in rest if isinstance(k, str)), None)
    if sub is not None:
        ln = find_key(tab, sub)
        if ln is not None:
            return ln
    return tab[2]


#: seed 001 bearing cases (:func:`meshphase.models.bearing.seed_case`) and the spellings accepted
_BEARING_CASES = {"1": "1", "2a": "2-A", "2b": "2-B"}


def _bearing_case(name) -> str | None:
    """Canonical seed 001 case name ("1", "2-A", "2-B") of ``name``, or None if unknown.

    Accepts the seed's labels and the usual spellings: "1", "case1", "Case 1", "2-B", "2B",
    "case2B", "case 2-B".
    """
    key = re.sub(r"[\s_\-]", "", str(name).lower())
    key = key[4:] if key.startswith("case") else key
    return _BEARING_CASES.get(key)


#: physical ranges of scene values (the checks of data_schemas/scene.md, "What is checked")
LIMITS = {
    # lengths typed in mm (carrier radius, face width): outside this a unit slip (metres,
    # micrometres) is far likelier than a real rig's gear [mm]
    "length_mm": (5.0, 5000.0),
    # fastest member speed [r/min]: beyond any gear test rig (1e5 r/min = 10 472 rad/s)
    "speed_rpm": 1e5,
    # Monte Carlo realisations: above "samples_warn" a run-time warning, above "samples_max"
    # refused; "mc_evals_max": realisations x time points x planets (hours with numba at the
    # kernel throughput below)
    "samples_warn": 10**6,
    "samples_max": 10**8,
    "mc_evals_max": 1e12,
    # mesh stiffness per unit face width [N/(mm·µm)] (ISO 6336: 20 by default, 10..25 usual)
    "c_g": (0.5, 1000.0),
    # a synthetic recording is generated whole in memory and processed with about this many
    # float64 copies of its samples alive (measured peak RSS 7.6x the samples for 8 min of
    # seed_rig through phasing + load sharing); refused above the machine's physical memory
    "processing_copies": 8,
    # input torque [N·m]: ten times the largest wind-turbine gearbox's (~1e7 N·m)
    "torque_Nm": 1e8,
    # analysis block of the onset detector [s]: it learns a template from the pulses of one
    # block, so a block shorter than this holds too few of them at any rig's speed
    "block_s_min": 0.01,
}

#: Monte Carlo kernel throughput for the run-time estimate of a warning [evaluations/s]: the
#: numba kernel on one core of the 2-core machine, 0.065-0.135 G evaluations/s as
#: ``meshphase bench models`` measures it unloaded (``meshphase bench models`` prints "Kernel throughput" of the machine
#: it runs on); an order of magnitude for a warning, not a promise
_MC_RATE = {"numba": 0.1e9}
#: results that need the planet tooth count (planet speed w_pc = -(Z_s / Z_p) w_sc)
_NEEDS_Z_PLANET = {"phasing": "the angle model's planet-spin terms",
                   "identify": "the identified planet offsets",
                   "tolerance": "the Monte Carlo's planet offsets"}

_EMPTY_HELP = (
    "a scene needs `results = [...]` (any of {results}) and the tables those results read: "
    "[gearset] (z_sun, z_ring, z_planet, n_planets or planet_angles_deg, carrier_radius_mm) "
    "for phasing, ideal_phasing, compare, identify, tolerance; [input] (recording = \"FILE\" "
    "or synthetic = \"SCENARIO\") for measured results; [tolerances] for tolerance; [bearing] "
    "for bearing_moments and tilt. data_schemas/scene.md lists every key; examples/ has one "
    "scene of each kind")


def load_scene(path, *, recording_given: bool = False) -> Scene:
    """Read and validate a scene TOML file.

    Parameters
    ----------
    path : str or Path
    recording_given : bool
        The caller supplies the recording that replaces the scene's ``[input]``
        (``meshphase process FILE --gearset SCENE``, ``meshphase campaign``): results that
        read a recording need no ``[input]`` then (:func:`parse_scene`).

    Raises
    ------
    FileNotFoundError
        The scene file does not exist.
    SceneError
        TOML syntax errors (with their line) or schema / consistency errors (key and line).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such scene file")
    try:
        data = path.read_bytes()
    except OSError as exc:  # EIO from a failing disk carries no file name: add it
        raise OSError(exc.errno, f"{path}: cannot read the scene: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise SceneError(path, "", f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                         f"{exc.start}): save the scene as UTF-8", line) from None
    return parse_scene(text, path, recording_given=recording_given)


def _walk(obj, keys=()):
    """(key path, value) of every leaf of a parsed TOML document."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _walk(v, keys + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _walk(v, keys + (i,))
    else:
        yield keys, obj


def _mm_hint(value: float, lo: float, hi: float) -> str:
    if value < lo:
        return f"a value in metres? {value:g} m = {value * 1e3:g} mm"
    return f"a value in micrometres? {value:g} µm = {value * 1e-3:g} mm"


def _physical_memory() -> int | None:
    """Physical memory of this machine [B], or None when the OS does not tell."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def parse_scene(text: str, path: Path | str | None = None, *, recording_given: bool = False) -> Scene:
    """Validate scene TOML ``text`` (``path`` only labels errors and anchors relative paths).

    ``recording_given``: the caller supplies the recording that replaces ``[input]``
    (``process``, ``campaign``), so results that read one need no ``[input]`` here.

    Everything that can be told from the scene alone is checked here, before anything runs
    (``data_schemas/scene.md``, "What is checked before anything runs"): the schema, finite
    numbers, physical ranges (lengths in mm, speeds, Monte Carlo size, the synthetic
    recording's memory), the gearset (coaxiality, assembly, planet tip clearance), the results
    against what the scene provides, and, when the scene reads a recording file, the scene
    against the file's header (:func:`check_recording`). Planet angles given in
    ``planet_angles_deg`` are snapped to the nearest assemblable angles
    psi_1 + 2 pi p_n / (Z_s + Z_r) when within the precision they were typed with.

    Raises
    ------
    SceneError
        Naming the file, the key and the line.

    Warns
    -----
    SceneWarning
        A Monte Carlo of more than ``LIMITS["samples_warn"]`` realisations (with its run-time
        estimate).
    """
    label = path if path is not None else "<scene>"
    raw = _read_toml(text, label)
    err = _error_maker(label, text)
    _check_schema(raw, text, label, err)
    base = Path(path).resolve().parent if path is not None else Path.cwd()
    gearset, profile_shift = _parse_gearset(raw, err)
    speeds, resolution = _parse_speeds(raw, gearset, err)
    channels, mounts = _parse_channels(raw, gearset, err)
    tacho = _parse_tacho(raw)
    labels = _parse_labels(raw, gearset, err)
    detector = _parse_onsets(raw, err)
    inp = _parse_input(raw, base, err, recording_given=recording_given)
    tol = _parse_tolerances(raw, gearset, err)
    bearing = _parse_bearing(raw, err, label, text)
    _check_block(raw, err)
    scene = Scene(
        path=Path(path) if path is not None else None,
        name=raw.get("name", Path(path).stem if path is not None else "scene"),
        results=list(raw.get("results", [])), gearset=gearset, speeds=speeds, channels=channels, input=inp,
        processing=dict(raw.get("processing", {})), tolerances=tol, bearing=bearing,
        output=output_folder(raw["output"]) if "output" in raw else None, raw=raw,
        speeds_resolution=resolution or None, fixed=raw.get("speeds", {}).get("fixed"), tacho=tacho, mounts=mounts,
        labels=labels, profile_shift=profile_shift, onset_detector=detector, text=text)
    _check_consistency(scene, text, label, recording_given=recording_given)
    stages = plan(scene, check=False)
    if "tolerance" in stages:
        _check_monte_carlo(scene, err)
    rec = scene.input.get("recording")
    if "load" in stages and rec and _file_state(rec) == "file":
        try:
            info = io.read_info(rec, **read_options(scene))
        except Exception:  # noqa: BLE001 - unreadable files are the load stage's to report
            info = None
        if info is not None:
            check_recording(scene, info)
    return scene


def _read_toml(text: str, label) -> dict:
    """The parsed TOML document; syntax errors as a SceneError with their line."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        # tomllib recurses once per nesting level of arrays / inline tables
        depth = max(text.count("["), text.count("{"))
        raise SceneError(label, "", f"nested arrays or inline tables too deep to read ({depth} "
                         "brackets): a scene nests at most a few levels", 1) from None
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        line = int(m.group(1)) if m else None
        if line is None and "end of document" in str(exc):
            line = max(1, len(text.splitlines()))
        raise SceneError(label, "", f"TOML syntax error: {exc}", line) from None


def _error_maker(label, text: str):
    """``err(keys, problem)``: the SceneError naming the key path and its line in ``text``."""
    def err(keys, problem):
        return SceneError(label, ".".join(str(k) for k in keys), problem, _line_of(text, list(keys)))
    return err


def scene_schema_errors(raw: dict) -> list:
    """Where a scene's TOML, read into a dict, breaks ``data_schemas/scene.schema.json``.

    Parameters
    ----------
    raw : dict
        The scene as :mod:`tomllib` reads it.

    Returns
    -------
    list of jsonschema.ValidationError
        Sorted by the path of the key; empty when the scene matches the schema.
    """
    # jsonschema (~90 modules: attrs, referencing, importlib.metadata) loads here, only for a
    # scene; the validator is data_schemas' own, built once per process
    return sorted(schema_errors(raw, "scene"), key=lambda e: [str(k) for k in e.absolute_path])


def _check_schema(raw: dict, text: str, label, err) -> None:
    """An empty scene, non-finite numbers, then ``data_schemas/scene.schema.json`` (the first
    problem named, with the number of the others)."""
    if not set(raw) - {"name", "description", "output"}:
        raise SceneError(label, "results", "the scene is empty (nothing to run): "
                         + _EMPTY_HELP.format(results=", ".join(RESULTS)), 1)
    for keys, v in _walk(raw):
        if isinstance(v, float) and not math.isfinite(v):
            raise err(keys, f"{v} is not a finite number (TOML reads inf and nan as numbers)")
    errors = scene_schema_errors(raw)
    if errors:
        e = errors[0]
        keys = [k for k in e.absolute_path]
        key = ".".join(str(k) for k in keys) or "(top level)"
        msg = e.message
        if e.validator == "additionalProperties":
            extra = re.findall(r"'([^']+)' was unexpected", msg)
            if extra:
                keys = keys + [extra[0]]
                key = ".".join(str(k) for k in keys)
                allowed = sorted(e.schema.get("properties", {}))
                msg = f"unknown key {extra[0]!r}; allowed here: {', '.join(allowed)}"
        elif e.validator in ("minimum", "maximum", "exclusiveMinimum") and "description" in e.schema:
            msg += f" ({e.schema['description']})"   # what the key means says why the limit
        more = f" (and {len(errors) - 1} more problem(s))" if len(errors) > 1 else ""
        raise SceneError(label, key, msg + more, _line_of(text, keys))


def _parse_gearset(raw: dict, err) -> tuple[Gearset | None, bool]:
    """``[gearset]`` -> (the checked Gearset, SI inside, or None; profile shifted)."""
    profile_shift = False
    if "gearset" not in raw:
        return None, profile_shift
    g = raw["gearset"]
    profile_shift = bool(g.get("profile_shift", False))
    lo, hi = LIMITS["length_mm"]
    for k in ("carrier_radius_mm", "face_width_mm"):
        if k in g and not lo <= g[k] <= hi:
            raise err(["gearset", k], f"{g[k]:g} mm is outside {lo:g} .. {hi:g} mm, where "
                      f"gear dimensions lie; {_mm_hint(g[k], lo, hi)}")
    if "planet_angles_deg" in g:
        angles = tuple(math.radians(a) for a in g["planet_angles_deg"])
    else:
        n = g["n_planets"]
        angles = tuple(2 * math.pi * k / n for k in range(n))
    try:
        gearset = Gearset(g["z_sun"], g["z_ring"], g.get("z_planet", 0), angles,
                          g["carrier_radius_mm"] * 1e-3, direction=g.get("direction", "cw"),
                          name=g.get("name", ""),
                          face_width=g["face_width_mm"] * 1e-3 if "face_width_mm" in g else None)
    except (ValueError, TypeError) as exc:
        raise err(["gearset", "z_ring"] if "z_ring" in str(exc) else ["gearset"], str(exc)) from None
    gearset = _check_gearset(gearset, g, profile_shift, err)
    return gearset, profile_shift


def _parse_speeds(raw: dict, gearset: Gearset | None, err) -> tuple[Speeds | None, dict | None]:
    """``[speeds]`` -> (nominal Speeds [rad/s] or None, the typed speeds' resolution
    [rad/s] by member or None)."""
    speeds = None
    if "speeds" not in raw or gearset is None:
        return speeds, None

    s = raw["speeds"]
    conv = {}
    resolution = {}
    for m in ("sun", "carrier", "ring", "planet"):
        if f"{m}_rpm" in s and f"{m}_rad_s" in s:
            raise err(["speeds", f"{m}_rad_s"], f"give {m}_rpm or {m}_rad_s, not both")
        if f"{m}_rpm" in s:
            conv[m] = rpm_to_rad_s(s[f"{m}_rpm"])
            resolution[m] = abs(rpm_to_rad_s(typed_resolution(s[f"{m}_rpm"])))
        elif f"{m}_rad_s" in s:
            conv[m] = float(s[f"{m}_rad_s"])
            resolution[m] = typed_resolution(s[f"{m}_rad_s"])
        if m in conv and abs(conv[m]) > rpm_to_rad_s(LIMITS["speed_rpm"]):
            k = f"{m}_rpm" if f"{m}_rpm" in s else f"{m}_rad_s"
            raise err(["speeds", k], f"{s[k]:g} {'r/min' if k.endswith('rpm') else 'rad/s'} is "
                      f"faster than gear rigs run (limit {LIMITS['speed_rpm']:g} r/min = "
                      f"{rpm_to_rad_s(LIMITS['speed_rpm']):.0f} rad/s); check the value and its unit")
    _complete_speeds(conv, resolution, s.get("fixed"), gearset)
    if "sun" in conv and "carrier" in conv:
        w_s, w_c = conv["sun"], conv["carrier"]
        if w_s == w_c:
            k = "sun_rpm" if "sun_rpm" in s else "sun_rad_s"
            raise err(["speeds", k], f"the sun turns with the carrier (both {w_s:.6g} rad/s): "
                      "the gearset turns as one block and no tooth meshes")
        # Willis, no planet teeth needed: w_r - w_c = -(Z_s / Z_r)(w_s - w_c)
        ring = w_c - gearset.z_sun / gearset.z_ring * (w_s - w_c)
        if "planet" in conv:
            speeds = Speeds(w_s, w_c, conv["planet"], conv.get("ring", ring))
        elif gearset.z_planet == 0:
            # the planet speed is unknown without Z_p (0 here); the results that need it
            # require z_planet (_check_consistency)
            speeds = Speeds(w_s, w_c, 0.0, conv.get("ring", ring))
        else:
            speeds = Speeds.kinematic(gearset, w_s, w_c)
        # nominal speeds are typed rounded (the seed's ring: -3.862 r/min): 0.1 % slack
        scale = max(abs(w_s), abs(w_c), abs(ring))
        if "ring" in conv and abs(ring - conv["ring"]) > 1e-3 * scale:
            raise err(["speeds", "ring_rpm" if "ring_rpm" in s else "ring_rad_s"],
                      f"ring speed {conv['ring']:.6g} rad/s is not consistent with sun/carrier "
                      f"and the tooth counts (kinematics give {ring:.6g} rad/s)")
    elif any(k != "fixed" for k in s):
        raise err(["speeds"], "give two of the sun, carrier and ring speeds, or one of them with "
                  "the held member ([speeds] fixed = \"ring\" or \"sun\")")
    return speeds, resolution


def _complete_speeds(conv: dict, resolution: dict, fixed, gearset: Gearset) -> None:
    """Sun and carrier speeds [rad/s] (and their typed resolution) from any two of sun,
    carrier and ring, a member stated held (``fixed``) counting as one at zero, by Willis
    ``w_r - w_c = -(Z_s / Z_r)(w_s - w_c)``; ``conv`` and ``resolution`` completed in place.
    A rig's user knows the input speed and which member is held: ``sun_rpm = 18.19`` with
    ``fixed = "ring"`` is the seed rig's carrier at 4.06 r/min."""
    if "sun" in conv and "carrier" in conv:
        return
    if fixed in ("ring", "sun") and fixed not in conv:
        conv[fixed], resolution[fixed] = 0.0, 0.0
    zs, zr = float(gearset.z_sun), float(gearset.z_ring)
    # a speed typed as 0 is a held member: exact, whatever digits it was typed with
    res = {m: 0.0 if conv.get(m) == 0.0 else resolution.get(m, 0.0) for m in ("sun", "carrier", "ring")}
    if "carrier" not in conv and "sun" in conv and "ring" in conv:
        conv["carrier"] = (zr * conv["ring"] + zs * conv["sun"]) / (zs + zr)
        resolution["carrier"] = (zr * res["ring"] + zs * res["sun"]) / (zs + zr)
    elif "sun" not in conv and "carrier" in conv and "ring" in conv:
        conv["sun"] = conv["carrier"] - zr / zs * (conv["ring"] - conv["carrier"])
        resolution["sun"] = (1.0 + zr / zs) * res["carrier"] + zr / zs * res["ring"]


def _parse_channels(raw: dict, gearset: Gearset | None, err) -> tuple[list, dict]:
    """``[[channels]]`` -> (the entries, SI inside: ``face_position`` [m], ``mount_angle``
    [rad], ``bridge`` a :class:`meshphase.io.bridge.BridgeConfig`; mount angle [rad] by the
    channel of each exact name)."""
    channels = []
    mounts = {}
    seen = {}
    for i, c in enumerate(raw.get("channels", [])):
        key = _channel_key(c, i, err)
        if (key, c[key]) in seen:
            raise err(["channels", i, key], f"channel {c[key]!r} is mapped twice (also "
                      f"[[channels]] number {seen[(key, c[key])] + 1}); map each channel once")
        seen[(key, c[key])] = i
        _check_channel(c, i, gearset, err)
        d = {k: v for k, v in c.items() if k not in ("face_position_mm", "mount_angle_deg")
             and k not in _BRIDGE_KEYS}
        if "face_position_mm" in c:
            d["face_position"] = c["face_position_mm"] * 1e-3
        if "mount_angle_deg" in c:
            d["mount_angle"] = math.radians(c["mount_angle_deg"])
            if key == "name" and not is_glob(c["name"]):
                mounts[c["name"]] = d["mount_angle"]
        if "bridge" in c or any(k in c for k in _BRIDGE_KEYS):
            d["bridge"] = _parse_bridge_keys(c, i, err)
        channels.append(d)
    return channels, mounts


#: [[channels]] keys of a bridge channel (its volts converted to strain: meshphase.io.bridge)
_BRIDGE_KEYS = ("bridge", "gauge_factor", "excitation_V", "poisson", "lead_ohm", "gauge_ohm",
                "null_window_s")


def _channel_key(c: dict, i: int, err) -> str:
    """``name`` or ``regex``: the key by which a ``[[channels]]`` entry maps (one of them; a
    regex that compiles, its ``tooth`` group not next to a ``tooth`` key)."""
    if ("name" in c) == ("regex" in c):
        raise err(["channels", i], "give name (a channel's name, or a glob such as "
                  '"SG*_sun*") or regex (a regular expression), one of them')
    if "name" in c:
        return "name"
    try:
        rx = re.compile(c["regex"])
    except re.error as exc:
        raise err(["channels", i, "regex"],
                  f"{c['regex']!r} is not a regular expression: {exc}") from None
    if "tooth" in rx.groupindex and "tooth" in c:
        raise err(["channels", i, "tooth"], "the regex's tooth group gives the tooth number; "
                  "give it there or here, not both")
    return "regex"


def _parse_bridge_keys(c: dict, i: int, err):
    """The bridge of one ``[[channels]]`` entry (:class:`meshphase.io.bridge.BridgeConfig`, SI),
    its problems as a SceneError at the key at fault."""
    if "bridge" not in c:
        given = next(k for k in _BRIDGE_KEYS if k in c)
        raise err(["channels", i, given], f"{given} belongs to a bridge channel: give its "
                  'bridge too (bridge = "quarter_I", ... : data_schemas/scene.md)')
    for k in ("gauge_factor", "excitation_V"):
        if k not in c:
            raise err(["channels", i, "bridge"], f"a bridge channel needs {k}")
    try:
        return BridgeConfig(c["bridge"], c["gauge_factor"], c["excitation_V"],
                            poisson=c.get("poisson"), lead_resistance=c.get("lead_ohm", 0.0),
                            gauge_resistance=c.get("gauge_ohm"),
                            null_window=c.get("null_window_s"))
    except ValueError as exc:
        text = str(exc)
        key = next((k for word, k in (("null_window", "null_window_s"),
                                      ("gauge_factor", "gauge_factor"),
                                      ("excitation", "excitation_V"), ("oisson", "poisson"),
                                      ("lead", "lead_ohm"), ("gauge_resistance", "gauge_ohm"))
                    if word in text), "bridge")
        raise err(["channels", i, key], text) from None


def _parse_tacho(raw: dict) -> dict:
    """``[tacho]`` -> ``key_angle`` [rad], ``channel``."""
    tacho = {}
    if "tacho" in raw:
        if "key_angle_deg" in raw["tacho"]:
            tacho["key_angle"] = math.radians(raw["tacho"]["key_angle_deg"])
        if "channel" in raw["tacho"]:
            tacho["channel"] = raw["tacho"]["channel"]
    return tacho


def _parse_labels(raw: dict, gearset: Gearset | None, err) -> dict:
    """``[labels]`` -> {gear: places from the first pulse to planet 1}; each below the number
    of planets."""
    out = {}
    for gear in ("sun", "ring"):
        k = raw.get("labels", {}).get(f"{gear}_shift")
        if k is None:
            continue
        if gearset is not None and k >= gearset.n_planets:
            raise err(["labels", f"{gear}_shift"], f"{k} places: a shift counts places along the "
                      f"pass order, below the number of planets ({gearset.n_planets})")
        out[gear] = int(k)
    return out


def _parse_onsets(raw: dict, err) -> str:
    """``[onsets] detector`` -> a registered onset detector's name (default "matched")."""
    name = raw.get("onsets", {}).get("detector", DEFAULT_ONSET_DETECTOR)
    try:
        return ONSET_DETECTORS.check(name)
    except ValueError as exc:
        raise err(["onsets", "detector"], str(exc)) from None


def output_folder(output) -> Path:
    """The folder a scene's ``output`` key names: relative to the current directory (the
    directory the command runs in), never to the scene file's folder, so a scene kept in a
    repository or an installed package writes its outputs where the user works.

    Parameters
    ----------
    output : str or Path
        The key's value (absolute, or relative to the current directory).

    Returns
    -------
    Path
        Absolute (normalised, symbolic links not resolved).
    """
    if not isinstance(output, (str, os.PathLike)) or not str(output).strip():
        raise ValueError(f"output must be a folder path, got {output!r}")
    return Path(os.path.normpath(os.path.abspath(output)))


#: The ``[input]`` keys that say how to read the recording file rather than which one (they
#: hold for any recording read with the scene: ``meshphase process``, ``campaign``):
#: the format tables ``mcap`` and ``csv``, the rate ``fs_Hz``, and ``options`` (format options
#: given beside the scene, e.g. on the command line, over the tables').
READ_KEYS = ("mcap", "csv", "fs_Hz", "options")

#: ``[input.csv]`` keys -> their types: the read options of delimited-text files with the same
#: names (``header_row`` the line number of the channel names, from 1; ``skip_rows`` the
#: lines of preamble above them).
CSV_KEYS = {"header_row": int, "skip_rows": int, "decimal": str, "delimiter": str}


def _parse_input(raw: dict, base: Path, err, *, recording_given: bool = False) -> dict:
    """``[input]`` -> ``recording`` (absolute Path) or ``synthetic`` (a known scenario that
    fits in memory), ``minutes``, ``seed``, ``start``/``stop`` [s]; the reading tables
    ``mcap`` and ``csv`` and ``fs_Hz`` (:data:`READ_KEYS`), which need a ``recording`` unless
    the caller supplies one (``recording_given``)."""
    inp = dict(raw.get("input", {}))
    if "recording" in inp and "synthetic" in inp:
        raise err(["input", "synthetic"], "give either recording or synthetic, not both")
    if "recording" in inp and "minutes" in inp:
        raise err(["input", "minutes"], "minutes sets the length of a synthetic scenario; a "
                  "recording file is read whole, or between start_s and stop_s")
    if "synthetic" in inp:
        for k in ("start_s", "stop_s"):
            if k in inp:
                raise err(["input", k], f"{k} selects a window of a recording file; a synthetic "
                          "scenario is generated from t = 0 for `minutes`")
    if "start_s" in inp and "stop_s" in inp and inp["stop_s"] <= inp["start_s"]:
        raise err(["input", "stop_s"], f"stop_s = {inp['stop_s']:g} s is not after start_s = "
                  f"{inp['start_s']:g} s: the window is empty")
    if "recording" in inp:
        # absolute, not resolved: a symlink loop or an over-long name is reported by the
        # file check below (with the key and line), not raised here
        inp["recording"] = Path(os.path.normpath(os.path.abspath(base / inp["recording"])))
    if "start_s" in inp:
        inp["start"] = inp.pop("start_s")
    if "stop_s" in inp:
        inp["stop"] = inp.pop("stop_s")
    if "mcap" in inp:
        inp["mcap"] = _parse_input_mcap(inp, err, recording_given)
    if "csv" in inp:
        inp["csv"] = _parse_input_csv(inp, err, recording_given)
    if "fs_Hz" in inp:
        _check_input_fs(inp, err, recording_given)
    if "synthetic" in inp:
        known = scenario_names("synthetic")
        if inp["synthetic"] not in known:
            raise err(["input", "synthetic"], f"unknown scenario {inp['synthetic']!r}; known: "
                      f"{', '.join(known) or 'none (no synthetic generator installed)'}")
        _check_synthetic_size(inp, err)
    return inp


def read_options(scene) -> dict:
    """The format options of every read of the scene's recording file
    (:func:`meshphase.io.read`): ``[input.mcap]``'s mapping, ``[input.csv]``'s reader
    options, ``[input] fs_Hz`` as ``fs`` (unless ``[input.mcap] fs_Hz`` gives it), then
    ``input["options"]`` (given beside the scene, e.g. the command line's input options)
    over them."""
    inp = scene.input
    out: dict = {}
    if "fs_Hz" in inp:
        out["fs"] = float(inp["fs_Hz"])
    for table in ("mcap", "csv"):
        out.update(inp.get(table) or {})
    out.update(inp.get("options") or {})
    return out


def with_recording(scene, path, options: dict | None = None) -> dict:
    """The ``[input]`` of ``scene`` reading recording file ``path`` instead of its own: its
    reading keys (:data:`READ_KEYS`: ``[input.mcap]``, ``[input.csv]``, ``fs_Hz``) kept, its
    file and window dropped; ``options`` (format options, e.g. the command line's) over the
    tables'.

    Parameters
    ----------
    scene : Scene
    path : str or Path
        The recording file.
    options : dict, optional
        Format options of :func:`meshphase.io.read` (``topics``, ``fs``, ``header_row`` ...).

    Returns
    -------
    dict
        For ``scene.input``.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    if options is not None and not isinstance(options, dict):
        raise TypeError(f"options must be a dict of format options, got {type(options).__name__}")
    inp = {k: scene.input[k] for k in READ_KEYS if k in scene.input}
    if options:
        inp["options"] = dict(inp.get("options") or {}, **options)
    inp["recording"] = Path(path)
    return inp


def _input_format(path: Path) -> str | None:
    """The format of the scene's recording file by its content; None when it is not (yet)
    a readable regular file (the load stage reports that)."""
    if _file_state(path) != "file":
        return None
    try:
        return io.detect_format(path)
    except (OSError, ValueError):
        return None


def _check_input_fs(inp: dict, err, recording_given: bool = False) -> None:
    """``[input] fs_Hz``: the sample rate of a file that states none (a format whose
    :class:`~meshphase.io.registry.FormatSpec` has ``rate_option``: a TDMS file without
    waveform timing or clock channel, an HDF5 file of another tool, text files without a time
    column ...); only there (``[input.mcap] fs_Hz`` for MCAP written by other tools)."""
    if "recording" not in inp and not recording_given:
        raise err(["input", "fs_Hz"], "fs_Hz is the sample rate of a recording file: give [input] "
                  "recording = \"FILE.tdms\" too")
    if "mcap" in inp:
        raise err(["input", "fs_Hz"], "an MCAP file's rate goes in [input.mcap] fs_Hz")
    fmt = _input_format(inp["recording"]) if "recording" in inp else None
    if fmt is not None and not io.get_spec(fmt).rate_option:
        takers = " or ".join(f.upper() for f in io.FORMATS if io.get_spec(f).rate_option)
        raise err(["input", "fs_Hz"], f"{inp['recording'].name} is a {fmt} file, which gives its own "
                  f"sample rate; fs_Hz is for a {takers} file that states none")


def _parse_input_csv(inp: dict, err, recording_given: bool = False) -> dict:
    """``[input.csv]`` (a delimited-text file: where its header is, its decimal mark and
    delimiter) -> the format options ``header_row``, ``skip_rows``, ``decimal``,
    ``delimiter`` (:data:`CSV_KEYS`); each checked against the recording's format when the
    file is there (a format that does not take an option is named)."""
    if "recording" not in inp and not recording_given:
        raise err(["input", "csv"], "[input.csv] says how to read a delimited-text recording file: "
                  "give [input] recording = \"FILE.csv\" too")
    if "mcap" in inp:
        raise err(["input", "csv"], "[input.csv] and [input.mcap] describe different formats: "
                  "give the one of the recording file")
    out = dict(inp["csv"])      # the schema checked the types, one character for the marks
    if "decimal" in out and out.get("delimiter") == out["decimal"]:
        raise err(["input", "csv", "delimiter"], f"delimiter and decimal are both {out['decimal']!r}: "
                  "the numbers could not be told apart")
    fmt = _input_format(inp["recording"]) if "recording" in inp else None
    if fmt is not None:
        takes = io.get_spec(fmt).read_options
        for key in out:
            if key not in takes:
                raise err(["input", "csv", key], f"{inp['recording'].name} is a {fmt} file, which "
                          f"takes no {key} option (its read options: "
                          f"{', '.join(sorted(takes)) or 'none'})")
    return out


def _parse_input_mcap(inp: dict, err, recording_given: bool = False) -> dict:
    """``[input.mcap]`` (an MCAP file written by another tool) -> the format options of
    :func:`meshphase.io.read`: ``topics`` (the ``[[input.mcap.channels]]`` tables, each
    ``name``, ``topic``, ``field`` and optionally ``kind``, ``units``, ``scale``, ``stamp``,
    ``gear``, ``tooth``, ``face_position_mm``, ``description``), ``fs`` [Hz], ``max_jitter``
    [s], ``stamp``. The mapping is checked here (:func:`meshphase.io.mcap.parse_topics`);
    the file against it when it is read."""
    # the mcap library (lz4, zstandard) behind it: loaded only by a scene that maps an MCAP file
    from ..io.mcap import parse_topics

    if "recording" not in inp and not recording_given:
        raise err(["input", "mcap"], "[input.mcap] maps the topics of an MCAP recording file: "
                  "give [input] recording = \"FILE.mcap\" too")
    fmt = _input_format(inp["recording"]) if "recording" in inp else None
    if fmt not in (None, "mcap"):
        raise err(["input", "mcap"], f"{inp['recording'].name} is a {fmt} file; [input.mcap] maps "
                  "the topics of an MCAP file")
    m = inp["mcap"]
    chans = []
    for c in m.get("channels", []):
        c = dict(c)
        if "face_position_mm" in c:
            c["face_position"] = c.pop("face_position_mm") * 1e-3
        chans.append(c)
    if not chans:
        raise err(["input", "mcap"], "[input.mcap] needs [[input.mcap.channels]] tables (name, "
                  "topic, field): which topic fields are the channels")
    try:
        parse_topics(chans, stamp=m.get("stamp"))
    except (TypeError, ValueError) as exc:
        i = next((k for k, _ in enumerate(chans) if f"topics[{k}]" in str(exc)), None)
        keys = ["input", "mcap", "channels"] + ([i] if i is not None else [])
        raise err(keys, str(exc)) from None
    out = {"topics": chans}
    for key, opt in (("fs_Hz", "fs"), ("max_jitter_s", "max_jitter"), ("stamp", "stamp")):
        if key in m:
            out[opt] = m[key]
    return out


def _parse_tolerances(raw: dict, gearset: Gearset | None, err) -> dict | None:
    """``[tolerances]`` -> bands in SI ([m], [rad] or "uniform"), ``samples``, ``sampler``,
    ``window`` [s], ``seed``; None without the table."""
    if "tolerances" not in raw:
        return None
    t = raw["tolerances"]
    if t.get("samples", 0) > LIMITS["samples_max"]:
        raise err(["tolerances", "samples"], f"{t['samples']:g} Monte Carlo samples is more "
                  f"than {LIMITS['samples_max']:.0e} (the statistics of Ave and Dev settle "
                  "long before: their standard errors fall as 1/sqrt(samples)); use 1e4 .. 1e6")
    tol = {}
    for g in ("sun", "ring", "planet"):
        tol[f"e_{g}"] = t.get(f"e_{g}_mm", 0.0) * 1e-3
        tol[f"mean_e_{g}"] = t.get(f"mean_e_{g}_mm", 0.0) * 1e-3
        k = t.get(f"kappa_{g}_deg", "uniform")
        tol[f"kappa_{g}"] = k if k == "uniform" else math.radians(k)
    tol["samples"] = t.get("samples", 20000)
    tol["sampler"] = t.get("sampler", "sobol")
    tol["window"] = t.get("window_s")
    tol["seed"] = t.get("seed", 0)
    if "seed" in t and (isinstance(t["seed"], bool) or not isinstance(t["seed"], int)
                        or t["seed"] < 0):
        raise err(["tolerances", "seed"], f"seed = {t['seed']!r}: the Monte Carlo's random "
                  "seed is a non-negative integer")
    if gearset is not None:
        for g in ("sun", "ring"):
            reach = sum(tol[f"{p}e_{m}"] for p in ("", "mean_") for m in (g, "planet"))
            if reach >= gearset.carrier_radius:
                k = f"e_{g}_mm" if f"e_{g}_mm" in t else f"mean_e_{g}_mm"
                raise err(["tolerances", k if k in t else "e_planet_mm"],
                          f"the {g} and planet bands reach {reach * 1e3:g} mm (mean + 3-sigma "
                          f"band, both gears), beyond the carrier radius "
                          f"{gearset.carrier_radius * 1e3:g} mm: the offset model needs "
                          "e_" + g + " + e_planet < R_c; are these values in µm?")
    return tol


def _parse_bearing(raw: dict, err, label, text: str) -> dict | None:
    """``[bearing]`` -> ``case``, ``input_torque`` [N·m], ``z_s``/``z_r`` [m], ``c_g``
    [N/m^2], ``k_tilt`` [N·m/rad] list, included-angle sweeps [rad]; None without the table."""
    if "bearing" not in raw:
        return None
    b = raw["bearing"]
    case = _bearing_case(b.get("case", "1"))
    if case is None:
        raise err(["bearing", "case"], f"unknown case {b['case']!r}; known: seed 001 cases "
                  f"{', '.join(sorted(set(_BEARING_CASES.values())))} (also written case1, case2B)")
    lo, hi = LIMITS["c_g"]
    if "c_g_N_per_mm_um" in b and not lo <= b["c_g_N_per_mm_um"] <= hi:
        raise err(["bearing", "c_g_N_per_mm_um"], f"{b['c_g_N_per_mm_um']:g} N/(mm·µm) is outside "
                  f"{lo:g} .. {hi:g} (ISO 6336: 20 by default); the key is in N/(mm·µm), "
                  "not SI (20 N/(mm·µm) = 2e10 N/m^2)")
    torque = b.get("input_torque_Nm")
    if torque is not None and not abs(torque) <= LIMITS["torque_Nm"]:
        raise err(["bearing", "input_torque_Nm"], f"{torque:g} N·m is beyond "
                  f"+-{LIMITS['torque_Nm']:.0e} N·m (the largest wind-turbine gearboxes carry "
                  "~1e7 N·m); the key is in N·m")
    bearing = {"case": case, "input_torque": torque,
               "z_s": b.get("z_s_mm", 0.0) * 1e-3, "z_r": b.get("z_r_mm", 0.0) * 1e-3,
               "c_g": b.get("c_g_N_per_mm_um", 20.0) * 1e9}
    bearing["k_tilt"] = _k_tilt_key(b, err)
    for key, old in (("double_pinion_included_angle_sp_deg", "double_pinion_beta_deg"),
                     ("double_pinion_included_angle_rp_deg", "double_pinion_gamma_deg")):
        given = _renamed_key(b, key, old, err, label, text)
        if given is not None:
            bearing[key.replace("_deg", "")] = [math.radians(v) for v in given]
    return bearing


def _check_block(raw: dict, err) -> None:
    """``[processing] block_s`` long enough for the onset detector's template."""
    block_s = raw.get("processing", {}).get("block_s")
    if isinstance(block_s, (int, float)) and not isinstance(block_s, bool) \
            and not block_s >= LIMITS["block_s_min"]:
        raise err(["processing", "block_s"], f"block_s = {block_s:g} s is shorter than "
                  f"{LIMITS['block_s_min']:g} s: the onset detector learns its template from the "
                  "pulses of one block (default: 2^20 samples)")


def _check_gearset(gearset: Gearset, g: dict, profile_shift: bool, err) -> Gearset:
    """Coaxiality, assembly and planet tip clearance of the scene's gearset (``g``: the
    ``[gearset]`` table as written); returns the gearset with typed planet angles snapped to
    the assemblable ones."""
    zs, zr, zp = gearset.z_sun, gearset.z_ring, gearset.z_planet
    n = gearset.n_planets
    where = "n_planets" if "n_planets" in g else "planet_angles_deg"
    if zp > 0 and not profile_shift:
        d = coaxiality_error(zs, zr, zp)
        if d != 0:
            coax = (f"the coaxial planet has (Z_r - Z_s)/2 = {(zr - zs) // 2} teeth" if (zr - zs) % 2 == 0
                    else f"Z_r - Z_s = {zr - zs} is odd, so no standard planet is coaxial")
            raise err(["gearset", "z_planet"],
                      f"Z_r = {zr} but Z_s + 2 Z_p = {zs} + 2 x {zp} = {zs + 2 * zp}: with standard "
                      f"gears the sun-planet and planet-ring centre distances differ by {abs(d) / 2:g} "
                      f"module(s) ({coax}); if the gears are profile shifted (a centre-distance "
                      "modification), say so with [gearset] profile_shift = true")
    z_sum = zs + zr
    counts = assemblable_planet_counts(zs, zr, zp or None, n_max=max(12, n))
    if where == "n_planets":
        if z_sum % n:
            raise err(["gearset", "n_planets"],
                      f"{n} equally spaced planets cannot be assembled: (Z_s + Z_r)/N = {z_sum}/{n} "
                      f"= {z_sum / n:.4g} is not an integer (Parker & Lin 2004); planet counts that "
                      f"can be{' (tip circles clear)' if zp else ''}: {', '.join(map(str, counts))}")
    else:
        typed = g["planet_angles_deg"]
        chk = assembly_check(gearset, atol=0.0)
        step = 360.0 / z_sum
        res1 = typed_resolution(typed[0])
        for i, a in enumerate(typed):
            tol = min(typed_resolution(a) + res1, step / 4) if i else math.inf
            err_deg = math.degrees(abs(chk.angle_error[i]))
            if err_deg > tol:
                p = int(chk.p[i])
                near = sorted(((q, typed[0] + q * step) for q in (p, p + 1 if chk.angle_error[i] > 0 else p - 1)),
                              key=lambda x: x[0])
                raise err(["gearset", "planet_angles_deg"],
                          f"planet {i + 1} at {a:g} deg cannot be assembled with Z_s + Z_r = {z_sum}: "
                          f"planets sit at whole multiples p of 360/{z_sum} = {step:.6g} deg from planet 1 "
                          f"(Parker & Lin 2004), and {a:g} deg is {err_deg:.3g} deg from the nearest "
                          f"(tolerance {tol:.3g} deg: the precision typed, at most a quarter step); nearest: "
                          + " or ".join(f"{v:.6g} deg (p = {q})" for q, v in near))
        p = np.mod(chk.p, z_sum)
        for i in range(1, n):
            j = np.flatnonzero(p[:i] == p[i])
            if j.size:
                raise err(["gearset", "planet_angles_deg"],
                          f"planets {j[0] + 1} and {i + 1} sit at the same place ({typed[j[0]]:g} and "
                          f"{typed[i]:g} deg)")
        gearset = Gearset(zs, zr, zp, tuple(float(x) for x in chk.nearest_angles), gearset.carrier_radius,
                          direction=gearset.direction, name=gearset.name, face_width=gearset.face_width)
    if zp > 0:
        margin = tip_clearance(zs, zr, zp, gearset.angles)
        if not margin > CLEARANCE_ATOL:
            lhs = (f"(Z_s + Z_p) = {zs + zp}" if zr == zs + 2 * zp else
                   f"(Z_s + Z_r)/2 = {z_sum / 2:g} (profile shifted: the mean centre distance)")
            if where == "n_planets":
                what = (f"{n} equally spaced planets collide: {lhs} x sin(pi/{n}) = "
                        f"{margin + zp + 2:.4g} is not more than the tip diameter Z_p + 2 = {zp + 2} "
                        f"(in modules); at most {max_equal_planets(zs, zr, zp)} fit, and these can "
                        f"be assembled: {', '.join(map(str, counts))}")
            else:
                what = (f"neighbouring planets collide: {lhs} x sin(gap/2) at the smallest gap "
                        f"between planets is {margin + zp + 2:.4g}, not more than the tip diameter "
                        f"Z_p + 2 = {zp + 2} (in modules)")
            raise err(["gearset", where], what)
    return gearset


def _check_channel(c: dict, i: int, gearset: Gearset | None, err) -> None:
    """One ``[[channels]]`` table against the gearset: tooth numbers, face positions, gain,
    a known unit, an encoder's shaft and pulses per revolution."""
    if "gain" in c and c["gain"] == 0:
        raise err(["channels", i, "gain"], "gain 0 would erase the channel; leave the key out "
                  "for gain 1")
    _check_encoder_entry(c, i, err)
    if c.get("kind") in GAUGE_KINDS and isinstance(c.get("units"), str) and parse_unit(c["units"]) is None:
        raise err(["channels", i, "units"], f"unknown unit {c['units']!r} for a {c['kind']} gauge: "
                  "a strain (m/m, µm/m, µε, ue, microstrain, mm/m, %) or a bridge's V, mV or mV/V")
    if gearset is None:
        return
    gear = c.get("gear") or (c.get("kind") if c.get("kind") in ("sun", "ring") else None)
    z = {"sun": gearset.z_sun, "ring": gearset.z_ring, "planet": gearset.z_planet or None}.get(gear)
    if "tooth" in c and z and c["tooth"] >= z:
        raise err(["channels", i, "tooth"], f"the {gear} has {z} teeth, numbered 0 .. {z - 1}; "
                  f"tooth {c['tooth']} does not exist")
    b = gearset.face_width
    if "face_position_mm" in c and b is not None and abs(c["face_position_mm"]) > 0.5 * b * 1e3:
        raise err(["channels", i, "face_position_mm"],
                  f"{c['face_position_mm']:g} mm lies outside the face (face_width_mm = {b * 1e3:g}: "
                  f"positions from the face centre run -{b * 5e2:g} .. +{b * 5e2:g} mm)")


def _check_encoder_entry(c: dict, i: int, err) -> None:
    """An encoder entry names its shaft and pulses per revolution (the schema checks their
    values); the two keys belong to encoder entries only."""
    given = [k for k in ("shaft", "pulses_per_rev") if k in c]
    if c.get("kind") != "encoder":
        if given:
            raise err(["channels", i, given[0]], f"{given[0]} belongs to an encoder channel: "
                      f'give kind = "encoder" (this entry has kind {c.get("kind", "unset")!r})')
        return
    for k in ("shaft", "pulses_per_rev"):
        if k not in c:
            example = 'shaft = "sun"' if k == "shaft" else "pulses_per_rev = 60"
            raise err(["channels", i, "kind"], f"an encoder channel needs {k} (e.g. {example})")
    if isinstance(c["pulses_per_rev"], bool) or not isinstance(c["pulses_per_rev"], int) \
            or c["pulses_per_rev"] < 1:
        raise err(["channels", i, "pulses_per_rev"], "pulses_per_rev must be a positive integer, "
                  f"got {c['pulses_per_rev']!r}")


def _synthetic_config(inp: dict):
    """The synthetic scenario's configuration (no samples generated), or None."""
    if inp.get("config") is not None:
        return inp["config"]
    name = inp.get("synthetic")
    return scenario_config(name, "synthetic") if isinstance(name, str) else None


def _check_synthetic_size(inp: dict, err) -> None:
    """``[input] minutes`` of a synthetic scenario against this machine's memory: the
    recording is generated whole and processed with ~LIMITS["processing_copies"] copies."""
    cfg = _synthetic_config(inp)
    mem = _physical_memory()
    if cfg is None or mem is None:
        return
    duration = 60.0 * inp["minutes"] if "minutes" in inp else cfg.duration
    n_ch = len(cfg.gauges) + (cfg.tacho is not None)
    need = duration * cfg.fs * n_ch * 8.0 * LIMITS["processing_copies"]
    if need > mem:
        fit = mem / (cfg.fs * n_ch * 8.0 * LIMITS["processing_copies"]) / 60.0
        raise err(["input", "minutes" if "minutes" in inp else "synthetic"],
                  f"{duration / 60:g} min of {inp['synthetic']!r} ({cfg.fs:g} Hz x {n_ch} channels) "
                  f"needs about {need / 2**30:.3g} GiB to generate and process (the samples are held "
                  f"in memory, ~{LIMITS['processing_copies']} copies), more than this machine's "
                  f"{mem / 2**30:.3g} GiB; at most about {fit:.3g} min fit (for long synthetic "
                  "files: `meshphase synth`, which writes in blocks)")


def _check_monte_carlo(scene: Scene, err) -> None:
    """Size of the Monte Carlo (realisations x time points x planets) before it runs: refused
    above ``LIMITS["mc_evals_max"]``, a SceneWarning with the run-time estimate above
    ``LIMITS["samples_warn"]`` realisations."""
    # scipy.special (the tolerance model's quantiles, computed at its import): only a Monte
    # Carlo scene loads it
    from ..models.tolerance import default_n_times, observation_window

    t, sp, g = scene.tolerances, scene.speeds, scene.gearset
    if t is None or sp is None or g is None:
        return
    try:
        window = observation_window(sp) if t.get("window") is None else (0.0, float(t["window"]))
        n_times = default_n_times(sp, window)
    except ValueError as exc:
        raise err(["speeds"], f"the Monte Carlo cannot run with these speeds: {exc}") from None
    evals = float(t["samples"]) * n_times * g.n_planets
    key = ["tolerances", "window_s" if t.get("window") is not None else "samples"]
    if evals > LIMITS["mc_evals_max"]:
        raise err(key, f"the Monte Carlo would evaluate {evals:.3g} phasings ({t['samples']} samples "
                  f"x {n_times} time points x {g.n_planets} planets), more than "
                  f"{LIMITS['mc_evals_max']:.0e} (~{evals / _MC_RATE['numba'] / 3600:.3g} h with numba): "
                  "fewer samples, or a window_s of about one revolution of the slowest offset "
                  "(the default)")
    if t["samples"] > LIMITS["samples_warn"]:
        line = _line_of(scene.text, ["tolerances", "samples"])
        where = f"{scene.path or '<scene>'}" + (f", line {line}" if line else "")
        warnings.warn(f"{where}: [tolerances.samples] {t['samples']:g} Monte Carlo samples: "
                      f"{evals:.3g} evaluations, of the order of {evals / _MC_RATE['numba']:.2g} s "
                      "with numba, longer on the numpy path (the standard errors fall only as "
                      "1/sqrt(samples))", SceneWarning, stacklevel=3)


def _source_checks(scene: Scene, fs: float | None, meta_gearset: dict | None, source: str,
                   text: str, label) -> None:
    """The scene against what its recording holds: planet count, filters against Nyquist."""
    raw_g = scene.raw.get("gearset", {})
    if scene.gearset is not None and isinstance(meta_gearset, dict):
        n_rec = len(meta_gearset.get("planet_angles") or ())
        if n_rec and n_rec != scene.gearset.n_planets:
            key = ["gearset", "n_planets" if "n_planets" in raw_g else "planet_angles_deg"]
            zs, zr, zp = (meta_gearset.get(k) for k in ("z_sun", "z_ring", "z_planet"))
            raise SceneError(label, ".".join(key),
                             f"the scene has {scene.gearset.n_planets} planets but {source} was "
                             f"made with {n_rec} (its metadata gearset: Z {zs}/{zr}/{zp}, {n_rec} "
                             "planets)", _line_of(text, key))
    notch = scene.processing.get("notch_hz")
    if fs and notch is not None and notch >= 0.5 * fs:
        raise SceneError(label, "processing.notch_hz",
                         f"notch_hz = {notch:g} Hz is at or above the Nyquist frequency "
                         f"{0.5 * fs:g} Hz of {source} (fs {fs:g} Hz): no such frequency is in "
                         "the samples", _line_of(text, ["processing", "notch_hz"]))


def check_recording(scene: Scene, info=None) -> None:
    """Check a scene against the recording file it reads, from the file's header only.

    Run by :func:`parse_scene` when the scene's results read a recording file that exists and
    whose header reads (a file that does not is the load stage's to report, with its
    position). Checks: the planet count against the recording's metadata gearset (synthetic
    files carry one); ``processing.notch_hz`` below the Nyquist frequency; the
    ``start_s``/``stop_s`` window inside the recording; every ``[[channels]]`` name and the
    ``[tacho] channel`` present, and a gauge channel when measured results are wanted (the
    same rules and messages as the load stage: :func:`meshphase.io.channels.map_channels`,
    :func:`meshphase.io.channels.check_gauges`), each bridge channel's ``null_window_s`` inside
    the recording.

    Parameters
    ----------
    scene : Scene
        With ``input["recording"]`` set.
    info : meshphase.io.RecordingInfo, optional
        The recording's header; read with :func:`meshphase.io.read_info` when None.

    Raises
    ------
    SceneError
        Naming the scene file, the key and its line.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene (meshphase.run.scene.load_scene), got {type(scene).__name__}")
    rec_path = scene.input.get("recording")
    if not rec_path:
        raise ValueError("scene.input has no recording to check against")
    if info is None:
        info = io.read_info(rec_path, **read_options(scene))
    text, label = scene.text, scene.path or "<scene>"
    source = str(rec_path)
    if not (math.isfinite(info.fs) and info.fs > 0):
        return  # a header without a sample rate: the load stage says what is wrong
    _source_checks(scene, info.fs, info.meta.get("gearset"), source, text, label)
    start, stop = scene.input.get("start"), scene.input.get("stop")
    t0, t_end = info.t0, info.t0 + info.duration
    span = f"{source} runs {t0:g} .. {t_end:g} s (fs {info.fs:g} Hz)"
    if start is not None and not start < t_end:
        raise SceneError(label, "input.start_s", f"start_s = {start:g} s is not before the end of "
                         f"the recording: {span}", _line_of(text, ["input", "start_s"]))
    if stop is not None and not stop > t0:
        raise SceneError(label, "input.stop_s", f"stop_s = {stop:g} s is not after the start of "
                         f"the recording: {span}", _line_of(text, ["input", "stop_s"]))
    if start is not None or stop is not None:
        try:
            info.window(start, stop)
        except ValueError as exc:
            key = ["input", "start_s" if start is not None else "stop_s"]
            raise SceneError(label, ".".join(key), f"{exc} (fs {info.fs:g} Hz)",
                             _line_of(text, key)) from None
    tacho = scene.tacho.get("channel")
    if tacho is not None and tacho not in info.names:
        raise SceneError(label, "tacho.channel", f"{source}: tacho channel {tacho!r} is not in the "
                         f"file; channels present: {', '.join(info.names) or 'none'}",
                         _line_of(text, ["tacho", "channel"]))
    empty = Recording(np.empty((0, len(info.channels))), info.fs, info.channels, info.t0,
                      meta=info.meta)
    try:
        mapped = apply_channel_overrides(empty, scene.channels, source)
    except ChannelMapError as exc:
        key = ["channels"] if exc.entry is None else ["channels", exc.entry, exc.key]
        raise SceneError(label, ".".join(map(str, key)), str(exc), _line_of(text, key)) from None
    _check_null_windows(scene, t0, t_end, span)
    _check_regex_teeth(scene, info.names)
    try:
        check_gauges(mapped, plan(scene, check=False), scene.results, source)
    except ValueError as exc:
        key = ["input", "recording"]
        raise SceneError(label, ".".join(key), str(exc), _line_of(text, key)) from None


def _check_regex_teeth(scene: Scene, names) -> None:
    """A tooth number a regex's ``tooth`` group reads from a channel name below its gear's
    tooth count (as a ``tooth`` key is checked when the scene is read)."""
    g = scene.gearset
    if g is None or not any("regex" in c for c in scene.channels):
        return
    for m in map_channels(names, scene.channels).matches:
        c = scene.channels[m.entry]
        gear = c.get("gear") or (c.get("kind") if c.get("kind") in ("sun", "ring") else None)
        z = {"sun": g.z_sun, "ring": g.z_ring, "planet": g.z_planet or None}.get(gear)
        if m.tooth is not None and z and m.tooth >= z:
            key = ["channels", m.entry, "regex"]
            raise SceneError(scene.path or "<scene>", ".".join(map(str, key)),
                             f"channel {m.channel!r} reads as tooth {m.tooth}, but the {gear} has "
                             f"{z} teeth, numbered 0 .. {z - 1}", _line_of(scene.text, key))


def _check_null_windows(scene: Scene, t0: float, t_end: float, span: str) -> None:
    """Each bridge channel's ``null_window_s`` inside the recording [t0, t_end] [s]."""
    for i, c in enumerate(scene.channels):
        w = getattr(c.get("bridge"), "null_window", None)
        if w is not None and not (t0 <= w[0] and w[1] <= t_end):
            key = ["channels", i, "null_window_s"]
            raise SceneError(scene.path or "<scene>", ".".join(map(str, key)),
                             f"null_window_s [{w[0]:g}, {w[1]:g}] s is not inside the "
                             f"recording: {span}", _line_of(scene.text, key))


def _check_consistency(scene: Scene, text: str, label, *, check_files: bool = True,
                       recording_given: bool = False) -> None:
    """Results against what the scene provides: each missing piece names its key.

    ``check_files``: also require the recording file to exist when a stage will read it (at
    load time; :func:`plan` skips it, so a run reports a file gone since as a failed stage).
    ``recording_given``: the caller supplies the recording, ``[input]`` may be absent.
    """
    stages = plan(scene, check=False)
    needs_gearset = set(stages) & gearset_stages()
    if needs_gearset and scene.gearset is None and not scene.input.get("synthetic"):
        raise SceneError(label, "gearset", f"results {scene.results} need a [gearset] table",
                         _line_of(text, ["results"]))
    need_zp = [s for s in _NEEDS_Z_PLANET if s in stages]
    if scene.gearset is not None and scene.gearset.z_planet == 0 and need_zp:
        g = scene.gearset
        hint = (f" (the coaxial value: (Z_r - Z_s)/2 = {(g.z_ring - g.z_sun) // 2})"
                if (g.z_ring - g.z_sun) % 2 == 0 else "")
        raise SceneError(label, "gearset.z_planet",
                         f"results {scene.results} need z_planet{hint}: "
                         + ", ".join(_NEEDS_Z_PLANET[s] for s in need_zp)
                         + " turn at the planet speed w_pc = -(Z_s/Z_p) w_sc",
                         _line_of(text, ["gearset", "z_planet"]))
    if set(stages) & _NEEDS_RECORDING and not scene.has_recording_input and not recording_given:
        raise SceneError(label, "input", f"results {scene.results} need an [input] recording or "
                         "synthetic scenario", _line_of(text, ["results"]))
    rec = scene.input.get("recording")
    state = _file_state(rec) if rec else "file"
    if check_files and set(stages) & _NEEDS_RECORDING and state != "file":
        # checked only when a stage will read it: a bearing scene never opens its recording
        raise SceneError(label, "input.recording", f"{state}: {rec}",
                         _line_of(text, ["input", "recording"]))
    if set(stages) & _NEEDS_RECORDING and not rec and scene.input.get("synthetic"):
        cfg = _synthetic_config(scene.input)
        if cfg is not None:
            _source_checks(scene, cfg.fs, cfg.gearset.to_dict(),
                           f"the synthetic scenario {scene.input['synthetic']!r}", text, label)
    if "tolerance" in stages and scene.tolerances is None:
        raise SceneError(label, "tolerances", "result 'tolerance' needs a [tolerances] table",
                         _line_of(text, ["results"]))
    if ("tolerance" in stages or "ideal" in stages) and scene.tolerances is not None \
            and scene.speeds is None and "tolerance" in stages:
        raise SceneError(label, "speeds", "the Monte Carlo needs nominal [speeds] (sun_rpm, carrier_rpm)",
                         _line_of(text, ["tolerances"]))
    if {"bearing_moments", "tilt"} & set(stages) and scene.bearing is None:
        raise SceneError(label, "bearing", "bearing results need a [bearing] table",
                         _line_of(text, ["results"]))
    if "tilt" in stages and not (scene.bearing or {}).get("k_tilt"):
        raise SceneError(label, "bearing.k_tilt_Nm_per_rad", "result 'tilt' needs k_tilt_Nm_per_rad "
                         "(or k_tilt_Nmm_per_rad, in the bearing catalogues' N·mm/rad)",
                         _line_of(text, ["bearing"]))


def _k_tilt_key(b: dict, err):
    """[bearing] tilting stiffness list [N·m/rad] from k_tilt_Nm_per_rad or, in the bearing
    catalogues' unit, k_tilt_Nmm_per_rad [N·mm/rad] (x 1e-3); None when neither is given."""
    if "k_tilt_Nm_per_rad" in b and "k_tilt_Nmm_per_rad" in b:
        raise err(["bearing", "k_tilt_Nmm_per_rad"], "give k_tilt_Nm_per_rad [N·m/rad] or "
                  "k_tilt_Nmm_per_rad [N·mm/rad], not both")
    scale = 1e-3 if "k_tilt_Nmm_per_rad" in b else 1.0
    k = b.get("k_tilt_Nmm_per_rad", b.get("k_tilt_Nm_per_rad"))
    if k is None:
        return None
    return [k * scale] if isinstance(k, (int, float)) else [v * scale for v in k]


def _renamed_key(b: dict, key: str, old: str, err, label, text):
    """[bearing] value under its new key, or its old key (with a DeprecatedNameWarning)."""
    if old not in b:
        return b.get(key)
    if key in b:
        raise err(["bearing", old], f"{old} is the old name of {key}; give only {key}")
    line = _line_of(text, ["bearing", old])
    warnings.warn(f"{label}" + (f", line {line}" if line else "") + f": [bearing] {old} is "
                  f"renamed {key} (same values, deg); the old key will be removed",
                  DeprecatedNameWarning, stacklevel=4)
    return b[old]


def plan(scene: Scene, *, check: bool = True) -> list[str]:
    """The stages the scene's results need, dependencies first, nothing more.

    ``compare`` pulls in ``tolerance`` only when the scene has tolerances (for band coverage)
    and ``identify`` always (the error model fitted to the measured passes); ``bearing_moments``
    pulls in ``centroids`` only when centroids are also requested (measured moments).
    """
    want: list[str] = []
    for r in scene.results:
        want.extend(RESULTS[r])
    if "compare" in want:
        # compare reads identify (the fitted model) and tolerance (the band) when present, so
        # they must run before it: move them ahead of compare, never after
        mc = scene.tolerances is not None or "tolerance" in want
        extra = ["identify"] + (["tolerance"] if mc else [])
        want = [s for s in want if s not in extra]
        i = want.index("compare")
        want[i:i] = extra
    order: list[str] = []

    def visit(s: str):
        for d in STAGES[s]:
            visit(d)
        if s not in order:
            order.append(s)

    for s in want:
        visit(s)
    if check:
        _check_consistency(scene, scene.text, scene.path or "<scene>", check_files=False)
    return order
