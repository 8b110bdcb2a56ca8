"""Installing abacus: a minimal install and its extras, the PyPI names `acoustics` and
`processing` taken by other projects, and the API conveniences a notebook user guesses.

The fresh-venv check (`pip install .`, no extras, then `abacus run`) is `.ci/minimal_install.py`,
a CI step; here, each missing extra is faked with ``sys.modules[name] = None``."""
from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import warnings

import numpy as np
import pytest

import acoustics
import processing
from processing.base.extras import EXTRAS, MissingExtra, missing_extra, require

from .conftest import ROOT

OPTIONAL = {"pyvista", "dask", "zarr", "motmetrics"}


def abacus(*args, cwd, pre: str = "pass", env=None):
    code = f"{pre}; import sys; from abacus.cli import main; sys.exit(main({[str(a) for a in args]!r}))"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd,
                          env=env)


def one_line(r) -> str:
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    return lines[0]


# --------------------------------------------------------------------------- packaging
def test_required_dependencies_leave_the_extras_out():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    required = {d.split("[")[0].split(">")[0].split("=")[0].strip() for d in project["dependencies"]}
    assert not required & OPTIONAL
    assert {"numpy", "xarray", "netCDF4", "matplotlib", "numba", "embreex"} <= required
    extras = project["optional-dependencies"]
    assert set(extras) >= {"view", "experiment", "dask", "zarr", "metrics", "all", "test"}
    assert extras["dask"] == ["abacus[experiment]"]
    (everything,) = extras["all"]
    assert everything.startswith("abacus[") and \
        set(everything[7:-1].split(",")) == set(extras) - {"all", "test", "dask"}
    assert "abacus[all]" in extras["test"]          # the tests run everything
    # every optional module maps to an extra that exists
    assert set(EXTRAS.values()) <= set(extras)


def test_ci_checks_a_minimal_install_then_runs_the_readme_command():
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    step = lines.index("python .ci/minimal_install.py")
    test = next(i for i, line in enumerate(lines) if "pytest" in line and not line.startswith("#"))
    assert step < test == len(lines) - 1     # pytest's summary stays the last line CI prints


# --------------------------------------------------------------------------- extras
def test_missing_extra_is_an_import_error_naming_the_extra():
    exc = MissingExtra("abacus view", "view", "pyvista")
    assert isinstance(exc, ImportError) and exc.extra == "view" and exc.name == "pyvista"
    assert str(exc) == 'abacus view needs the extra \'view\': pip install "abacus[view]"'
    found = missing_extra(ModuleNotFoundError("No module named 'zarr'", name="zarr"), "writing Zarr")
    assert found.extra == "zarr" and str(found).startswith("writing Zarr needs the extra 'zarr'")
    # a module that is not an extra's, or a broken (not missing) one, is not a missing extra
    assert missing_extra(ModuleNotFoundError("x", name="scipy")) is None
    assert missing_extra(ImportError("libGL.so.1: cannot open shared object file", name="vtk")) is None


def test_require_names_the_extra(monkeypatch):
    for name in ("distributed", "dask.distributed"):     # either may be imported already
        monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(MissingExtra, match=r"needs the extra 'experiment'"):
        require("dask.distributed", "a cluster")
    monkeypatch.setitem(sys.modules, "motmetrics", None)
    with pytest.raises(MissingExtra) as info:
        require("motmetrics", "scoring")
    assert info.value.extra == "metrics"


@pytest.fixture(scope="module")
def two_nc(tmp_path_factory):
    """A small simulated dataset with its truth (tracks are scored against it)."""
    path = tmp_path_factory.mktemp("two") / "two.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = acoustics.simulate("two_targets", pings=3)
    processing.write_tree(tree, path)
    return path


def test_tracking_scores_without_motmetrics_name_the_extra(two_nc, monkeypatch):
    monkeypatch.setitem(sys.modules, "motmetrics", None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(MissingExtra) as info:
            processing.track(two_nc)
    assert info.value.extra == "metrics" and "abacus[metrics]" in str(info.value)


@pytest.mark.parametrize("args, blocked, extra, output", [
    (["view", "two_targets", "-o", "v.png"], ["pyvista"], "view", "v.png"),
    (["simulate", "two_targets", "-o", "two.zarr"], ["zarr"], "zarr", "two.zarr"),
    (["simulate", "two_targets", "-o", "two.nc", "--format", "zarr"], ["zarr"], "zarr", "two.nc"),
    (["experiment", "two_targets", "-o", "exp", "--pings", "2", "--workers", "1"],
     ["dask", "distributed"], "experiment", "exp"),
    (["experiment", "two_targets", "-o", "exp", "--pings", "2", "--format", "zarr"], ["zarr"],
     "zarr", "exp"),
    (["track", "TWO", "-o", "tracks.nc"], ["motmetrics"], "metrics", "tracks.nc"),
])
def test_a_command_needing_a_missing_extra_says_which_in_one_line(tmp_path, two_nc, args, blocked,
                                                                  extra, output):
    args = [str(two_nc) if a == "TWO" else a for a in args]
    pre = "import sys; " + "; ".join(f"sys.modules[{m!r}] = None" for m in blocked)
    r = abacus(*args, cwd=tmp_path, pre=pre)
    line = one_line(r)
    assert r.returncode == 2
    assert line.startswith("error: ") and line.endswith(
        f"needs the extra '{extra}': pip install \"abacus[{extra}]\""), line
    assert not (tmp_path / output).exists()


def test_view_line_is_exactly_the_documented_one(tmp_path):
    r = abacus("view", "two_targets", "-o", "v.png", cwd=tmp_path,
               pre="import sys; sys.modules['pyvista'] = None")
    assert r.returncode == 2
    assert one_line(r) == 'error: abacus view needs the extra \'view\': pip install "abacus[view]"'


# --------------------------------------------------------------------------- foreign packages
def _env(pythonpath):
    import os
    env = dict(os.environ)
    env["PYTHONPATH"] = str(pythonpath)
    return env


def test_our_packages_are_not_foreign():
    from abacus.clash import foreign_packages
    assert foreign_packages() is None


@pytest.mark.parametrize("name, project", [("acoustics", "python-acoustics"),
                                           ("processing", "multiprocessing backport")])
def test_a_foreign_package_on_the_path_is_named_with_the_remedy(tmp_path, name, project):
    fake = tmp_path / "site" / name
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(f'"""A stand-in for PyPI\'s {name}."""\n__version__ = "0.2.6"\n')
    work = tmp_path / "work"
    work.mkdir()
    for cmd in ([sys.executable, "-m", "abacus", "--version"],          # the command's own entry
                [sys.executable, "-c", "import sys; from abacus.cli import main; "
                                       "sys.exit(main(['run', 'two_targets']))"]):
        r = subprocess.run(cmd, capture_output=True, text=True, cwd=work, env=_env(fake.parent))
        line = one_line(r)
        assert r.returncode == 2 and r.stdout == ""
        assert line.startswith(f"error: the package '{name}' that Python imports ({fake}")
        assert project in line and f"pip uninstall {name}" in line and "venv" in line
    assert list(work.iterdir()) == []


def test_a_foreign_package_installed_over_ours_is_named(tmp_path):
    """pip installs both into one site-packages: the folder is abacus' neighbour, the package
    in it the other project's."""
    site = tmp_path / "site"
    ignore = shutil.ignore_patterns("__pycache__")
    for pkg in ("abacus", "processing"):
        shutil.copytree(ROOT / pkg, site / pkg, ignore=ignore)
    (site / "acoustics").mkdir()
    (site / "acoustics" / "__init__.py").write_text('__all__ = ["Signal"]\n__version__ = "0.2.6"\n')
    r = subprocess.run([sys.executable, "-m", "abacus", "--version"], capture_output=True,
                       text=True, cwd=tmp_path, env=_env(site))
    line = one_line(r)
    assert r.returncode == 2 and "the package 'acoustics'" in line
    assert "has no acoustics.simulate" in line and "python-acoustics" in line


# --------------------------------------------------------------------------- API conveniences
def test_simulate_takes_a_scene_path_or_name_and_a_number_of_pings():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = acoustics.load_scene("two_targets")
        by_path = acoustics.simulate(ROOT / "scenes" / "two_targets.yaml", pings=2, seed=3)
        by_name = acoustics.simulate("two_targets", pings=[0, 1], seed=3)
        by_scene = acoustics.simulate(scene, pings=range(2), seed=3)
    a, b, c = (t["Sonar/Beam_group1"]["backscatter_r"].values for t in (by_path, by_name, by_scene))
    assert a.shape[1] == 2 and np.array_equal(a, b) and np.array_equal(a, c)
    for bad in (0, -3):
        with pytest.raises(ValueError, match="pings must be >= 1"):
            acoustics.simulate(scene, pings=bad)
    with pytest.raises(acoustics.SceneError):
        acoustics.simulate("no_such_scene_anywhere")
