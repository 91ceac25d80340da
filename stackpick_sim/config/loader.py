"""Load ``scenes/*.toml`` into a :class:`SceneConfig`, with ``extends`` and ``--set`` overrides.

A scene file may start with ``extends = "paper"`` to take another scene and change only some
keys. Overrides are ``dotted.key=value`` strings whose value is parsed as a TOML value
(``objects.count=[4,6]``, ``camera.shadows=true``); for a string-valued key an unquoted value
is taken as the string itself. Every problem raises one :class:`ConfigError` naming the key,
what was given and what is allowed.
"""

from __future__ import annotations

import dataclasses
import tomllib
import typing
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from stackpick_sim.config.scene_config import SceneConfig
from stackpick_sim.exceptions import ConfigError
from stackpick_sim.files import shown
from stackpick_sim.paths import SCENES_DIR

#: How many ``extends`` links a scene may follow (guards against cycles).
MAX_EXTENDS_DEPTH = 8
#: The largest scene file read, bytes (a scene is a few dozen keys; this bounds the parse).
MAX_SCENE_BYTES = 1 << 20
#: How deeply tables and lists may nest in a scene file or an override value (a scene's
#: deepest key is ``object_types.NAME.rgba``: 3 levels and a list).
MAX_NESTING = 8


def available_scenes() -> list[str]:
    """Names of the scenes shipped in ``scenes/``."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def resolve_scene_path(name_or_path: str) -> Path:
    """A scene name (``paper``) or a path to a ``.toml`` file, resolved to an existing file."""
    candidate = Path(name_or_path)
    if "\0" in name_or_path:
        raise ConfigError(f"scene {name_or_path!r} is not a file name (it holds a NUL byte)")
    if candidate.suffix == ".toml" or candidate.parent != Path("."):
        if not candidate.is_file():
            state = "is not a regular file" if candidate.exists() else "does not exist"
            raise ConfigError(f"scene file '{shown(candidate)}' {state}")
        return candidate
    shipped = SCENES_DIR / f"{name_or_path}.toml"
    if not shipped.is_file():
        raise ConfigError(f"unknown scene {name_or_path!r}; known scenes: "
                          f"{', '.join(available_scenes())} (or give a path to a .toml file)")
    return shipped


def _nesting(value: Any) -> int:
    """How deeply tables and lists nest in a parsed TOML value (iterative: no recursion)."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, depth = stack.pop()
        deepest = max(deepest, depth)
        if deepest > MAX_NESTING:
            break
        children = item.values() if isinstance(item, Mapping) else (
            item if isinstance(item, list) else ())
        stack += [(child, depth + 1) for child in children]
    return deepest


def _loads(text: str, what: str) -> dict[str, Any]:
    """Parse TOML text (TOMLDecodeError if malformed); ConfigError naming ``what`` if it nests
    tables or lists more than MAX_NESTING levels deep."""
    try:
        doc: dict[str, Any] | None = tomllib.loads(text)
    except RecursionError:
        doc = None
    if doc is None or _nesting(doc) > MAX_NESTING:
        raise ConfigError(f"{what} nests tables or lists more than {MAX_NESTING} levels deep")
    return doc


def _read_toml(path: Path) -> dict[str, Any]:
    name = shown(path)
    try:
        with path.open("rb") as fh:
            data = fh.read(MAX_SCENE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"cannot read scene file {name}: {exc.strerror}") from None
    if len(data) > MAX_SCENE_BYTES:
        raise ConfigError(f"scene file {name} is larger than {MAX_SCENE_BYTES} bytes")
    try:
        text = data.decode("utf-8-sig")  # a BOM some editors write is fine
    except UnicodeDecodeError as exc:
        raise ConfigError(f"scene file {name} is not UTF-8 text (byte {exc.start}); save it "
                          "as UTF-8") from None
    try:
        return _loads(text, f"scene file {name}")
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"malformed TOML in {name}: {exc}") from None


def _merge(base: dict[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in top.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def _load_raw(path: Path, depth: int = 0) -> dict[str, Any]:
    if depth > MAX_EXTENDS_DEPTH:
        raise ConfigError(f"{path}: more than {MAX_EXTENDS_DEPTH} 'extends' links (a cycle?)")
    raw = _read_toml(path)
    parent = raw.pop("extends", None)
    if parent is None:
        return raw
    if not isinstance(parent, str):
        raise ConfigError(f"{path}: extends = {parent!r} must be a scene name or path string")
    parent_path = resolve_scene_path(parent) if not parent.endswith(".toml") else (
        path.parent / parent)
    return _merge(_load_raw(parent_path, depth + 1), raw)


def known_keys(cls: type = SceneConfig, prefix: str = "") -> list[str]:
    """Every dotted key a scene accepts (dict sections show as ``section.*.field``)."""
    keys: list[str] = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            keys += known_keys(typing.cast(type, hint), f"{prefix}{f.name}.")
        elif typing.get_origin(hint) is dict and dataclasses.is_dataclass(
                typing.get_args(hint)[1]):
            keys += known_keys(typing.get_args(hint)[1], f"{prefix}{f.name}.*.")
        elif typing.get_origin(hint) is dict:
            keys.append(f"{prefix}{f.name}.*")
        else:
            keys.append(f"{prefix}{f.name}")
    return keys


def _type_name(hint: Any) -> str:
    origin = typing.get_origin(hint)
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_type_name(args[0])}"
        return f"a list of {len(args)} {_type_name(args[0])}"
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in typing.get_args(hint))
    return {float: "number", int: "integer", bool: "boolean", str: "string"}.get(hint, str(hint))


def _convert(value: Any, hint: Any, key: str) -> Any:
    """Check ``value`` (as TOML gives it) against the annotation ``hint`` and convert it."""
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key} must be a table of keys, got {value!r}")
        return _build(typing.cast(type, hint), value, f"{key}.")
    if origin is dict:
        return _convert_tables(value, typing.get_args(hint)[1], key)
    if origin is tuple:
        return _convert_list(value, hint, key)
    if origin is typing.Literal:
        allowed = typing.get_args(hint)
        if value not in allowed:
            raise ConfigError(f"{key} = {value!r} is not allowed; choose one of "
                              f"{', '.join(repr(a) for a in allowed)}")
        return value
    if hint in _SCALARS:
        if not _SCALARS[hint](value):
            raise _wrong_type(value, hint, key)
        return float(value) if hint is float else value
    raise TypeError(f"unsupported config annotation {hint!r} at {key}")  # a bug, not bad input


#: What a TOML value must be to fill a field of each scalar type (a bool is no number).
_SCALARS: dict[type, Callable[[Any], bool]] = {
    bool: lambda v: isinstance(v, bool),
    int: lambda v: isinstance(v, int) and not isinstance(v, bool),
    float: lambda v: isinstance(v, int | float) and not isinstance(v, bool),
    str: lambda v: isinstance(v, str),
}


def _wrong_type(value: Any, hint: Any, key: str) -> ConfigError:
    return ConfigError(f"{key} = {value!r} has the wrong type; expected {_type_name(hint)}")


def _convert_tables(value: Any, value_cls: Any, key: str) -> dict[str, Any]:
    """A ``dict[str, X]`` field: each entry converted to ``value_cls``, errors naming it."""
    if not isinstance(value, Mapping):
        raise ConfigError(f"{key} must be a table of tables, got {value!r}")
    out = {}
    for name, v in value.items():
        try:
            out[name] = _convert(v, value_cls, f"{key}.{name}")
        except ConfigError as exc:  # name the entry instead of the generic ``*``
            raise ConfigError(str(exc).replace(f"{key}.*.", f"{key}.{name}.")) from None
    return out


def _convert_list(value: Any, hint: Any, key: str) -> tuple[Any, ...]:
    """A tuple field: ``tuple[X, ...]`` of any length, or one of fixed length and types."""
    args = typing.get_args(hint)
    if not isinstance(value, list | tuple):
        raise _wrong_type(value, hint, key)
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(_convert(v, args[0], key) for v in value)
    if len(value) != len(args):
        raise _wrong_type(value, hint, key)
    return tuple(_convert(v, a, key) for v, a in zip(value, args, strict=True))


def _build(cls: type, data: Mapping[str, Any], prefix: str) -> Any:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    for key in data:
        if key not in names:
            raise ConfigError(f"unknown scene key {prefix + key!r}; known keys: "
                              f"{', '.join(known_keys())}")
    kwargs = {k: _convert(v, hints[k], prefix + k) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except TypeError as exc:  # a required field is missing
        raise ConfigError(f"{prefix.rstrip('.') or 'scene'}: {exc}") from None


def _hint_at(dotted: str) -> Any:
    """The annotation of a dotted key, or raise the unknown-key error."""
    hint: Any = SceneConfig
    for part in dotted.split("."):
        if dataclasses.is_dataclass(hint):
            fields = typing.get_type_hints(hint)
            if part not in fields:
                break
            hint = fields[part]
        elif typing.get_origin(hint) is dict:
            hint = typing.get_args(hint)[1]
        else:
            break
    else:
        return hint
    raise ConfigError(f"unknown scene key {dotted!r}; known keys: {', '.join(known_keys())}")


def parse_override(text: str) -> tuple[str, Any]:
    """``"conveyor.speed=0.2"`` -> ``("conveyor.speed", 0.2)``, the value parsed as TOML."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"override {text!r} is not of the form key=value "
                          "(e.g. --set conveyor.speed=0.2)")
    if "\n" in text or "\r" in text:
        raise ConfigError(f"override {text!r} spans several lines; give each key its own --set")
    hint = _hint_at(key)
    try:
        value = _loads(f"v = {raw.strip()}", f"override {key}")["v"]
    except tomllib.TOMLDecodeError:
        if hint is str or typing.get_origin(hint) is typing.Literal:
            return key, raw.strip()
        raise ConfigError(f"override {key}={raw!r}: the value is not a TOML value; expected "
                          f"{_type_name(hint)}") from None
    return key, value


def _set_dotted(data: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    head, _, rest = key.partition(".")
    out = dict(data)
    if not rest:
        out[head] = value
    else:
        child = out.get(head, {})
        out[head] = _set_dotted(dict(child) if isinstance(child, Mapping) else {}, rest, value)
    return out


def _as_raw(cfg: Any) -> Any:
    if dataclasses.is_dataclass(cfg):
        return {f.name: _as_raw(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    if isinstance(cfg, dict):
        return {k: _as_raw(v) for k, v in cfg.items()}
    if isinstance(cfg, tuple):
        return list(cfg)
    return cfg


def load_scene(name_or_path: str = "paper", overrides: Iterable[str] = ()) -> SceneConfig:
    """Load a scene by name or path and apply ``key=value`` overrides in order."""
    path = resolve_scene_path(name_or_path)
    raw = _load_raw(path)
    raw.setdefault("name", path.stem)
    # Defaults first, so that an override of one object type's field keeps its other fields.
    merged = _merge(_as_raw(SceneConfig()), raw)
    if "object_types" in raw:
        merged["object_types"] = raw["object_types"]
    for text in overrides:
        key, value = parse_override(text)
        merged = _set_dotted(merged, key, value)
    return typing.cast(SceneConfig, _build(SceneConfig, merged, ""))


def scene_to_dict(cfg: SceneConfig) -> dict[str, Any]:
    """A JSON/TOML-friendly dict of a config (tuples as lists)."""
    return typing.cast(dict[str, Any], _as_raw(cfg))
