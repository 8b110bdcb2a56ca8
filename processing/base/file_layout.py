"""How a dataset lies in its file: echopype's groups as groups, abacus' own groups flat in
/Vendor_specific.

echopype's EchoData (0.11) names every group of a file that holds data by its convention table
(``echodata/convention/1.0.yml``): the repr of a file with any other group fails (``KeyError:
'Processing/Sv'``), and so does every tool that prints one. SONAR-netCDF4 1.0 leaves vendor
content to /Vendor_specific, so in the file abacus' own groups — processing's products
(/Processing, /Processing/Sv, ...) and the per-arrival truth (/Vendor_specific/Arrivals) — lie
there, flat: variable, dimension and attribute ``name`` of group ``G`` as
:func:`processing.base.contract.flat_name` ``(G, name)`` (``Processing.Sv.Sv`` along
``Processing.Sv.range_cell``), and the attribute :data:`~processing.base.contract.FLAT_MAP_ATTR`
lists what each group held. :func:`flatten` is what :func:`processing.base.dataset.write_tree`
writes; :func:`restore`, what :func:`processing.base.dataset.open_tree` gives back: in memory the
groups are groups (``tree["Processing/Sv"]``), and a file written before (groups as groups)
opens as it was.
"""
from __future__ import annotations

import json

import xarray as xr

from processing.base.contract import ECHOPYPE_GROUPS, FLAT_HOST, FLAT_MAP_ATTR, flat_name, node_path

__all__ = ["flatten", "restore"]


def _datasets(tree: xr.DataTree) -> dict:
    """Node path -> the node's own dataset (nothing inherited), in the tree's order."""
    return {node_path(n.path): n.to_dataset(inherit=False) for n in tree.subtree}


def flatten(tree: xr.DataTree) -> xr.DataTree:
    """The tree as the file holds it: every group echopype does not know moved flat into
    /Vendor_specific (names by :func:`~processing.base.contract.flat_name`).

    Parameters
    ----------
    tree : xarray.DataTree

    Returns
    -------
    xarray.DataTree
        ``tree`` itself when every group is one echopype knows; otherwise a new tree sharing the
        arrays (nothing copied).
    """
    groups = _datasets(tree)
    host_path = node_path(FLAT_HOST)
    # empty ones too: echopype takes a group of the file without data for a group it cannot read
    moved = {p: ds for p, ds in groups.items() if p not in ECHOPYPE_GROUPS}
    if not moved:
        return tree
    host = groups.get(host_path)
    data = {k: host.variables[k] for k in host.data_vars} if host is not None else {}
    coords = {k: host.variables[k] for k in host.coords} if host is not None else {}
    attrs = dict(host.attrs) if host is not None else {}
    table = {}
    for path, ds in moved.items():
        g = path.strip("/")
        for name, var in ds.variables.items():
            flat = xr.Variable(tuple(flat_name(g, d) for d in var.dims), var.data, var.attrs, var.encoding)
            (coords if name in ds.coords else data)[flat_name(g, name)] = flat
        attrs.update({flat_name(g, a): v for a, v in ds.attrs.items()})
        table[g] = {"variables": [str(k) for k in ds.data_vars], "coordinates": [str(k) for k in ds.coords],
                    "dimensions": [str(d) for d in ds.dims], "attributes": [str(a) for a in ds.attrs]}
    attrs[FLAT_MAP_ATTR] = json.dumps({"host_was_empty": host is None or not (host.variables or host.attrs),
                                       "groups": table})
    kept = {p: ds for p, ds in groups.items() if p not in moved and p != host_path}
    kept[host_path] = xr.Dataset(data, coords=coords, attrs=attrs)
    return xr.DataTree.from_dict(kept)


def restore(tree: xr.DataTree) -> xr.DataTree:
    """The tree as abacus works with it: the groups :func:`flatten` moved into /Vendor_specific
    back in their places.

    Parameters
    ----------
    tree : xarray.DataTree
        As read from a file.

    Returns
    -------
    xarray.DataTree
        ``tree`` itself when nothing lies flat (a file from before, or one without such groups).

    Raises
    ------
    ValueError
        The map names a variable the file does not hold (a damaged file).
    """
    host_path = node_path(FLAT_HOST)
    try:
        host = tree[FLAT_HOST].to_dataset(inherit=False)
    except KeyError:
        return tree
    if FLAT_MAP_ATTR not in host.attrs:
        return tree
    spec = json.loads(str(host.attrs[FLAT_MAP_ATTR]))
    groups = _datasets(tree)
    taken, taken_attrs = set(), {FLAT_MAP_ATTR}
    back = {}
    for g, s in spec["groups"].items():
        def var(name, g=g):
            flat = flat_name(g, name)
            if flat not in host.variables:
                raise ValueError(f"/{FLAT_HOST}: {flat} is listed in {FLAT_MAP_ATTR} but not in the file")
            taken.add(flat)
            v = host.variables[flat]
            dims = {flat_name(g, d): d for d in s["dimensions"]}
            return xr.Variable(tuple(dims.get(d, d) for d in v.dims), v.data, v.attrs, v.encoding)
        attrs = {}
        for a in s["attributes"]:
            attrs[a] = host.attrs[flat_name(g, a)]
            taken_attrs.add(flat_name(g, a))
        back[node_path(g)] = xr.Dataset({k: var(k) for k in s["variables"]},
                                        coords={k: var(k) for k in s["coordinates"]}, attrs=attrs)
    rest = host.drop_vars(sorted(taken))
    rest.attrs = {k: v for k, v in host.attrs.items() if k not in taken_attrs}
    out = {p: ds for p, ds in groups.items() if p != host_path}
    if not (spec.get("host_was_empty") and not (rest.variables or rest.attrs)):
        out[host_path] = rest
    out.update(back)
    return xr.DataTree.from_dict(out)
