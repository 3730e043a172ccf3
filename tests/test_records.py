"""Records of more than four fields are built by keyword: their classes refuse
position, so two fields of one type cannot be swapped by a call that lists them in
another order. Keyword-only construction leaves the wire format as it was (a message's
fields go out in their declared order)."""

from __future__ import annotations

import ast
from pathlib import Path

import msgspec
import numpy as np
import pytest

import uavtrack
from uavtrack.agents.messages import VERSION, Lost, decode, encode
from uavtrack.agents.security import Envelope
from uavtrack.methods import Assigned

PACKAGE = Path(uavtrack.__file__).parent


def records() -> list[tuple[str, str, int, bool]]:
    """Every dataclass, msgspec Struct and NamedTuple of the package: (module, class,
    fields, keyword-only)."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef):
                continue
            calls = [d for d in node.decorator_list if "dataclass" in ast.unparse(d)]
            bases = [ast.unparse(b) for b in node.bases]
            struct = any(b.endswith("Struct") for b in bases)
            if not (calls or struct or "NamedTuple" in bases):
                continue
            fields = [
                s
                for s in node.body
                if isinstance(s, ast.AnnAssign) and "ClassVar" not in ast.unparse(s.annotation)
            ]
            keywords = node.keywords + [
                k for d in calls if isinstance(d, ast.Call) for k in d.keywords
            ]
            kw_only = any(k.arg == "kw_only" and ast.unparse(k.value) == "True" for k in keywords)
            module = str(path.relative_to(PACKAGE))
            out.append((module, node.name, len(fields), kw_only))
    return out


def test_every_record_of_more_than_four_fields_refuses_position():
    found = records()
    assert len([r for r in found if r[2] > 4]) >= 30  # the walk sees the records
    positional = [f"{m}: {name}" for m, name, count, kw_only in found if count > 4 and not kw_only]
    assert positional == []


def test_a_record_built_by_position_is_refused():
    none = np.zeros(2, dtype=np.int64)
    with pytest.raises(TypeError):
        Assigned(none, np.zeros((2, 3, 2)), none, none)  # type: ignore[misc]
    assigned = Assigned(target=none, seconds=np.zeros((2, 3, 2)), sent=none, delivered=none)
    assert assigned.held is None
    with pytest.raises(TypeError):
        Lost(VERSION, "r", 3, 1, "x")  # type: ignore[misc]


def test_messages_keep_their_wire_format():
    # an envelope is an array in field order: msgpack [1, 2, 3, b"abc", b"t"]
    envelope = Envelope(sender=1, receiver=2, seq=3, body=b"abc", tag=b"t")
    assert msgspec.msgpack.encode(envelope) == b"\x95\x01\x02\x03\xc4\x03abc\xc4\x01t"
    # a tagged message is a map: its tag, then the fields in declared order
    lost = Lost(version=VERSION, run="r", k=3, program=1, reason="x")
    wire = msgspec.msgpack.decode(encode(lost))
    assert list(wire.items()) == [
        ("type", "lost"), ("version", VERSION), ("run", "r"), ("k", 3), ("program", 1),
        ("reason", "x"),
    ]  # fmt: skip
    assert decode(encode(lost), "r") == lost
