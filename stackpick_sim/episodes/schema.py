"""The one place where records become JSON lines and JSON lines become typed records.

:func:`record_to_json` writes a line of ``results.jsonl``; :func:`record_from_json` reads one
back, checking it against the schema (the fields of
:class:`~stackpick_sim.episodes.record.EpisodeRecord` or
:class:`~stackpick_sim.episodes.record.SceneErrorRecord`, their types and the rules between
them). Anything else raises :class:`RecordError`, whose message names the class of the
problem (the same message for every record with that problem, so that they can be counted).
The field types come from the dataclasses' annotations: a field added there is read and
checked without a change here.
"""

from __future__ import annotations

import json
import types
from dataclasses import MISSING, fields
from functools import cache
from typing import Any, Union, get_args, get_origin, get_type_hints

from stackpick_sim.episodes.record import (
    FAILURES,
    PHASES,
    RUNNER_FAILURES,
    SCHEMA_VERSION,
    EpisodeRecord,
    PoseErrors,
    Record,
    SceneErrorRecord,
)
from stackpick_sim.exceptions import StackpickError

#: Fields an episode record must have even though the dataclass gives them a default.
REQUIRED_OUTCOME = ("success", "failure")
#: Keys of a serialised PoseErrors: the two poses and the errors derived from them.
POSE_KEYS = frozenset({"estimated", "actual", "center_error_px", "theta_x_error_deg",
                       "theta_y_error_deg"})


class RecordError(StackpickError):
    """A JSON value is not a record of the schema; the message names the class of problem."""


class NotJSONError(RecordError):
    """A line that is not JSON at all (a damaged file rather than an edited record)."""


class NewerSchemaError(RecordError):
    """A record written by a newer stackpick-sim (a higher ``schema_version``)."""


def record_to_json(record: Record) -> str:
    """One line of ``results.jsonl`` (no newline): sorted keys, as every reader expects."""
    return json.dumps(record.as_dict(), sort_keys=True)


def record_from_json(line: str | bytes) -> Record:
    """The record on one line of ``results.jsonl``; RecordError if it is not one (including
    text that is not JSON)."""
    try:
        data = json.loads(line)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise NotJSONError(f"not JSON: {type(exc).__name__}") from None
    return record_from_dict(data)


def record_from_dict(data: object) -> Record:
    """The typed record of a decoded JSON value; RecordError if it breaks the schema."""
    if not isinstance(data, dict):
        raise RecordError(f"not a JSON object but {_kind(data)}")
    version = data.get("schema_version", 1)
    if not _is_int(version) or version < 1:
        raise RecordError("field 'schema_version' is not an integer >= 1")
    if version > SCHEMA_VERSION:
        raise NewerSchemaError(f"schema_version {version} is newer than this stackpick-sim's "
                               f"{SCHEMA_VERSION}")
    if "error" in data:
        return SceneErrorRecord(**_fields(SceneErrorRecord, data, ()))
    record = EpisodeRecord(**_fields(EpisodeRecord, data, REQUIRED_OUTCOME))
    _check_outcome(record)
    return record


def _fields(cls: type, data: dict[str, Any], required: tuple[str, ...]) -> dict[str, Any]:
    """The keyword arguments of ``cls`` from ``data``: every key known, typed, none missing
    unless it has a default (and is not in ``required``)."""
    hints = _hints(cls)
    unknown = sorted(set(data) - set(hints))
    if unknown:
        raise RecordError(f"unknown field {unknown[0]!r}")
    out: dict[str, Any] = {}
    for f in fields(cls):
        if f.name not in data:
            if f.name in required or (f.default is MISSING and f.default_factory is MISSING):
                raise RecordError(f"missing field {f.name!r}")
            continue
        out[f.name] = _typed(data[f.name], hints[f.name], f.name)
    if out["seed"] < 0:
        raise RecordError("field 'seed' is negative")
    return out


@cache
def _hints(cls: type) -> dict[str, Any]:
    return get_type_hints(cls)


def _check_outcome(record: EpisodeRecord) -> None:
    if record.failure is not None and record.failure not in (*FAILURES, *RUNNER_FAILURES):
        raise RecordError("field 'failure' is not a failure reason")
    if record.success == (record.failure is not None):
        raise RecordError("a success must have no failure reason and a failure must have one")
    if record.failed_phase is not None and record.failed_phase not in PHASES:
        raise RecordError("field 'failed_phase' is not a phase")


def _typed(value: object, hint: Any, name: str) -> Any:
    """``value`` checked against the annotation ``hint`` (and converted where JSON cannot
    say it: tuples, PoseErrors)."""
    origin = get_origin(hint)
    if origin in (Union, types.UnionType):
        options = get_args(hint)
        if value is None and type(None) in options:
            return None
        (inner,) = [o for o in options if o is not type(None)]
        return _typed(value, inner, name)
    if hint is PoseErrors:
        return _pose(value, name)
    if origin is list and isinstance(value, list):
        (item,) = get_args(hint)
        return [_typed(v, item, name) for v in value]
    if origin is tuple and isinstance(value, list) and len(value) == len(get_args(hint)):
        return tuple(_typed(v, t, name) for v, t in zip(value, get_args(hint), strict=True))
    if origin is dict and isinstance(value, dict):
        _, item = get_args(hint)
        return {str(k): _typed(v, item, name) for k, v in value.items()}
    if origin is None and _scalar_ok(value, hint):
        return float(value) if hint is float else value  # type: ignore[arg-type]
    raise RecordError(f"field {name!r} is not {_describe(hint)}")


def _scalar_ok(value: object, hint: Any) -> bool:
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return _is_int(value)
    if hint is float:
        return _is_int(value) or isinstance(value, float)
    return hint is str and isinstance(value, str)


def _pose(value: object, name: str) -> PoseErrors | None:
    """A serialised PoseErrors; the placeholder with null errors (no detection) is None."""
    if not isinstance(value, dict) or not set(value) <= POSE_KEYS:
        raise RecordError(f"field {name!r} is not a pose comparison")
    if value.get("estimated") is None and all(v is None for v in value.values()):
        return None
    pose = _hints(PoseErrors)["estimated"]
    return PoseErrors(estimated=_typed(value.get("estimated"), pose, name),
                      actual=_typed(value.get("actual"), pose, name))


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _describe(hint: Any) -> str:
    origin = get_origin(hint)
    if origin is not None:
        return {list: "a list", tuple: "a list", dict: "an object"}.get(origin, str(hint))
    return {bool: "a boolean", int: "an integer", float: "a number",
            str: "a string"}.get(hint, str(hint))


def _kind(value: object) -> str:
    return {list: "an array", str: "a string", bool: "a boolean", int: "a number",
            float: "a number", type(None): "null"}.get(type(value), type(value).__name__)
