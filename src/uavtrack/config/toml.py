"""Reading and writing scenarios as TOML, dotted field names (``a.b``), values given on
the command line, and one-line messages for pydantic's validation errors.
"""

from __future__ import annotations

import sys
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeGuard, cast

from pydantic import (
    ValidationError,
)

from ..errors import ScenarioError

MAX_BYTES = 1 << 20
"""The largest config file read [bytes]: a scenario with every field set and commented
(`uavtrack params --toml`) takes about 20 KiB; a device or a runaway file is refused
after this many bytes, not read whole."""

MAX_DEPTH = 16
"""The deepest nesting of tables and arrays a config holds: a scenario nests three
levels; deeper input is refused before anything recurses through it."""


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file into a dict, with one-line errors: a file larger than
    `MAX_BYTES` or nested deeper than `MAX_DEPTH` is refused."""
    try:
        with open(path, "rb") as file:
            raw = file.read(MAX_BYTES + 1)
        if len(raw) > MAX_BYTES:
            raise ScenarioError(
                f"config file {path} is larger than {MAX_BYTES // 1024} KiB; "
                "a scenario takes a few KiB"
            )
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ScenarioError(f"cannot read config file {path}: {reason}") from None
    return loads(text, f"config file {path}")


def loads(text: str, where: str) -> dict[str, Any]:
    """`tomllib.loads` with one-line errors naming `where`: invalid TOML, numbers of
    more digits than Python converts, nesting deeper than `MAX_DEPTH`."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(f"{where} is nested deeper than {MAX_DEPTH} levels") from None
    except ValueError:  # an integer of more digits than int() converts (4300)
        raise ScenarioError(
            f"{where} holds a number of more than {sys.get_int_max_str_digits()} digits"
        ) from None
    if _depth(data) > MAX_DEPTH:
        raise ScenarioError(f"{where} is nested deeper than {MAX_DEPTH} levels")
    return data


def _depth(value: object) -> int:
    """How deeply tables and arrays nest in a parsed TOML value (a scalar: 0), found
    without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        node, depth = stack.pop()
        if _is_table(node):
            children: list[object] = list(node.values())
        elif isinstance(node, list):
            children = cast(list[object], node)
        else:
            continue
        deepest = max(deepest, depth + 1)
        if deepest > MAX_DEPTH:
            return deepest
        stack.extend((child, depth + 1) for child in children)
    return deepest


def _is_table(value: object) -> TypeGuard[dict[str, Any]]:
    """Whether `value` is a table: a TOML table's keys, as a scenario's, are text."""
    return isinstance(value, dict)


def _is_array(value: object) -> TypeGuard[Sequence[object]]:
    """Whether `value` is written as a TOML array (a list, or a tuple of a frozen field)."""
    return isinstance(value, list | tuple)


def flatten(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A nested dict as ``{"a.b": value}`` (the dotted field names of a scenario)."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        if _is_table(value):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``data["a"]["b"] = value`` for ``dotted = "a.b"``, refusing unknown names."""
    keys = dotted.split(".")
    node: object = data
    for depth, key in enumerate(keys):
        if not _is_table(node) or key not in node:
            where = ".".join(keys[: depth + 1])
            raise ScenarioError(f"unknown scenario field '{where}'{_did_you_mean(dotted, data)}")
        if depth == len(keys) - 1:
            if isinstance(node[key], dict):
                raise ScenarioError(f"'{dotted}' is a group of fields; set one of its fields")
            node[key] = value
        else:
            node = node[key]


def _did_you_mean(dotted: str, data: dict[str, Any]) -> str:
    """'; did you mean X?' for the field name of `data` closest to `dotted`, and where
    every field is listed."""
    close = closest(dotted, data)
    return f"; did you mean {close}?{_PARAMS_HINT}" if close else _PARAMS_HINT


def closest(dotted: str, data: dict[str, Any]) -> str | None:
    """The dotted field name of the nested dict `data` closest to `dotted`, or None."""
    import difflib

    names = list(flatten(data))
    leaves = {name.rsplit(".", 1)[-1]: name for name in names}
    close = difflib.get_close_matches(dotted, names, n=1, cutoff=0.6)
    if not close:  # a leaf name without its group, or a typo in it
        found = difflib.get_close_matches(dotted.rsplit(".", 1)[-1], leaves, n=1, cutoff=0.7)
        close = [leaves[found[0]]] if found else []
    return close[0] if close else None


_PARAMS_HINT = " (uavtrack params lists every field)"


def describe_errors(exc: ValidationError, fields: dict[str, Any] | None = None) -> str:
    """Pydantic errors as one line: ``field: problem (got value)``, joined by '; '. An
    unknown field is given the closest of `fields` (a scenario's nested dict), if any."""
    parts: list[str] = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"])
        if err["type"] == "extra_forbidden":
            close = closest(loc, fields) if fields is not None else None
            parts.append(f"unknown field '{loc}'" + (f" (did you mean {close}?)" if close else ""))
            continue
        msg = err["msg"].removeprefix("Value error, ")
        got = err.get("input")
        shown = "" if isinstance(got, dict) or got is None else f" (got {_short(got)})"
        parts.append(f"{loc}: {msg}{shown}" if loc else f"{msg}{shown}")
    return "; ".join(parts)


def _short(value: object, most: int = 60) -> str:
    """repr(value), cut to `most` characters: an error line stays one readable line."""
    text = repr(value)
    return text if len(text) <= most else f"{text[: most - 12]}... ({len(text)} chars)"


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["a.b=1", "c=[1, 2]"]`` -> ``{"a.b": 1, "c": [1, 2]}`` (values read as TOML,
    `parse_value`): the ``--set FIELD=VALUE`` options of every command.

    A field set twice is refused: which of the two was meant cannot be told.
    """
    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ScenarioError(f"--set expects FIELD=VALUE, got {item!r}")
        if name in out:
            raise ScenarioError(f"--set {name} is given twice; give each field once")
        out[name] = parse_value(text.strip(), where=f"--set {name}")
    return out


def parse_value(text: str, where: str = "value") -> Any:
    """Read a command-line value as TOML (numbers, booleans, lists), ``none`` as None (an
    optional field left unset), else as a string.

    A value is one line: text after a line break would otherwise be read as more TOML
    or dropped. `where` names the value in the error message.
    """
    if "\n" in text or "\r" in text:
        raise ScenarioError(f"{where}: value {text!r} spans several lines; give it on one line")
    if text.strip() == "none":  # TOML has no null: `none` unsets an optional field
        return None
    try:
        data = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return text
    except (RecursionError, ValueError):  # too deep, or too many digits: `loads` says which
        data = loads(f"v = {text}", where)
    if _depth(data) > MAX_DEPTH:
        raise ScenarioError(f"{where} is nested deeper than {MAX_DEPTH} levels")
    return data["v"]


def dump_toml(
    data: dict[str, Any], docs: dict[str, str] | None = None, unset: Sequence[str] = ()
) -> str:
    """Minimal TOML writer for the scenario's shape: scalars, lists, nested tables; with
    `docs` (dotted name -> description) each key gets its description as a comment, and
    the dotted names in `unset` are written as commented-out keys."""
    import textwrap

    def entry(prefix: str, key: str, value: Any) -> list[str]:
        name = prefix + key
        lines: list[str] = []
        if docs is not None and docs.get(name):
            lines += [f"# {part}" for part in textwrap.wrap(docs[name], 86)]
        lines.append(
            f"# {key} =   (not set)" if value is _UNSET else f"{key} = {_toml_value(value)}"
        )
        return lines

    def keys(table: dict[str, Any], prefix: str) -> list[str]:
        missing = {n[len(prefix) :]: _UNSET for n in unset if n.startswith(prefix)}
        missing = {k: v for k, v in missing.items() if "." not in k and k not in table}
        out: list[str] = []
        for key, value in {**table, **missing}.items():
            if not isinstance(value, dict):
                out += entry(prefix, key, value)
        return out

    def tables(table: dict[str, Any], prefix: str) -> list[str]:
        out: list[str] = []
        for key, value in ((k, v) for k, v in table.items() if _is_table(v)):
            name = prefix + key
            out += ["", f"[{name}]", *keys(value, f"{name}."), *tables(value, f"{name}.")]
        return out

    return "\n".join(keys(data, "") + tables(data, "")) + "\n"


_UNSET = object()


def _toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if _is_array(value):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")
