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
from collections.abc import Callable
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
    plan = _plan(cls)
    if len(data) > len(plan) or not data.keys() <= plan.keys():
        raise RecordError(f"unknown field {sorted(data.keys() - plan.keys())[0]!r}")
    out: dict[str, Any] = {}
    for name, (check, optional) in plan.items():
        if name in data:
            out[name] = check(data[name], name)
        elif name in required or not optional:
            raise RecordError(f"missing field {name!r}")
    if out["seed"] < 0:
        raise RecordError("field 'seed' is negative")
    return out


#: A field's check: (JSON value, field name) -> the typed value, or RecordError.
Check = Callable[[object, str], Any]


@cache
def _plan(cls: type) -> dict[str, tuple[Check, bool]]:
    """Per field of ``cls``: its check (from the annotation) and whether it may be absent."""
    hints = get_type_hints(cls)
    return {f.name: (_compile(hints[f.name]),
                     f.default is not MISSING or f.default_factory is not MISSING)
            for f in fields(cls)}


def _compile(hint: Any) -> Check:
    """The check of an annotation: bool, int, float, str, PoseErrors, ``X | None`` and
    list/tuple/dict of those (what the record dataclasses use)."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, types.UnionType):
        (inner,) = [a for a in args if a is not type(None)]  # X | None only
        check = _compile(inner)
        return lambda value, name: None if value is None else check(value, name)
    if hint is PoseErrors:
        return _pose
    if origin is list:
        return _list_of(_compile(args[0]))
    if origin is tuple:
        return _tuple_of(tuple(_compile(a) for a in args))
    if origin is dict:
        return _dict_of(_compile(args[1]))
    return _SCALARS[hint]


def _scalar(kinds: tuple[type, ...], what: str) -> Check:
    def check(value: object, name: str) -> Any:
        if type(value) not in kinds:  # exact types: a boolean is not an integer here
            raise RecordError(f"field {name!r} is not {what}")
        return float(value) if float in kinds else value  # type: ignore[arg-type]

    return check


_SCALARS: dict[type, Check] = {bool: _scalar((bool,), "a boolean"),
                               int: _scalar((int,), "an integer"),
                               float: _scalar((int, float), "a number"),
                               str: _scalar((str,), "a string")}


def _list_of(item: Check) -> Check:
    def check(value: object, name: str) -> list[Any]:
        if type(value) is not list:
            raise RecordError(f"field {name!r} is not a list")
        return [item(v, name) for v in value]

    return check


def _tuple_of(items: tuple[Check, ...]) -> Check:
    def check(value: object, name: str) -> tuple[Any, ...]:
        if type(value) is not list or len(value) != len(items):
            raise RecordError(f"field {name!r} is not a list of {len(items)}")
        return tuple(c(v, name) for c, v in zip(items, value, strict=True))

    return check


def _dict_of(item: Check) -> Check:
    def check(value: object, name: str) -> dict[str, Any]:
        if type(value) is not dict:
            raise RecordError(f"field {name!r} is not an object")
        return {k: item(v, name) for k, v in value.items()}

    return check


def _check_outcome(record: EpisodeRecord) -> None:
    if record.failure is not None and record.failure not in (*FAILURES, *RUNNER_FAILURES):
        raise RecordError("field 'failure' is not a failure reason")
    if record.success == (record.failure is not None):
        raise RecordError("a success must have no failure reason and a failure must have one")
    if record.failed_phase is not None and record.failed_phase not in PHASES:
        raise RecordError("field 'failed_phase' is not a phase")


def _pose(value: object, name: str) -> PoseErrors | None:
    """A serialised PoseErrors; the placeholder with null errors (no detection) is None."""
    if type(value) is not dict or not value.keys() <= POSE_KEYS:
        raise RecordError(f"field {name!r} is not a pose comparison")
    if value.get("estimated") is None and all(v is None for v in value.values()):
        return None
    pose = _plan(PoseErrors)["estimated"][0]
    return PoseErrors(estimated=pose(value.get("estimated"), name),
                      actual=pose(value.get("actual"), name))


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _kind(value: object) -> str:
    return {list: "an array", str: "a string", bool: "a boolean", int: "a number",
            float: "a number", type(None): "null"}.get(type(value), type(value).__name__)
