"""The scene :func:`meshphase.process` runs, from what a notebook user has at hand.

The gearset comes as a scene TOML path (what ``meshphase process --gearset`` takes), a dict
(a scene's ``[gearset]`` table in its engineering units, ``carrier_radius_mm`` ...; a
:meth:`~meshphase.models.gearset.Gearset.to_dict` dict in SI; or a whole scene with a
``gearset`` key), a :class:`~meshphase.models.gearset.Gearset`, or, when none is given, the
recording's own metadata (synthetic recordings carry one). Every form but a ready
:class:`~meshphase.run.scene.Scene` goes through :func:`meshphase.run.scene.parse_scene`, so a dict is
checked exactly as a scene file is (coaxiality, assembly, ranges; errors name the key).
"""

from __future__ import annotations

import copy
import json
import math
import os
from collections.abc import Mapping

from ..models.gearset import Gearset
from ..run.scene import RESULTS, Scene, load_scene, parse_scene
from ..run.stages import PROCESS_RESULTS

__all__ = ["build_scene", "toml_text", "gearset_table"]

#: a scene built here asks only for a result that needs no recording until the input is set
_PLACEHOLDER_RESULTS = ["ideal_phasing"]

_GEARSET_SI_KEYS = {"z_sun", "z_ring", "z_planet", "planet_angles", "carrier_radius",
                    "direction", "name", "face_width"}


def _toml_value(v, key: str) -> str:
    """One TOML value: bool, int, float, str, a list of them, or an inline table."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(int(v))
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return repr(float(v)) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)   # JSON's escapes are TOML basic-string escapes
    if isinstance(v, os.PathLike):
        return json.dumps(os.fspath(v), ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x, key) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x, k)}" for k, x in v.items()) + "}"
    if hasattr(v, "item") and getattr(v, "ndim", None) == 0:      # numpy scalars
        return _toml_value(v.item(), key)
    raise TypeError(f"scene value {key!r}: cannot be written as TOML: {type(v).__name__} {v!r}")


def _toml_key(k) -> str:
    if not isinstance(k, str) or not k:
        raise TypeError(f"scene keys must be non-empty strings, got {k!r}")
    return k if all(c.isalnum() or c in "_-" for c in k) else json.dumps(k)


def toml_text(scene: Mapping) -> str:
    """A scene given as a dict, as TOML text (:func:`meshphase.run.scene.parse_scene` reads it).

    Parameters
    ----------
    scene : mapping
        Top-level keys with scalars or lists, tables as dicts, arrays of tables as lists of
        dicts (``channels``); deeper dicts become inline tables.

    Returns
    -------
    str
    """
    if not isinstance(scene, Mapping):
        raise TypeError(f"scene must be a dict, got {type(scene).__name__}")
    head, tables = [], []
    for k, v in scene.items():
        if isinstance(v, Mapping):
            body = [f"{_toml_key(kk)} = {_toml_value(vv, kk)}" for kk, vv in v.items()]
            tables.append("\n".join([f"[{_toml_key(k)}]", *body]))
        elif isinstance(v, (list, tuple)) and v and all(isinstance(x, Mapping) for x in v):
            for row in v:
                body = [f"{_toml_key(kk)} = {_toml_value(vv, kk)}" for kk, vv in row.items()]
                tables.append("\n".join([f"[[{_toml_key(k)}]]", *body]))
        else:
            head.append(f"{_toml_key(k)} = {_toml_value(v, k)}")
    return "\n\n".join(["\n".join(head), *tables]) + "\n"


def gearset_table(g: Gearset) -> dict:
    """A :class:`Gearset` as a scene's ``[gearset]`` table (mm, deg).

    Equally spaced planets are written as ``n_planets``, others as ``planet_angles_deg``;
    a gearset whose teeth are not coaxial for standard gears (Z_r != Z_s + 2 Z_p) is marked
    ``profile_shift = true``: a Gearset object is taken as built on purpose.
    """
    if not isinstance(g, Gearset):
        raise TypeError(f"g must be a Gearset, got {type(g).__name__}")
    n = g.n_planets
    equal = all(abs(((a - 2 * math.pi * k / n) + math.pi) % (2 * math.pi) - math.pi) < 1e-9
                for k, a in enumerate(g.angles))
    t: dict = {"z_sun": g.z_sun, "z_ring": g.z_ring}
    if g.z_planet:
        t["z_planet"] = g.z_planet
    if equal:
        t["n_planets"] = n
    else:
        t["planet_angles_deg"] = [math.degrees(a) for a in g.angles]
    t["carrier_radius_mm"] = g.carrier_radius * 1e3
    if g.face_width:
        t["face_width_mm"] = g.face_width * 1e3
    t["direction"] = g.direction
    if g.name:
        t["name"] = g.name
    if g.z_planet and g.z_ring != g.z_sun + 2 * g.z_planet:
        t["profile_shift"] = True
    return t


def _scene_of_gearset(gearset, label: str) -> Scene:
    """The scene of a ``gearset=`` argument (see the module docstring)."""
    if isinstance(gearset, (str, os.PathLike)):
        return load_scene(gearset, recording_given=True)  # the recording replaces [input]
    if isinstance(gearset, Gearset):
        table = gearset_table(gearset)
    elif isinstance(gearset, Mapping):
        if "gearset" in gearset:
            return _scene_of_dict(gearset, label)
        table = (gearset_table(Gearset.from_dict(gearset))
                 if set(gearset) <= _GEARSET_SI_KEYS and "carrier_radius" in gearset
                 else dict(gearset))
    else:
        raise TypeError("gearset must be a scene TOML path, a dict (a scene's [gearset] table, "
                        "Gearset.to_dict() or a whole scene) or a meshphase.models.Gearset, got "
                        f"{type(gearset).__name__}")
    return _scene_of_dict({"name": table.get("name") or label, "results": _PLACEHOLDER_RESULTS,
                           "gearset": table}, label)


def _scene_of_dict(d: Mapping, label: str) -> Scene:
    d = dict(d)
    d.setdefault("results", _PLACEHOLDER_RESULTS)
    return parse_scene(toml_text(d), None, recording_given=True)


def _scene_of_scene(scene, label: str) -> Scene:
    """The scene of a ``scene=`` argument: a Scene (copied), a TOML path or a dict."""
    if isinstance(scene, Scene):
        out = copy.copy(scene)
        out.input, out.results = dict(scene.input), list(scene.results)
        return out
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene, recording_given=True)  # the recording replaces [input]
    if isinstance(scene, Mapping):
        return _scene_of_dict(scene, label)
    raise TypeError(f"scene must be a meshphase.run.scene.Scene, a scene TOML path or a dict, got "
                    f"{type(scene).__name__}")


def _results(scene: Scene, results, tolerance: bool = False) -> list[str]:
    """The results to compute: ``results`` as given, else what ``meshphase process``
    computes (:data:`meshphase.run.stages.PROCESS_RESULTS`, plus centroids when the scene asks);
    the Monte Carlo only when ``tolerance`` (or ``results`` names it)."""
    if results is None:
        want = list(PROCESS_RESULTS) + (["centroids"] if "centroids" in scene.results else [])
        return want + (["tolerance"] if tolerance else [])
    if isinstance(results, str):
        results = [results]
    if not isinstance(results, (list, tuple)) or not all(isinstance(r, str) for r in results):
        raise TypeError(f"results must be a list of result names, got {results!r}")
    if not results:
        raise ValueError(f"results is empty; choose from {', '.join(RESULTS)}")
    unknown = [r for r in results if r not in RESULTS]
    if unknown:
        raise ValueError(f"unknown result(s) {', '.join(map(repr, unknown))}; choose from "
                         f"{', '.join(RESULTS)}")
    return list(dict.fromkeys(list(results) + (["tolerance"] if tolerance else [])))


def build_scene(gearset=None, scene=None, results=None, *, meta_gearset=None,
                label: str = "meshphase.process", tolerance: bool = False) -> Scene:
    """The validated scene a :func:`meshphase.process` call runs (its input is set later).

    Parameters
    ----------
    gearset : str, Path, dict or Gearset, optional
        See the module docstring.
    scene : Scene, str, Path or dict, optional
        A whole scene (tolerances, speeds, channel mapping ...); not together with ``gearset``.
    results : sequence of str, optional
        Results to compute (:data:`meshphase.run.scene.RESULTS`); default those of
        ``meshphase process`` (:data:`meshphase.run.stages.PROCESS_RESULTS`, plus centroids when
        the scene asks for them).
    meta_gearset : callable, optional
        Returns the recording's metadata gearset (a :meth:`Gearset.to_dict` dict) or None;
        asked only when neither argument gives a gearset.
    label : str
        Names the scene in messages.
    tolerance : bool
        Run the scene's Monte Carlo (``[tolerances]``) and compare against its band, as
        ``meshphase process --tolerance``; without it the tolerances are set aside.

    Returns
    -------
    Scene

    Raises
    ------
    TypeError
        An argument of the wrong type, or both ``gearset`` and ``scene``.
    ValueError
        No gearset anywhere; unknown results; a SceneError (a ValueError) for a gearset or
        scene that does not validate.
    """
    if gearset is not None and scene is not None:
        raise TypeError("give gearset= or scene=, not both (a scene's [gearset] table is its "
                        "gearset)")
    if scene is not None:
        sc = _scene_of_scene(scene, label)
    elif gearset is not None:
        sc = _scene_of_gearset(gearset, label)
    else:
        meta = meta_gearset() if meta_gearset is not None else None
        if not meta:
            raise ValueError("meshphase.process needs a gearset: pass gearset= (a scene TOML "
                             "path, a dict like a scene's [gearset] table, or a "
                             "meshphase.models.Gearset) or scene=; this recording's metadata "
                             "carries none")
        sc = _scene_of_gearset(Gearset.from_dict(meta), label)
    if sc.gearset is None:
        meta = meta_gearset() if meta_gearset is not None else None
        if not meta:
            raise ValueError(f"{sc.path or label}: the scene has no [gearset] table and the "
                             "recording's metadata carries none; meshphase.process needs one")
        sc.gearset = Gearset.from_dict(meta)
    sc.results = _results(sc, results, tolerance)
    if "tolerance" not in sc.results:
        sc.tolerances = None         # the plan would pull the Monte Carlo in for compare's band
    elif sc.tolerances is None:
        raise ValueError(f"{sc.path or label}: tolerance needs a [tolerances] table in the scene")
    return sc
