"""Validated configuration files: YAML reading, unit conventions and readable errors.

Scene files (``acoustics``) and processing-settings files (``processing``) share this
machinery, which lives here because ``processing`` must never import ``acoustics``.

Rules every configuration model follows:

* pydantic v2 models with ``extra="forbid"``, frozen, sequences as tuples;
* numbers are strict (``"0.02"`` or ``true`` is not a length) and finite;
* SI units inside; the only non-SI keys in a file are angles, and those end in ``_deg``.
  A ``_deg`` key is converted to radians on load and back to degrees on dump, so a
  resolved file (``abacus scene show``) reads like the file a user wrote;
* every error names the file, the line, the key path (``sonar.pose.position_m[2]``),
  the value found and what is accepted.
"""
from __future__ import annotations

import math
import os
import re
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import yaml
from pydantic import (BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, TypeAdapter,
                      ValidationError)

__all__ = ["ConfigError", "ConfigWarning", "ConfigModel", "Real", "PositiveReal",
           "NonNegativeReal", "Count", "PositiveCount", "Vec3", "AngleDeg", "AngleRangeDeg", "read_yaml",
           "parse_yaml", "MAX_YAML_BYTES", "MAX_YAML_DEPTH",
           "validate_file", "format_key_path", "dump_yaml"]


class ConfigError(ValueError):
    """A configuration file (scene, settings) that cannot be used.

    The message is complete and meant for the user as it is: file, line, key path, the
    value found and what is accepted, one problem per line. ``problems`` holds the same
    information as a list of dicts for programs.
    """

    def __init__(self, message: str, problems: list[dict] | None = None):
        super().__init__(message)
        self.problems = problems or []


class ConfigWarning(UserWarning):
    """Legal but surprising physics in a configuration file (printed, never fatal)."""


# ---------------------------------------------------------------------------- types
def _finite(v):
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError("must be a finite number (not inf or nan)")
    return v


Real = Annotated[float, Field(strict=True), BeforeValidator(_finite)]
PositiveReal = Annotated[float, Field(strict=True, gt=0), BeforeValidator(_finite)]
NonNegativeReal = Annotated[float, Field(strict=True, ge=0), BeforeValidator(_finite)]
Count = Annotated[int, Field(strict=True, ge=0)]
PositiveCount = Annotated[int, Field(strict=True, gt=0)]
Vec3 = tuple[Real, Real, Real]


def _fmt_num(x: float) -> str:
    return f"{x:g}"


def AngleDeg(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
             hi_open: bool = False):
    """A scalar angle written in degrees in files (key ``*_deg``) and held in radians.

    Bounds are checked in degrees so the message speaks the file's language.
    """

    def to_rad(v):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError("must be a number of degrees")
        v = float(v)
        if not math.isfinite(v):
            raise ValueError("must be a finite number of degrees")
        bad = ((lo is not None and (v < lo or (lo_open and v == lo)))
               or (hi is not None and (v > hi or (hi_open and v == hi))))
        if bad:
            left = "(" if lo_open else "["
            right = ")" if hi_open else "]"
            lo_s = _fmt_num(lo) if lo is not None else "-inf"
            hi_s = _fmt_num(hi) if hi is not None else "inf"
            raise ValueError(f"must be in {left}{lo_s}, {hi_s}{right} degrees")
        return math.radians(v)

    def to_deg(v: float) -> float:
        return float(f"{math.degrees(v):.12g}")

    schema: dict[str, Any] = {"type": "number", "description_unit": "degrees"}
    if lo is not None:
        schema["exclusiveMinimum" if lo_open else "minimum"] = lo
    if hi is not None:
        schema["exclusiveMaximum" if hi_open else "maximum"] = hi
    return Annotated[float, BeforeValidator(to_rad), PlainSerializer(to_deg, return_type=float),
                     Field(json_schema_extra=schema)]


def AngleRangeDeg(lo: float, hi: float):
    """[low, high] pair of angles in degrees in files, radians inside; low < high."""
    one = AngleDeg(lo, hi)

    def to_rad(v):
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            raise ValueError("must be a list [low, high] of two angles in degrees")
        ta = TypeAdapter(one)
        a, b = ta.validate_python(v[0]), ta.validate_python(v[1])
        if not a < b:
            raise ValueError("must be [low, high] with low < high")
        return (a, b)

    def to_deg(v):
        return [float(f"{math.degrees(x):.12g}") for x in v]

    return Annotated[tuple[float, float], BeforeValidator(to_rad),
                     PlainSerializer(to_deg, return_type=list),
                     Field(json_schema_extra={"description_unit": "degrees"})]


#: Whether the settings' attribute docstrings become their descriptions (JSON Schema). pydantic
#: reads them from the source files when each class is made — 0.25 s of every command's start —
#: so they are read only in a process that writes the schema (ABACUS_FIELD_DOCS=1; see
#: acoustics.scene.json_schema, which starts one).
FIELD_DOCS = os.environ.get("ABACUS_FIELD_DOCS") == "1"


class ConfigModel(BaseModel):
    """Base of every configuration section: frozen, closed, validated defaults."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True,
                              populate_by_name=False, allow_inf_nan=False,
                              use_attribute_docstrings=FIELD_DOCS)


# ------------------------------------------------------------------------- reading
def format_key_path(loc: tuple) -> str:
    """``('a', 'b', 3, 'c')`` -> ``'a.b[3].c'``."""
    out = ""
    for item in loc:
        if isinstance(item, int):
            out += f"[{item}]"
        else:
            out += ("." if out else "") + str(item)
    return out or "(top level)"


def _walk_nodes(node, path: tuple, marks: dict, file: str):
    """Record the line of every key path; reject duplicate and non-string keys."""
    marks[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        seen: dict[str, int] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag != "tag:yaml.org,2002:str":
                line = key_node.start_mark.line + 1
                raise ConfigError(
                    f"{file}:{line}: {format_key_path(path)}: key {_short(key_node.value)} is not a "
                    f"plain string; keys are names such as 'width_m' (quote keys like 'on' or "
                    f"'yes' that YAML would read as booleans)")
            key = key_node.value
            line = key_node.start_mark.line + 1
            if key in seen:
                raise ConfigError(
                    f"{file}:{line}: {format_key_path(path + (key,))}: duplicate key (first "
                    f"given on line {seen[key]}); each key may appear once")
            seen[key] = line
            marks[path + (key,)] = line
            _walk_nodes(value_node, path + (key,), marks, file)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _walk_nodes(item, path + (i,), marks, file)


#: the largest configuration file read (bytes): scene files are a few kB
MAX_YAML_BYTES = 1 << 20
#: the deepest nesting of mappings and sequences accepted (a scene nests about 6 deep)
MAX_YAML_DEPTH = 32


class _StrictLoader(yaml.SafeLoader):
    """PyYAML's safe loader without anchors and aliases, and with a bounded depth.

    Aliases are what "billion laughs" documents are made of (a few lines that expand to
    gigabytes), and a self-referencing alias builds a cyclic structure; configuration files
    have no need of either. Deep nesting would end in a RecursionError."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
            raise yaml.constructor.ConstructorError(
                None, None, "anchors and aliases (&name, *name) are not accepted in configuration "
                "files: write the values out", event.start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise yaml.composer.ComposerError(
                    None, None, f"nested more than {MAX_YAML_DEPTH} levels deep", event.start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


# YAML 1.2 reads 1e12 and 1.0e-3 as numbers; PyYAML (YAML 1.1) wants a dot and a signed
# exponent and would read them as text, which the strict number types then refuse
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def parse_yaml(text: str, *, source: str = "<text>") -> tuple[Any, dict[tuple, int]]:
    """YAML text into plain Python data and a map key path -> line number, safely (no
    anchors or aliases, bounded size and depth, safe tags only).

    Raises
    ------
    ConfigError
        Too large, a YAML syntax error, an alias, too deep, duplicate or non-string keys; the
        message names ``source`` and the line.
    """
    if len(text) > MAX_YAML_BYTES:
        raise ConfigError(f"{source}: {len(text):,} characters; configuration files are at most "
                          f"{MAX_YAML_BYTES:,}")
    loader = _StrictLoader(text)
    try:
        node = loader.get_single_node()
        marks: dict[tuple, int] = {}
        if node is None:
            return None, marks
        _walk_nodes(node, (), marks, source)
        data = loader.construct_document(node)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}:{mark.line + 1}:{mark.column + 1}" if mark else source
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        context = getattr(exc, "context", None)
        detail = f"{problem} ({context})" if context else problem
        kind = "YAML syntax error" if isinstance(exc, (yaml.scanner.ScannerError,
                                                        yaml.parser.ParserError)) else "YAML error"
        raise ConfigError(f"{where}: {kind}: {detail}") from None
    except RecursionError:  # pragma: no cover - the depth bound comes first
        raise ConfigError(f"{source}: nested too deeply") from None
    finally:
        loader.dispose()
    return data, marks


def read_yaml(path: str | Path) -> tuple[Any, dict[tuple, int]]:
    """Read a YAML file into plain Python data and a map key path -> line number.

    Only regular files of at most :data:`MAX_YAML_BYTES` are read (never a device, a pipe or a
    folder); see :func:`parse_yaml` for what the text may hold.

    Raises
    ------
    ConfigError
        unreadable file, too large, YAML syntax error, anchors or aliases, too deep, duplicate
        keys, non-string keys.
    """
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot be read ({exc.strerror or exc.__class__.__name__})") from None
    if path.is_dir():
        raise ConfigError(f"{path}: is a directory, expected a YAML file")
    if not path.is_file():
        raise ConfigError(f"{path}: not a regular file (a device or a pipe); expected a YAML file")
    if st.st_size > MAX_YAML_BYTES:
        raise ConfigError(f"{path}: {st.st_size:,} bytes; configuration files are at most "
                          f"{MAX_YAML_BYTES:,} bytes")
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read(MAX_YAML_BYTES + 1)
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file (not UTF-8); expected YAML") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot be read ({exc.strerror or exc.__class__.__name__})") from None
    return parse_yaml(text, source=str(path))


def dump_yaml(data: Any) -> str:
    """Plain, stable YAML for resolved configurations: keys in model order (tags such as
    ``kind`` and ``model`` first), mappings in block style, short lists of numbers inline."""

    class _Dumper(yaml.SafeDumper):
        pass

    def _seq(dumper, value):
        flow = all(not isinstance(v, (dict, list, tuple)) for v in value)
        return dumper.represent_sequence("tag:yaml.org,2002:seq", list(value), flow_style=flow)

    def _map(dumper, value):
        first = [k for k in ("kind", "model") if k in value]
        items = [(k, value[k]) for k in first] + [(k, v) for k, v in value.items() if k not in first]
        return dumper.represent_mapping("tag:yaml.org,2002:map", items, flow_style=False)

    _Dumper.add_representer(tuple, _seq)
    _Dumper.add_representer(list, _seq)
    _Dumper.add_representer(dict, _map)
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=100, allow_unicode=True)


# ------------------------------------------------------------- error formatting
def _unwrap(ann):
    while typing.get_origin(ann) is Annotated:
        ann = typing.get_args(ann)[0]
    return ann


def _is_model(ann) -> bool:
    return isinstance(ann, type) and issubclass(ann, BaseModel)


def _union_members(ann) -> list | None:
    origin = typing.get_origin(ann)
    if origin is Union or origin is types.UnionType:
        return [_unwrap(a) for a in typing.get_args(ann)]
    return None


def _tag_of(model: type[BaseModel]) -> list[str]:
    tags = []
    for name, field in model.model_fields.items():
        ann = _unwrap(field.annotation)
        if typing.get_origin(ann) is Literal:
            tags.extend(str(a) for a in typing.get_args(ann))
    return tags


def _describe_path(root: type[BaseModel], loc: tuple) -> tuple[tuple, type[BaseModel] | None]:
    """Turn a pydantic ``loc`` into the file's key path, dropping union tags.

    Also returns the model class the last key belongs to (for listing accepted keys).
    """
    ann: Any = root
    shown: list = []
    parent_model: type[BaseModel] | None = root
    for item in loc:
        ann = _unwrap(ann)
        members = _union_members(ann)
        if members is not None:
            non_none = [m for m in members if m is not type(None)]
            picked = None
            for m in non_none:
                if _is_model(m) and (item in _tag_of(m) or item == m.__name__):
                    picked = m
                    break
                if isinstance(item, str) and not _is_model(m) and item == getattr(m, "__name__", None):
                    picked = m
                    break
            if picked is not None:
                ann = picked
                continue
            if len(non_none) == 1:
                ann = non_none[0]
            elif isinstance(item, str) and ("[" in item or item in {"float", "int", "str", "bool", "none"}):
                continue
            else:
                models = [m for m in non_none if _is_model(m)]
                ann = models[0] if models else non_none[0]
            ann = _unwrap(ann)
        if _is_model(ann):
            parent_model = ann
            target = None
            for name, field in ann.model_fields.items():
                if item == (field.alias or name):
                    target = field.annotation
                    break
            shown.append(item)
            ann = target
            continue
        origin = typing.get_origin(ann)
        args = typing.get_args(ann)
        if origin in (list, tuple, set, frozenset) and isinstance(item, int):
            shown.append(item)
            if origin is tuple and args and args[-1] is not Ellipsis:
                ann = args[item] if item < len(args) else None
            else:
                ann = args[0] if args else None
            continue
        if origin is dict:
            shown.append(item)
            ann = args[1] if len(args) == 2 else None
            continue
        shown.append(item)
        ann = None
    return tuple(shown), parent_model


def _accepted_keys(model: type[BaseModel]) -> list[str]:
    return [f.alias or n for n, f in model.model_fields.items()]


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 70 else text[:67] + "..."


def _explain(err: dict, parent: type[BaseModel] | None) -> str:
    kind = err["type"]
    msg = err["msg"]
    ctx = err.get("ctx") or {}
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    if msg.startswith("Assertion failed, "):
        msg = msg[len("Assertion failed, "):]
    if kind == "extra_forbidden":
        keys = ", ".join(_accepted_keys(parent)) if parent else "?"
        return f"unknown key; accepted keys here: {keys}"
    if kind == "missing":
        if err["loc"] and isinstance(err["loc"][-1], int):
            return "this list is too short (an entry is missing)"
        return "required key is missing"
    if kind == "literal_error":
        return f"not an accepted value; accepted: {ctx.get('expected', '')}"
    if kind == "union_tag_invalid":
        return (f"{ctx.get('discriminator', 'kind')} {ctx.get('tag')!r} is not accepted; "
                f"accepted: {ctx.get('expected_tags')}")
    if kind == "union_tag_not_found":
        return f"the key {ctx.get('discriminator', 'kind')} is required here"
    if kind.startswith("float") or kind.startswith("int"):
        return {"float_type": "must be a number (not text or true/false)",
                "int_type": "must be a whole number (not text, true/false or 3.0)",
                "int_from_float": "must be a whole number",
                "float_parsing": "must be a number",
                "int_parsing": "must be a whole number",
                "finite_number": "must be a finite number (not inf or nan)"}.get(kind, msg)
    if kind == "greater_than":
        return f"must be > {ctx.get('gt')}"
    if kind == "greater_than_equal":
        return f"must be >= {ctx.get('ge')}"
    if kind == "less_than":
        return f"must be < {ctx.get('lt')}"
    if kind == "less_than_equal":
        return f"must be <= {ctx.get('le')}"
    if kind in ("tuple_type", "list_type"):
        return "must be a list, e.g. [0.0, 0.0, 1.0]"
    if kind == "too_short" or kind == "too_long":
        return msg.replace("Tuple", "list").replace("List", "list")
    if kind == "model_type" or kind == "dict_type":
        keys = ""
        return "must be a mapping of keys (key: value)" + keys
    if kind == "bool_type":
        return "must be true or false"
    if kind == "string_type":
        return "must be text"
    return msg


def validate_file(model: type[BaseModel], data: Any, *, file: str | Path,
                  marks: dict[tuple, int] | None = None, context: dict | None = None):
    """Validate plain data against ``model``; on failure raise one readable ConfigError."""
    marks = marks or {}
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{file}: the file must hold a mapping of keys (key: value), "
                          f"found {type(data).__name__}")
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        lines, problems = [], []
        for err in exc.errors(include_url=False):
            path, parent = _describe_path(model, tuple(err["loc"]))
            # the innermost line we know: the key itself, or its closest parent
            line = None
            for cut in range(len(path), -1, -1):
                if path[:cut] in marks:
                    line = marks[path[:cut]]
                    break
            where = f"{file}:{line}" if line else str(file)
            key = format_key_path(path)
            reason = _explain(err, parent if err["type"] == "extra_forbidden" else None)
            shown = ""
            if err["type"] not in ("missing",) and "input" in err:
                if err["type"] == "extra_forbidden":
                    shown = ""
                elif not isinstance(err["input"], dict):
                    shown = f" (got {_short(err['input'])})"
            lines.append(f"{where}: {key}: {reason}{shown}")
            problems.append({"file": str(file), "line": line, "key": key, "problem": reason,
                             "value": err.get("input")})
        order = sorted(range(len(lines)), key=lambda i: (problems[i]["line"] or 0, i))
        lines = [lines[i] for i in order]
        problems = [problems[i] for i in order]
        head = (f"{file}: {len(lines)} problem{'s' if len(lines) > 1 else ''} found:\n  "
                if len(lines) > 1 else "")
        raise ConfigError(head + "\n  ".join(lines), problems) from None
