"""Real echosounder recordings in (issue 28): a Simrad EK60 recording converted by echopype,
calibrated to Sv by abacus and compared with echopype's own ``compute_Sv`` stored beside it
(tests/data/README.md: the recording's origin and licence, echopype's version); EK80-style files
in echopype's layout read and checked; every missing variable named in one message."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import processing
from processing.backscatter.sv import write_mvbs_csv
from processing.base.contract import SV_GROUP

from .test_cli import abacus

DATA = Path(__file__).parent / "data"
EK60 = DATA / "ek60_DY1201_38kHz.nc"
REF = DATA / "ek60_DY1201_38kHz_Sv.npz"


@pytest.fixture(scope="module")
def ek60_sv():
    return processing.sv(processing.open_record(EK60), range_bin_m=5.0, ping_bin=5)[SV_GROUP].ds


def test_ek60_sv_matches_echopype_compute_sv_within_0p1_db(ek60_sv):
    """Every sample's Sv within 0.1 dB of echopype 0.11.1's compute_Sv of the same file (the
    tolerance echosounder calibration is trusted to), the same samples without Sv (r' ≤ 0),
    and the same echo_range."""
    ref = np.load(REF)
    sv = ek60_sv["Sv"].values[:, :, 0]                      # (ping, sample), one channel
    assert sv.shape == ref["Sv"].shape
    np.testing.assert_array_equal(np.isnan(sv), np.isnan(ref["Sv"]))
    assert np.isfinite(sv).sum() > 0.99 * sv.size
    assert np.nanmax(np.abs(sv - ref["Sv"])) < 0.1
    np.testing.assert_allclose(ek60_sv["cell_range_m"].values[:, :, 0], ref["echo_range"], rtol=1e-9)
    # the linear s_v is Sv's, and the MVBS is the linear mean of echopype's Sv over each bin
    np.testing.assert_allclose(ek60_sv["s_v"].values[:, :, 0], 10 ** (ref["Sv"] / 10), rtol=0.024)
    r, lin = ref["echo_range"], 10 ** (ref["Sv"] / 10)
    for k, (a, b) in enumerate([(0, 5), (5, 10), (10, 15), (15, 20)]):
        rows = slice(5 * k, 5 * k + 5)
        for j in (3, 10, 20):
            cell = (r[rows] >= 5.0 * j) & (r[rows] < 5.0 * (j + 1)) & np.isfinite(lin[rows])
            want = 10 * np.log10(lin[rows][cell].mean())
            assert abs(float(ek60_sv["Sv_mean"][k, j, 0]) - want) < 0.1


def test_abacus_sv_on_the_ek60_file_writes_cells_and_echoview_empty_cells(tmp_path):
    """The command line: `abacus sv` on the echopype file, cells as CSV within 0.1 dB of
    echopype's Sv, and the MVBS bin that holds only samples without Sv (0–0.3 m: the first two
    samples, before the time-varied gain starts) written −999 with --empty -999, blank without."""
    r = abacus("sv", str(EK60), "-o", "sv.nc", "--csv", "m.csv", "--cells-csv", "c.csv", "--empty", "-999",
               "--range-bin", "0.3", "--ping-bin", "20", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    ref = np.load(REF)
    rows = list(csv.DictReader(open(tmp_path / "c.csv")))
    ping0 = [row for row in rows if row["Ping"] == "0"]
    assert len(ping0) == ref["Sv"].shape[1]
    got = np.array([float(row["Sv"]) for row in ping0])
    want = ref["Sv"][0]
    assert np.all(got[np.isnan(want)] == -999)
    assert np.max(np.abs(got[~np.isnan(want)] - want[~np.isnan(want)])) < 0.1
    mvbs = list(csv.DictReader(open(tmp_path / "m.csv")))
    assert mvbs[0]["Range_start"] == "0" and mvbs[0]["Sv_mean"] == "-999"
    assert all(float(m["Sv_mean"]) > -200 for m in mvbs[1:])
    out = processing.open_tree(tmp_path / "sv.nc")
    write_mvbs_csv(out, tmp_path / "blank.csv")                 # the default: blank, as before
    assert list(csv.DictReader(open(tmp_path / "blank.csv")))[0]["Sv_mean"] == ""
    assert out.attrs["keywords"] == "EK60"                    # the recording kept as echopype wrote it
    np.testing.assert_array_equal(out["Sonar/Beam_group1"].ds["backscatter_r"].values,
                                  xr.open_datatree(EK60)["Sonar/Beam_group1"].ds["backscatter_r"].values)


def test_an_ek60_file_converts_and_imaging_says_what_it_needs(tmp_path):
    r = abacus("convert", str(EK60), "ek.nc", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "EK60" in r.stdout
    r = abacus("count", "ek.nc", cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "EK60" in r.stderr and "abacus sv" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def _drop(tree: xr.DataTree, where: dict) -> xr.DataTree:
    t = tree.copy()
    for group, names in where.items():
        t[group].dataset = t[group].to_dataset(inherit=False).drop_vars(names)
    return t


def test_an_incomplete_ek60_file_names_every_missing_variable_at_once(tmp_path):
    tree = xr.open_datatree(EK60).load()
    _drop(tree, {"Sonar/Beam_group1": ["transmit_power", "angle_alongship"], "Environment": ["absorption_indicative"],
                 "Vendor_specific": ["sa_correction"]}).to_netcdf(tmp_path / "bad.nc")
    r = abacus("sv", "bad.nc", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    for name in ("/Sonar/Beam_group1/transmit_power", "/Sonar/Beam_group1/angle_alongship",
                 "/Environment/absorption_indicative", "/Vendor_specific/sa_correction"):
        assert name in r.stderr
    assert "4 variables" in r.stderr


def test_a_single_beam_ek60_channel_reads_without_angles(tmp_path, ek60_sv):
    """The same channel declared single-beam (echopype's beam_type 0) and without the
    split-beam angles reads, and its Sv is the split-beam file's (Sv uses no angle); declared
    split-beam, the missing angles are named."""
    tree = xr.open_datatree(EK60).load()
    angles = ["angle_alongship", "angle_athwartship"]
    single = _drop(tree, {"Sonar/Beam_group1": angles})
    bg = single["Sonar/Beam_group1"].to_dataset(inherit=False)
    bg["beam_type"] = bg["beam_type"] * 0
    single["Sonar/Beam_group1"].dataset = bg
    single.to_netcdf(tmp_path / "single.nc")
    sv = processing.sv(processing.open_record(tmp_path / "single.nc"), range_bin_m=5.0, ping_bin=5)[SV_GROUP].ds
    np.testing.assert_array_equal(sv["Sv"].values, ek60_sv["Sv"].values)
    _drop(tree, {"Sonar/Beam_group1": angles}).to_netcdf(tmp_path / "split.nc")
    with pytest.raises(processing.DatasetError, match="angle_alongship, /Sonar/Beam_group1/angle_athwartship"):
        processing.open_record(tmp_path / "split.nc")


def _ek80(*, drop=()) -> xr.DataTree:
    """An EK80 file in echopype's layout (echodata/convention/1.0.yml, as open_raw(...,
    sonar_model="EK80") writes complex WBT samples): a split-beam channel of 4 sectors and a
    single-beam channel (its sectors 2-4 NaN, as echopype pads them)."""
    rng = np.random.default_rng(1)
    ch = ["WBT 1 ES38-7 split", "WBT 2 ES200-7C single"]
    t = np.array(["2024-01-01T00:00:00", "2024-01-01T00:00:01", "2024-01-01T00:00:02"], dtype="datetime64[ns]")
    x = rng.normal(size=(2, 3, 50, 4)) + 1j * rng.normal(size=(2, 3, 50, 4))
    x[1, :, :, 1:] = np.nan
    per = (("channel", "ping_time"), np.ones((2, 3)))
    bg = xr.Dataset({"backscatter_r": (("channel", "ping_time", "range_sample", "beam"), x.real),
                     "backscatter_i": (("channel", "ping_time", "range_sample", "beam"), x.imag),
                     "frequency_nominal": ("channel", [38e3, 200e3]), "beam_type": ("channel", [1, 0]),
                     "equivalent_beam_angle": ("channel", [-20.6, -20.7]),
                     "sample_interval": (per[0], per[1] * 2.6e-5), "transmit_power": (per[0], per[1] * 400),
                     "transmit_duration_nominal": (per[0], per[1] * 1.024e-3),
                     "transmit_frequency_start": (per[0], per[1] * [[35e3], [185e3]]),
                     "transmit_frequency_stop": (per[0], per[1] * [[45e3], [255e3]])},
                    coords={"channel": ch, "ping_time": t, "range_sample": np.arange(50), "beam": ["1", "2", "3", "4"]})
    env = xr.Dataset({"sound_speed_indicative": (("time1",), [1490.0])}, coords={"time1": t[:1]})
    vend = xr.Dataset({"gain_correction": (("channel", "pulse_length_bin"), np.full((2, 2), 27.0)),
                       "sa_correction": (("channel", "pulse_length_bin"), np.zeros((2, 2))),
                       "pulse_length": (("channel", "pulse_length_bin"), [[5.12e-4, 1.024e-3]] * 2)},
                      coords={"channel": ch})
    groups = {"/": xr.Dataset(attrs={"keywords": "EK80", "sonar_convention_version": "1.0"}),
              "/Environment": env, "/Sonar": xr.Dataset(attrs={"sonar_model": "EK80"}),
              "/Sonar/Beam_group1": bg.drop_vars(list(drop)), "/Vendor_specific": vend}
    return xr.DataTree.from_dict(groups)


def test_an_ek80_file_of_split_and_single_beam_channels_is_read_whole(tmp_path):
    """open_record reads both channels, every sector of the split-beam one, unchanged; `abacus
    convert` writes it back; `abacus sv` says whose calibration it needs, in one line."""
    _ek80().to_netcdf(tmp_path / "ek80.nc")
    t = processing.open_record(tmp_path / "ek80.nc")
    bg = t["Sonar/Beam_group1"].ds
    assert bg.sizes["channel"] == 2 and bg.sizes["beam"] == 4
    ref = _ek80()["Sonar/Beam_group1"].ds["backscatter_r"].values
    np.testing.assert_array_equal(bg["backscatter_r"].values, ref)
    r = abacus("convert", "ek80.nc", "out.nc", cwd=tmp_path)
    assert r.returncode == 0 and "EK80" in r.stdout, r.stderr
    r = abacus("sv", "out.nc", cwd=tmp_path)
    assert r.returncode == 2 and "EK80" in r.stderr and "compute_Sv" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_an_incomplete_ek80_file_names_every_missing_variable_at_once(tmp_path):
    _ek80(drop=("backscatter_i", "sample_interval", "transmit_power")).to_netcdf(tmp_path / "bad.nc")
    r = abacus("convert", "bad.nc", "out.nc", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    # without backscatter_i it reads as a power file: what a power file needs is named
    for name in ("sample_interval", "transmit_power"):
        assert f"/Sonar/Beam_group1/{name}" in r.stderr
    _ek80(drop=("transmit_frequency_start", "beam_type", "equivalent_beam_angle")).to_netcdf(tmp_path / "bad2.nc")
    with pytest.raises(processing.DatasetError) as err:
        processing.open_record(tmp_path / "bad2.nc")
    assert all(n in str(err.value) for n in ("transmit_frequency_start", "beam_type", "equivalent_beam_angle"))
    assert "3 variables" in str(err.value)


def test_a_hand_written_64_element_file_names_every_missing_variable_at_once(tmp_path):
    """A SONAR-netCDF4 file of 64 elements written by hand without the replica, the
    transmitter's weights and the element subarrays: one message naming all four, not the
    first of them."""
    n = 64
    bg = xr.Dataset({"backscatter_r": (("channel", "ping_time", "range_sample", "beam"), np.ones((1, 2, 100, n), "f4")),
                     "backscatter_i": (("channel", "ping_time", "range_sample", "beam"), np.zeros((1, 2, 100, n), "f4")),
                     "sample_interval": (("channel", "ping_time"), np.full((1, 2), 1e-5)),
                     **{f"element_{a}": ("beam", np.zeros(n)) for a in "xyz"}},
                    coords={"channel": ["rx"], "ping_time": np.array(["2024-01-01", "2024-01-02"], "datetime64[ns]"),
                            "beam": [f"E{i}" for i in range(n)]})
    sonar = xr.Dataset({"transmit_frequency_center": 400e3, "transmit_bandwidth": 40e3,
                        **{f"tx_element_{a}": ("tx_element", np.zeros(4)) for a in "xyz"}})
    xr.DataTree.from_dict({"/Environment": xr.Dataset({"sound_speed_indicative": 1500.0}), "/Sonar": sonar,
                           "/Sonar/Beam_group1": bg}).to_netcdf(tmp_path / "hand.nc")
    r = abacus("convert", "hand.nc", "out.nc", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    for name in ("/Sonar/replica_r", "/Sonar/replica_i", "/Sonar/tx_element_weight",
                 "/Sonar/Beam_group1/element_subarray"):
        assert name in r.stderr
    assert "4 variables" in r.stderr
