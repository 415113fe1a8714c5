"""File layouts and config shapes of meshphase, as JSON Schema plus short docs.

Every ``<name>.schema.json`` next to this file is a JSON Schema (draft 2020-12). Schemas may
refer to each other by file name (``{"$ref": "channel_spec.schema.json"}``): all of them are
registered under ``https://meshphase.invalid/schemas/<file name>`` (a base that is never
fetched), or under their own ``$id`` when they set one.

>>> from meshphase.data_schemas import load_schema, validate
>>> validate({"name": "sun_1", "kind": "sun"}, "channel_spec")

Functions
---------
load_schema(name) -> dict
    The parsed schema (a fresh copy).
validate(instance, name, *, where=None) -> None
    ValueError naming the schema file and the offending key when ``instance`` does not match.
schema_names() -> list of str
    Names of the schemas available here.
"""

from __future__ import annotations

import copy
import functools
import json
from pathlib import Path
from typing import Any

__all__ = ["load_schema", "validate", "schema_errors", "schema_names", "SCHEMA_DIR", "BASE_URI"]

#: Directory holding the ``*.schema.json`` files.
SCHEMA_DIR = Path(__file__).resolve().parent
#: Base URI under which schemas are registered (never fetched).
BASE_URI = "https://meshphase.invalid/schemas/"
_SUFFIX = ".schema.json"


def schema_names() -> list[str]:
    """Names (without ``.schema.json``) of the schemas in :data:`SCHEMA_DIR`, sorted."""
    return sorted(p.name[: -len(_SUFFIX)] for p in SCHEMA_DIR.glob(f"*{_SUFFIX}"))


def _file_name(name: str) -> str:
    if not isinstance(name, str):
        raise TypeError(f"schema name must be a string, got {type(name).__name__} {name!r}")
    base = name[: -len(_SUFFIX)] if name.endswith(_SUFFIX) else name
    if not base or "/" in base or "\\" in base or base.startswith("."):
        raise ValueError(f"schema name must be a plain name like 'channel_spec', got {name!r}")
    return base + _SUFFIX


@functools.lru_cache(maxsize=None)
def _load(file_name: str) -> dict:
    path = SCHEMA_DIR / file_name
    if not path.is_file():
        raise ValueError(f"no schema {file_name!r} in {SCHEMA_DIR}; available: {', '.join(schema_names())}")
    try:
        schema = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"schema file {path}: not valid JSON: {exc}") from exc
    if not isinstance(schema, dict):
        raise ValueError(f"schema file {path}: top level must be a JSON object, got {type(schema).__name__}")
    return schema


def load_schema(name: str) -> dict:
    """The JSON Schema ``name`` (e.g. ``"hdf5_layout"`` or ``"hdf5_layout.schema.json"``).

    Parameters
    ----------
    name : str
        Schema name, with or without the ``.schema.json`` suffix.

    Returns
    -------
    dict
        A deep copy of the parsed schema (safe to modify).

    Raises
    ------
    ValueError
        When no such schema exists or its file is not valid JSON.
    """
    return copy.deepcopy(_load(_file_name(name)))


@functools.lru_cache(maxsize=1)
def _registry():
    from referencing import Registry, Resource
    from referencing.jsonschema import DRAFT202012

    resources = []
    for n in schema_names():
        fname = n + _SUFFIX
        try:
            schema = _load(fname)
        except ValueError:
            continue  # a broken neighbour is reported when it is itself used, not here
        res = Resource.from_contents(schema, default_specification=DRAFT202012)
        resources.append((BASE_URI + fname, res))
        if isinstance(schema.get("$id"), str) and schema["$id"] != BASE_URI + fname:
            resources.append((schema["$id"], res))
    return Registry().with_resources(resources)


@functools.lru_cache(maxsize=None)
def _validator(file_name: str):
    from jsonschema import Draft202012Validator
    from jsonschema.exceptions import SchemaError
    from jsonschema.validators import validator_for

    schema = _load(file_name)
    cls = validator_for(schema, default=Draft202012Validator)
    try:
        cls.check_schema(schema)
    except SchemaError as exc:
        raise ValueError(f"schema file {SCHEMA_DIR / file_name}: not a valid JSON Schema: "
                         f"{exc.message}") from exc
    if "$id" not in schema:
        schema = dict(schema, **{"$id": BASE_URI + file_name})
    return cls(schema, registry=_registry())


def _pointer(path) -> str:
    parts = [str(p).replace("~", "~0").replace("/", "~1") for p in path]
    return "/" + "/".join(parts) if parts else "(top level)"


def schema_errors(instance: Any, name: str) -> list:
    """Every place where ``instance`` breaks the schema ``name``, from the validator kept for
    it (built and checked on first use).

    Parameters
    ----------
    instance : JSON-like
    name : str
        Schema name, with or without ``.schema.json``.

    Returns
    -------
    list of jsonschema.ValidationError
        In the validator's order; empty when ``instance`` matches.

    Raises
    ------
    ValueError
        The schema is missing or invalid.
    """
    return list(_validator(_file_name(name)).iter_errors(instance))


def validate(instance: Any, name: str, *, where: str | None = None) -> None:
    """Check ``instance`` against the schema ``name``.

    Parameters
    ----------
    instance : JSON-like
        Plain dicts, lists, str, int, float, bool, None.
    name : str
        Schema name, with or without ``.schema.json``.
    where : str, optional
        What is being checked (a file path, a config key), put at the start of the message.

    Raises
    ------
    ValueError
        ``"<where>: does not match <file>: at <json pointer>: <problem>"`` for the most relevant
        violation; also when the schema itself is missing or invalid.
    """
    from jsonschema.exceptions import best_match

    fname = _file_name(name)
    validator = _validator(fname)
    error = best_match(validator.iter_errors(instance))
    if error is None:
        return
    prefix = f"{where}: " if where else ""
    raise ValueError(f"{prefix}does not match {fname}: at {_pointer(error.absolute_path)}: {error.message}")
