"""The ICES SONAR-netCDF4 2.0 definition, read from the convention's own tables.

tests/data/sonar-netcdf4-2.0/ holds unmodified copies of the convention's AsciiDoc tables (source
and licence in its README.md). Each table is read into a :class:`GroupDef`: its attributes,
types (enums and variable-length vectors), dimensions, variables (type, dimensions, obligation,
attributes with their fixed values) and sub-groups. :func:`check_file` checks a written file
against them: the independent reference of tests/test_sonar_netcdf2.py (the writer reads
abacus' own table, processing/base/contract_v2.py; this reads the convention's text).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent / "data" / "sonar-netcdf4-2.0"

#: group path in a file -> the table that defines it
TABLES = {
    "/": "tableToplevel", "/Environment": "tableEnvironment", "/Platform": "tablePlatform",
    "/Provenance": "tableProvenance", "/Sonar": "tableSonar", "/Sonar/Beam_group1": "tableBeamGroup1",
    "/Sonar/Beam_group1/SingleTarget": "tableSingleTarget_sub_group",
    "/Sonar/Grid_group1": "tableBeamGridGroup1",
}

#: the convention's scalar type names -> numpy dtypes (netCDF4: "float" is 32-bit, "double" 64)
SCALARS = {"float": np.float32, "double": np.float64, "int": np.int32, "short": np.int16,
           "byte": np.int8, "uint64": np.uint64}


@dataclass
class VarDef:
    name: str
    type: str
    dims: tuple
    obligation: str
    attrs: dict = field(default_factory=dict)      # name -> fixed value (str) or None


@dataclass
class GroupDef:
    attrs: dict = field(default_factory=dict)      # name -> (obligation, fixed value or None)
    enums: dict = field(default_factory=dict)      # type name -> {member: value}
    vlens: dict = field(default_factory=dict)      # type name -> base type
    dims: dict = field(default_factory=dict)       # name -> obligation ("" when unstated)
    variables: dict = field(default_factory=dict)  # name -> VarDef
    subgroups: dict = field(default_factory=dict)  # name -> obligation


_SECTION = re.compile(r"^s\|(.+?)\s*\|")
_VAR = re.compile(r"^\s*\|\{var\}\s*(\S+)\s+(\w+)\s*(?:\(([^)]*)\))?\s*\|\s*(\w*)\s*\|")
_NAME_ONLY = re.compile(r"^\s*\|\{var\}\s*(\w+)(?:\s*=\s*unlimited)?\s*\|\s*(\w*)\s*\|")
_ATTR = re.compile(r"^\s*\d\+\|\{attr\}\s*(?:(\w+)\s+)?:(\w+)(?:\s*=\s*(.*?))?\s*(?:\|.*)?$")
_GROUP_ATTR = re.compile(r"^\s*\|\{attr\}\s*(?:\w+\s+)?:?\s*(?:\w+\s*)?:(\w+)(?:\s*=\s*\"([^\"]*)\")?\s*\|\s*(\w+)\s*\|")
_ENUM = re.compile(r"^\s*2\+\|\{var\}\s*\w+\s+enum\s+(\w+)\s*\{([^}]*)\}")
_VLEN = re.compile(r"^\s*2\+\|\{var\}\s*(\w+)\(\*\)\s+(\w+)")


def _value(text: str | None):
    """A fixed attribute value as the table writes it: a quoted string, else None (a number or
    a range, checked by type only)."""
    if text is None:
        return None
    text = text.replace("\xa0", " ")
    m = re.fullmatch(r'"([^"]*)"(?:\s+or\s+.*)?', text.strip())
    if not m or m.group(1) == "as appropriate":       # "use units appropriate for the data"
        return None
    return m.group(1)


def read_table(name: str) -> GroupDef:
    """One of the convention's tables (``"tableBeamGroup1"``) as a :class:`GroupDef`."""
    g = GroupDef()
    section, last = "", None
    for line in (HERE / f"{name}.adoc").read_text().splitlines():
        if (m := _SECTION.match(line)):
            section, last = m.group(1).strip().lower(), None
            continue
        if section == "group attributes" and (m := _GROUP_ATTR.match(line)):
            value = m.group(2).replace("\xa0", " ") if m.group(2) is not None else None
            g.attrs[m.group(1)] = (m.group(3), value)
        elif section == "types" and (m := _ENUM.match(line)):
            members = {}
            for part in m.group(2).split(","):
                k, v = part.split("=")
                members[k.strip()] = int(v)
            g.enums[m.group(1)] = members
        elif section == "types" and (m := _VLEN.match(line)):
            g.vlens[m.group(2)] = m.group(1)
        elif section == "dimensions" and (m := _NAME_ONLY.match(line)):
            g.dims[m.group(1)] = m.group(2)
        elif section == "subgroups" and (m := _NAME_ONLY.match(line)):
            g.subgroups[m.group(1)] = m.group(2)
        elif section in ("variables", "coordinate variables"):
            if (m := _VAR.match(line)):
                dims = tuple(d.strip() for d in (m.group(3) or "").split(",") if d.strip())
                last = VarDef(m.group(2), m.group(1), dims, m.group(4))
                g.variables[last.name] = last
            elif (m := _NAME_ONLY.match(line)) and section == "variables":
                # the platform table lists its sub-groups among its variables
                g.subgroups[m.group(1)] = m.group(2)
                last = None
            elif last is not None and (m := _ATTR.match(line)):
                last.attrs[m.group(2)] = _value(m.group(3))
    return g


def definition() -> dict:
    """Group path -> :class:`GroupDef` of every group abacus writes."""
    return {path: read_table(table) for path, table in TABLES.items()}


def _type_problems(where: str, var, want: str, defs: dict) -> list:
    """Whether a netCDF4 variable has the convention's type: a scalar type, an enum or a vlen
    of the convention's (defined in this group or an enclosing one), or a string."""
    import netCDF4
    dt = var.datatype
    if want == "string":
        return [] if var.dtype is str else [f"{where}: type {dt}, the convention has string"]
    if want in SCALARS:
        ok = isinstance(dt, np.dtype) and dt == np.dtype(SCALARS[want])
        return [] if ok else [f"{where}: type {dt}, the convention has {want}"]
    for g in defs:
        if want in g.enums:
            if not isinstance(dt, netCDF4.EnumType) or dt.name != want:
                return [f"{where}: type {dt}, the convention has enum {want}"]
            missing = {k: v for k, v in g.enums[want].items() if dt.enum_dict.get(k) != v}
            return [f"{where}: enum {want} lacks {missing}"] if missing else []
        if want in g.vlens:
            # netCDF-C reads a variable of one of several equal vlen types (vectors of float)
            # as the first of them: a vlen is known by its base type
            if not isinstance(dt, netCDF4.VLType) or var.dtype is str:
                return [f"{where}: type {dt}, the convention has vlen {want}"]
            base = SCALARS.get(g.vlens[want])
            if base is not None and dt.dtype != np.dtype(base):
                return [f"{where}: vlen {want} of {dt.dtype}, the convention has {g.vlens[want]}"]
            return []
    return [f"{where}: the convention's type {want!r} is not defined in its tables"]


def check_file(path, *, applicable=(), exceptions=()) -> list:
    """Where a SONAR-netCDF4 2.0 file departs from the convention's tables, one line each.

    Checked for every group of :data:`TABLES` the file has: the mandatory (M) group attributes,
    dimensions and variables are there, and the variables ``applicable`` names
    (``"/Sonar/Beam_group1/backscatter_i"``: the MA ones that apply to this file); every variable
    of the convention the file has has the convention's type (scalar, enum with the
    convention's members, vlen), dimensions and fixed attribute values (``units``,
    ``long_name``, ...); fixed group attribute values are the convention's. The groups
    /, /Environment, /Platform, /Provenance, /Sonar and one beam group are mandatory.

    ``exceptions`` names checks (the returned lines) the caller documents as departures.
    """
    import netCDF4
    defs = definition()
    problems = []
    with netCDF4.Dataset(path) as nc:
        for gpath, gdef in defs.items():
            try:
                grp = nc if gpath == "/" else nc[gpath]
            except (IndexError, KeyError):
                if gpath in ("/", "/Environment", "/Platform", "/Provenance", "/Sonar",
                             "/Sonar/Beam_group1"):
                    problems.append(f"{gpath}: mandatory group missing")
                continue
            enclosing = [defs[p] for p in defs if gpath.startswith(p.rstrip("/") + "/") or p == "/"]
            enclosing = [gdef] + [d for d in enclosing if d is not gdef]
            for name, (obl, value) in gdef.attrs.items():
                if obl == "M" and name not in grp.ncattrs():
                    problems.append(f"{gpath}: mandatory attribute {name} missing")
                elif value is not None and name in grp.ncattrs() and str(grp.getncattr(name)) != value:
                    problems.append(f"{gpath}: attribute {name} = {grp.getncattr(name)!r}, the "
                                    f"convention has {value!r}")
            dims = {}
            g = grp
            while g is not None:                       # dimensions visible here
                dims = {**g.dimensions, **dims}
                g = g.parent
            for name, obl in gdef.dims.items():
                if obl == "M" and name not in dims:
                    problems.append(f"{gpath}: mandatory dimension {name} missing")
            for name, v in gdef.variables.items():
                where = f"{gpath.rstrip('/')}/{name}"
                if name not in grp.variables:
                    if v.obligation == "M" or where in applicable:
                        problems.append(f"{where}: mandatory, missing")
                    continue
                var = grp.variables[name]
                problems += _type_problems(where, var, v.type, enclosing)
                if tuple(var.dimensions) != v.dims:
                    problems.append(f"{where}: dims {tuple(var.dimensions)}, the convention has {v.dims}")
                for a, value in v.attrs.items():
                    if a not in var.ncattrs():
                        problems.append(f"{where}: attribute {a} missing")
                    elif value is not None and str(var.getncattr(a)) != value:
                        problems.append(f"{where}: attribute {a} = {var.getncattr(a)!r}, the "
                                        f"convention has {value!r}")
                if v.obligation == "M" and var.size == 0:
                    problems.append(f"{where}: mandatory, empty")
    return [p for p in problems if p not in exceptions]
