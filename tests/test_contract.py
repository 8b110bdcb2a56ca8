"""The data contract as data (processing/base/contract.py): what the simulator and `abacus convert`
write is in the table, with the table's units, the mandatory pieces present; the builder refuses
what the table does not know; docs/dataset.md shows the table as it is."""
from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
import scipy.io

import acoustics
from processing.base import contract
from processing.base.contract import (ARRIVALS_GROUP, ELEMENT_GROUP, ENVIRONMENT_GROUP, GROUPS, PLATFORM_GROUP, ROOT_GROUP,
                                      SONAR_GROUP, TRUTH_GROUP, group_spec, node_path)
from processing.base.convert import from_legacy, read_mat
from processing.base.dataset import TRUTH_GROUP as TRUTH_GROUP_OF_DATASET
from processing.base.dataset import beam_samples, open_tree, write_tree
from processing.base.groups import ContractError, build_group, check_tree

from .conftest import ROOT
from .test_interop import _legacy, _recording


@pytest.fixture(scope="module")
def simulated():
    """Two pings of two targets."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return acoustics.simulate(acoustics.load_scene("two_targets"), pings=range(2))


#: two targets seen from a rolling platform by an ADC that quantises, with noise: the variables
#: only such scenes write (ping_sonar_*, roll, ..., adc_clipped_samples)
ROLLING_QUANTISED = (ROOT / "scenes" / "two_targets.yaml").read_text() + """
sonar:
  motion:
    kind: swell
    swell: {roll_amplitude_deg: 3.0, roll_period_s: 8.0, heave_amplitude_m: 0.2, heave_period_s: 7.0}
sampling:
  adc: {quantize: true}
noise: {enabled: true}
"""


def _variables(tree):
    """(group path, variable name, variable) of every variable and coordinate of a tree."""
    for node in tree.subtree:
        ds = node.to_dataset(inherit=False)
        for name, var in ds.variables.items():
            yield node_path(node.path), str(name), var


def _assert_follows_the_table(tree):
    """Every variable written is in the table, with its dimensions and units (none where the
    table has none), and nothing the table makes mandatory is missing."""
    seen = set()
    for path, name, var in _variables(tree):
        row = group_spec(path).variable(name)
        assert row is not None, f"{path}/{name} is not in the contract's table"
        assert var.dims == row.dims, f"{path}/{name}"
        assert var.attrs.get("units") == row.units, f"{path}/{name}"
        seen.add((path, name))
    for g in GROUPS.values():
        for v in g.variables:
            if v.mandatory:
                assert (g.path, v.name) in seen, f"mandatory {g.path}/{v.name} missing"
    assert check_tree(tree) == []


def test_a_simulation_writes_only_what_the_table_says_with_its_units(simulated, tmp_path):
    _assert_follows_the_table(simulated)
    # and as the file holds it (strings and times come back through NetCDF)
    write_tree(simulated, tmp_path / "s.nc")
    _assert_follows_the_table(open_tree(tmp_path / "s.nc"))
    # every group but the opt-in per-arrival truth (tests/test_arrivals.py writes that one)
    assert {node_path(n.path) for n in simulated.subtree} == set(GROUPS) - {node_path(ARRIVALS_GROUP)}


def test_a_moving_quantising_simulation_follows_the_table(tmp_path):
    (tmp_path / "s.yaml").write_text(ROLLING_QUANTISED)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate(acoustics.load_scene(tmp_path / "s.yaml"), pings=range(2))
    for name in ("ping_sonar_rotation", "roll", "vertical_offset"):
        assert name in tree[PLATFORM_GROUP].ds
    assert "adc_clipped_samples" in tree[ELEMENT_GROUP].ds
    _assert_follows_the_table(tree)


def test_every_quantity_has_a_unit_and_only_labels_go_without():
    """The table's own rule: no unit only for text, indices, identifiers and flags."""
    for g in GROUPS.values():
        for v in g.variables:
            if v.units is None:
                assert v.kind in "UMi", f"{g.path}/{v.name}: a float without units"


def test_a_converted_recording_writes_only_what_the_table_says(tmp_path):
    _recording(tmp_path / "rec.mat", pings=2, element_size=np.full((16, 2), 0.004),
               tx_size=np.full((8, 2), 0.004), alpha=0.05)
    tree = read_mat(tmp_path / "rec.mat")
    _assert_follows_the_table(tree)
    assert tree.attrs["data_kind"] == "recorded"
    assert tree[ELEMENT_GROUP].ds["element_x"].attrs["units"] == "m"          # gained units
    assert tree[SONAR_GROUP].ds["transmit_bandwidth"].attrs["units"] == "Hz"


def test_the_previous_layout_converted_follows_the_table(simulated):
    _assert_follows_the_table(from_legacy(_legacy(simulated)))


def test_the_simulator_and_the_converter_write_the_same_variables_alike(simulated, tmp_path):
    """One builder: a variable both write has the same dims, units and long_name in both."""
    _recording(tmp_path / "rec.mat", pings=2)
    converted = read_mat(tmp_path / "rec.mat")
    sim = {(p, n): v for p, n, v in _variables(simulated)}
    common = [((p, n), v) for p, n, v in _variables(converted) if (p, n) in sim]
    assert len(common) > 20
    for key, var in common:
        other = sim[key]
        assert var.dims == other.dims and var.attrs.get("units") == other.attrs.get("units"), key
        assert var.attrs.get("long_name") == other.attrs.get("long_name"), key


def test_the_builder_takes_units_and_attributes_from_the_table():
    ds = build_group(ENVIRONMENT_GROUP, {"sound_speed_indicative": 1500, "absorption_indicative": [0.1],
                                         "frequency": [420e3]})
    assert ds["sound_speed_indicative"].attrs == {"units": "m/s"}
    assert ds["sound_speed_indicative"].dtype == np.float64                # an int widened
    assert ds["frequency"].attrs["units"] == "Hz" and "frequency" in ds.coords
    root = build_group(ROOT_GROUP, {}, attrs={"title": "t"})
    assert root.attrs["sonar_convention_name"] == "SONAR-netCDF4"          # filled in
    assert root.attrs["conventions"] == contract.CONVENTIONS


@pytest.mark.parametrize("group, values, attrs, words", [
    (ENVIRONMENT_GROUP, {"sound_speed": 1500.0}, None, "'sound_speed' is not in the data contract"),
    (ENVIRONMENT_GROUP, {"absorption_indicative": 0.1}, None, "0 dimension(s) given"),
    (ELEMENT_GROUP, {"element_subarray": np.zeros(3)}, None, "kind 'U'"),
    (ROOT_GROUP, {}, {"tilte": "x"}, "attribute 'tilte'"),
    (ROOT_GROUP, {}, {"sonar_convention_version": "2.0"}, "is '1.0' by the contract"),
])
def test_the_builder_refuses_what_the_table_does_not_say(group, values, attrs, words):
    with pytest.raises(ContractError, match=words.replace("(", r"\(").replace(")", r"\)")):
        build_group(group, values, attrs=attrs)


def test_the_check_names_a_departure(simulated):
    t = simulated.copy()
    ds = t[SONAR_GROUP].to_dataset(inherit=False)
    ds["transmit_bandwidth"].attrs["units"] = "kHz"
    t[SONAR_GROUP].dataset = ds.drop_vars("tx_element_weight").assign(stray=1.0)
    problems = check_tree(t)
    assert "/Sonar/transmit_bandwidth: units 'kHz', the contract has 'Hz'" in problems
    assert "/Sonar/tx_element_weight: mandatory, missing" in problems
    assert "/Sonar/stray: not in the data contract" in problems


def test_group_paths_are_defined_once_and_still_importable_from_dataset():
    assert TRUTH_GROUP_OF_DATASET is TRUTH_GROUP
    assert ELEMENT_GROUP == "Sonar/Beam_group1" and node_path(ELEMENT_GROUP) in GROUPS


def test_docs_dataset_md_shows_the_table_as_it_is():
    """docs/dataset.md's variable and attribute tables are the table's own markdown, verbatim
    (regenerate: python -m processing.base.contract --markdown)."""
    text = (ROOT / "docs" / "dataset.md").read_text()
    begin, end = text.index(contract.MARKDOWN_BEGIN), text.index(contract.MARKDOWN_END)
    assert text[begin:end + len(contract.MARKDOWN_END)] + "\n" == contract.markdown()
    out = subprocess.run([sys.executable, "-m", "processing.base.contract", "--markdown"],
                         capture_output=True, text=True, check=True).stdout
    assert out == contract.markdown()
    for g in GROUPS.values():
        for v in g.variables:
            assert f"`{v.name}`" in text, v.name


def test_a_mat_file_saved_by_scipy_round_trips_to_the_same_contract(tmp_path):
    """The samples of a .mat recording reach /Sonar/Beam_group1 unchanged (float32 pairs)."""
    path = _recording(tmp_path / "r.mat", pings=1)
    x = scipy.io.loadmat(path, squeeze_me=True)["samples"]
    tree = read_mat(path)
    got = np.asarray(beam_samples(tree[ELEMENT_GROUP].ds))
    np.testing.assert_array_equal(got, x[None].astype(np.complex64))
