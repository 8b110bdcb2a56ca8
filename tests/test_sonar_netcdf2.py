"""SONAR-netCDF4 2.0 out and in (processing/base/sonar_netcdf2.py, sonar_netcdf2_read.py,
contract_v2.py): a processed simulation written as 2.0 follows the ICES convention's own
definition tables (tests/data/sonar-netcdf4-2.0, read by tests/ices_definition.py), its
SingleTarget group holds the chain's single targets where the truth has the fish, its gridded group
the MVBS, its beam rotations point where the sonar looks; the 1.0 dataset is untouched; abacus'
2.0 files read back to the same samples and detections; an EK80-style 2.0 file (written here by
hand after the convention: complex samples of four split-aperture sub-beams, pings of different
lengths) is read completely and locates its target where it was put; what a file lacks is named
in one message."""
from __future__ import annotations

import warnings

import netCDF4
import numpy as np
import pytest

import acoustics
import processing
from processing.base.contract import ELEMENT_GROUP, TRUTH_GROUP
from processing.base.contract_v2 import GROUPS_V2
from processing.base.convert import open_record
from processing.base.dataset import DatasetError, beam_samples, open_tree, write_tree
from processing.base.groups import check_tree
from processing.base.sonar_netcdf2 import check_file, write_sonar_netcdf2

from .ices_definition import check_file as ices_check
from .ices_definition import definition

#: the MA variables that apply to abacus' files (complex samples, a pulse model, single targets)
APPLICABLE = tuple(f"/Sonar/Beam_group1/{n}" for n in (
    "backscatter_i", "transmit_pulse_model_r", "transmit_pulse_model_i", "frequency",
    "beamwidth_transmit_major", "beamwidth_transmit_minor", "receive_transducer_index",
    "transmit_transducer_index", "transmit_beam_index")) + tuple(
    f"/Sonar/Beam_group1/SingleTarget/{n}" for n in (
        "single_target_identifier", "single_target_range", "single_target_alongship_angle",
        "single_target_athwartship_angle", "compensated_TS", "uncompensated_TS", "param_TS_threshold")) + (
    "/Provenance/source_filenames", "/Platform/transducer_ids", "/Sonar/Grid_group1/ping_axis_interval_type")
#: the one documented departure (docs/dataset.md): the convention's sonar_type vocabulary has
#: only "omni-sonar"; ABACUS is a multibeam
DEPARTURES = ("/Sonar: attribute sonar_type = 'multibeam', the convention has 'omni-sonar'",)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Three pings of two fixed targets, tracked (their ids persist), with an MVBS grid of one
    ping per bin; written as 1.0 and as 2.0."""
    folder = tmp_path_factory.mktemp("nc2")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(3))
        tree = processing.track(tree)
        tree = processing.sv(tree, range_bin_m=0.5, ping_bin=1)
        before = tree.copy(deep=True)
        write_tree(tree, folder / "run.nc")
        processing.write_sonar_netcdf2(tree, folder / "run2.nc")
    return {"tree": tree, "before": before, "v1": folder / "run.nc", "v2": folder / "run2.nc"}


def test_the_2_0_file_follows_the_ices_definition(run):
    assert ices_check(run["v2"], applicable=APPLICABLE, exceptions=DEPARTURES) == []
    assert check_file(run["v2"]) == []                       # and abacus' own 2.0 table
    with netCDF4.Dataset(run["v2"]) as nc:
        assert nc.sonar_convention_version == "2.0"
        assert set(nc["Sonar"].groups) == {"Beam_group1", "Grid_group1"}
        assert set(nc["Sonar/Beam_group1"].groups) == {"SingleTarget"}


def test_the_ices_check_finds_departures(run, tmp_path):
    """The reference is not vacuous: a renamed mandatory variable, a wrong unit and a wrong
    type are each reported."""
    import shutil
    bad = tmp_path / "bad.nc"
    shutil.copy(run["v2"], bad)
    with netCDF4.Dataset(bad, "a") as nc:
        bg = nc["Sonar/Beam_group1"]
        bg.renameVariable("platform_roll", "roll")
        bg["sample_interval"].units = "ms"
        nc["Environment"].createVariable("absorption_indicative_2", "f8", ())
    problems = ices_check(bad, applicable=APPLICABLE, exceptions=DEPARTURES)
    assert "/Sonar/Beam_group1/platform_roll: mandatory, missing" in problems
    assert "/Sonar/Beam_group1/sample_interval: attribute units = 'ms', the convention has 's'" in problems
    assert "/Sonar/Beam_group1/platform_roll: mandatory, missing" in check_file(bad)


def test_the_definition_tables_are_read_whole():
    """The parser reads every group's mandatory pieces (a guard against a table it misreads)."""
    d = definition()
    bg = d["/Sonar/Beam_group1"]
    assert bg.variables["backscatter_r"].dims == ("ping_time", "beam", "subbeam")
    assert bg.variables["backscatter_r"].type == "sample_t" and bg.vlens["sample_t"] == "float"
    # the table's mandatory variables, coordinates included (as `grep -c '{var}.*|M |'` counts them)
    assert sum(v.obligation == "M" for v in bg.variables.values()) == 29
    assert d["/Sonar"].enums["beam_t"]["split_aperture_4_subbeams"] == 2
    assert d["/"].attrs["sonar_convention_version"] == ("M", "2.0")
    st = d["/Sonar/Beam_group1/SingleTarget"].variables
    assert st["compensated_TS"].dims == ("ping_time", "beam", "frequency")
    # every 2.0 variable abacus writes that the convention defines has the convention's type
    for path, g in GROUPS_V2.items():
        for v in g.variables:
            if v.obligation != "V" and path in d:
                assert v.name in d[path].variables, f"{path}/{v.name}"
                assert d[path].variables[v.name].dims == v.dims, f"{path}/{v.name}"


def test_single_targets_are_the_chains_and_where_the_fish_are(run):
    """Ranges and athwartship angles (azimuth) where the truth has the two targets (within a
    range cell, c/2B = 3.8 cm, and the 0.3° the location is known to), compensated TS within
    0.5 dB of the truth's, each target keeping its track id on every ping."""
    truth = run["tree"][TRUTH_GROUP].ds
    with netCDF4.Dataset(run["v2"]) as nc:
        st = nc["Sonar/Beam_group1/SingleTarget"]
        ranges, ids = st["single_target_range"][:], st["single_target_identifier"][:]
        athwart, ts = st["single_target_athwartship_angle"][:], st["compensated_TS"][:]
        count = st["single_target_count"][:]
    assert count.ravel().tolist() == [2, 2, 2]
    for p in range(3):
        rows = truth["target_ping_index"].values == p
        t_r, t_az = truth["target_range"].values[rows], np.degrees(truth["target_azimuth"].values[rows])
        t_ts = truth["target_ts"].values[rows]
        got = np.asarray(ranges[p, 0])
        match = [int(np.argmin(np.abs(t_r - r))) for r in got]
        assert np.all(np.abs(got - t_r[match]) < 0.038)
        assert np.all(np.abs(np.asarray(athwart[p, 0]) - t_az[match]) < 0.3)
        assert np.all(np.abs(np.asarray(ts[p, 0, 0]) - t_ts[match]) < 0.5)
        assert sorted(np.asarray(ids[p, 0]).tolist()) == sorted(np.asarray(ids[0, 0]).tolist())


def test_the_gridded_group_holds_the_mvbs_at_its_depths(run):
    """integrated_backscatter is the MVBS Sv (dB, float32), one frequency entry per formed
    beam naming its beam; a cell of a sonar looking straight down lies at depth r cos(azimuth)."""
    sv = run["tree"]["Processing/Sv"].ds
    with netCDF4.Dataset(run["v2"]) as nc:
        g = nc["Sonar/Grid_group1"]
        ib = g["integrated_backscatter"][:].filled(np.nan)
        depth, az = g["cell_depth"][:], np.radians(g["beam_azimuth"][:])
        r0, r1 = g["range_axis_start"][:], g["range_axis_stop"][:]
        assert list(g["beam_reference"][:]) == list(g["beam"][:])
        assert g["backscatter_type"].datatype.enum_dict["Sv"] == 0 and np.all(g["backscatter_type"][:] == 0)
    np.testing.assert_allclose(ib, sv["Sv_mean"].values.astype(np.float32), rtol=0, atol=0, equal_nan=True)
    np.testing.assert_allclose(depth, 0.5 * (r0 + r1)[:, None] * np.cos(az)[None], rtol=1e-6)


def _beam_axis(psi, theta, phi):
    """The beam axis (beam-frame z) in the platform frame: the convention's R_BCS->TCS =
    Rz(Ψ) Ry(Θ) Rx(Φ) applied to (0, 0, 1) (crr341 §"Coordinate systems")."""
    p, t, f = np.radians([psi, theta, phi])
    rz = np.array([[np.cos(p), -np.sin(p), 0], [np.sin(p), np.cos(p), 0], [0, 0, 1]])
    ry = np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])
    rx = np.array([[1, 0, 0], [0, np.cos(f), -np.sin(f)], [0, np.sin(f), np.cos(f)]])
    return rz @ ry @ rx @ np.array([0.0, 0.0, 1.0])


def test_beams_point_where_the_sonar_looks_and_the_antennas_are_separate(run):
    look = run["tree"]["Platform"].ds["sonar_rotation"].values[:, 2]       # the sonar's z axis
    with netCDF4.Dataset(run["v2"]) as nc:
        bg, pl = nc["Sonar/Beam_group1"], nc["Platform"]
        rx = [float(bg[f"rx_beam_rotation_{k}"][0, 0]) for k in ("psi", "theta", "phi")]
        tx = [float(bg[f"tx_beam_rotation_{k}"][0, 0]) for k in ("psi", "theta", "phi")]
        vec = np.array([float(bg[f"beam_direction_{a}"][0]) for a in "xyz"])
        functions = pl["transducer_function"].datatype.enum_dict
        assert sorted(pl["transducer_function"][:].tolist()) == [functions["receive_only"], functions["transmit_only"]]
        assert int(bg["receive_transducer_index"][0]) != int(bg["transmit_transducer_index"][0, 0])
        assert bg["backscatter_r"].shape == (3, 1, run["tree"][ELEMENT_GROUP].sizes["beam"])
        grid = nc["Sonar/Grid_group1"]
        az = np.radians(grid["beam_azimuth"][:])
        g_rot = [grid[f"rx_beam_rotation_{k}"][0, :] for k in ("psi", "theta", "phi")]
    np.testing.assert_allclose(_beam_axis(*rx), look, atol=1e-6)
    np.testing.assert_allclose(_beam_axis(*tx), look, atol=1e-6)
    np.testing.assert_allclose(vec, look, atol=1e-6)
    # each formed beam of the grid is the boresight turned by its azimuth about the sonar's y
    rot = run["tree"]["Platform"].ds["sonar_rotation"].values
    for b in (0, len(az) // 2, len(az) - 1):
        want = rot @ np.array([np.sin(az[b]), 0.0, np.cos(az[b])])
        np.testing.assert_allclose(_beam_axis(*(float(g[b]) for g in g_rot)), want, atol=1e-5)


def test_the_1_0_dataset_of_the_same_run_is_unchanged(run):
    """Writing 2.0 leaves the tree as it was, and the 1.0 file still follows the 1.0 contract."""
    assert run["tree"].identical(run["before"])
    v1 = open_tree(run["v1"])
    assert v1.attrs["sonar_convention_version"] == "1.0"
    assert check_tree(v1) == []


def test_an_abacus_2_0_file_reads_back_to_the_same_record(run):
    tree = open_record(run["v2"])
    assert check_tree(tree) == []
    assert tree.attrs["keywords"] == run["tree"].attrs["keywords"] == "ABACUS"   # echopype's sonar model
    a = np.asarray(beam_samples(run["tree"][ELEMENT_GROUP].ds))
    b = np.asarray(beam_samples(tree[ELEMENT_GROUP].ds))
    np.testing.assert_array_equal(a, b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d1 = processing.detections_of(processing.detect(run["before"]))
        d2 = processing.detections_of(processing.detect(tree))
    # the settings written as float32 (sample_interval: 1 part in 1e7) move ranges by < 1 µm
    np.testing.assert_allclose(d2["range_m"].values, d1["range_m"].values, atol=1e-6)
    np.testing.assert_allclose(d2["elevation_rad"].values, d1["elevation_rad"].values, atol=1e-9)
    with pytest.raises(DatasetError, match="a SONAR-netCDF4 2.0 file; read it with processing.open_record"):
        open_tree(run["v2"])


# ------------------------------------------------------------------ an EK80-style 2.0 file
#: EK80 sub-beam order: aft-starboard, aft-port, fore-port, fore-starboard (athwart, along signs)
SECTORS = ((+1, -1), (-1, -1), (-1, +1), (+1, +1))


def write_ek80_style(path, *, lengths=(1200, 1400, 1300), target_range_m=19.5, along_deg=2.0,
                     athwart_deg=-3.0, sensitivity=(21.97, 21.97), drop=(), beam_type=2, c=1480.0,
                     fs=50e3, f1=34e3, f2=45e3, duration=1.024e-3, groups=("Beam_group1",)):
    """A SONAR-netCDF4 2.0 file as an EK80 writes it natively (its beam group after the
    convention): a 38 kHz split-aperture beam, FM 34–45 kHz, complex samples of four sub-beams as
    vlen vectors, pings of ``lengths`` samples (ragged), time in ns since 1601. One target at
    ``target_range_m`` and (alongship, athwartship) angles, in the ping(s) long enough to hold
    it; each sub-beam's phase is k r·û, r its phase centre (half the spacing d = S/k from the
    axis), so the split-aperture angles are the given ones (echopype's rule: phase of fore ×
    conj(aft) / S)."""
    rng = np.random.default_rng(1)
    f0, bw = 0.5 * (f1 + f2), f2 - f1
    k = 2 * np.pi * f0 / c
    spacing = [s / k for s in sensitivity]
    az, el = np.radians(athwart_deg), np.radians(along_deg)
    u = np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])

    def chirp(t):
        return np.exp(1j * np.pi * bw * t**2 / duration - 1j * np.pi * bw * t)

    t_rep = np.arange(int(round(duration * fs))) / fs
    replica = np.sin(np.pi * t_rep / duration) ** 2 * chirp(t_rep)
    samples = []
    for n in lengths:
        t = np.arange(n) / fs - 2 * target_range_m / c
        inside = (t >= 0) & (t < duration)
        echo = np.zeros(n, complex)
        echo[inside] = np.sin(np.pi * t[inside] / duration) ** 2 * chirp(t[inside])
        ping = np.stack([1000.0 * echo * np.exp(1j * k * np.array([sx * spacing[0] / 2, sy * spacing[1] / 2, 0]) @ u)
                         for sx, sy in SECTORS])
        samples.append(ping + rng.normal(0, 1, ping.shape) + 1j * rng.normal(0, 1, ping.shape))
    n_p = len(lengths)
    with netCDF4.Dataset(path, "w") as nc:
        nc.setncatts({"Conventions": "CF-1.7, SONAR-netCDF4-2.0, ACDD-1.3", "sonar_convention_authority": "ICES",
                      "sonar_convention_name": "SONAR-netCDF4", "sonar_convention_version": "2.0",
                      "date_created": "2024-03-13T18:40:00Z", "keywords": "EK80", "summary": "",
                      "title": "EK80-style file"})
        env = nc.createGroup("Environment")
        env.createDimension("frequency", 1)
        env.createVariable("frequency", "f4", ("frequency",))[:] = f0
        env.createVariable("absorption_indicative", "f4", ("frequency",))[:] = 0.0098
        env.createVariable("sound_speed_indicative", "f4", ())[...] = c
        sonar = nc.createGroup("Sonar")
        beam_t = sonar.createEnumType(np.uint8, "beam_t", {"single": 0, "split_aperture_angles": 1,
                                                            "split_aperture_4_subbeams": 2})
        for name in groups:
            bg = sonar.createGroup(name)
            bg.beam_mode, bg.conversion_equation_type = "vertical", 4
            sample_t, pulse_t = bg.createVLType(np.float32, "sample_t"), bg.createVLType(np.float32, "pulse_t")
            for dim, n in (("ping_time", None), ("beam", 1), ("subbeam", 4), ("tx_beam", 1)):
                bg.createDimension(dim, n)
            bg.createVariable("beam", str, ("beam",))[0] = "WBT 1-ES38-7"
            times = bg.createVariable("ping_time", "u8", ("ping_time",))
            times.units = "nanoseconds since 1601-01-01 00:00:00Z"
            times[:] = (np.datetime64("2024-03-13T18:40:00", "ns") - np.datetime64("1601-01-01", "ns")).astype(
                np.int64) + np.arange(n_p, dtype=np.int64) * 10**9
            bg.createVariable("beam_type", beam_t, ())[...] = np.uint8(beam_type)
            for part, fn in (("r", np.real), ("i", np.imag)):
                if f"backscatter_{part}" not in drop:
                    v = bg.createVariable(f"backscatter_{part}", sample_t, ("ping_time", "beam", "subbeam"))
                    for p in range(n_p):
                        for s in range(4):
                            v[p, 0, s] = fn(samples[p][s]).astype(np.float32)
                if f"transmit_pulse_model_{part}" not in drop:
                    v = bg.createVariable(f"transmit_pulse_model_{part}", pulse_t, ("ping_time", "tx_beam"))
                    for p in range(n_p):
                        v[p, 0] = fn(replica).astype(np.float32)
            for var, dims, value, units in (
                    ("echoangle_major_sensitivity", ("beam",), [sensitivity[0]], "1"),
                    ("echoangle_minor_sensitivity", ("beam",), [sensitivity[1]], "1"),
                    ("beamwidth_receive_major", ("ping_time", "beam"), np.full((n_p, 1), 7.0), "arc_degree"),
                    ("beamwidth_receive_minor", ("ping_time", "beam"), np.full((n_p, 1), 7.0), "arc_degree"),
                    ("sample_interval", ("ping_time",), np.full(n_p, 1 / fs), "s"),
                    ("blanking_interval", ("ping_time", "beam"), np.zeros((n_p, 1)), "s"),
                    ("sample_time_offset", ("ping_time", "tx_beam"), np.zeros((n_p, 1)), "s"),
                    ("transmit_frequency_start", ("ping_time", "tx_beam"), np.full((n_p, 1), f1), "Hz"),
                    ("transmit_frequency_stop", ("ping_time", "tx_beam"), np.full((n_p, 1), f2), "Hz"),
                    ("transmit_duration_nominal", ("ping_time", "tx_beam"), np.full((n_p, 1), duration), "s")):
                if var not in drop:
                    v = bg.createVariable(var, "f4", dims)
                    v[...] = value
                    v.units = units
    return samples, spacing


def test_an_ek80_style_file_is_read_completely(tmp_path):
    """Every ping, every sample of the longest ping (the others padded with zeros), the four
    quadrants at ±d/2 with d = S λ/2π, the times of the 1601 epoch."""
    samples, spacing = write_ek80_style(tmp_path / "ek.nc")
    tree = open_record(tmp_path / "ek.nc")
    eg = tree[ELEMENT_GROUP].ds
    x = np.asarray(beam_samples(eg))
    assert x.shape == (3, 4, 1400)
    for p, ping in enumerate(samples):
        np.testing.assert_array_equal(x[p, :, :ping.shape[1]], ping.astype(np.complex64))
        assert not np.any(x[p, :, ping.shape[1]:])
    np.testing.assert_allclose(np.abs(eg["element_x"].values), spacing[0] / 2, rtol=1e-6)
    np.testing.assert_allclose(np.abs(eg["element_y"].values), spacing[1] / 2, rtol=1e-6)
    assert eg["element_subarray"].values.tolist() == ["A", "A", "B", "B"]
    assert str(eg["ping_time"].values[0]) == "2024-03-13T18:40:00.000000000"
    assert tree["Environment"].ds["sound_speed_indicative"].values == pytest.approx(1480.0)


def test_an_ek80_style_file_locates_its_target_at_the_far_end_of_its_record(tmp_path):
    """A target at 19.5 m, beyond every ping but the longest, is detected in that ping at its
    range (within 1 cm) and its split-aperture angles (within 0.05°): the record is read and
    imaged whole, and the quadrants' geometry is the convention's."""
    write_ek80_style(tmp_path / "ek.nc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                 # the zero padding is not Rayleigh noise
        det = processing.detections_of(processing.detect(open_record(tmp_path / "ek.nc")))
    assert set(det["ping"].values.tolist()) == {1}
    best = int(np.argmax(det["snr_db"].values))
    assert det["range_m"].values[best] == pytest.approx(19.5, abs=0.01)
    assert np.degrees(det["elevation_rad"].values[best]) == pytest.approx(2.0, abs=0.05)
    assert np.degrees(det["azimuth_rad"].values[best]) == pytest.approx(-3.0, abs=0.05)


def test_what_a_2_0_file_lacks_is_named_in_one_message(tmp_path):
    drop = ("backscatter_i", "sample_interval", "transmit_pulse_model_r", "transmit_pulse_model_i",
            "echoangle_minor_sensitivity")
    write_ek80_style(tmp_path / "ek.nc", drop=drop)
    with pytest.raises(DatasetError) as err:
        open_record(tmp_path / "ek.nc")
    text = str(err.value)
    assert "\n" not in text and text.count("2.0 file lacks") == 1
    for name in drop:
        assert f"/Sonar/Beam_group1/{name}" in text


def test_power_angle_samples_are_refused_in_one_line(tmp_path):
    write_ek80_style(tmp_path / "ek.nc", beam_type=1)
    with pytest.raises(DatasetError, match="power/angle samples .*split_aperture_angles"):
        open_record(tmp_path / "ek.nc")


def test_the_commands_write_and_read_2_0(tmp_path, capsys):
    """abacus simulate --format sonar-netcdf4-2 writes a 2.0 file that abacus convert reads back
    to the same samples; a 2.0 output that is not .nc is refused in one line."""
    from abacus.cli.app import main
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["simulate", "two_targets", "--pings", "1", "-o", str(tmp_path / "s2.nc"),
                     "--format", "sonar-netcdf4-2"]) == 0
        assert main(["convert", str(tmp_path / "s2.nc"), str(tmp_path / "s1.nc")]) == 0
    assert check_file(tmp_path / "s2.nc") == []
    with netCDF4.Dataset(tmp_path / "s2.nc") as nc:
        first = np.asarray(nc["Sonar/Beam_group1/backscatter_r"][0, 0, 0])
    back = np.asarray(beam_samples(open_tree(tmp_path / "s1.nc")[ELEMENT_GROUP].ds))
    np.testing.assert_array_equal(back[0, 0].real, first)
    assert main(["simulate", "two_targets", "--pings", "1", "-o", str(tmp_path / "s.zarr"),
                 "--format", "sonar-netcdf4-2"]) == 2
    assert "name the output *.nc" in capsys.readouterr().err


def test_docs_dataset_md_shows_the_2_0_table_as_it_is():
    """docs/dataset.md's 2.0 tables are contract_v2's own markdown, verbatim (regenerate:
    python -m processing.base.contract_v2 --markdown)."""
    from processing.base import contract_v2

    from .conftest import ROOT
    text = (ROOT / "docs" / "dataset.md").read_text()
    begin, end = text.index(contract_v2.MARKDOWN_BEGIN), text.index(contract_v2.MARKDOWN_END)
    assert text[begin:end + len(contract_v2.MARKDOWN_END)] + "\n" == contract_v2.markdown()


def test_a_moving_platform_and_a_recording_round_trip(tmp_path):
    """The per-ping pose of a rolling platform (and the ADC's clipping variables) survive 2.0;
    a .mat recording that gives no absorption is written with the convention's fill value and
    read back without one; an empty single-target table is written as empty vectors."""
    from .test_contract import ROLLING_QUANTISED
    from .test_interop import _recording
    (tmp_path / "s.yaml").write_text(ROLLING_QUANTISED)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(acoustics.load_scene(tmp_path / "s.yaml"), pings=range(2))
    empty = {k: np.array([]) for k in ("ping", "range_m", "azimuth_deg", "elevation_deg",
                                         "ts_uncomp_db", "ts_comp_db")}
    write_sonar_netcdf2(tree, tmp_path / "roll.nc", targets=empty)
    assert ices_check(tmp_path / "roll.nc", exceptions=DEPARTURES) == []
    with netCDF4.Dataset(tmp_path / "roll.nc") as nc:
        assert nc["Sonar/Beam_group1/SingleTarget/single_target_count"][:].ravel().tolist() == [0, 0]
        roll = nc["Sonar/Beam_group1/platform_roll"][:]
    np.testing.assert_allclose(roll, tree["Platform"].ds["roll"].values, atol=1e-5)
    back = open_record(tmp_path / "roll.nc")
    assert check_tree(back) == []
    for name in ("ping_sonar_rotation", "ping_sonar_position", "vertical_offset"):
        np.testing.assert_allclose(back["Platform"].ds[name].values, tree["Platform"].ds[name].values, atol=1e-6)
    np.testing.assert_array_equal(back[ELEMENT_GROUP].ds["adc_clipped_samples"].values,
                                  tree[ELEMENT_GROUP].ds["adc_clipped_samples"].values)

    from processing.base.convert import read_mat
    rec = read_mat(_recording(tmp_path / "r.mat", pings=2))
    assert "absorption_indicative" not in rec["Environment"].ds
    write_sonar_netcdf2(rec, tmp_path / "r2.nc")
    assert ices_check(tmp_path / "r2.nc", exceptions=DEPARTURES) == []
    again = open_record(tmp_path / "r2.nc")
    assert "absorption_indicative" not in again["Environment"].ds
    np.testing.assert_array_equal(np.asarray(beam_samples(again[ELEMENT_GROUP].ds)),
                                  np.asarray(beam_samples(rec[ELEMENT_GROUP].ds)))


def test_a_2_0_file_beyond_the_memory_limit_is_refused_before_it_is_read(tmp_path):
    from processing.base.resources import ResourceError
    write_ek80_style(tmp_path / "ek.nc")
    with pytest.raises(ResourceError):
        open_record(tmp_path / "ek.nc", max_memory_gb=1e-6)


def test_a_file_of_several_beam_groups_says_which_it_read(tmp_path):
    """An EK80 writes one beam group per channel: the one read is named, the others listed, and
    each can be chosen."""
    from processing.base.dataset import DatasetWarning
    write_ek80_style(tmp_path / "ek.nc", groups=("Beam_group1", "Beam_group2"))
    with pytest.warns(DatasetWarning, match=r"read /Sonar/Beam_group1, one of 2 beam groups; the others \(Beam_group2\)"):
        open_record(tmp_path / "ek.nc")
    with pytest.warns(DatasetWarning, match="Beam_group1"):
        tree = open_record(tmp_path / "ek.nc", beam_group="Beam_group2")
    assert tree[ELEMENT_GROUP].sizes["range_sample"] == 1400
    with pytest.raises(DatasetError, match="no /Sonar/Beam_group3; its beam groups are Beam_group1, Beam_group2"):
        open_record(tmp_path / "ek.nc", beam_group="Beam_group3")


def test_abacus_run_writes_2_0_beside_the_1_0_run(tmp_path):
    """``abacus run --format sonar-netcdf4-2`` (abacus.run(..., sonar_netcdf2=True)): run.nc
    stays 1.0, and run.sonar-netcdf4-2.nc holds the run with its single targets and gridded Sv."""
    import abacus
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = abacus.run("two_targets", tmp_path / "r", pings=1, plots=False, sonar_netcdf2=True)
    v2 = result.folder / "run.sonar-netcdf4-2.nc"
    assert "run.sonar-netcdf4-2.nc" in result.made
    assert open_tree(result.folder / "run.nc").attrs["sonar_convention_version"] == "1.0"
    assert ices_check(v2, applicable=APPLICABLE, exceptions=DEPARTURES) == []
    with netCDF4.Dataset(v2) as nc:
        assert set(nc["Sonar"].groups) == {"Beam_group1", "Grid_group1"}
        assert nc["Sonar/Beam_group1/SingleTarget/single_target_count"][:].ravel().tolist() == [2]
