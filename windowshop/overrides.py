"""Settings from the command line, `KEY=VALUE` overrides and the service's API, all derived from
the configuration dataclasses of `windowshop.config`: a knob is one dataclass field, and its flag,
its override key and its `WINDOWSHOP_JOB__...` environment variable follow from it.

- `apply_overrides(config, {"fit.seconds": 30, "voxel_pixels": 2})`: a new config with the values
  checked against the fields' types. Keys are field names, dotted through nested stage configs
  (`render.frames`); a name that only one stage has may be given alone (`frames` is ambiguous in a
  pipeline, `fps` is not).
- `parse_assignments(["fit.seconds=30"])`: `--set KEY=VALUE` items, values read as YAML scalars.
- `add_flags(parser, cls)` / `flag_values(args)`: one flag per leaf field, named after it (`--fit.seconds`
  and, where unambiguous, `--seconds`), with the help text of the field's comment in config.py and
  its default, never repeated here.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import inspect
import io
import tokenize
import types
import typing
from typing import Any

import yaml

from windowshop.errors import UserError

DEST = "__config__"  # prefix of the argparse dests this module adds (dest = DEST + dotted path)


def _is_config(hint: Any) -> bool:
    return isinstance(hint, type) and dataclasses.is_dataclass(hint)


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


@functools.cache
def field_help(cls: type) -> dict[str, str]:
    """Field name -> the comment that follows it in `cls`'s source (the field's documentation)."""
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return {}
    names, helps = {f.name for f in dataclasses.fields(cls)}, {}
    current = None
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.NAME and token.start[1] == 4 and token.string in names:
            current = token.string if token.string not in helps else None
        elif token.type == tokenize.COMMENT and current is not None:
            helps[current] = token.string.lstrip("# ").strip()
            current = None
        elif token.type == tokenize.NEWLINE:
            current = None
    return helps


def leaves(cls: type, prefix: str = "") -> dict[str, tuple[type, dataclasses.Field]]:
    """Dotted path -> (owning dataclass, field) of every non-dataclass field under `cls`."""
    out = {}
    for f in dataclasses.fields(cls):
        hint = _hints(cls)[f.name]
        if _is_config(hint):
            out.update(leaves(hint, f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = (cls, f)
    return out


def named(key: str, paths: dict[str, Any]) -> list[str]:
    """The paths of `paths` (from `leaves`) that the key `key` names: itself, or every path
    ending in `.key` (more than one: ambiguous; none: no such setting)."""
    key = key.replace("-", "_")
    return [key] if key in paths else [p for p in paths if p.endswith("." + key)]


def _resolve(key: str, paths: dict[str, Any], where: str) -> str:
    """The full dotted path `key` names: itself, the one path ending in `.key`, or an entry
    `name.entry` of a dict field `name` (checked by whoever reads the dict)."""
    key = key.replace("-", "_")
    head = key.rpartition(".")[0]
    if key in paths or (head in paths and _hints(paths[head][0])[paths[head][1].name] is dict):
        return key
    matches = named(key, paths)
    if len(matches) == 1:
        return matches[0]
    if matches:
        raise UserError(f"{where}: {key} is ambiguous; say which: {', '.join(sorted(matches))}")
    raise UserError(f"{where}: no setting {key}; the settings: {', '.join(sorted(paths))}")


def check_value(key: str, value: Any, hint: Any, where: str) -> Any:
    """`value` for the field `key` of type `hint`, checked: ints become floats, lists tuples, and a
    string from a flag or an environment variable is read as YAML first."""
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    kinds = [typing.get_origin(k) or k for k in (typing.get_args(hint) if union else (hint,))]
    if value is None:
        if type(None) in kinds:
            return None
        raise UserError(f"{where}: {key} needs a value")
    expected = next((k for k in (bool, int, float, str, tuple) if k in kinds), None)
    if isinstance(value, str) and expected not in (str, None):
        value = _from_text(value, expected)
    if expected is float:
        value = _number(value)
    ok = {bool: lambda v: isinstance(v, bool),
          int: lambda v: isinstance(v, int) and not isinstance(v, bool),
          float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
          str: lambda v: isinstance(v, str), tuple: lambda v: isinstance(v, (list, tuple))}
    if expected is not None and not ok[expected](value):
        names = {bool: "true or false", int: "an integer", float: "a number", str: "a string",
                 tuple: "a list"}
        raise UserError(f"{where}: {key} must be {names[expected]}, got {value!r}")
    return float(value) if expected is float else tuple(value) if expected is tuple else value


def _from_text(text: str, expected: type) -> Any:
    """A flag's text as a value: YAML scalars, and `1,2,3` as a list for tuple fields."""
    if expected is tuple and not text.strip().startswith("["):
        return [yaml.safe_load(part) for part in text.split(",") if part.strip()]
    try:
        return yaml.safe_load(text) if text.strip() else None
    except yaml.YAMLError:
        return text


def _number(value: Any) -> Any:
    """`value`, or the float a string spells: YAML 1.1 reads `1e-4` (no dot) as text."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            pass
    return value


def apply_overrides(config: Any, overrides: dict[str, Any], where: str = "settings") -> Any:
    """`config` (a frozen dataclass, possibly of stage dataclasses) with `overrides` applied.

    Setting only one of a stage's budgets `iters` and `seconds` clears the other, as every command
    does with `--iters` or `--seconds`.
    """
    paths = leaves(type(config))
    resolved = {_resolve(k, paths, where): v for k, v in overrides.items()}
    for path in list(resolved):
        stage, _, name = path.rpartition(".")
        other = {"iters": "seconds", "seconds": "iters"}.get(name)
        partner = f"{stage}.{other}" if stage else other
        if other and partner in paths and partner not in resolved and resolved[path] is not None:
            resolved[partner] = None
    for path, value in resolved.items():
        if path in paths:
            owner, f = paths[path]
            resolved[path] = check_value(path, value, _hints(owner)[f.name], where)
    return _replace(config, resolved)


def _replace(config: Any, values: dict[str, Any]) -> Any:
    nested: dict[str, dict[str, Any]] = {}
    flat = {}
    for path, value in values.items():
        head, _, rest = path.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            flat[head] = value
    for head, inner in nested.items():
        current = getattr(config, head)
        flat[head] = {**current, **inner} if isinstance(current, dict) else _replace(current, inner)
    return dataclasses.replace(config, **flat)


def parse_assignments(items: list[str]) -> dict[str, Any]:
    """`--set KEY=VALUE` items as a dict; values read as YAML scalars (10, 0.5, true, nerf)."""
    settings = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UserError(f"--set {item!r}: expected KEY=VALUE, e.g. --set batch_rays=1024")
        settings[key.strip().replace("-", "_")] = yaml.safe_load(value) if value.strip() else None
    return settings


def _flag_type(hint: Any) -> tuple[Any, dict]:
    """argparse keywords for a field of type `hint`."""
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    kinds = [k for k in (typing.get_args(hint) if union else (hint,)) if k is not type(None)]
    kind = typing.get_origin(kinds[0]) or kinds[0]
    if kind is bool:
        return None, {"action": argparse.BooleanOptionalAction}
    if kind is tuple:
        return None, {"metavar": "A,B,..."}
    return kind, {"metavar": {int: "N", float: "X"}.get(kind, "TEXT")}


def add_flags(parser: argparse.ArgumentParser, cls: type, title: str | None = None,
              exclude: tuple[str, ...] = (), defaults: Any = None) -> None:
    """One flag per leaf field of `cls` not in `exclude` (dotted paths or field names).

    Every leaf has its dotted flag (`--fit.seconds`) where `cls` nests stages; a field name that
    only one stage has also gets its plain flag (`--seconds`). Flags default to "not given"; the
    help shows the default of `defaults` (an instance of `cls`, default `cls()`).
    """
    paths = {p: v for p, v in leaves(cls).items()
             if p not in exclude and p.rsplit(".", 1)[-1] not in exclude}
    defaults = defaults if defaults is not None else cls()
    counts: dict[str, int] = {}
    for path in paths:
        name = path.rsplit(".", 1)[-1]
        counts[name] = counts.get(name, 0) + 1
    groups: dict[str, argparse._ArgumentGroup] = {}
    for path, (owner, f) in paths.items():
        stage, _, name = path.rpartition(".")
        if stage not in groups:
            groups[stage] = parser.add_argument_group(
                f"{title or cls.__name__}{' / ' + stage if stage else ''}")
        flags = [f"--{path.replace('_', '-')}"]
        if stage and counts[name] == 1:
            flags.insert(0, f"--{name.replace('_', '-')}")
        kind, extra = _flag_type(_hints(owner)[f.name])
        default = get_path(defaults, path)
        text = field_help(owner).get(f.name, "")
        groups[stage].add_argument(*flags, dest=DEST + path, type=kind, default=None,
                                   help=f"{text} (default: {default})".replace("%", "%%"), **extra)


def get_path(config: Any, path: str) -> Any:
    """The value at the dotted `path` of a nested config."""
    for part in path.split("."):
        config = getattr(config, part)
    return config


def flag_values(args: argparse.Namespace) -> dict[str, Any]:
    """The dotted paths and values of the generated flags the user gave."""
    return {k[len(DEST):]: v for k, v in vars(args).items() if k.startswith(DEST) and v is not None}
