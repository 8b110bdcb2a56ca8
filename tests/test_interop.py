"""Standard data in and out (issue 16): the SONAR-netCDF4 layout, recorded .mat files of another
array read and imaged, and the previous abacus layout converted to the same detections. The
files here are written by the tests themselves (scipy.io, plain xarray), not by abacus' writer."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.io
import xarray as xr

import acoustics
import processing
from processing.base.dataset import ELEMENT_GROUP, TRUTH_GROUP, beam_samples, open_tree

from .test_cli import abacus

C, F0, B, FS = 1500.0, 200e3, 20e3, 80e3


def _recording(path, *, az_deg=10.0, el_deg=0.5, range_m=18.0, pings=3, ns=2048, **override):
    """A .mat recording of a point target by a 200 kHz sonar unlike ABACUS: two subarrays of 8
    elements at 0.6 λ pitch, 2 λ apart, an 8-element transmitter; echoes computed here from the
    two-way delay of every element (the LFM replica delayed, carrier phase −2π f0 τ)."""
    lam = C / F0
    T = 1e-3
    t = np.arange(int(T * FS)) / FS
    rep = np.exp(1j * np.pi * (B / T) * (t - T / 2) ** 2) * np.hanning(t.size)
    x = (np.arange(8) - 3.5) * 0.6 * lam
    el = np.concatenate([np.c_[x, np.full(8, -lam), np.zeros(8)], np.c_[x, np.full(8, lam), np.zeros(8)]])
    tx = np.c_[np.zeros(8), (np.arange(8) - 3.5) * 0.5 * lam, np.zeros(8)]
    th, ph = np.radians(az_deg), np.radians(el_deg)
    p = range_m * np.array([np.cos(ph) * np.sin(th), np.sin(ph), np.cos(ph) * np.cos(th)])
    t0 = 0.01
    ts = t0 + np.arange(ns) / FS
    X = np.zeros((pings, 16, ns), complex)
    for k in range(16):
        tau = (np.linalg.norm(p - tx.mean(0)) + np.linalg.norm(p - el[k])) / C
        u = np.interp(ts - tau, t, rep.real, left=0, right=0) + 1j * np.interp(ts - tau, t, rep.imag, left=0, right=0)
        X[:, k] = 100 * u * np.exp(-2j * np.pi * F0 * tau)
    rng = np.random.default_rng(0)
    X += rng.normal(0, 1, X.shape) + 1j * rng.normal(0, 1, X.shape)
    fields = {"samples": X, "fs": FS, "f0": F0, "bandwidth": B, "replica": rep, "c": C,
              "element_xyz": el, "element_subarray": np.array(list("A" * 8 + "B" * 8)), "tx_xyz": tx,
              "t0": t0, "tx_beamwidth_deg": [30.0, 14.0]}
    fields.update(override)
    fields = {k: v for k, v in fields.items() if v is not None}
    scipy.io.savemat(path, fields)
    return path


def test_a_mat_recording_of_another_array_is_converted_imaged_and_located(tmp_path):
    """`abacus convert` then `abacus count`: the target is found at its range within a quarter of
    the 3.75 cm range resolution, its azimuth within 0.25° (2 % of the 8-element beam's 12°) and
    its interferometric elevation within 0.1° (σ ≈ λ/(2π b √SNR) ≈ 0.05° at the 40 dB per-element
    SNR of the recording)."""
    _recording(tmp_path / "rec.mat")
    r = abacus("convert", "rec.mat", "rec.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    tree = open_tree(tmp_path / "rec.nc")
    assert tree[ELEMENT_GROUP].ds["backscatter_r"].dims == ("channel", "ping_time", "range_sample", "beam")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = processing.detections_of(processing.detect(tree))
    for p in range(3):
        k = np.flatnonzero(d["ping"].values == p)
        i = k[np.argmax(d["amplitude"].values[k])]
        assert abs(float(d["range_m"][i]) - 18.0) < 0.25 * C / (2 * B)
        assert abs(np.degrees(float(d["azimuth_rad"][i])) - 10.0) < 0.25
        assert abs(np.degrees(float(d["elevation_rad"][i])) - 0.5) < 0.1


@pytest.mark.parametrize("override, words", [
    ({"fs": None}, "missing field 'fs'"),
    ({"element_xyz": np.zeros((15, 3))}, "element positions must be 16 x 3"),
    ({"element_subarray": np.arange(16.0)}, "'element_subarray' must be text"),
    ({"mode": "sideways"}, "accepted: interferometric, normal, combined"),
])
def test_a_bad_mat_recording_is_one_line_naming_the_field(tmp_path, override, words):
    _recording(tmp_path / "bad.mat", pings=1, **override)
    r = abacus("convert", "bad.mat", "out.nc", cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.nc").exists()


def test_a_matlab_v73_file_says_how_to_save_it(tmp_path):
    (tmp_path / "r.mat").write_bytes(b"MATLAB 7.3 MAT-file, Platform: GLNXA64" + b"\0" * 200)
    r = abacus("convert", "r.mat", "out.nc", cwd=tmp_path)
    assert r.returncode == 2 and "-v7" in r.stderr


def _legacy(tree) -> xr.DataTree:
    """The layout abacus wrote before SONAR-netCDF4, rebuilt by hand from a dataset's arrays."""
    eg = tree[ELEMENT_GROUP].to_dataset(inherit=False)
    x = np.asarray(beam_samples(eg)).astype(np.complex64)             # (ping, element, sample)
    old = xr.Dataset(
        {"element_r": (("ping_time", "rx_element", "range_sample"), x.real),
         "element_i": (("ping_time", "rx_element", "range_sample"), x.imag),
         **{f"element_{k}": ("rx_element", eg[f"element_{k}"].values)
            for k in ("x", "y", "z", "width", "height", "rotation", "subarray", "index_in_subarray")},
         "sample_interval": float(eg["sample_interval"].values.ravel()[0]),
         "sample_time_offset": float(eg["blanking_interval"].values.ravel()[0])},
        coords={"ping_time": eg["ping_time"].values, "ping_index": ("ping_time", eg["ping_index"].values),
                "rx_element": np.arange(x.shape[1]), "channel": ("rx_element", eg["beam"].values)},
        attrs=eg.attrs)
    groups = {"/": tree.to_dataset(inherit=False), "/Simulation/Element_group1": old,
              "/Simulation/Ground_truth": tree[TRUTH_GROUP].to_dataset(inherit=False)}
    for name in ("Environment", "Platform", "Provenance"):
        groups[f"/{name}"] = tree[name].to_dataset(inherit=False)
    sonar = tree["Sonar"].to_dataset(inherit=False)
    groups["/Sonar"] = sonar.drop_vars(["beam_group_name", "beam_group_descr", "beam_group"]).assign_coords(
        channel_all=eg["beam"].values)
    return xr.DataTree.from_dict(groups)


def test_the_previous_layout_converts_to_the_same_detections(tmp_path):
    scene = acoustics.load_scene("two_targets")
    tree = acoustics.simulate(scene, pings=range(2))
    processing.write_tree(tree, tmp_path / "new.nc")
    _legacy(tree).to_netcdf(tmp_path / "old.nc")
    r = abacus("count", "old.nc", cwd=tmp_path)
    assert r.returncode == 2 and "abacus convert" in r.stderr           # says what to do
    r = abacus("convert", "old.nc", "conv.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = processing.detections_of(processing.count(open_tree(tmp_path / "new.nc")))
        b = processing.detections_of(processing.count(open_tree(tmp_path / "conv.nc")))
    assert a.sizes == b.sizes and len(a["range_m"]) > 0
    for v in ("range_m", "azimuth_rad", "elevation_rad", "amplitude", "world_z_m"):
        np.testing.assert_array_equal(a[v].values, b[v].values)
    conv = open_tree(tmp_path / "conv.nc")
    np.testing.assert_array_equal(conv[TRUTH_GROUP].ds["target_range"].values,
                                  tree[TRUTH_GROUP].ds["target_range"].values)


def test_the_dataset_is_sonar_netcdf4_as_echopype_reads_it(tmp_path):
    """What echopype's open_converted and repr rely on (checked with echopype itself by
    benchmarks/interop.py, docs/interop.md): the convention attributes, keywords as the sonar
    model, every group one echopype knows, beam_group_descr for the beam group, and the samples
    in Beam_group1 equal to the simulation's."""
    tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2))
    processing.write_tree(tree, tmp_path / "s.nc")
    t = xr.open_datatree(tmp_path / "s.nc")
    a = t.attrs
    assert (a["sonar_convention_authority"], a["sonar_convention_name"], a["sonar_convention_version"]) == \
        ("ICES", "SONAR-netCDF4", "1.0")
    assert a["keywords"] == t["Sonar"].attrs["sonar_model"] == "ABACUS"
    known = {"/", "/Environment", "/Platform", "/Provenance", "/Sonar", "/Sonar/Beam_group1", "/Vendor_specific"}
    assert {n.path for n in t.subtree} <= known
    assert t["Sonar"].ds["beam_group_descr"].sel(beam_group="Beam_group1").size == 1
    bg = t["Sonar/Beam_group1"].ds
    assert bg["backscatter_r"].dims == ("channel", "ping_time", "range_sample", "beam")
    np.testing.assert_array_equal(np.asarray(beam_samples(bg)), np.asarray(beam_samples(tree[ELEMENT_GROUP].ds)))
    for v in ("sample_interval", "blanking_interval", "transmit_frequency_start", "transmit_duration_nominal"):
        assert bg[v].dims == ("channel", "ping_time")
    for v in ("beam_direction_z", "beamwidth_receive_major", "equivalent_beam_angle"):
        assert bg[v].dims == ("channel", "beam") and np.all(np.isfinite(bg[v].values))
    assert t["Environment"].ds["absorption_indicative"].dims == ("frequency",)


def test_a_mat_twin_of_a_simulation_gives_the_same_detections(tmp_path):
    """The same samples in a third-party layout: a simulation's per-element samples and geometry
    saved to a .mat file by scipy.io, converted, and counted under the same settings, give the
    detections of the abacus-written dataset exactly (same numbers in, same numbers out)."""
    tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2))
    eg = tree[ELEMENT_GROUP].ds
    sonar = tree["Sonar"].ds
    x = np.asarray(beam_samples(eg)).astype(np.complex64)
    scipy.io.savemat(tmp_path / "twin.mat", {
        "samples": x, "fs": 1.0 / float(eg["sample_interval"].values.ravel()[0]),
        "t0": float(eg["blanking_interval"].values.ravel()[0]),
        "f0": float(sonar["transmit_frequency_center"]), "bandwidth": float(sonar["transmit_bandwidth"]),
        "replica": sonar["replica_r"].values + 1j * sonar["replica_i"].values,
        "c": float(tree["Environment"].ds["sound_speed_indicative"]),
        "element_xyz": np.stack([eg[f"element_{a}"].values for a in "xyz"], -1),
        "element_subarray": np.array(list("".join(eg["element_subarray"].values.astype(str)))),
        "tx_xyz": np.stack([sonar[f"tx_element_{a}"].values for a in "xyz"], -1),
        "tx_weight": sonar["tx_element_weight"].values,
        "tx_beamwidth_deg": [float(sonar["beamwidth_transmit_major"]), float(sonar["beamwidth_transmit_minor"])]})
    r = abacus("convert", "twin.mat", "twin.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    settings = processing.resolve_settings(tree)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = processing.detections_of(processing.detect(tree, settings))
        b = processing.detections_of(processing.detect(open_tree(tmp_path / "twin.nc"), settings))
    assert len(a["range_m"]) > 0 and a.sizes == b.sizes
    for v in ("range_m", "azimuth_rad", "elevation_rad", "amplitude", "snr_db"):
        np.testing.assert_allclose(a[v].values, b[v].values, rtol=1e-6, atol=1e-9)


def test_a_sonar_netcdf4_file_written_with_plain_xarray_is_read(tmp_path):
    """A conformant file made without abacus' writer (only the variables the contract names,
    scalars where the standard allows (channel, ping_time)): processing reads it directly and
    locates the target of the 200 kHz recording."""
    m = scipy.io.loadmat(_recording(tmp_path / "r.mat", pings=2), squeeze_me=True)
    x = m["samples"]
    rep = m["replica"]
    names = [f"{s}{i % 8}" for i, s in enumerate("A" * 8 + "B" * 8)]
    bg = xr.Dataset(
        {"backscatter_r": (("channel", "ping_time", "range_sample", "beam"), x.real.transpose(0, 2, 1)[None].astype("f4")),
         "backscatter_i": (("channel", "ping_time", "range_sample", "beam"), x.imag.transpose(0, 2, 1)[None].astype("f4")),
         "sample_interval": (("channel", "ping_time"), np.full((1, 2), 1 / FS)),
         "blanking_interval": (("channel", "ping_time"), np.full((1, 2), 0.01)),
         "element_x": ("beam", m["element_xyz"][:, 0]), "element_y": ("beam", m["element_xyz"][:, 1]),
         "element_z": ("beam", m["element_xyz"][:, 2]), "element_subarray": ("beam", list("A" * 8 + "B" * 8))},
        coords={"channel": ["rx"], "beam": names, "ping_time": np.array(["2024-01-01T00:00:00", "2024-01-01T00:00:01"],
                                                                        dtype="datetime64[ns]")})
    sonar = xr.Dataset({"replica_r": ("replica_sample", rep.real), "replica_i": ("replica_sample", rep.imag),
                        "transmit_frequency_center": F0, "transmit_bandwidth": B,
                        "tx_element_x": ("tx_element", m["tx_xyz"][:, 0]), "tx_element_y": ("tx_element", m["tx_xyz"][:, 1]),
                        "tx_element_z": ("tx_element", m["tx_xyz"][:, 2]), "tx_element_weight": ("tx_element", np.ones(8)),
                        "beamwidth_transmit_major": 30.0, "beamwidth_transmit_minor": 14.0})
    xr.DataTree.from_dict({"/": xr.Dataset(attrs={"sonar_convention_name": "SONAR-netCDF4"}),
                           "/Environment": xr.Dataset({"sound_speed_indicative": C}),
                           "/Sonar": sonar, "/Sonar/Beam_group1": bg}).to_netcdf(tmp_path / "plain.nc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = processing.detections_of(processing.detect(open_tree(tmp_path / "plain.nc")))
    i = int(np.argmax(d["amplitude"].values))
    assert abs(float(d["range_m"][i]) - 18.0) < 0.01 and abs(np.degrees(float(d["azimuth_rad"][i])) - 10.0) < 0.25
    # and what is missing is named: the transmitter's element weights
    t = xr.open_datatree(tmp_path / "plain.nc").load()
    t["Sonar"].dataset = t["Sonar"].to_dataset(inherit=False).drop_vars("tx_element_weight")
    with pytest.raises(processing.DatasetError, match="tx_element_weight"):
        processing.detect(t)


def test_a_split_recording_images_its_whole_record_and_finds_a_target_at_35_m(tmp_path):
    """A .mat recording split into subarrays A and B, 7.5–45.9 m recorded, a target at 35 m:
    without a scene the image spans the whole record (not the thesis' 13–26 m default), and the
    target is located at its range within a quarter of the 3.75 cm range resolution and its
    azimuth within 0.25°."""
    _recording(tmp_path / "far.mat", range_m=35.0, pings=1, ns=4096)
    tree = processing.open_record(tmp_path / "far.mat")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        im = processing.images_of(processing.image(tree))
        d = processing.detections_of(processing.detect(tree))
    assert set(im.groups) == {"A", "B"}
    assert im.range_m[0] < 8.0 and im.range_m[-1] > 45.0
    i = int(np.argmax(d["amplitude"].values))
    assert abs(float(d["range_m"][i]) - 35.0) < 0.25 * C / (2 * B)
    assert abs(np.degrees(float(d["azimuth_rad"][i])) - 10.0) < 0.25


def test_the_echopype_view_calibrates_back_to_abacus_sv(tmp_path):
    """`abacus sv --echopype`: the image in the EK60's convention. Through the EK60 equation
    (processing/backscatter/ek60.py, which matches echopype's compute_Sv on a real EK60 file to
    0.1 dB: tests/test_echosounder.py) it gives back abacus' Sv of every cell to 1e-6 dB, the same
    cells without Sv, and each cell's range within half a range cell; the view holds what
    echopype's combine_echodata needs (Provenance's conversion_software_name, one time axis)."""
    from processing.backscatter.ek60 import sv_of_power
    from processing.base.echosounder import read_power_record
    processing.write_tree(acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2)),
                          tmp_path / "s.nc")
    r = abacus("sv", "s.nc", "-o", "p.nc", "--echopype", "view.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    cells = open_tree(tmp_path / "p.nc")["Processing/Sv"].ds
    view = processing.open_record(tmp_path / "view.nc")
    assert view.attrs["keywords"] == "EK60"
    assert view["Provenance"].attrs["conversion_software_name"] == "abacus"
    sv, rng = sv_of_power(read_power_record(view))                 # (beam, ping, sample)
    want = cells["Sv"].values.transpose(2, 0, 1)
    n0 = sv.shape[2] - want.shape[2]
    np.testing.assert_array_equal(np.isnan(sv[:, :, n0:]), np.isnan(want))
    assert np.all(np.isnan(sv[:, :, :n0]))
    assert np.nanmax(np.abs(sv[:, :, n0:] - want)) < 1e-6
    r_cells = cells["cell_range_m"].values[0, :, 0]
    assert np.max(np.abs(rng[0, 0, n0:] - r_cells)) <= 0.5 * np.median(np.diff(r_cells)) + 1e-9


#: the groups echopype's EchoData knows (echodata/convention/1.0.yml of echopype 0.11, read from
#: its source): its repr looks up every group of a file that holds data in this table
ECHOPYPE_TABLE = {"/", "/Environment", "/Platform", "/Platform/NMEA", "/Provenance", "/Sonar", "/Sonar/Beam_group1",
                  "/Sonar/Beam_group2", "/Sonar/Beam_group3", "/Sonar/Beam_group4", "/Vendor_specific"}


def _nodes(tree) -> dict:
    return {n.path: n.to_dataset(inherit=False) for n in tree.subtree}


@pytest.fixture(scope="module")
def processed():
    """Two pings of two targets with arrivals, counted, tracked and with Sv of every cell:
    every group abacus writes."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2), arrivals=True)
        return processing.sv(processing.track(processing.count(tree)), cells=True)


@pytest.mark.parametrize("name", ["p.nc", "p.zarr"])
def test_a_processed_file_holds_only_echopypes_groups_and_opens_as_it_was(processed, tmp_path, name):
    """echopype's repr fails on any group outside its table that holds data (KeyError
    'Processing/Sv'), its combine_echodata on an empty one: in the file the products and the
    arrivals lie flat in /Vendor_specific; open_tree gives back every
    group, variable, coordinate and attribute identical (NetCDF and Zarr)."""
    assert {"/Processing/Sv", "/Processing/Tracks", "/Vendor_specific/Arrivals"} <= set(_nodes(processed))
    processing.write_tree(processed, tmp_path / name)
    how = {"engine": "zarr", "consolidated": False} if name.endswith(".zarr") else {"engine": "netcdf4"}
    with xr.open_datatree(tmp_path / name, **how) as raw:
        # every group, empty ones included (echopype's combine_echodata reads each as a dataset)
        assert {n.path for n in raw.subtree} <= ECHOPYPE_TABLE
        vend = raw["Vendor_specific"].ds
        assert all(str(d).startswith("Processing.Sv.") for d in vend["Processing.Sv.Sv"].dims)
        assert vend["Vendor_specific.Arrivals.arrival_delay"].dims == ("Vendor_specific.Arrivals.arrival",)
    back = open_tree(tmp_path / name)
    want, got = _nodes(processed), _nodes(back)
    assert set(got) == set(want)
    for path, ds in want.items():
        assert got[path].identical(ds), path


def test_a_file_with_groups_as_groups_still_opens(processed, tmp_path):
    """A file written before the flat layout (each product its own group) opens as it was."""
    processed.to_netcdf(tmp_path / "old.nc")
    back = open_tree(tmp_path / "old.nc")
    assert back["Processing/Sv"].to_dataset(inherit=False).identical(processed["Processing/Sv"].to_dataset(inherit=False))


def test_a_damaged_map_of_the_flat_groups_is_one_line(processed, tmp_path):
    processing.write_tree(processed, tmp_path / "p.nc")
    t = xr.open_datatree(tmp_path / "p.nc").load()
    t["Vendor_specific"].dataset = t["Vendor_specific"].to_dataset(inherit=False).drop_vars("Processing.Sv.Sv")
    t.to_netcdf(tmp_path / "bad.nc")
    with pytest.raises(processing.DatasetError, match="Processing.Sv.Sv"):
        open_tree(tmp_path / "bad.nc")


def test_the_truth_lies_along_ping_time_and_the_layout_before_still_processes(tmp_path):
    """The truth rows along ping_time (each row at its ping's time: what echopype's
    combine_echodata appends), the run timings as attributes; a file of the layout before (rows
    along `target`, per-ping counts, timings along `stage`) gives the same truth rows, the same
    stage timings and the same counts."""
    from processing.base.dataset import stage_seconds
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(3))
    gt = tree[TRUTH_GROUP].to_dataset(inherit=False)
    times = tree[ELEMENT_GROUP].ds["ping_time"].values
    assert gt["target_x"].dims == ("ping_time",)
    np.testing.assert_array_equal(gt["ping_time"].values, times[gt["target_ping_index"].values])
    assert "stage_seconds" not in tree["Provenance"].ds and set(stage_seconds(tree)) >= {"targets", "echoes"}
    # the layout before, written with plain xarray
    rows = gt.drop_vars("ping_time").rename_dims(ping_time="target")
    rows = rows.assign(truth_count_total=("ping_time", np.bincount(gt["target_ping_index"].values)),
                       ping_time=("ping_time", times))
    rows.attrs = {k: v for k, v in gt.attrs.items() if not k.startswith("counting_range_")}
    rows.attrs["counting_range_m"] = [gt.attrs["counting_range_min_m"], gt.attrs["counting_range_max_m"]]
    prov = tree["Provenance"].to_dataset(inherit=False)
    sec = stage_seconds(tree)
    prov = prov.assign(stage_seconds=("stage", list(sec.values())), stage=("stage", list(sec)))
    prov.attrs = {k: v for k, v in prov.attrs.items() if k not in ("stage_seconds_json", "stage_calls_json")}
    old = tree.copy()
    old[TRUTH_GROUP].dataset = rows
    old["Provenance"].dataset = prov
    old.to_netcdf(tmp_path / "old.nc")
    back = open_tree(tmp_path / "old.nc")
    assert stage_seconds(back) == sec
    for k in ("target_ping_index", "target_id", "target_world_x", "target_in_counting_volume"):
        np.testing.assert_array_equal(back[TRUTH_GROUP].ds[k].values, gt[k].values)
    new_counts = processing.counts_of(processing.count(tree))
    old_counts = processing.counts_of(processing.count(back))
    for k in new_counts.data_vars:
        np.testing.assert_array_equal(old_counts[k].values, new_counts[k].values)


def test_sv_alone_leaves_no_empty_group_in_the_file(tmp_path):
    """`abacus sv` on a raw file makes /Processing/Sv under an empty /Processing: the file holds
    neither (an empty group outside echopype's table stops its combine_echodata), and open_tree
    gives /Processing/Sv back."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = processing.sv(acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(1)), cells=True)
    assert not tree["Processing"].has_data
    processing.write_tree(tree, tmp_path / "p.nc")
    with xr.open_datatree(tmp_path / "p.nc") as raw:
        assert {n.path for n in raw.subtree} <= ECHOPYPE_TABLE
    back = open_tree(tmp_path / "p.nc")
    assert back["Processing/Sv"].to_dataset(inherit=False).identical(tree["Processing/Sv"].to_dataset(inherit=False))
