"""Declarative, versioned YAML model files (format version 1).

A model file describes a :class:`~se3dyn.model.specs.Model` (nodes, joints, loads, gravity)
plus optional
simulation settings, with names instead of numbers::

    se3dyn: 1
    name: pendulum
    gravity: [0, 0, -9.81]
    nodes:
      ground: {position: [0, 0, 0], fixed: true}
      bob: {position: [1, 0, 0], mass: 1.0, inertia: [1.0e-3, 1.0e-3, 1.0e-3]}
    joints:
      pivot: {type: hinge, a: ground, b: bob, axis: [0, 1, 0]}
    simulation: {t_end: 2.0, step: 0.01}

>>> from se3dyn.io.modelfile import load_model
>>> model, settings = load_model("examples/slider_crank.yaml")   # doctest: +SKIP
>>> result = se3dyn.simulate(model, **settings)                   # doctest: +SKIP

One source of truth: :data:`FIELDS` lists, per section, every field with its type, default and
description; the sections of the element types (``joints``, ``loads``, ``springs``, ``bushings``,
...) come from their modules in :mod:`se3dyn.elements` (``model_file(mf)`` returning an
:class:`ElementSection`: fields, builder call, saver), in registry order. The loader
validates against it, :func:`json_schema` turns it into a JSON Schema (draft 2020-12,
``docs/model-file.schema.json``) and :func:`markdown_reference` into the field-by-field
reference of ``docs/model-file.md``.

Safety: files are parsed with a :class:`yaml.SafeLoader` subclass (nothing is ever evaluated as
code); YAML tags, anchors and aliases are rejected (no "billion laughs"), and file size, nesting
depth, collection lengths and node counts are bounded. Every invalid file raises
:class:`ModelFileError` naming the file, the line, the item, the field, what was expected and what
came. Regenerate the schema with
``python -m se3dyn.io.modelfile schema docs/model-file.schema.json``.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from se3dyn.errors import ModelError, close_matches
from se3dyn.model.builder import ModelBuilder, marker_offset
from se3dyn.model.joint_types import JOINT_TYPES
from se3dyn.model.specs import Model
from se3dyn.model.timefunc import Constant, Ramp, Sine, Step, Table
from se3dyn.model.visuals import SHAPES, visual_to_dict

__all__ = [
    "FORMAT_VERSION", "FIELDS", "ModelFileError", "load_model", "loads_model", "save_model",
    "json_schema", "markdown_reference", "write_schema", "parse_model_data", "format_model_data",
    "ElementSection", "ELEMENT_SECTIONS",
]

#: The format version written by :func:`save_model` and the only one :func:`loads_model` reads.
FORMAT_VERSION = 1

MAX_FILE_BYTES = 10 * 1024 * 1024  #: larger files are refused before parsing
MAX_DEPTH = 32  #: maximum nesting of YAML collections
MAX_ITEMS = 10_000  #: maximum entries of one YAML list or mapping
MAX_NODES = 200_000  #: maximum YAML nodes in a document

_JOINT_KEYS = tuple(sorted([*JOINT_TYPES, "universal"]))
_TF_KINDS = ("constant", "step", "ramp", "table", "sine")


# =================================================================================================
# Error
# =================================================================================================
class ModelFileError(ModelError):
    """An invalid model file: a :class:`~se3dyn.errors.ModelError` located in a file.

    Attributes (besides ``item``, ``field``, ``expected``, ``got`` of ModelError)
    ----------
    filename : str
    line : int or None
        1-based line number, when YAML gives one.

    The message reads ``"<file>, line <n>: <item>: field '<field>': expected <...>, got <...>
    (<hint>)"``.
    """

    def __init__(self, filename: str, line: int | None, item: str, field: str, expected: str,
                 got: Any = None, hint: str = "", *, message: str | None = None):
        super().__init__(item, field, expected, got, hint)
        self.filename = filename
        self.line = line
        loc = f"{filename}, line {line}" if line else str(filename)
        text = message if message is not None else self.args[0]
        text = re.sub(r"\s*\n\s*", " ", text)  # one line, always
        self.args = (f"{loc}: {text}",)


class _Got:
    """A ``got`` value whose repr is a ready-made description."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return self.text


class _Reject(Exception):
    """Raised inside the composer; turned into a ModelFileError by the loader."""

    def __init__(self, mark, field: str, expected: str, got: str, hint: str = ""):
        super().__init__(expected)
        self.mark, self.field, self.expected, self.got, self.hint = mark, field, expected, got, hint


# =================================================================================================
# Safe, bounded YAML composition with line numbers
# =================================================================================================
class _Loader(yaml.SafeLoader):
    """SafeLoader that composes a bounded node graph: no aliases or anchors, limited depth,
    collection sizes and node count. Plain scalars like ``1e-4`` are floats (as in YAML 1.2)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._count = 0
        self._path: list[str] = []
        self.tagged: list[tuple[Node, str]] = []  # nodes with an explicit tag, where

    def _where(self) -> str:
        return ".".join(self._path) or "(document)"

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            ev = self.peek_event()
            raise _Reject(ev.start_mark, self._where(), "plain values (no YAML aliases)",
                          f"alias *{ev.anchor}", "anchors (&name) and aliases (*name) are not "
                          "supported in se3dyn model files; write the values out")
        ev = self.peek_event()
        if getattr(ev, "anchor", None) is not None:
            raise _Reject(ev.start_mark, self._where(), "plain values (no YAML anchors)",
                          f"anchor &{ev.anchor}", "anchors (&name) and aliases (*name) are not "
                          "supported in se3dyn model files; write the values out")
        tag = getattr(ev, "tag", None)  # explicit tags only (!name, !!type): all refused,
        # naming the item and field where the tagged value sits (_section), or at worst where
        # it is in the document (_load_root)
        self._count += 1
        if self._count > MAX_NODES:
            raise _Reject(ev.start_mark, self._where(), f"at most {MAX_NODES} YAML values",
                          "more", "the document is too large")
        if self._depth >= MAX_DEPTH:
            raise _Reject(ev.start_mark, self._where(), f"at most {MAX_DEPTH} nested levels",
                          "deeper nesting")
        self._depth += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if tag is not None:
            node.explicit_tag = tag
            self.tagged.append((node, self._where()))
        return node

    def compose_sequence_node(self, anchor):
        start = self.get_event()
        tag = start.tag
        if tag is None or tag == "!":
            tag = self.resolve(SequenceNode, None, start.implicit)
        node = SequenceNode(tag, [], start.start_mark, None, flow_style=start.flow_style)
        i = 0
        while not self.check_event(yaml.SequenceEndEvent):
            if i >= MAX_ITEMS:
                raise _Reject(start.start_mark, self._where(),
                              f"a list of at most {MAX_ITEMS} items", "a longer list")
            self._path.append(f"[{i}]")
            try:
                node.value.append(self.compose_node(node, i))
            finally:
                self._path.pop()
            i += 1
        node.end_mark = self.get_event().end_mark
        return node

    def compose_mapping_node(self, anchor):
        start = self.get_event()
        tag = start.tag
        if tag is None or tag == "!":
            tag = self.resolve(MappingNode, None, start.implicit)
        node = MappingNode(tag, [], start.start_mark, None, flow_style=start.flow_style)
        while not self.check_event(yaml.MappingEndEvent):
            if len(node.value) >= MAX_ITEMS:
                raise _Reject(start.start_mark, self._where(),
                              f"a mapping of at most {MAX_ITEMS} entries", "a larger mapping")
            key = self.compose_node(node, None)
            self._path.append(str(key.value)[:40] if isinstance(key, ScalarNode) else "?")
            try:
                value = self.compose_node(node, key)
            finally:
                self._path.pop()
            node.value.append((key, value))
        node.end_mark = self.get_event().end_mark
        return node


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


# =================================================================================================
# Field types: validation + JSON schema + documentation text from one description
# =================================================================================================
_BAD = object()


class _Ctx:
    def __init__(self, filename: str, loader: _Loader):
        self.filename = filename
        self.loader = loader

    @staticmethod
    def line(node: Node | None) -> int | None:
        return None if node is None else node.start_mark.line + 1

    def scalar(self, node: Node) -> Any:
        if not isinstance(node, ScalarNode):
            return _BAD
        try:
            return self.loader.construct_object(node, deep=True)
        except Exception:  # unknown tags, oversized ints, bad timestamps: all "not a value"
            return _BAD

    def describe(self, node: Node) -> _Got:
        if isinstance(node, SequenceNode):
            return _Got(f"a list of {len(node.value)} item(s)")
        if isinstance(node, MappingNode):
            keys = [str(k.value) for k, _ in node.value[:5] if isinstance(k, ScalarNode)]
            return _Got("a mapping" + (f" with keys {', '.join(keys)}" if keys else " (empty)")
                        + (" ..." if len(node.value) > 5 else ""))
        v = self.scalar(node)
        if v is _BAD:
            return _Got(f"{node.value!r} (tag {node.tag})"[:100])
        s = repr(v)
        return _Got(s if len(s) <= 100 else s[:97] + "...")

    def fail(self, node: Node | None, item: str, fld: str, expected: str, got: Any = _BAD,
             hint: str = ""):
        if got is _BAD:
            got = self.describe(node) if node is not None else _Got("nothing")
        raise ModelFileError(self.filename, self.line(node), item, fld, expected, got, hint)


class _Type:
    """A field type of the format. The types, :class:`Field` and :class:`ElementSection` are
    frozen dataclasses that compare by identity (the schema never compares them, and each
    method a dataclass generates is compiled at every start-up); the types without
    parameters are plain classes."""

    text = ""

    def schema(self) -> dict:
        raise NotImplementedError

    def convert(self, ctx: _Ctx, node: Node, item: str, fld: str) -> Any:
        raise NotImplementedError


_schema_type = dataclass(frozen=True, eq=False)


def _num(ctx, node, item, fld, expected="a finite number") -> float:
    v = ctx.scalar(node)
    if isinstance(v, bool) or not isinstance(v, int | float):
        ctx.fail(node, item, fld, expected)
    try:
        f = float(v)
    except OverflowError:
        ctx.fail(node, item, fld, expected)
    if not math.isfinite(f):
        ctx.fail(node, item, fld, expected, hint="NaN and infinity are not allowed")
    return f


def _numlist(ctx, node, item, fld, expected, lo=0, hi=None) -> list[float]:
    if not isinstance(node, SequenceNode) or len(node.value) < lo or (
            hi is not None and len(node.value) > hi):
        ctx.fail(node, item, fld, expected)
    return [_num(ctx, n, item, f"{fld}[{i}]", f"a finite number ({expected})")
            for i, n in enumerate(node.value)]


_NUMBER = {"type": "number"}


@_schema_type
class Num(_Type):
    """A finite number; optional bounds; ``integer`` for counts."""

    minimum: float | None = None
    exclusive_minimum: float | None = None
    maximum: float | None = None
    integer: bool = False

    @property
    def text(self) -> str:
        s = "integer" if self.integer else "number"
        if self.exclusive_minimum is not None:
            s += f" > {self.exclusive_minimum:g}"
        elif self.minimum is not None:
            s += f" >= {self.minimum:g}"
        if self.maximum is not None:
            s += f", <= {self.maximum:g}"
        return s

    def schema(self) -> dict:
        d: dict[str, Any] = {"type": "integer" if self.integer else "number"}
        if self.minimum is not None:
            d["minimum"] = self.minimum
        if self.exclusive_minimum is not None:
            d["exclusiveMinimum"] = self.exclusive_minimum
        if self.maximum is not None:
            d["maximum"] = self.maximum
        return d

    def convert(self, ctx, node, item, fld):
        expected = ("an " if self.integer else "a finite ") + self.text
        if self.integer:
            v = ctx.scalar(node)
            if isinstance(v, bool) or not isinstance(v, int):
                ctx.fail(node, item, fld, expected)
            x: Any = v
        else:
            x = _num(ctx, node, item, fld, expected)
        if ((self.minimum is not None and x < self.minimum)
                or (self.exclusive_minimum is not None and x <= self.exclusive_minimum)
                or (self.maximum is not None and x > self.maximum)):
            ctx.fail(node, item, fld, expected)
        return x


class Version(_Type):
    text = f"integer, {FORMAT_VERSION}"

    def schema(self) -> dict:
        return {"const": FORMAT_VERSION}

    def convert(self, ctx, node, item, fld):
        v = ctx.scalar(node)
        if isinstance(v, bool) or not isinstance(v, int):
            ctx.fail(node, item, fld, f"the format version number {FORMAT_VERSION}")
        if v != FORMAT_VERSION:
            ctx.fail(node, item, fld, f"format version {FORMAT_VERSION}", v,
                     f"this se3dyn reads version {FORMAT_VERSION} only; upgrade se3dyn for "
                     f"newer files")
        return v


class Bool(_Type):
    text = "true / false"

    def schema(self) -> dict:
        return {"type": "boolean"}

    def convert(self, ctx, node, item, fld):
        v = ctx.scalar(node)
        if not isinstance(v, bool):
            ctx.fail(node, item, fld, "true or false")
        return v


@_schema_type
class BoolOr(_Type):
    """true / false, or one of the strings ``choices``."""

    choices: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        return "true / false / " + " / ".join(f"`{c}`" for c in self.choices)

    def schema(self) -> dict:
        return {"oneOf": [{"type": "boolean"}, {"enum": list(self.choices)}]}

    def convert(self, ctx, node, item, fld):
        v = ctx.scalar(node)
        if not (isinstance(v, bool) or (isinstance(v, str) and v in self.choices)):
            ctx.fail(node, item, fld, "true, false or " + ", ".join(self.choices))
        return v


@_schema_type
class Str(_Type):
    """A string, optionally one of ``choices``; ``ref`` for a node name (strings or integers)."""

    choices: tuple[str, ...] = ()
    ref: str = ""

    @property
    def text(self) -> str:
        if self.choices:
            return "one of " + ", ".join(f"`{c}`" for c in self.choices)
        return f"{self.ref} name" if self.ref else "string"

    def schema(self) -> dict:
        if self.choices:
            return {"enum": list(self.choices)}
        return {"type": ["string", "integer"]} if self.ref else {"type": "string"}

    def convert(self, ctx, node, item, fld):
        ok = (isinstance(node, ScalarNode) and node.tag in (
            "tag:yaml.org,2002:str", *(("tag:yaml.org,2002:int",) if self.ref else ())))
        expected = (f"one of {', '.join(self.choices)}" if self.choices
                    else f"a {self.ref} name" if self.ref else "a string")
        if not ok or not node.value:
            ctx.fail(node, item, fld, expected)
        v = str(node.value)
        if self.choices and v not in self.choices:
            close = close_matches(v, self.choices, n=1)
            ctx.fail(node, item, fld, expected, v, f"did you mean '{close[0]}'?" if close else "")
        return v


class Strs(_Type):
    """A string, or a list of 1..6 strings (a tuple of them)."""

    text = "a string or a list of 1-6 strings"

    def schema(self) -> dict:
        one = {"type": "string", "minLength": 1}
        return {"oneOf": [one, {"type": "array", "items": one, "minItems": 1, "maxItems": 6}]}

    def convert(self, ctx, node, item, fld):
        if isinstance(node, SequenceNode) and 1 <= len(node.value) <= 6:
            return tuple(Str().convert(ctx, n, item, f"{fld}[{i}]")
                         for i, n in enumerate(node.value))
        if isinstance(node, SequenceNode):
            ctx.fail(node, item, fld, self.text)
        return Str().convert(ctx, node, item, fld)


@_schema_type
class StrList(_Type):
    """A list of names (a single name is a list of one)."""

    @property
    def text(self) -> str:
        return "list of names"

    def schema(self) -> dict:
        return {"oneOf": [{"type": "string"}, {"type": "array", "items": {"type": "string"}}]}

    def convert(self, ctx, node, item, fld):
        items = node.value if isinstance(node, SequenceNode) else [node]
        out = []
        for n in items:
            if not isinstance(n, ScalarNode) or not n.value:
                ctx.fail(n, item, fld, "a list of names")
            out.append(str(n.value))
        return tuple(out)


@_schema_type
class Vec(_Type):
    """``n`` numbers (``n`` None: ``lo``..``hi`` numbers)."""

    n: int | None = 3
    lo: int = 1
    hi: int = 6

    @property
    def text(self) -> str:
        return f"{self.n} numbers" if self.n else f"list of {self.lo}-{self.hi} numbers"

    def schema(self) -> dict:
        lo, hi = (self.n, self.n) if self.n else (self.lo, self.hi)
        return {"type": "array", "items": _NUMBER, "minItems": lo, "maxItems": hi}

    def convert(self, ctx, node, item, fld):
        lo, hi = (self.n, self.n) if self.n else (self.lo, self.hi)
        return _numlist(ctx, node, item, fld, f"a list of {self.text}", lo, hi)


@_schema_type
class Mat(_Type):
    """A list of ``rmin``..``rmax`` rows of ``cols`` numbers each (``cols`` None: 0..6, all rows
    of equal length); ``flat``: a single list of ``rmin`` numbers is accepted too (k = 1)."""

    rmin: int = 3
    rmax: int = 3
    cols: int | None = 3
    flat: bool = False

    @property
    def text(self) -> str:
        r = (str(self.rmin) if self.rmin == self.rmax else
             f"{self.rmin} or {self.rmax}" if self.rmax == self.rmin + 1 else "n")
        c = str(self.cols) if self.cols else "k"
        s = f"{r} x {c} numbers (list of rows)"
        return s + (f", or {self.rmin} numbers (k = 1)" if self.flat else "")

    def schema(self) -> dict:
        row = {"type": "array", "items": _NUMBER, "minItems": self.cols or 0,
               "maxItems": self.cols or 6}
        d = {"type": "array", "items": row, "minItems": self.rmin, "maxItems": self.rmax}
        if self.flat:
            return {"oneOf": [d, {"type": "array", "items": _NUMBER, "minItems": self.rmin,
                                  "maxItems": self.rmin}]}
        return d

    def convert(self, ctx, node, item, fld):
        expected = "a list of " + self.text
        if not isinstance(node, SequenceNode) or not self.rmin <= len(node.value) <= self.rmax:
            ctx.fail(node, item, fld, expected)
        if self.flat and all(isinstance(n, ScalarNode) for n in node.value):
            return _numlist(ctx, node, item, fld, expected, self.rmin, self.rmin)
        lo, hi = (self.cols, self.cols) if self.cols else (0, 6)
        out = [_numlist(ctx, r, item, f"{fld}[{i}]",
                        f"a row of {self.cols or 'k'} numbers ({expected})", lo, hi)
               for i, r in enumerate(node.value)]
        if len({len(r) for r in out}) > 1:
            ctx.fail(node, item, fld, expected + " (rows of equal length)")
        return out


@_schema_type
class MatList(_Type):
    """A list of ``lo``..``hi`` matrices of ``rows`` x ``cols`` numbers (lists of rows)."""

    rows: int = 4
    cols: int = 4
    lo: int = 2
    hi: int = 100001

    @property
    def text(self) -> str:
        return f"list of {self.rows} x {self.cols} matrices (lists of rows)"

    def schema(self) -> dict:
        return {"type": "array", "items": Mat(self.rows, self.rows, self.cols).schema(),
                "minItems": self.lo, "maxItems": self.hi}

    def convert(self, ctx, node, item, fld):
        if not isinstance(node, SequenceNode) or not self.lo <= len(node.value) <= self.hi:
            ctx.fail(node, item, fld, f"a {self.text}, {self.lo} or more")
        m = Mat(self.rows, self.rows, self.cols)
        return [m.convert(ctx, x, item, f"{fld}[{i}]") for i, x in enumerate(node.value)]


@_schema_type
class OneOf(_Type):
    """The first alternative whose YAML shape matches (scalar / list / list of lists)."""

    alts: tuple[_Type, ...] = ()

    @property
    def text(self) -> str:
        return " or ".join(a.text for a in self.alts)

    def schema(self) -> dict:
        return {"oneOf": [a.schema() for a in self.alts]}

    def convert(self, ctx, node, item, fld):
        def shape(t):
            if isinstance(t, Num):
                return "scalar"
            if isinstance(t, Mat):
                return "matrix"
            return "list"

        if isinstance(node, SequenceNode):
            nested = bool(node.value) and isinstance(node.value[0], SequenceNode)
            want = "matrix" if nested else "list"
        else:
            want = "scalar"
        for a in self.alts:
            if shape(a) == want:
                return a.convert(ctx, node, item, fld)
        ctx.fail(node, item, fld, self.text)


@_schema_type
class Section(_Type):
    """A mapping whose fields are ``FIELDS[name]``."""

    name: str = ""

    @property
    def text(self) -> str:
        return f"mapping, see [{self.name}](#{self.name.replace(' ', '-')})"

    def schema(self) -> dict:
        return {"$ref": f"#/$defs/{self.name}"}

    def convert(self, ctx, node, item, fld):
        if self.name == "simulation":  # its own item: "simulation: field 'step': ..."
            return _section(ctx, node, self.name, "simulation", "")
        return _section(ctx, node, self.name, item, f"{fld}." if fld else "")


@_schema_type
class Named(_Type):
    """A mapping from names (keys, order kept) to ``FIELDS[section]`` mappings."""

    section: str = ""

    @property
    def text(self) -> str:
        return f"mapping name -> {self.section}, see [{self.section}](#{self.section})"

    def schema(self) -> dict:
        return {"type": "object", "additionalProperties": {"$ref": f"#/$defs/{self.section}"}}

    def convert(self, ctx, node, item, fld):
        if not isinstance(node, MappingNode):
            ctx.fail(node, item, fld, f"a mapping from {self.section} names to {self.section}s")
        out = []
        seen: dict[str, int] = {}
        for k, v in node.value:
            if not isinstance(k, ScalarNode) or not k.value:
                ctx.fail(k, item, fld, f"a {self.section} name (a non-empty string)")
            name = str(k.value)
            if name in seen:
                ctx.fail(k, f"{self.section} {name!r}", "name", f"a unique {self.section} name",
                         name, f"{self.section} {name!r} is already defined at line "
                         f"{seen[name]}")
            seen[name] = ctx.line(k)
            obj = _section(ctx, v, self.section, f"{self.section} {name!r}", "")
            obj.name, obj.line = name, ctx.line(k)
            out.append(obj)
        return out


class TimeFunc(_Type):
    """A number or list (constant) or ``{kind: {fields}}`` with kind in constant, step, ramp,
    table, sine."""

    text = "time function: number, list, or {constant\\|step\\|ramp\\|table\\|sine: {...}}"

    def schema(self) -> dict:
        return {"$ref": "#/$defs/time_function"}

    def convert(self, ctx, node, item, fld):
        expected = ("a number, a list of numbers or a time function {kind: {...}} with kind "
                    "one of " + ", ".join(_TF_KINDS))
        if isinstance(node, ScalarNode):
            return _num(ctx, node, item, fld, expected)
        if isinstance(node, SequenceNode):
            return _numlist(ctx, node, item, fld, expected, 1, 6)
        if len(node.value) != 1:
            ctx.fail(node, item, fld, expected + " (exactly one kind)")
        knode, vnode = node.value[0]
        kind = str(knode.value) if isinstance(knode, ScalarNode) else ""
        if kind not in _TF_KINDS:
            close = close_matches(kind, _TF_KINDS, n=1)
            ctx.fail(knode, item, fld, "a time function kind: " + ", ".join(_TF_KINDS),
                     _Got(repr(kind)), f"did you mean '{close[0]}'?" if close else "")
        obj = _section(ctx, vnode, kind, item, f"{fld}.{kind}.")
        cls = {"constant": Constant, "step": Step, "ramp": Ramp, "table": Table,
               "sine": Sine}[kind]
        try:
            return cls(**obj.values)
        except ModelError as e:
            key = e.field if e.field in obj.lines else None
            raise ModelFileError(ctx.filename, obj.lines.get(key, ctx.line(vnode)), item,
                                 f"{fld}.{kind}.{e.field}", e.expected, e.got) from None


class ByIndex(_Type):
    """A time function, or a mapping ``{coordinate index: time function}`` (a drive of a
    joint with several coordinates)."""

    text = "time function, or {index: time function} by coordinate index"

    def schema(self) -> dict:
        return {"oneOf": [{"$ref": "#/$defs/time_function"},
                          {"type": "object", "minProperties": 1,
                           "patternProperties": {"^[0-9]+$": {"$ref": "#/$defs/time_function"}},
                           "additionalProperties": False}]}

    def convert(self, ctx, node, item, fld):
        tf = TimeFunc()
        keys = [k for k, _ in node.value] if isinstance(node, MappingNode) else []
        if not keys or not all(isinstance(k, ScalarNode) and str(k.value).isdigit()
                               for k in keys):
            return tf.convert(ctx, node, item, fld)
        return {int(k.value): tf.convert(ctx, v, item, f"{fld}.{k.value}")
                for k, v in node.value}


class Color(_Type):
    """A colour: a string (``#rrggbb``, ``#rgb`` or a name, checked by the builder) or 3
    numbers in [0, 1]."""

    text = "`'#rrggbb'`, a colour name, or 3 numbers in [0, 1]"

    def schema(self) -> dict:
        return {"oneOf": [{"type": "string"}, {"type": "array", "items": _NUMBER,
                                               "minItems": 3, "maxItems": 3}]}

    def convert(self, ctx, node, item, fld):
        if isinstance(node, SequenceNode):
            return _numlist(ctx, node, item, fld, "3 numbers in [0, 1]", 3, 3)
        if not isinstance(node, ScalarNode) or node.tag != "tag:yaml.org,2002:str":
            ctx.fail(node, item, fld, "a colour: '#rrggbb', a colour name or 3 numbers in "
                     "[0, 1]")
        return str(node.value)


@_schema_type
class Field:
    """One field of a section: name, type, default (``None``: absent), description."""

    name: str
    type: _Type
    default: Any = None
    doc: str = ""
    required: bool = False


_V3 = Vec(3)
_M33 = Mat(3, 3, 3)
_VALUE = OneOf((Num(), Vec(None, 1, 6)))


@_schema_type
class ElementSection:
    """The model-file section of an element type, declared by its module in
    :mod:`se3dyn.elements` as ``model_file(mf) -> ElementSection`` (``mf``: this module, for
    the field types). :data:`FIELDS`, the loader, :func:`save_model`, the JSON Schema and the
    Markdown reference are generated from these, in the order of the element registry.

    Attributes
    ----------
    key : str
        The top-level field of the file, a mapping name -> entry (e.g. ``springs``).
    kind : str
        What an entry is: its section in :data:`FIELDS`, and the item in error messages
        (e.g. ``spring_damper``).
    doc : str
        Description of the top-level field.
    entry_doc : str
        Description of one entry.
    fields : tuple of Field
        The fields of an entry.
    add : callable (ModelBuilder, name, dict of field values) -> None
        Adds one entry to the builder (raising :class:`~se3dyn.errors.ModelError`).
    save : callable (Model) -> dict
        name -> entry (plain data) of a model's elements of this type; empty for none.
    subsections : tuple of (name, doc, fields)
        Mappings inside an entry (:class:`Section` fields), e.g. a joint's ``control``.
    nodes : callable (Model) -> set of str, optional
        Names of the nodes the entries create themselves (a beam's intermediate nodes): left
        out of the ``nodes:`` section when saving.
    """

    key: str
    kind: str
    doc: str
    entry_doc: str
    fields: tuple[Field, ...]
    add: Callable[[ModelBuilder, str, dict], None]
    save: Callable[[Model], dict]
    subsections: tuple[tuple[str, str, tuple[Field, ...]], ...] = ()
    nodes: Callable[[Model], set] | None = None


def _element_sections() -> tuple[ElementSection, ...]:
    from se3dyn.elements import REGISTRY

    mf = sys.modules[__name__]
    return tuple(mod.model_file(mf) for mod in REGISTRY.values()
                 if hasattr(mod, "model_file"))


#: The sections of the element types (registry order): ``model_file(mf)`` of their modules.
ELEMENT_SECTIONS: tuple[ElementSection, ...] = _element_sections()

#: The single source of truth of the format: section -> fields.
FIELDS: dict[str, tuple[Field, ...]] = {
    "model": (
        Field("se3dyn", Version(), None, "Format version of the file (required).", True),
        Field("name", Str(), "model", "Model name (used in results and files)."),
        Field("gravity", _V3, [0, 0, 0], "Gravity acceleration in the inertial frame (m/s^2)."),
        Field("nodes", Named("node"), None, "Nodes by name, in order (required).", True),
        *(Field(es.key, Named(es.kind), {}, es.doc) for es in ELEMENT_SECTIONS),
        Field("visuals", Named("visual"), {}, "Shapes drawn by the viewer, by name (pictures "
              "only, no effect on the motion)."),
        Field("markers", Named("marker"), {}, "Frames fixed on nodes, by name: where the "
              "results read positions, velocities, accelerations, an accelerometer and a "
              "gyroscope (outputs only, no effect on the motion)."),
        Field("drives", Named("drive"), {}, "Prescribed motion of joint coordinates, by "
              "name (rheonomic drivers; the force or torque they supply is an output)."),
        Field("couplings", Named("coupling"), {}, "Exact couplings of joint coordinates by "
              "name (gears, racks, belts, mimic joints): follower = ratio leader + offset."),
        Field("simulation", Section("simulation"), {}, "Simulation settings, returned by "
              "`load_model` as a dict for `se3dyn.simulate(model, **settings)`."),
    ),
    "node": (
        Field("position", _V3, [0, 0, 0], "Initial position in the inertial frame (m)."),
        Field("orientation", _M33, "identity", "Initial rotation R0 (rows of the matrix; its "
              "columns are the material axes in the inertial frame)."),
        Field("mass", Num(minimum=0), 0, "Mass (kg)."),
        Field("inertia", OneOf((_V3, _M33)), None, "Principal moments (J1, J2, J3) about "
              "`principal_axes`, or a full symmetric 3x3 tensor in the inertial frame of the "
              "initial configuration (kg m^2). Required when mass > 0."),
        Field("principal_axes", _M33, "identity", "Rotation whose columns are the principal "
              "axes (only with 3 principal moments)."),
        Field("fixed", Bool(), False, "Clamped node (no unknowns; no mass, no velocity)."),
        Field("velocity", _V3, [0, 0, 0], "Initial linear velocity (m/s)."),
        Field("angular_velocity", _V3, [0, 0, 0], "Initial angular velocity (rad/s)."),
        Field("velocity_frame", Str(("inertial", "material")), "inertial",
              "Frame of `velocity` and `angular_velocity`."),
        Field("com", _V3, None, "Centre of mass as a point in the inertial frame of the initial "
              "configuration (m), when the node is not at it (at a joint, at the fixed point of "
              "a top); `inertia` is then about the centre of mass. Absent: at the node."),
    ),
    **{name: fields for es in ELEMENT_SECTIONS
       for name, fields in ((es.kind, es.fields), *((n, f) for n, _, f in es.subsections))},
    "visual": (
        Field("node", Str(ref="node"), None, "The node the shape moves with (required).", True),
        Field("shape", Str(tuple(SHAPES)), None, "Shape (required).", True),
        Field("size", OneOf((Num(exclusive_minimum=0), Vec(None, 1, 3))), None, "box: side "
              "lengths (a, b, c) or one number (cube); sphere: radius; cylinder, capsule: "
              "(radius, length) along the shape's z axis (capsule: length between the "
              "hemisphere centres); mesh: scale, one or 3 numbers (default 1). Required "
              "except for meshes (m)."),
        Field("color", Color(), "palette", "Colour: `'#rrggbb'`, `'#rgb'`, a name (red, green, "
              "blue, orange, grey, ...) or RGB in [0, 1]."),
        Field("offset", _V3, [0, 0, 0], "Origin of the shape in the material frame of the node "
              "(m)."),
        Field("axis", _V3, None, "Direction of the shape's z axis in the material frame of the "
              "node (instead of `orientation`)."),
        Field("orientation", _M33, "identity", "Rotation of the shape in the material frame of "
              "the node (rows of the matrix; its columns are the shape's axes)."),
        Field("file", Str(), None, "Mesh file (STL, OBJ, glTF/GLB) for `shape: mesh`; a "
              "relative path is looked up next to the model file."),
    ),
    "marker": (
        Field("node", Str(ref="node"), None, "The node (body) the marker moves with; a fixed "
              "node is allowed (required).", True),
        Field("at", _V3, None, "Origin of the marker as a point in the inertial frame of the "
              "initial configuration (m). Absent (and no `offset`): at the node."),
        Field("offset", _V3, None, "Instead of `at`: the origin in the material frame of the "
              "node (m)."),
        Field("orientation", _M33, "the node's", "Rotation of the marker in the initial "
              "configuration (rows of the matrix; its columns are the marker axes in the "
              "inertial frame)."),
    ),
    "drive": (
        Field("joint", Str(ref="joint"), None, "The driven joint: abelian (hinge, prismatic, "
              "cylindrical, screw, universal; required).", True),
        Field("position", ByIndex(), None, "Its coordinate alpha(t) (absolute: zero in the "
              "initial configuration, or the joint's `initial` there); `{index: ...}` for a "
              "joint with several coordinates."),
        Field("velocity", ByIndex(), None, "Instead of `position` (per coordinate): its rate "
              "v(t), the position integrated by the time loop."),
    ),
    "coupling": (
        Field("leader", Str(ref="joint"), None, "The leading joint (abelian; required).", True),
        Field("follower", Str(ref="joint"), None, "The following joint (abelian; required).",
              True),
        Field("ratio", Num(), 1, "alpha_follower = ratio alpha_leader + offset (a gear pair: "
              "minus the ratio of the teeth numbers; nonzero)."),
        Field("offset", Num(), 0, "The offset (rad or m)."),
        Field("leader_coordinate", Num(integer=True, minimum=0), 0, "The leader's coordinate "
              "(joints with several)."),
        Field("follower_coordinate", Num(integer=True, minimum=0), 0, "The follower's "
              "coordinate (joints with several)."),
    ),
    "simulation": (
        Field("t_end", Num(), None, "Final time (s)."),
        Field("step", Num(exclusive_minimum=0), None, "Time step h (s)."),
        Field("t_start", Num(), 0, "Initial time (s)."),
        Field("rho_inf", Num(minimum=0, maximum=1), 0.9, "Spectral radius at infinite "
              "frequency (Eq. 44)."),
        Field("tol_residual", Num(exclusive_minimum=0), 1e-10, "Newton residual tolerance."),
        Field("tol_constraint", Num(exclusive_minimum=0), 1e-11, "Constraint tolerance."),
        Field("max_iter", Num(minimum=1, integer=True), 25, "Newton iterations per step."),
        Field("output_every", Num(minimum=1, integer=True), 1, "Store every k-th step."),
        Field("formulation", Str(("index2", "index3")), "index2", "Stabilized index-2 "
              "(second order in positions, velocities and multipliers) or the paper's index-3 "
              "form."),
        Field("redundant", Str(("drop", "error")), "drop", "Redundant constraint equations: "
              "left out with zero multipliers, or an error."),
        Field("tol", Num(exclusive_minimum=0), None, "Adaptive time stepping: the local "
              "position errors (m, RMS over each body's mass) add up to `tol` over a run of "
              "even difficulty; where it varies, the steps vary as the -1/6th power of the "
              "local error (docs/accuracy.md); `step` is then the initial step."),
        Field("h_min", Num(exclusive_minimum=0), "1e-12 x duration", "Smallest adaptive step "
              "(s)."),
        Field("h_max", Num(exclusive_minimum=0), "duration / 10", "Largest adaptive step (s)."),
        Field("output_step", Num(exclusive_minimum=0), None, "Store results every output_step "
              "seconds (dense output), whatever the internal steps."),
        Field("initial_velocities", Str(("project", "strict")), "project", "Initial "
              "velocities the joints do not allow: projected onto the velocity constraints "
              "(reported per node in the run summary and the results' stats), or refused."),
        Field("global_error", BoolOr(("bound",)), False, "With `tol`: `true` estimates the "
              "run's global position error by a companion run on its steps taken two at a "
              "time (Richardson; about half the steps again), reported in the run summary and "
              "the results' stats; `bound` also repeats the run on its steps refined until the "
              "estimate is within `tol` (the results are then written when the run is done)."),
        Field("condense", Bool(), True, "Nodes joined by rigid joints move as one body in the "
              "time loop (fewer unknowns; every node's motion and every joint's reactions are "
              "still reported); false keeps the rigid joints as constraints."),
    ),
    "constant": (
        Field("value", _VALUE, None, "f(t) = value (required).", True),
    ),
    "step": (
        Field("value", _VALUE, None, "Value for start <= t < stop, zero otherwise (required).",
              True),
        Field("start", Num(), 0, "Switch-on time (s)."),
        Field("stop", Num(), "forever", "Switch-off time (s); omit for never."),
    ),
    "ramp": (
        Field("value", _VALUE, None, "Final value (required).", True),
        Field("start", Num(), 0, "Start of the ramp (s); zero before."),
        Field("duration", Num(exclusive_minimum=0), 1, "Duration of the linear rise (s)."),
    ),
    "table": (
        Field("times", Vec(None, 2, MAX_ITEMS), None, "Strictly increasing times (required).",
              True),
        Field("values", OneOf((Vec(None, 2, MAX_ITEMS), Mat(2, MAX_ITEMS, None))), None,
              "One value (or one row of k values) per time; piecewise linear, held constant "
              "outside (required).", True),
    ),
    "sine": (
        Field("amplitude", _VALUE, None, "Amplitude (required).", True),
        Field("frequency", Num(minimum=0), None, "Frequency (Hz) (required).", True),
        Field("phase", Num(), 0, "Phase (rad)."),
        Field("offset", _VALUE, 0, "Offset."),
    ),
}

_SECTION_DOC = {
    "model": "The top level of the file.",
    "node": "An entry of `nodes:` (key: the node name). A frame in SE(3) with optional rigid-"
            "body inertia.",
    **{name: doc for es in ELEMENT_SECTIONS
       for name, doc in ((es.kind, es.entry_doc), *((n, d) for n, d, _ in es.subsections))},
    "visual": "An entry of `visuals:` (key: the visual name). A shape drawn with a node by "
              "`se3dyn view` and `se3dyn export --gltf`, placed in the material frame of the "
              "node; it has no mass and no effect on the motion. A node with visuals is drawn "
              "by them instead of the default solid sized from its inertia.",
    "marker": "An entry of `markers:` (key: the marker name). A frame fixed on a node; the "
              "results give its position, rotation, velocity and acceleration (material and "
              "inertial), an accelerometer (specific force R_m^T (a - g) in the marker axes: "
              "-g at rest) and a gyroscope (angular velocity in the marker axes), as methods of "
              "`Results` and as `marker/<name>/...` channels.",
    "drive": "An entry of `drives:` (key: the drive name). Coordinates of an abelian joint "
             "follow the given functions of time exactly, beside the free motion of the rest; "
             "the driving force or torque is `Results.drive_effort(name)` and the channel "
             "`drive/<name>/effort` (see `ModelBuilder.drive`).",
    "coupling": "An entry of `couplings:` (key: the coupling name). The follower's coordinate "
                "moves with the leader's exactly; the coupling's force on the follower is "
                "`Results.coupling_force(name)` and the channel `coupling/<name>/force` (see "
                "`ModelBuilder.coupling`).",
    "simulation": "The `simulation:` mapping: keyword arguments of `se3dyn.simulate`.",
    "constant": "Time function `{constant: {...}}`.",
    "step": "Time function `{step: {...}}`.",
    "ramp": "Time function `{ramp: {...}}`: zero before start, linear to value at start + "
            "duration, constant after.",
    "table": "Time function `{table: {...}}`: `values` is a list of numbers or a list of rows "
             "(k-vector function).",
    "sine": "Time function `{sine: {...}}`: offset + amplitude sin(2 pi frequency t + phase).",
}


@dataclass(eq=False)
class _Obj:
    values: dict = field(default_factory=dict)
    lines: dict = field(default_factory=dict)
    line: int | None = None
    name: str = ""


def _plain(text: str) -> str:
    """Documentation text without Markdown (for error messages)."""
    text = re.sub(r", see \[[^]]*\]\([^)]*\)", "", text)
    return text.replace("\\|", "|").replace("`", "")


_NO_TAGS = "tags (!name, !!type) are not supported in se3dyn model files; write the plain value"


def _tagged(node: Node, deep: bool) -> Node | None:
    """The first node with an explicit YAML tag: ``node`` itself, or with ``deep`` any node
    inside it."""
    if getattr(node, "explicit_tag", None) is not None:
        return node
    if deep and isinstance(node, SequenceNode | MappingNode):
        for sub in (node.value if isinstance(node, SequenceNode)
                    else [x for kv in node.value for x in kv]):
            hit = _tagged(sub, True)
            if hit is not None:
                return hit
    return None


def _tag_fail(ctx: _Ctx, node: Node, item: str, fld: str):
    ctx.fail(node, item, fld, "a plain value (no YAML tags)",
             _Got(f"a value tagged {node.explicit_tag}"[:100]), _NO_TAGS)


def _section(ctx: _Ctx, node: Node, sec: str, item: str, prefix: str) -> _Obj:
    fields = {f.name: f for f in FIELDS[sec]}
    where = prefix.rstrip(".") or "(fields)"
    if not isinstance(node, MappingNode):
        ctx.fail(node, item, where, f"a mapping of {sec} fields ({', '.join(fields)})",
                 hint="write {} for all defaults" if isinstance(node, ScalarNode)
                 and node.tag.endswith(":null") else "")
    obj = _Obj(line=ctx.line(node))
    for k, v in node.value:
        if not isinstance(k, ScalarNode):
            ctx.fail(k, item, where, "field names (plain strings)")
        key = str(k.value)
        if key in obj.lines:
            ctx.fail(k, item, prefix + key, "each field once", _Got(f"a second '{key}'"),
                     f"'{key}' is already given at line {obj.lines[key]}")
        obj.lines[key] = ctx.line(k)
        f = fields.get(key)
        if f is None:
            close = close_matches(key, list(fields), n=1)
            ctx.fail(k, item, prefix + key, f"a {sec} field: " + ", ".join(fields),
                     _Got(f"unknown field {key!r}"),
                     f"did you mean '{close[0]}'?" if close else "")
        hit = _tagged(k, False) or _tagged(v, not isinstance(f.type, Section | Named))
        if hit is not None:
            _tag_fail(ctx, hit, item, prefix + key)
        if isinstance(v, ScalarNode) and v.tag == "tag:yaml.org,2002:null" and not f.required:
            continue  # null = not given
        obj.values[key] = f.type.convert(ctx, v, item, prefix + key)
    for f in FIELDS[sec]:
        if f.required and f.name not in obj.values:
            ctx.fail(node, item, prefix + f.name, f"a value for the required field '{f.name}' "
                     f"({_plain(f.type.text)})", _Got("nothing"))
    return obj


# =================================================================================================
# Loading
# =================================================================================================
def load_model(path_or_text: str | os.PathLike | bytes) -> tuple[Model, dict]:
    """Load a model file.

    Parameters
    ----------
    path_or_text : str, os.PathLike or bytes
        A path, or the YAML text itself: ``bytes`` and ``str`` values containing a newline are
        taken as text, other ``str`` values and path objects as file names.

    Returns
    -------
    (Model, dict)
        The built model and the ``simulation:`` settings as given (keyword arguments of
        :func:`se3dyn.simulate`; empty when the file has none).

    Raises
    ------
    ModelFileError
        For any invalid file (unreadable, too large, not UTF-8, bad YAML, invalid model).
    """
    if isinstance(path_or_text, bytes) or (isinstance(path_or_text, str)
                                           and "\n" in path_or_text):
        return loads_model(path_or_text)
    if not isinstance(path_or_text, str | os.PathLike):
        raise ModelFileError("<argument>", None, "file", "path", "a file name (str or path) or "
                             "YAML text", _Got(type(path_or_text).__name__))
    name = os.fspath(path_or_text)
    if not isinstance(name, str):
        name = os.fsdecode(name)
    try:
        size = os.path.getsize(name)
        if size > MAX_FILE_BYTES:
            raise ModelFileError(name, None, "file", "size", f"at most {MAX_FILE_BYTES} bytes",
                                 _Got(f"{size} bytes"))
        with open(name, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except (OSError, ValueError) as e:  # ValueError: a NUL character in the name
        raise ModelFileError(name, None, "file", "path", "a readable model file",
                             _Got(f"{type(e).__name__}: {getattr(e, 'strerror', None) or e}")
                             ) from None
    return loads_model(data, filename=name)


def loads_model(text: str | bytes, filename: str = "<string>") -> tuple[Model, dict]:
    """Load a model from YAML text (``str`` or UTF-8 ``bytes``); see :func:`load_model`.

    ``filename`` is only used in error messages.
    """
    if isinstance(text, bytes):
        if len(text) > MAX_FILE_BYTES:
            raise ModelFileError(filename, None, "file", "size",
                                 f"at most {MAX_FILE_BYTES} bytes", _Got(f"{len(text)} bytes"))
        try:
            text = text.decode("utf-8-sig")
        except UnicodeDecodeError as e:
            line = text[: e.start].count(b"\n") + 1
            raise ModelFileError(filename, line, "file", "encoding", "UTF-8 text",
                                 _Got(f"byte 0x{text[e.start]:02x} at offset {e.start}"),
                                 "save the file as UTF-8") from None
    if not isinstance(text, str):
        raise ModelFileError(filename, None, "file", "text", "YAML text (str or bytes)",
                             _Got(type(text).__name__))
    if len(text) > MAX_FILE_BYTES:
        raise ModelFileError(filename, None, "file", "size", f"at most {MAX_FILE_BYTES} "
                             "characters", _Got(f"{len(text)} characters"))
    loader = None
    try:
        loader = _Loader(text)
        root = loader.get_single_node()
    except _Reject as r:
        raise ModelFileError(filename, r.mark.line + 1, "document", r.field, r.expected,
                             _Got(r.got), r.hint) from None
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        problem = " ".join(s for s in (e.context, e.problem) if s)
        raise ModelFileError(filename, mark.line + 1 if mark else None, "document", "syntax",
                             "valid YAML", _Got(problem or "invalid YAML")) from None
    except yaml.reader.ReaderError as e:  # control characters
        pos = e.position if isinstance(e.position, int) else 0
        raise ModelFileError(filename, text[:pos].count("\n") + 1, "document", "syntax",
                             "valid YAML (printable characters)",
                             _Got(f"character #x{e.character:04x} at offset {pos}"
                                  if isinstance(e.character, int) else "a special character"),
                             "special characters are not allowed") from None
    except yaml.YAMLError as e:
        raise ModelFileError(filename, None, "document", "syntax", "valid YAML",
                             _Got(str(e).splitlines()[0] if str(e) else "invalid YAML")) from None
    except RecursionError:  # pragma: no cover - bounded by MAX_DEPTH
        raise ModelFileError(filename, None, "document", "nesting", "less deeply nested YAML",
                             _Got("too deep")) from None
    ctx = _Ctx(filename, loader)
    try:
        return _load_root(ctx, root)
    finally:
        loader.dispose()


def _load_root(ctx: _Ctx, root: Node | None) -> tuple[Model, dict]:
    item = "model"
    if root is None:
        ctx.fail(None, item, "se3dyn", f"a mapping starting with 'se3dyn: {FORMAT_VERSION}'",
                 _Got("an empty document"))
    if not isinstance(root, MappingNode):
        ctx.fail(root, item, "(document)",
                 f"a mapping starting with 'se3dyn: {FORMAT_VERSION}'")
    # the version first: a newer file gets a version error, not a list of unknown fields
    ver = [v for k, v in root.value if isinstance(k, ScalarNode) and k.value == "se3dyn"]
    if not ver:
        ctx.fail(root, item, "se3dyn", f"the format version 'se3dyn: {FORMAT_VERSION}' at the "
                 "top", _Got("no 'se3dyn' field"), "every se3dyn model file starts with "
                 f"'se3dyn: {FORMAT_VERSION}'")
    if _tagged(root, False) is not None:
        _tag_fail(ctx, root, item, "(document)")
    Version().convert(ctx, ver[0], item, "se3dyn")
    top = _section(ctx, root, "model", item, "")
    if ctx.loader.tagged:  # a tag where no field looked (e.g. on an item name)
        node, where = ctx.loader.tagged[0]
        _tag_fail(ctx, node, "document", where)
    return _build(ctx, top)


_FIELD_ALIAS = {"node_a": "a", "node_b": "b"}


def _rethrow(ctx: _Ctx, e: ModelError, obj: _Obj | None, items: dict[str, int]) -> None:
    """Re-raise a builder ModelError with the file name and the line of the offending field."""
    fld = _FIELD_ALIAS.get(e.field, e.field)
    msg = str(e)
    if fld != e.field:
        msg = msg.replace(f"field '{e.field}'", f"field '{fld}'", 1)
    line = None
    if obj is None:
        for key, ln in items.items():
            if e.item == key or e.item.startswith(key + " "):
                line = ln
    else:
        root = re.split(r"[.\[]", fld)[0]
        line = obj.lines.get(root, obj.line)
        if root == "actuator" and root not in obj.lines:
            line = obj.lines.get("torque", obj.lines.get("force", obj.line))
    raise ModelFileError(ctx.filename, line, e.item, fld, e.expected, e.got,
                         message=msg) from None


def _build(ctx: _Ctx, top: _Obj) -> tuple[Model, dict]:
    v = top.values
    items: dict[str, int] = {}
    try:
        mb = ModelBuilder(gravity=v.get("gravity", (0.0, 0.0, 0.0)), name=v.get("name", "model"))
    except ModelError as e:
        _rethrow(ctx, e, top, items)
    # section -> (item kind in error messages, builder call with the entry's name and fields)
    sections = (
        ("nodes", "node", lambda name, kw: mb.node(name, **kw)),
        *((es.key, es.kind, lambda name, kw, es=es: es.add(mb, name, kw))
          for es in ELEMENT_SECTIONS),
        ("visuals", "visual",
         lambda name, kw: mb.visual(name, kw.pop("node"), kw.pop("shape"), **kw)),
        ("markers", "marker", lambda name, kw: mb.marker(name, kw.pop("node"), **kw)),
        ("drives", "drive", lambda name, kw: mb.drive(name, kw.pop("joint"), **kw)),
        ("couplings", "coupling", lambda name, kw: mb.coupling(name, **kw)),
    )
    for sec, kind, add in sections:
        for obj in v.get(sec, []):
            items[f"{kind} {obj.name!r}"] = obj.line
            try:
                add(obj.name, dict(obj.values))
            except ModelError as e:
                _rethrow(ctx, e, obj, items)
    try:
        model = mb.build()
    except ModelError as e:
        _rethrow(ctx, e, None, items)
    sim = v.get("simulation")
    return model, (dict(sim.values) if sim is not None else {})


def parse_model_data(text: str | bytes, filename: str = "<string>") -> dict:
    """The document of a valid model file as plain data (dicts, lists, numbers, strings).

    The text is validated first by :func:`loads_model` (same errors, same safety limits) and
    read with the same scalar rules (``1e-4`` is a float). Edit the data and load it back with
    ``loads_model(format_model_data(data))``; used by parameter sweeps (:mod:`se3dyn.sweep`).

    Raises
    ------
    ModelFileError
        For any invalid model file, as :func:`loads_model`.
    """
    loads_model(text, filename)
    if isinstance(text, bytes):
        text = text.decode("utf-8-sig")
    loader = _Loader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def format_model_data(data: dict) -> str:
    """YAML text of model-file data (plain dicts, lists, numbers, strings, in order), the
    inverse of :func:`parse_model_data`; load it with :func:`loads_model`."""
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, default_flow_style=None,
                     width=10_000, allow_unicode=True)


# =================================================================================================
# Saving
# =================================================================================================
def plain(x: Any) -> Any:
    """Plain Python floats/lists for the YAML dumper (arrays, tuples, numpy scalars)."""
    if isinstance(x, np.ndarray):
        return x.astype(float).tolist()
    if isinstance(x, list | tuple):
        return [plain(e) for e in x]
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, int | float | np.integer | np.floating):
        return float(x)
    return x


def time_function_data(f: Any, item: str, fld: str) -> Any:
    """The model-file data of a built-in time function (ModelError for a Python callable,
    naming ``item`` and ``fld``)."""
    if isinstance(f, Constant):
        return plain(f.value)
    if isinstance(f, Step):
        d = {"value": plain(f.value), "start": float(f.start)}
        if math.isfinite(f.stop):
            d["stop"] = float(f.stop)
        return {"step": d}
    if isinstance(f, Ramp):
        return {"ramp": {"value": plain(f.value), "start": float(f.start),
                         "duration": float(f.duration)}}
    if isinstance(f, Table):
        return {"table": {"times": plain(f.times), "values": plain(f.values)}}
    if isinstance(f, Sine):
        return {"sine": {"amplitude": plain(f.amplitude), "frequency": float(f.frequency),
                         "phase": float(f.phase), "offset": plain(f.offset)}}
    raise ModelError(item, fld, "a built-in time function (constant, step, ramp, table, sine) "
                     "to write a model file", getattr(f, "fn", f),
                     "a Python callable cannot be saved; replace it by a table or another "
                     "built-in time function")


def _node_out(n) -> dict:
    d: dict[str, Any] = {"position": plain(n.position)}
    if not np.array_equal(n.orientation, np.eye(3)):
        d["orientation"] = plain(n.orientation)
    if n.mass != 0:
        d["mass"] = float(n.mass)
    if np.any(n.inertia != 0):
        # the builder symmetrises full tensors; R J' R^T from principal axes may be asymmetric
        # in the last bit: write the symmetric part, which is what loading gives anyway
        J = 0.5 * (n.inertia + n.inertia.T)
        d["inertia"] = plain(np.diag(J)) if np.array_equal(J, np.diag(np.diag(J))) else plain(J)
    if n.fixed:
        d["fixed"] = True
    if np.any(n.velocity[:3] != 0):
        d["velocity"] = plain(n.velocity[:3])
    if np.any(n.velocity[3:] != 0):
        d["angular_velocity"] = plain(n.velocity[3:])
    if n.com is not None:
        d["com"] = plain(n.com)
    return d


def _marker_out(model: Model, mk) -> dict:
    """A marker as given to the builder; as its offset X (origin in the node frame, axes at
    t0) when its node's initial frame has changed since (a model from ``assemble``)."""
    d: dict[str, Any] = {"node": mk.node}
    node = model.node(mk.node)
    if np.array_equal(marker_offset(node, mk.at, mk.offset, mk.orientation), mk.X):
        for fld in ("at", "offset", "orientation"):
            if getattr(mk, fld) is not None:
                d[fld] = plain(getattr(mk, fld))
        return d
    d["offset"] = plain(mk.X[:3, 3])
    if not np.array_equal(mk.X[:3, :3], np.eye(3)):
        d["orientation"] = plain(node.orientation @ mk.X[:3, :3])
    return d


def _coupling_out(c) -> dict:
    """A coupling as given to the builder."""
    d: dict[str, Any] = {"leader": c.leader[0], "follower": c.follower[0], "ratio": c.ratio}
    if c.offset:
        d["offset"] = c.offset
    for fld, end in (("leader_coordinate", c.leader), ("follower_coordinate", c.follower)):
        if end[1]:
            d[fld] = end[1]
    return d


def _drive_out(model: Model, d) -> dict:
    """A drive as given to the builder (a dict by index for a joint of several coordinates)."""
    out: dict[str, Any] = {"joint": d.joint}
    many = len(model.composites.get(d.joint, ())) > 1 or (
        d.joint not in model.composites and model.joint(d.joint).k > 1)
    for fld in ("position", "velocity"):
        given = getattr(d, fld)
        data = {i: time_function_data(f, f"drive {d.name!r}", f"{fld}[{i}]")
                for i, f in given.items()}
        if data:
            out[fld] = data if many else data[0]
    return out


class _Dumper(yaml.SafeDumper):
    pass


def save_model(model: Model, path: str | os.PathLike | None = None,
               settings: dict | None = None) -> str:
    """Write ``model`` (and optional simulation ``settings``) as a version-1 model file.

    Returns the YAML text; also writes it to ``path`` when given. ``load_model(save_model(m))``
    gives a model equal to ``m`` (built-in time functions only).

    Raises
    ------
    ModelError
        When a time function is a Python callable (it cannot be written), naming the joint or
        load and the field; or when ``settings`` holds a key that is not a simulation field.
    """
    if not isinstance(model, Model):
        raise ModelError("save_model", "model", "a Model (ModelBuilder.build())", model)
    doc: dict[str, Any] = {"se3dyn": FORMAT_VERSION, "name": model.name,
                           "gravity": plain(model.gravity)}
    made = {f"{c}:cross" for c in model.composites}  # nodes their elements create
    for es in ELEMENT_SECTIONS:
        if es.nodes is not None:
            made |= es.nodes(model)
    doc["nodes"] = {n.name: _node_out(n) for n in model.nodes if n.name not in made}
    for es in ELEMENT_SECTIONS:
        entries = es.save(model)
        if entries:
            doc[es.key] = entries
    if model.visuals:
        doc["visuals"] = {v.name: visual_to_dict(v) for v in model.visuals}
    if model.markers:
        doc["markers"] = {mk.name: _marker_out(model, mk) for mk in model.markers}
    if model.drives:
        doc["drives"] = {d.name: _drive_out(model, d) for d in model.drives}
    if model.couplings:
        doc["couplings"] = {c.name: _coupling_out(c) for c in model.couplings}
    if settings:
        known = {f.name: f for f in FIELDS["simulation"]}
        sim = {}
        for key, val in settings.items():
            if key not in known:
                close = close_matches(str(key), list(known), n=1)
                raise ModelError("simulation", str(key), "one of " + ", ".join(known), key,
                                 f"did you mean '{close[0]}'?" if close else "")
            t = known[key].type
            sim[key] = int(val) if isinstance(t, Num) and t.integer else float(val)
        doc["simulation"] = sim
    text = (f"# se3dyn model file, format version {FORMAT_VERSION} (see docs/model-file.md)\n"
            + yaml.dump(doc, Dumper=_Dumper, sort_keys=False, default_flow_style=None,
                        width=10_000, allow_unicode=True))
    # the dumped text must load back: never write a file we could not read
    if path is not None:
        try:
            Path(path).write_text(text, encoding="utf-8")
        except (OSError, TypeError, ValueError) as e:
            raise ModelError("save_model", "path", "a writable file name", path,
                             f"{type(e).__name__}: {getattr(e, 'strerror', None) or e}"
                             ) from None
    return text


# =================================================================================================
# JSON Schema and Markdown reference, generated from FIELDS
# =================================================================================================
def _section_schema(sec: str) -> dict:
    fs = FIELDS[sec]
    props = {}
    for f in fs:
        p = dict(f.type.schema())
        if "$ref" in p:
            p = {"allOf": [p]}
        p["description"] = f.doc
        if f.default is not None and not isinstance(f.default, str) or isinstance(
                f.default, str) and f.name in ("name", "velocity_frame"):
            p["default"] = f.default
        props[f.name] = p
    d: dict[str, Any] = {"type": "object", "description": _SECTION_DOC[sec],
                         "properties": props, "additionalProperties": False}
    req = [f.name for f in fs if f.required]
    if req:
        d["required"] = req
    return d


def json_schema() -> dict:
    """The JSON Schema (draft 2020-12) of the model file format, generated from :data:`FIELDS`.

    Stricter loader checks that a schema cannot express (unit axes, rotations, positive-definite
    inertias, node names that exist, per-type joint parameters, duplicate keys) are done by
    :func:`load_model` only.
    """
    defs = {sec: _section_schema(sec) for sec in FIELDS if sec != "model"}
    defs["time_function"] = {
        "description": "A number or a list (constant), or exactly one of "
                       "{constant|step|ramp|table|sine: {...}}.",
        "oneOf": [
            _NUMBER,
            {"type": "array", "items": _NUMBER, "minItems": 1, "maxItems": 6},
            {"type": "object", "minProperties": 1, "maxProperties": 1,
             "properties": {k: {"$ref": f"#/$defs/{k}"} for k in _TF_KINDS},
             "additionalProperties": False},
        ],
    }
    root = _section_schema("model")
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "https://se3dyn.invalid/model-file.schema.json",
            "title": f"se3dyn model file, format version {FORMAT_VERSION}",
            **root, "$defs": defs}


def write_schema(path: str | os.PathLike = "docs/model-file.schema.json") -> str:
    """Write :func:`json_schema` to ``path`` (2-space JSON, trailing newline); returns the text."""
    text = json.dumps(json_schema(), indent=2) + "\n"
    Path(path).write_text(text, encoding="utf-8")
    return text


def _default_text(f: Field) -> str:
    if f.required:
        return "required"
    if f.default is None:
        return "absent"
    if isinstance(f.default, bool):
        return "`true`" if f.default else "`false`"
    if isinstance(f.default, str):
        return f.default if f.name not in ("name", "velocity_frame") else f"`{f.default}`"
    if f.default == {}:
        return "none"
    return f"`{json.dumps(f.default)}`"


def markdown_reference() -> str:
    """The field-by-field reference (Markdown) of ``docs/model-file.md``, from :data:`FIELDS`."""
    out = ["<!-- generated by se3dyn.io.modelfile.markdown_reference(); do not edit by hand -->",
           "## Field reference", ""]
    for sec, fs in FIELDS.items():
        out += [f"### {sec}", "", _SECTION_DOC[sec], "",
                "| field | type | default | description |", "|---|---|---|---|"]
        for f in fs:
            out.append(f"| `{f.name}` | {f.type.text} | {_default_text(f)} | {f.doc} |")
        out.append("")
    out += ["### joint types", "", "| type | parameters | description |", "|---|---|---|"]
    for key in _JOINT_KEYS:
        if key == "universal":
            params, doc = ("axes",), ("two hinges with orthogonal axes through an intermediate "
                                      "massless node '<name>:cross' (k = 2)")
        else:
            params, doc = JOINT_TYPES[key].params, JOINT_TYPES[key].doc
        out.append(f"| `{key}` | {', '.join(f'`{p}`' for p in params) or '-'} | {doc} |")
    out.append("")
    return "\n".join(out)


def _main(argv: list[str] | None = None) -> int:
    import argparse
    import sys

    ap = argparse.ArgumentParser(prog="python -m se3dyn.io.modelfile",
                                 description="se3dyn model files: schema, reference, check")
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("schema", help="write the JSON Schema")
    s.add_argument("path", nargs="?", default="docs/model-file.schema.json")
    sub.add_parser("reference", help="print the Markdown field reference")
    c = sub.add_parser("check", help="load model files and report errors")
    c.add_argument("files", nargs="+")
    args = ap.parse_args(argv)
    if args.cmd == "schema":
        write_schema(args.path)
    elif args.cmd == "reference":
        sys.stdout.write(markdown_reference())
    else:
        bad = 0
        for fname in args.files:
            try:
                m, _ = load_model(Path(fname))
                print(f"{fname}: ok ({len(m.nodes)} nodes, {len(m.joints)} joints)")
            except ModelFileError as e:
                bad += 1
                print(e, file=sys.stderr)
        return 1 if bad else 0
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
