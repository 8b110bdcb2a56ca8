"""The groups of the data contract, made and checked from its table (processing.base.contract).

Every writer of the contract — the simulator (acoustics/simulation/dataset.py) and ``abacus
convert`` (processing/base/convert.py) — makes its groups here, giving values only: dimensions,
units, ``long_name`` and the other attributes, and the fixed attributes of a group (the convention
names, ``sonar_type``) come from the table::

    env = build_group(ENVIRONMENT_GROUP, {"sound_speed_indicative": 1500.0,
                                          "absorption_indicative": [0.1], "frequency": [420e3]})
    tree = tree_of({ROOT_GROUP: root, ENVIRONMENT_GROUP: env, SONAR_GROUP: sonar, ...})

:func:`conform_group` brings a group read from another layout to the table's attributes,
keeping what the table does not know; :func:`check_tree` lists where a tree departs from the
contract (the test of every writer, tests/test_contract.py).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import xarray as xr

from processing.base.contract import GROUPS, KINDS, PRODUCT_GROUPS, Group, Variable, group_spec, node_path
from processing.base.dataset import DatasetError

__all__ = ["ContractError", "build_group", "conform_group", "tree_of", "check_tree", "complex_pair",
           "per_ping", "per_beam"]


class ContractError(DatasetError):
    """A group that does not follow the table: an unknown variable or attribute, or values of
    the wrong shape or kind (named in the message)."""


def _array(spec: Group, v: Variable, value) -> np.ndarray:
    """``value`` as the array the table says: its dimensions checked, an integer widened to
    float where the table holds a float; never copied otherwise."""
    a = np.asarray(value)
    where = f"{spec.path}/{v.name}"
    if a.ndim != len(v.dims):
        raise ContractError(f"{where}: {a.ndim} dimension(s) given, the contract has "
                            f"{len(v.dims)} ({', '.join(v.dims) or 'a scalar'})")
    if a.size and a.dtype.kind not in KINDS[v.kind]:
        raise ContractError(f"{where}: dtype {a.dtype} given, the contract holds kind {v.kind!r}")
    if v.kind == "f" and a.dtype.kind in "iu":
        a = a.astype(np.float64)
    return a


def _group_attrs(spec: Group, given: Mapping | None) -> dict:
    """The table's fixed attributes of a group, then the given ones (each known to the table)."""
    out = {a.name: a.value for a in spec.attributes if a.value is not None}
    for name, value in (given or {}).items():
        row = spec.attribute(name)
        if row is None:
            raise ContractError(f"{spec.path}: attribute {name!r} is not in the data contract "
                                f"(processing/base/contract.py)")
        if row.value is not None and value != row.value:
            raise ContractError(f"{spec.path}: attribute {name!r} is {row.value!r} by the contract, "
                                f"not {value!r}")
        out[name] = value
    return out


def build_group(group: str, values: Mapping[str, Any], *, attrs: Mapping | None = None) -> xr.Dataset:
    """One group of the contract from its values.

    Parameters
    ----------
    group : str
        A group path of :mod:`processing.base.contract` (``ELEMENT_GROUP``, ``ROOT_GROUP``, ...).
    values : mapping of str to array_like
        Data variables and coordinates by name, each shaped as the table's dimensions say (a
        scalar for ``()``); arrays are wrapped, not copied (integers given for a float variable
        are widened to float64).
    attrs : mapping, optional
        The group's attributes besides the fixed ones the table fills in.

    Returns
    -------
    xarray.Dataset
        Every variable with the table's dimensions, ``units``, ``long_name`` and attributes.

    Raises
    ------
    ContractError
        A variable or attribute the table does not have, a value of the wrong number of
        dimensions or kind, or a fixed attribute given another value.
    """
    spec = group_spec(group)
    data, coords = {}, {}
    for name, value in values.items():
        v = spec.variable(name)
        if v is None:
            raise ContractError(f"{spec.path}: variable {name!r} is not in the data contract "
                                f"(processing/base/contract.py)")
        (coords if v.coord else data)[name] = xr.Variable(v.dims, _array(spec, v, value),
                                                          v.attributes())
    return xr.Dataset(data, coords=coords, attrs=_group_attrs(spec, attrs))


def conform_group(group: str, ds: xr.Dataset) -> xr.Dataset:
    """A group from another layout with the table's attributes: every variable the table knows
    gets its ``units``, ``long_name`` and attributes (its other attributes kept), the group its
    fixed attributes; values, dimensions and the variables the table does not know are kept.

    Parameters
    ----------
    group : str
        A group path of :mod:`processing.base.contract`.
    ds : xarray.Dataset

    Returns
    -------
    xarray.Dataset
        A shallow copy (the arrays are shared).
    """
    spec = group_spec(group)
    out = ds.copy()
    for name, var in out.variables.items():
        v = spec.variable(str(name))
        if v is not None:
            var.attrs.update(v.attributes())
    out.attrs.update({a.name: a.value for a in spec.attributes if a.value is not None})
    return out


def tree_of(groups: Mapping[str, xr.Dataset]) -> xr.DataTree:
    """The DataTree of groups given by contract path (``ROOT_GROUP``, ``ELEMENT_GROUP``, ...)."""
    return xr.DataTree.from_dict({node_path(k): v for k, v in groups.items()})


def complex_pair(name: str, values) -> dict:
    """``{name_r: real, name_i: imag}``: a complex array as the contract stores it, float32
    (views of a complex64 array's parts, no copy; anything else rounded to float32)."""
    v = np.asarray(values)
    return {f"{name}_r": v.real.astype(np.float32, copy=False),
            f"{name}_i": v.imag.astype(np.float32, copy=False)}


def per_ping(value: float, n_pings: int) -> np.ndarray:
    """A setting of every ping of the one channel: shape (1, n_pings), float64 (the beam
    group's (channel, ping_time) variables)."""
    return np.full((1, n_pings), float(value))


def per_beam(values) -> np.ndarray:
    """Values of every beam (element) of the one channel: shape (1, n_beams), float64 (the beam
    group's (channel, beam) variables)."""
    return np.asarray(values, float)[None, :]


def _kind_ok(kind: str, dtype: np.dtype) -> bool:
    """Whether data as written hold the table's kind (a float is a float there, not an int)."""
    return dtype.kind in ("f" if kind == "f" else KINDS[kind])


def check_tree(tree: xr.DataTree) -> list:
    """Where a dataset departs from the contract, one line each (empty: it follows it).

    Checked: every group is one of the table's (or a /Processing product, not checked further);
    every variable and coordinate of a group is in the table, with its dimensions, its units
    (none where the table has none) and a dtype of its kind; every attribute of a group is in
    the table; the mandatory groups, variables and attributes are present.

    Parameters
    ----------
    tree : xarray.DataTree

    Returns
    -------
    list of str
    """
    problems = []
    seen = set()
    products = tuple(node_path(p) for p in PRODUCT_GROUPS)
    for node in tree.subtree:
        path = node_path(node.path)
        if path.startswith(products):
            continue
        spec = GROUPS.get(path)
        if spec is None:
            problems.append(f"{path}: not a group of the data contract")
            continue
        seen.add(path)
        ds = node.to_dataset(inherit=False)
        for name, var in ds.variables.items():
            v = spec.variable(str(name))
            if v is None:
                problems.append(f"{path}/{name}: not in the data contract")
                continue
            if tuple(var.dims) != v.dims:
                problems.append(f"{path}/{name}: dims {tuple(var.dims)}, the contract has {v.dims}")
            if var.attrs.get("units") != v.units:
                problems.append(f"{path}/{name}: units {var.attrs.get('units')!r}, the contract "
                                f"has {v.units!r}")
            if var.size and not _kind_ok(v.kind, var.dtype):
                problems.append(f"{path}/{name}: dtype {var.dtype}, the contract holds kind {v.kind!r}")
            if bool(name in ds.coords) != v.coord:
                problems.append(f"{path}/{name}: {'a' if name in ds.coords else 'not a'} coordinate, "
                                f"the contract says {'a' if v.coord else 'not a'} coordinate")
        problems += [f"{path}: attribute {a!r} not in the data contract" for a in ds.attrs
                     if spec.attribute(a) is None]
        problems += [f"{path}/{v.name}: mandatory, missing" for v in spec.variables
                     if v.mandatory and v.name not in ds.variables]
        problems += [f"{path}: mandatory attribute {a.name!r} missing" for a in spec.attributes
                     if a.mandatory and a.name not in ds.attrs]
    problems += [f"{g.path}: mandatory group missing" for g in GROUPS.values()
                 if g.mandatory and g.path not in seen]
    return problems
