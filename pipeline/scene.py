"""Scenes: a TOML file -> a typed, SI-unit config -> the stages its results need.

A scene names the gearset, the gauges, the inputs (a recording file or a synthetic
scenario), the tolerances and the results wanted (``data_schemas/scene.schema.json``,
documented in ``data_schemas/scene.md``). It is validated up front; errors name the key and
the line of the scene file. :func:`plan` turns the requested results into the ordered list of
stages that must run, and nothing else: a bearing-moment scene opens no recording, a scene
without tolerances runs no Monte Carlo, a scene without face-width gauges does no centroid
work. The stages themselves live in :mod:`pipeline.stages`.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .models.gearset import Gearset, Speeds, rpm_to_rad_s

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "plan", "STAGES", "RESULTS"]

#: stage -> the stages it needs (a DAG; flows one way, as in DESIGN.md)
STAGES: dict[str, tuple[str, ...]] = {
    "load": (),
    "condition": ("load",),
    "onsets": ("condition",),
    "phasing": ("onsets",),
    "load_sharing": ("onsets",),
    "centroids": ("onsets",),
    "ideal": (),
    "tolerance": (),
    "identify": ("phasing",),
    "compare": ("phasing", "ideal"),
    "bearing_moments": (),
    "tilt": (),
}

#: result name -> stages that produce it
RESULTS: dict[str, tuple[str, ...]] = {
    "ideal_phasing": ("ideal",),
    "phasing": ("phasing",),
    "load_sharing": ("load_sharing",),
    "centroids": ("centroids",),
    "compare": ("compare",),
    "identify": ("identify",),
    "tolerance": ("tolerance",),
    "bearing_moments": ("bearing_moments",),
    "tilt": ("tilt",),
}

_NEEDS_RECORDING = {"load"}


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
        Gauge-to-channel overrides (``name``, ``kind``, ``tooth``, ``face_position`` [m], ``gain``).
    input : dict
        ``recording`` (Path) or ``synthetic`` (scenario name) with ``minutes``, ``seed``,
        ``start``/``stop`` [s].
    processing : dict
    tolerances : dict or None
        Bands in SI ([m], [rad] or "uniform"), ``samples``, ``sampler``, ``window`` [s], ``seed``.
    bearing : dict or None
        ``case``, ``input_torque`` [N·m], ``z_s``/``z_r`` [m], ``k_tilt`` [N·m/rad] list,
        ``c_g`` [N/m^2], double-pinion angle sweeps [rad].
    output : Path or None
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

    @property
    def has_recording_input(self) -> bool:
        return bool(self.input.get("recording") or self.input.get("synthetic"))


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


#: seed 001 bearing cases (:func:`pipeline.models.bearing.seed_case`) and the spellings accepted
_BEARING_CASES = {"1": "1", "2a": "2-A", "2b": "2-B"}


def _bearing_case(name) -> str | None:
    """Canonical seed 001 case name ("1", "2-A", "2-B") of ``name``, or None if unknown.

    Accepts the seed's labels and the usual spellings: "1", "case1", "Case 1", "2-B", "2B",
    "case2B", "case 2-B".
    """
    key = re.sub(r"[\s_\-]", "", str(name).lower())
    key = key[4:] if key.startswith("case") else key
    return _BEARING_CASES.get(key)


def load_scene(path) -> Scene:
    """Read and validate a scene TOML file.

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
    text = path.read_text(encoding="utf-8")
    return parse_scene(text, path)


def parse_scene(text: str, path: Path | str | None = None) -> Scene:
    """Validate scene TOML ``text`` (``path`` only labels errors and anchors relative paths)."""
    label = path if path is not None else "<scene>"
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        line = int(m.group(1)) if m else None
        if line is None and "end of document" in str(exc):
            line = max(1, len(text.splitlines()))
        raise SceneError(label, "", f"TOML syntax error: {exc}", line) from None
    from data_schemas import load_schema

    import jsonschema

    validator = jsonschema.Draft202012Validator(load_schema("scene"))
    errors = sorted(validator.iter_errors(raw), key=lambda e: [str(k) for k in e.absolute_path])
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
        more = f" (and {len(errors) - 1} more problem(s))" if len(errors) > 1 else ""
        raise SceneError(label, key, msg + more, _line_of(text, keys))
    base = Path(path).resolve().parent if path is not None else Path.cwd()

    def err(keys, problem):
        return SceneError(label, ".".join(keys), problem, _line_of(text, keys))

    results = list(raw.get("results", []))
    gearset = None
    if "gearset" in raw:
        g = raw["gearset"]
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
    speeds = None
    resolution = None
    if "speeds" in raw and gearset is not None:
        from .angles import typed_resolution

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
        if "sun" in conv and "carrier" in conv:
            w_s, w_c = conv["sun"], conv["carrier"]
            if "planet" in conv or gearset.z_planet == 0:
                speeds = Speeds(w_s, w_c, conv.get("planet", 0.0), conv.get("ring", 0.0))
            else:
                speeds = Speeds.kinematic(gearset, w_s, w_c)
                # nominal speeds are typed rounded (the seed's ring: -3.862 r/min): 0.1 % slack
                scale = max(abs(w_s), abs(w_c), abs(speeds.ring))
                if "ring" in conv and abs(speeds.ring - conv["ring"]) > 1e-3 * scale:
                    raise err(["speeds", "ring_rpm" if "ring_rpm" in s else "ring_rad_s"],
                              f"ring speed {conv['ring']:.6g} rad/s is not consistent with sun/carrier "
                              f"and the tooth counts (kinematics give {speeds.ring:.6g} rad/s)")
        elif any(k != "fixed" for k in s):
            raise err(["speeds"], "give both the sun and the carrier speed")
    fixed = raw.get("speeds", {}).get("fixed")
    channels = []
    mounts = {}
    for i, c in enumerate(raw.get("channels", [])):
        d = {k: v for k, v in c.items() if k not in ("face_position_mm", "mount_angle_deg")}
        if "face_position_mm" in c:
            d["face_position"] = c["face_position_mm"] * 1e-3
        if "mount_angle_deg" in c:
            mounts[c["name"]] = math.radians(c["mount_angle_deg"])
        channels.append(d)
    tacho = {}
    if "tacho" in raw:
        if "key_angle_deg" in raw["tacho"]:
            tacho["key_angle"] = math.radians(raw["tacho"]["key_angle_deg"])
        if "channel" in raw["tacho"]:
            tacho["channel"] = raw["tacho"]["channel"]
    inp = dict(raw.get("input", {}))
    if "recording" in inp and "synthetic" in inp:
        raise err(["input", "synthetic"], "give either recording or synthetic, not both")
    if "recording" in inp:
        inp["recording"] = (base / inp["recording"]).resolve()
    if "start_s" in inp:
        inp["start"] = inp.pop("start_s")
    if "stop_s" in inp:
        inp["stop"] = inp.pop("stop_s")
    if "synthetic" in inp:
        from synthetic.scenarios import SCENARIOS

        if inp["synthetic"] not in SCENARIOS:
            raise err(["input", "synthetic"], f"unknown scenario {inp['synthetic']!r}; known: "
                      f"{', '.join(sorted(SCENARIOS))}")
    tol = None
    if "tolerances" in raw:
        t = raw["tolerances"]
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
    bearing = None
    if "bearing" in raw:
        b = raw["bearing"]
        case = _bearing_case(b.get("case", "1"))
        if case is None:
            raise err(["bearing", "case"], f"unknown case {b['case']!r}; known: seed 001 cases "
                      f"{', '.join(sorted(set(_BEARING_CASES.values())))} (also written case1, case2B)")
        bearing = {"case": case, "input_torque": b.get("input_torque_Nm"),
                   "z_s": b.get("z_s_mm", 0.0) * 1e-3, "z_r": b.get("z_r_mm", 0.0) * 1e-3,
                   "c_g": b.get("c_g_N_per_mm_um", 20.0) * 1e9}
        k = b.get("k_tilt_Nm_per_rad")
        bearing["k_tilt"] = None if k is None else ([k] if isinstance(k, (int, float)) else list(k))
        for key in ("double_pinion_beta_deg", "double_pinion_gamma_deg"):
            if key in b:
                bearing[key.replace("_deg", "")] = [math.radians(v) for v in b[key]]
    scene = Scene(
        path=Path(path) if path is not None else None,
        name=raw.get("name", Path(path).stem if path is not None else "scene"),
        results=results, gearset=gearset, speeds=speeds, channels=channels, input=inp,
        processing=dict(raw.get("processing", {})), tolerances=tol, bearing=bearing,
        output=(base / raw["output"]) if "output" in raw else None, raw=raw,
        speeds_resolution=resolution or None, fixed=fixed, tacho=tacho, mounts=mounts)
    _check_consistency(scene, text, label)
    return scene


def _check_consistency(scene: Scene, text: str, label, *, check_files: bool = True) -> None:
    """Results against what the scene provides: each missing piece names its key.

    ``check_files``: also require the recording file to exist when a stage will read it (at
    load time; :func:`plan` skips it, so a run reports a file gone since as a failed stage).
    """
    stages = plan(scene, check=False)
    needs_gearset = set(stages) & {"onsets", "phasing", "load_sharing", "ideal", "tolerance",
                                   "identify", "compare"}
    if needs_gearset and scene.gearset is None and not scene.input.get("synthetic"):
        raise SceneError(label, "gearset", f"results {scene.results} need a [gearset] table",
                         _line_of(text, ["results"]))
    if set(stages) & _NEEDS_RECORDING and not scene.has_recording_input:
        raise SceneError(label, "input", f"results {scene.results} need an [input] recording or "
                         "synthetic scenario", _line_of(text, ["results"]))
    rec = scene.input.get("recording")
    if check_files and set(stages) & _NEEDS_RECORDING and rec and not Path(rec).is_file():
        # checked only when a stage will read it: a bearing scene never opens its recording
        what = ("not a regular file (a folder, FIFO or device)" if Path(rec).exists()
                else "no such recording file")
        raise SceneError(label, "input.recording", f"{what}: {rec}",
                         _line_of(text, ["input", "recording"]))
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
        raise SceneError(label, "bearing.k_tilt_Nm_per_rad", "result 'tilt' needs k_tilt_Nm_per_rad",
                         _line_of(text, ["bearing"]))


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
        _check_consistency(scene, "", scene.path or "<scene>", check_files=False)
    return order
