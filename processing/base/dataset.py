"""The data contract between the simulator (or a recorder) and processing, and its I/O.

Layout (ICES SONAR-netCDF4 1.0 as echopype lays it out; every variable, its dimensions and units
are in one table, processing/base/contract.py, which docs/dataset.md shows)::

    /                               conventions, sonar_convention_*, keywords (the sonar model), ...
    /Environment                    sound_speed_indicative, absorption_indicative (frequency), ...
    /Platform                       sonar pose in the world frame, transducer offsets
    /Provenance                     resolved scene text, sha256, seed, versions, stage timings
    /Sonar                          sonar_* attributes, beam_group_name/descr, transmit pulse +
                                    replica, transmitter elements, calibration
    /Sonar/Beam_group1              backscatter_r/_i (channel, ping_time, range_sample, beam)
                                    float32: one channel (the receiver), one beam per receive
                                    element; element geometry and subarrays per beam; sample
                                    interval, blanking interval, transmit parameters
    /Vendor_specific                abacus' ground truth: targets per ping (simulated data only)
    /Processing                     images, detections, counts, tracks (processing); in the
                                    file flat in /Vendor_specific (processing/base/file_layout.py)

Complex arrays are stored as ``_r``/``_i`` float32 pairs; ``range_sample`` stays in one chunk.
This is the only module that writes NetCDF or Zarr. Writes are atomic: a temporary file (or
folder) next to the target is renamed over it when complete, so an interrupted write never leaves
a half file under the final name.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from processing.base.atomic import staged
from processing.base.extras import require
# the group paths and the convention are the contract's table's, importable from here too
from processing.base.contract import (CONVENTIONS, ELEMENT_GROUP, ENVIRONMENT_GROUP, LEGACY_ELEMENT_GROUP,
                                      SONAR_GROUP, TRUTH_GROUP)

__all__ = ["DatasetError", "DatasetWarning", "FORMATS", "CONVENTIONS", "ELEMENT_GROUP", "ping_indices", "TRUTH_GROUP",
           "write_tree", "write_dataset", "check_finite", "NAN_MEANS", "open_tree", "tree_pings", "source_of", "PairedSamples", "complex_of", "split_complex", "SonarRecord",
           "read_record", "beam_samples", "LEGACY_ELEMENT_GROUP", "as_tree", "group_of", "has_group",
           "missing_variables", "echosounder_model", "SIMRAD_MODELS", "sonar_convention_version",
           "stage_seconds"]

FORMATS = ("netcdf", "zarr")


class DatasetError(ValueError):
    """A dataset that does not follow the contract; the message names file, group, variable."""


class DatasetWarning(UserWarning):
    """A dataset that can be processed, but not as its attributes say (named in the message)."""


# ------------------------------------------------------------------------- I/O
def _format_of(path: Path, fmt: str | None) -> str:
    if fmt is None:
        fmt = "zarr" if path.suffix == ".zarr" else "netcdf"
    if fmt not in FORMATS:
        raise DatasetError(f"format must be one of {FORMATS}, got {fmt!r}")
    return fmt


def _encoding(tree: xr.DataTree) -> dict:
    """Keep each variable's range_sample axis in one chunk; chunk along pings."""
    enc = {}
    for node in tree.subtree:
        per = {}
        for name, var in node.ds.data_vars.items():
            # a product lying flat in /Vendor_specific has its ping_time as `<group>.ping_time`
            per_ping = [str(d).rsplit(".", 1)[-1] == "ping_time" for d in var.dims]
            if any(per_ping) and var.ndim >= 2:
                chunks = tuple(1 if p else var.sizes[d] for d, p in zip(var.dims, per_ping))
                per[name] = {"chunksizes": chunks}
        if per:
            enc[node.path] = per
    return enc


@contextmanager
def _small_chunk_cache(size_bytes: int = 4 << 20):
    """HDF5's chunk cache for the files opened inside, ``size_bytes`` per variable.

    netCDF's default is 64 MB per variable, and a write that hands HDF5 a whole variable keeps
    its chunks there until the file closes: the 100 pings of the default scene cost 2 × 26 MB
    more resident memory (measured: +82 → +34 MB during the write) and 40 % more time. Every
    chunk is written whole, once, so a cache that holds a few chunks loses nothing."""
    import netCDF4
    previous = netCDF4.get_chunk_cache()
    netCDF4.set_chunk_cache(size_bytes)
    try:
        yield
    finally:
        netCDF4.set_chunk_cache(*previous)


def _write_netcdf(tree: xr.DataTree, path: Path, encoding: dict) -> None:
    """Write the groups of ``tree`` to one NetCDF4 file, as ``DataTree.to_netcdf`` does.

    The same encoding path (xarray's CF encoder and its ``NetCDF4DataStore``), so the bytes on
    disk are those of ``to_netcdf``; what differs is the lock. ``to_netcdf`` asks dask, when it
    is installed, which scheduler would run the write, and that question imports ``distributed``
    with tornado and asyncio (≈ 300 modules, 0.3–0.6 s of a 3 s ``abacus run``, again at exit).
    Every array here is in memory and written now, in this thread, so the lock that matters is
    the one that keeps HDF5 to one thread at a time: xarray's own, the one its readers take."""
    from xarray.backends import NetCDF4DataStore
    from xarray.backends.locks import HDF5_LOCK, NETCDFC_LOCK, combine_locks

    root = NetCDF4DataStore.open(str(path), mode="w", format="NETCDF4",
                                 lock=combine_locks([NETCDFC_LOCK, HDF5_LOCK]))
    try:
        for node in tree.subtree:
            at_root = node is tree
            store = root if at_root else root.get_child_store(node.path)
            node.to_dataset(inherit=at_root).dump_to_store(store, encoding=encoding.get(node.path))
    finally:
        root.close()


def write_tree(tree: xr.DataTree, path: str | Path, *, fmt: str | None = None) -> Path:
    """Write a dataset atomically as NetCDF4 (default) or Zarr.

    Parameters
    ----------
    tree : xarray.DataTree
    path : str or Path
        Final file (``.nc``) or folder (``.zarr``).
    fmt : {"netcdf", "zarr"}, optional
        Default from the suffix (``.zarr`` -> zarr, otherwise netcdf).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    fmt = _format_of(path, fmt)
    if not path.parent.exists():
        raise DatasetError(f"{path}: the folder {path.parent} does not exist")
    from processing.base.file_layout import flatten
    for node in tree.subtree:
        check_finite(node.ds, where=f"{path}: /{node.path.strip('/')}")
    if fmt == "zarr":
        require("zarr", f"writing Zarr ({path.name})")
    # the groups echopype does not know lie flat in /Vendor_specific (open_tree restores them)
    tree = flatten(tree)
    with staged(path) as tmp:
        if fmt == "netcdf":
            with _small_chunk_cache():
                _write_netcdf(tree, tmp, _encoding(tree))
        else:
            tree.to_zarr(tmp, mode="w", consolidated=False, zarr_format=2)
    return path


#: the attribute that lets a variable hold NaN or inf: it says what they mean
NAN_MEANS = "nan_means"


def check_finite(ds: xr.Dataset, *, where: str) -> None:
    """Refuse to write NaN or inf, except in variables whose ``nan_means`` attribute documents
    what they mean (e.g. an SNR where no noise level exists).

    Raises
    ------
    DatasetError
        Names the variables (a bug, or a setting beyond what the numbers survive).
    """
    bad = []
    for name, var in ds.data_vars.items():
        if var.dtype.kind in "fc" and NAN_MEANS not in var.attrs:
            values = var.values
            if values.size and not np.all(np.isfinite(values)):
                bad.append(str(name))
    if bad:
        raise DatasetError(f"{where}: refusing to write NaN or inf in {', '.join(bad)} (settings "
                           f"beyond what the numbers survive, or a bug: please report it)")


def write_dataset(ds: xr.Dataset, path: str | Path, *, fmt: str | None = None,
                  chunk_dim: str | None = None) -> Path:
    """Write one flat dataset atomically as NetCDF4 or Zarr (e.g. an experiment's results).

    Parameters
    ----------
    ds : xarray.Dataset
    path : str or Path
    fmt : {"netcdf", "zarr"}, optional
        Default from the suffix.
    chunk_dim : str, optional
        Chunk every variable that has this dimension one step along it (whole along the rest).

    Returns
    -------
    Path
    """
    path = Path(path)
    fmt = _format_of(path, fmt)
    if not path.parent.exists():
        raise DatasetError(f"{path}: the folder {path.parent} does not exist")
    check_finite(ds, where=str(path))
    chunks = {}
    if chunk_dim is not None:
        chunks = {k: tuple(1 if d == chunk_dim else ds.sizes[d] for d in v.dims)
                  for k, v in ds.data_vars.items() if chunk_dim in v.dims}
    if fmt == "zarr":
        require("zarr", f"writing Zarr ({path.name})")
    with staged(path) as tmp:
        if fmt == "zarr":
            ds.to_zarr(tmp, mode="w", encoding={k: {"chunks": c} for k, c in chunks.items()},
                       zarr_format=2, consolidated=True)
        else:
            ds.to_netcdf(tmp, engine="netcdf4",
                         encoding={k: {"chunksizes": c} for k, c in chunks.items()})
    return path


def open_tree(path: str | Path, *, max_memory_gb: float | None = None,
              work_factor: float = 1.0) -> xr.DataTree:
    """Open a dataset written by :func:`write_tree` (or any SONAR-netCDF4-like file) in memory.

    The file is opened lazily first: its size in memory, times ``work_factor`` (what the caller
    will make of it, e.g. images), must fit the memory limit
    (:func:`processing.base.resources.memory_limit_bytes`) before anything is loaded.

    Raises
    ------
    DatasetError
        Missing, unreadable or damaged file, with the reason.
    processing.base.resources.ResourceError
        Too large for the memory limit.
    """
    from processing.base.resources import Estimate, check_resources
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such file or folder")
    if not path.is_dir() and not path.is_file():
        raise DatasetError(f"{path}: not a regular file (a device or a pipe); expected NetCDF4 or Zarr")
    if path.is_dir():
        require("zarr", f"reading Zarr ({path.name})")
    elif sonar_convention_version(path).startswith("2"):
        raise DatasetError(f"{path}: a SONAR-netCDF4 2.0 file; read it with processing.open_record(path), "
                           f"or convert it to the 1.0 dataset processing reads: abacus convert {path.name} OUT.nc")
    try:
        if path.is_dir():
            tree = xr.open_datatree(path, engine="zarr", consolidated=False)
        else:
            tree = xr.open_datatree(path, engine="netcdf4")
    except Exception as exc:  # a foreign or damaged file: say so in one line
        raise DatasetError(f"{path}: cannot be read as a NetCDF4/Zarr dataset "
                           f"({exc.__class__.__name__}: {_first_line(exc)})") from None
    try:
        size = float(sum(v.nbytes for node in tree.subtree for v in node.ds.variables.values()))
        check_resources(Estimate(size * (1.0 + work_factor), 0.0, [("dataset", size)],
                                 keys="the pings in the file (process it in parts)"),
                        what=f"{path}", max_memory_gb=max_memory_gb)
        from processing.base.file_layout import restore
        return restore(tree.load())
    except (DatasetError, ValueError) as exc:
        if exc.__class__.__name__ == "ResourceError" or isinstance(exc, DatasetError):
            raise
        raise DatasetError(f"{path}: damaged or truncated ({exc.__class__.__name__}: "
                           f"{_first_line(exc)})") from None
    except Exception as exc:
        raise DatasetError(f"{path}: damaged or truncated ({exc.__class__.__name__}: "
                           f"{_first_line(exc)})") from None
    finally:
        tree.close()


def sonar_convention_version(path: Path) -> str:
    """The root attribute ``sonar_convention_version`` of a netCDF4 file ("" when it has none
    or is not netCDF4): how a SONAR-netCDF4 2.0 file is told from a 1.0 dataset."""
    import netCDF4
    try:
        with netCDF4.Dataset(path) as nc:
            return str(getattr(nc, "sonar_convention_version", "")).strip()
    except Exception:        # not netCDF4: xarray's reader says what it is
        return ""


def _first_line(exc) -> str:
    text = str(exc).strip().splitlines()
    return (text[0][:200] if text else "")


def as_tree(data) -> xr.DataTree:
    """A dataset given as a tree, or as the path of a file :func:`open_tree` opens.

    Parameters
    ----------
    data : xarray.DataTree, str or Path

    Returns
    -------
    xarray.DataTree

    Raises
    ------
    DatasetError
        A path that cannot be opened (named), or neither a tree nor a path.
    """
    if isinstance(data, xr.DataTree):
        return data
    if isinstance(data, (str, Path)):
        return open_tree(data)
    raise DatasetError(f"expected a dataset (xarray.DataTree) or the path of one, not "
                       f"{type(data).__name__}")


def source_of(tree: xr.DataTree) -> str:
    """What to call a dataset in messages: the file it was read from, else its title."""
    src = getattr(tree, "encoding", {}).get("source")
    return str(Path(src).name if src else tree.attrs.get("title", "dataset"))


def ping_indices(group: xr.Dataset) -> np.ndarray:
    """The scene's ping index of every ping of an element group, shape (n_pings,): its
    ``ping_index`` variable, else 0, 1, 2, ... (a recorded file numbers its pings in order)."""
    if "ping_index" in group.variables:
        return np.asarray(group["ping_index"].values, int)
    return np.arange(group.sizes["ping_time"])


def tree_pings(tree: xr.DataTree) -> int:
    """Pings in a dataset's per-element samples (0 when it has none)."""
    try:
        return int(tree[ELEMENT_GROUP].ds.sizes.get("ping_time", 0))
    except KeyError:
        return 0


def split_complex(name: str, values, dims, attrs=None) -> dict:
    """``{name_r: DataArray, name_i: DataArray}`` float32 pair for a complex array."""
    v = np.asarray(values)
    attrs = dict(attrs or {})
    # complex64 input: the pair are views of it (no copy); anything else is rounded to float32
    return {f"{name}_r": xr.DataArray(v.real.astype(np.float32, copy=False), dims=dims, attrs=attrs),
            f"{name}_i": xr.DataArray(v.imag.astype(np.float32, copy=False), dims=dims, attrs=attrs)}


def complex_of(ds: xr.Dataset, name: str, *, where: str = "") -> np.ndarray:
    """Rebuild a complex array from its ``_r``/``_i`` pair (complex128)."""
    try:
        re, im = ds[f"{name}_r"], ds[f"{name}_i"]
    except KeyError:
        raise DatasetError(f"{where}: missing variables {name}_r/{name}_i") from None
    return re.values.astype(np.float64) + 1j * im.values.astype(np.float64)


class PairedSamples:
    """Complex samples held as the dataset's real/imaginary pair, made complex128 only where
    indexed: a record's samples are never copied whole (100 pings of ABACUS: 52 MB as float32
    pairs, 105 MB more as complex128).

    Indexing the ping axis with a slice (or an index array) gives another ``PairedSamples``
    (views where numpy allows); any index that drops the ping axis gives a complex128 ndarray.
    ``np.asarray(samples)`` materialises the whole complex128 array.

    Attributes
    ----------
    real, imag : ndarray, shape (n_pings, n_channels, n_samples)
        The pair, any real dtype (float32 in datasets), ADC counts.
    """

    def __init__(self, real, imag):
        self.real = np.asarray(real)
        self.imag = np.asarray(imag)
        if self.real.shape != self.imag.shape:
            raise ValueError(f"real and imaginary parts differ in shape: {self.real.shape} vs "
                             f"{self.imag.shape}")

    shape = property(lambda self: self.real.shape)
    ndim = property(lambda self: self.real.ndim)
    dtype = np.dtype(np.complex128)

    def __len__(self):
        return self.real.shape[0]

    def __getitem__(self, index):
        re, im = self.real[index], self.imag[index]
        if re.ndim == self.real.ndim:
            return PairedSamples(re, im)
        return _pair_to_complex(re, im)

    def __array__(self, dtype=None, copy=None):
        out = _pair_to_complex(self.real, self.imag)
        return out if dtype is None else out.astype(dtype)

    def all_finite(self) -> bool:
        """Whether every sample is finite (checked on the pair, without a complex copy)."""
        return bool(np.all(np.isfinite(self.real)) and np.all(np.isfinite(self.imag)))


def _pair_to_complex(re, im) -> np.ndarray:
    out = np.empty(np.shape(re), np.complex128)
    out.real, out.imag = re, im
    return out


# ------------------------------------------------------------- processing view
@dataclass(frozen=True, eq=False)
class SonarRecord:
    """What processing needs from a dataset, in SI units and the sonar frame.

    Attributes
    ----------
    samples : PairedSamples or ndarray, shape (n_pings, n_channels, n_samples), complex
        Per-element complex baseband samples (ADC counts); from a dataset a
        :class:`PairedSamples` (complex128 where indexed, never copied whole).
    ping_index : ndarray of int, shape (n_pings,)
    rate_hz : float
        Sampling rate.
    time_offset_s : float
        Time of sample 0 after the start of transmission.
    replica : ndarray, shape (M,), complex128
        Sampled transmit pulse u(j/fs).
    center_frequency_hz, bandwidth_hz, sound_speed_m_s : float
    element_position_m : ndarray, shape (n_channels, 3)
        Receiver element centres (m), sonar frame.
    element_subarray : ndarray of str, shape (n_channels,)
    transmitter_position_m : ndarray, shape (n_tx, 3)
        Transmitter element centres (m).
    transmitter_weight : ndarray, shape (n_tx,)
    mode : str
        "interferometric", "normal" or "combined".
    source : str
        File the record came from (for messages).
    """

    samples: np.ndarray
    ping_index: np.ndarray
    rate_hz: float
    time_offset_s: float
    replica: np.ndarray
    center_frequency_hz: float
    bandwidth_hz: float
    sound_speed_m_s: float
    element_position_m: np.ndarray
    element_subarray: np.ndarray
    transmitter_position_m: np.ndarray
    transmitter_weight: np.ndarray
    mode: str
    source: str = ""

    @property
    def wavelength_m(self) -> float:
        return self.sound_speed_m_s / self.center_frequency_hz

    @property
    def image_groups(self) -> dict:
        """Channel indices of each image: {"A": ..., "B": ...}, or {"AB": all} in combined mode."""
        names = self.element_subarray
        if self.mode == "combined":
            return {"AB": np.arange(len(names))}
        return {str(s): np.flatnonzero(names == s) for s in dict.fromkeys(names.tolist())}

    @property
    def transmitter_center_m(self) -> np.ndarray:
        w = np.abs(self.transmitter_weight)
        return (self.transmitter_position_m * w[:, None]).sum(0) / w.sum()


def _need(tree, group, name, where):
    try:
        node = tree[group]
    except KeyError:
        raise DatasetError(f"{where}: missing group /{group}") from None
    if name not in node.ds.variables:
        raise DatasetError(f"{where}: /{group} has no variable '{name}'")
    return node.ds[name]


def group_of(tree: xr.DataTree, group: str) -> xr.Dataset | None:
    """A group's variables, or None when the dataset has no such group.

    Parameters
    ----------
    tree : xarray.DataTree
    group : str
        A group path of :mod:`processing.base.contract` (``SONAR_GROUP``, ``ELEMENT_GROUP``, ...).

    Returns
    -------
    xarray.Dataset or None
        The node's dataset (a view: its coordinates include those it inherits).
    """
    try:
        node = tree[group]
    except KeyError:
        return None
    return node.ds if isinstance(node, xr.DataTree) else None


def stage_seconds(tree: xr.DataTree) -> dict:
    """The wall time of each simulation stage that made the dataset, in the order they ran.

    Parameters
    ----------
    tree : xarray.DataTree

    Returns
    -------
    dict of str to float
        Stage name -> seconds (s); empty without /Provenance or its timings. Read from the
        ``stage_seconds_json`` attribute, or from the ``stage_seconds`` variable along ``stage``
        of files written before the timings became attributes.
    """
    import json

    from processing.base.contract import PROVENANCE_GROUP
    prov = group_of(tree, PROVENANCE_GROUP)
    if prov is None:
        return {}
    if "stage_seconds_json" in prov.attrs:
        return {str(k): float(v) for k, v in json.loads(str(prov.attrs["stage_seconds_json"])).items()}
    if "stage_seconds" in prov and "stage" in prov:          # the layout before
        return {str(k): float(v) for k, v in zip(prov["stage"].values, prov["stage_seconds"].values)}
    return {}


def has_group(tree: xr.DataTree, group: str) -> bool:
    """Whether the dataset has the group (``ELEMENT_GROUP``, ``DETECTIONS_GROUP``, ...)."""
    return group_of(tree, group) is not None


def _per_channel_scalar(tree, group, name, where, default=None) -> float:
    """A beam-group variable that may be given per channel and ping (SONAR-netCDF4) or as a
    scalar: its one value (it must not change across pings: one record, one setting)."""
    if default is not None and name not in tree[group].ds.variables:
        return float(default)
    v = np.asarray(_need(tree, group, name, where).values, float).ravel()
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise DatasetError(f"{where}: /{group}/{name} is empty or not finite")
    if np.ptp(v) > 1e-9 * max(abs(v[0]), 1e-30):
        raise DatasetError(f"{where}: /{group}/{name} changes across pings or channels "
                           f"({v.min():.6g}…{v.max():.6g}); a record must hold one setting")
    return float(v[0])


def beam_samples(ds: xr.Dataset, *, where: str = "") -> PairedSamples:
    """The per-element samples of a beam group as (ping, element, sample).

    ``backscatter_r/_i`` on (channel, ping_time, range_sample, beam) (echopype's complex layout)
    or (ping_time, range_sample, beam); one channel only (the receiver; its beams are its
    elements). Views of the stored arrays, no copy.
    """
    try:
        re, im = ds["backscatter_r"], ds["backscatter_i"]
    except KeyError:
        raise DatasetError(f"{where}: missing variables backscatter_r/backscatter_i") from None
    dims = tuple(re.dims)
    if "channel" in dims:
        if re.sizes["channel"] != 1:
            raise DatasetError(f"{where}/backscatter_r has {re.sizes['channel']} channels; abacus reads "
                               f"one receiver channel whose beams are its elements (docs/dataset.md)")
        re, im = re.isel(channel=0), im.isel(channel=0)
        dims = tuple(re.dims)
    if set(dims) != {"ping_time", "range_sample", "beam"} or im.dims != re.dims:
        raise DatasetError(f"{where}/backscatter_r must have dims (channel, ping_time, range_sample, "
                           f"beam), found {ds['backscatter_r'].dims}")
    order = [dims.index(d) for d in ("ping_time", "beam", "range_sample")]
    try:
        return PairedSamples(np.transpose(re.values, order), np.transpose(im.values, order))
    except ValueError as exc:
        raise DatasetError(f"{where}/backscatter_r/_i: {exc}") from None


#: sonar models (the root's ``keywords``, echopype's ``sonar_model``) -> the family read here
SIMRAD_MODELS = {"EK60": "EK60", "ES70": "EK60", "EK80": "EK80", "ES80": "EK80", "EA640": "EK80"}


def echosounder_model(tree: xr.DataTree) -> str | None:
    """"EK60" or "EK80" for a file echopype converted from a Simrad echosounder (its root
    ``keywords`` or /Sonar ``sonar_model`` names one of :data:`SIMRAD_MODELS`), else None.

    abacus' own files (one channel whose beams are elements, ``element_subarray``) are never
    taken for one, whatever their keywords say.
    """
    bg = group_of(tree, ELEMENT_GROUP)
    if bg is not None and "element_subarray" in bg.variables:
        return None
    sonar = group_of(tree, SONAR_GROUP)
    for name in (tree.attrs.get("keywords"), sonar.attrs.get("sonar_model") if sonar is not None else None):
        family = SIMRAD_MODELS.get(str(name or "").strip().upper())
        if family:
            return family
    return None


def missing_variables(tree: xr.DataTree) -> list:
    """The variables processing cannot do without (the contract's mandatory ones) that a
    dataset lacks, as ``/group/variable`` paths, in the table's order (empty: none missing)."""
    from processing.base.contract import GROUPS
    out = []
    for path, spec in GROUPS.items():
        names = [v.name for v in spec.variables if v.mandatory]
        if not names:
            continue
        ds = group_of(tree, path.strip("/"))
        out += [f"{path}/{n}" for n in names if ds is None or n not in ds.variables]
    return out


def read_record(tree: xr.DataTree, *, source: str = "") -> SonarRecord:
    """The processing view of a dataset; every missing or malformed piece is named (every
    missing variable in one message).

    Raises
    ------
    DatasetError
    """
    where = source or "dataset"
    eg = ELEMENT_GROUP
    if not has_group(tree, eg) and has_group(tree, LEGACY_ELEMENT_GROUP):
        raise DatasetError(f"{where}: the previous abacus layout (/{LEGACY_ELEMENT_GROUP}); "
                           f"bring it to SONAR-netCDF4 with `abacus convert IN OUT`")
    model = echosounder_model(tree)
    if model is not None:
        raise DatasetError(f"{where}: an {model} file converted by echopype: one channel per transducer "
                           f"(power, angles or sector samples), not the per-element samples of an array that "
                           f"imaging, detection and counting need; `abacus sv` calibrates it")
    missing = missing_variables(tree)
    if missing:
        raise DatasetError(f"{where}: lacks {len(missing)} variable{'s' if len(missing) > 1 else ''} processing "
                           f"needs: {', '.join(missing)} (docs/dataset.md)")
    ds = tree[eg].ds
    samples = beam_samples(ds, where=f"{where}: /{eg}")
    if not samples.all_finite():
        raise DatasetError(f"{where}: /{eg}/backscatter_r/_i contain NaN or inf samples")
    interval = _per_channel_scalar(tree, eg, "sample_interval", where)
    if not interval > 0:
        raise DatasetError(f"{where}: /{eg}/sample_interval must be > 0 s, found {interval}")
    # time of sample k after transmission: blanking_interval + k / fs − sample_time_offset
    offset = (_per_channel_scalar(tree, eg, "blanking_interval", where, default=0.0)
              - _per_channel_scalar(tree, eg, "sample_time_offset", where, default=0.0))
    pos = np.stack([_need(tree, eg, f"element_{a}", where).values for a in "xyz"], -1).astype(float)
    sub = np.asarray(_need(tree, eg, "element_subarray", where).values).astype(str)
    sonar = group_of(tree, SONAR_GROUP)
    if sonar is None:
        raise DatasetError(f"{where}: missing group /{SONAR_GROUP} (transmit pulse)")
    replica = complex_of(sonar, "replica", where=f"{where}: /{SONAR_GROUP}")
    if replica.size == 0 or not np.any(replica) or not np.all(np.isfinite(replica)):
        raise DatasetError(f"{where}: /{SONAR_GROUP}/replica_r/_i (the transmit pulse) is empty, all zero or "
                           f"not finite: nothing to compress the echoes with")
    tx = np.stack([_need(tree, SONAR_GROUP, f"tx_element_{a}", where).values for a in "xyz"], -1)
    txw = _need(tree, SONAR_GROUP, "tx_element_weight", where).values.astype(float)
    f0 = float(_need(tree, SONAR_GROUP, "transmit_frequency_center", where).values)
    bw = float(_need(tree, SONAR_GROUP, "transmit_bandwidth", where).values)
    c = float(_need(tree, ENVIRONMENT_GROUP, "sound_speed_indicative", where).values)
    mode = str(ds.attrs.get("mode", "interferometric"))
    if mode not in ("interferometric", "normal", "combined"):
        raise DatasetError(f"{where}: /{eg} attribute mode={mode!r}; accepted: interferometric, "
                           f"normal, combined")
    present = set(sub.tolist())
    if mode in ("interferometric", "combined") and not {"A", "B"} <= present:
        # interferometry needs both subarrays: say so, and image what is there
        import warnings
        warnings.warn(f"{where}: /{eg} says mode={mode!r} but holds only subarray(s) "
                      f"{', '.join(sorted(present))}: imaged in normal mode; no elevation, so no "
                      f"counts after interferometry", DatasetWarning, stacklevel=2)
        mode = "normal"
    if samples.shape[0] == 0:
        raise DatasetError(f"{where}: /{eg} holds no pings")
    ping = ping_indices(ds)
    return SonarRecord(samples, ping, 1.0 / interval, offset, replica, f0, bw, c, pos, sub,
                       tx.astype(float), txw, mode, where)
