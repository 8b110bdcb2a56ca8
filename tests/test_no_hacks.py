"""No process-level tricks in the packages (issue 26, "Performance stays inside stages"): no
``ctypes``, no ``os._exit``, no fork of this process (``os.fork``, the "fork" start method of
multiprocessing, a process pool left to the platform's default), no writes to the process'
environment, and no monkey-patching of a third-party module. Speed is won inside a stage, in
the open, or not at all.

The checker reads every .py file of ``abacus/``, ``acoustics/`` and ``processing/`` (their
syntax trees, not their text: a comment or a docstring may name what the code may not do) and
lists each violation as ``file:line: what``; it is itself tested on planted violations.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("abacus", "acoustics", "processing")
#: first-party top-level modules: assigning to their attributes is ours to do
FIRST_PARTY = set(PACKAGES) | {"abacus_scenes"}
#: functions that choose a multiprocessing start method by name
START_METHOD = {"get_context", "set_start_method"}
#: process pools that fork unless given a context ("spawn" / "forkserver")
POOLS = {"ProcessPoolExecutor"}


def _third_party(module: str | None, level: int = 0) -> bool:
    if level or not module:
        return False
    top = module.split(".")[0]
    return top not in FIRST_PARTY and top not in sys.stdlib_module_names


def _dotted(node) -> str:
    """``a.b.c`` for an attribute chain on a name (subscripts skipped), else ''."""
    parts = []
    while isinstance(node, (ast.Attribute, ast.Subscript)):
        if isinstance(node, ast.Attribute):
            parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
        return ".".join(reversed(parts))
    return ""


def _root(node):
    """The name an attribute / subscript chain starts from, or None."""
    while isinstance(node, (ast.Attribute, ast.Subscript)):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


def violations(source: str, filename: str = "<string>") -> list[str]:
    """``filename:line: what`` for every process-level trick in ``source``."""
    tree = ast.parse(source, filename)
    found = []

    def report(node, what):
        found.append(f"{filename}:{node.lineno}: {what}")

    # names bound by imports, anywhere in the module (conservative: scopes are not told apart)
    os_names, third_party = {"os", "posix"}, {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                bound = alias.asname or alias.name.split(".")[0]
                if alias.name.split(".")[0] == "ctypes":
                    report(node, "imports ctypes")
                if alias.name in ("os", "posix"):
                    os_names.add(bound)
                if _third_party(alias.name):
                    third_party[bound] = alias.name
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if module.split(".")[0] == "ctypes" and not node.level:
                report(node, "imports ctypes")
            for alias in node.names:
                if not node.level and module in ("os", "posix") and alias.name in ("_exit", "fork", "forkpty"):
                    report(node, f"imports {module}.{alias.name}")
                if _third_party(module, node.level):
                    third_party[alias.asname or alias.name] = f"{module}.{alias.name}"

    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in os_names:
            if node.attr == "_exit":
                report(node, f"{node.value.id}._exit")
            elif node.attr in ("fork", "forkpty"):
                report(node, f"{node.value.id}.{node.attr}")
            elif node.attr == "putenv":
                report(node, f"{node.value.id}.putenv (writes the process' environment)")
        elif isinstance(node, ast.Name) and node.id == "ctypes":
            report(node, "uses ctypes")
        elif isinstance(node, ast.Call):
            name = _dotted(node.func).split(".")[-1]
            args = [a.value for a in node.args if isinstance(a, ast.Constant)]
            args += [k.value.value for k in node.keywords if isinstance(k.value, ast.Constant)]
            if name in START_METHOD and "fork" in args:
                report(node, f'{name}("fork"): forks this process')
            if name in ("__import__", "import_module") and "ctypes" in args:
                report(node, "imports ctypes")
            if name in POOLS and not any(k.arg == "mp_context" for k in node.keywords):
                report(node, f"{name} without mp_context (forks this process by default)")
            if name in ("setdefault", "update", "pop", "clear", "__setitem__") and \
                    _dotted(node.func).rsplit(".", 1)[0] in {f"{o}.environ" for o in os_names}:
                report(node, f"{_dotted(node.func)}: writes the process' environment")
            if name == "setattr" and node.args and _root(node.args[0]) in third_party:
                report(node, f"setattr on {third_party[_root(node.args[0])]} (monkey-patches a third-party module)")
        if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign, ast.Delete)):
            targets = node.targets if isinstance(node, (ast.Assign, ast.Delete)) else [node.target]
            for target in targets:
                for t in (target.elts if isinstance(target, (ast.Tuple, ast.List)) else [target]):
                    if not isinstance(t, (ast.Attribute, ast.Subscript)):
                        continue
                    root = _root(t)
                    if root in third_party:
                        report(node, f"assigns {_dotted(t) or root}... of {third_party[root]} "
                                     f"(monkey-patches a third-party module)")
                    elif _dotted(t).startswith(tuple(f"{o}.environ" for o in os_names)):
                        report(node, f"assigns {_dotted(t)}: writes the process' environment")
    return found


def _sources():
    for package in PACKAGES:
        yield from sorted((ROOT / package).rglob("*.py"))


def test_the_packages_use_no_process_level_tricks():
    found = []
    for path in _sources():
        found += violations(path.read_text(), str(path.relative_to(ROOT)))
    assert found == [], "process-level tricks:\n" + "\n".join(found)


def test_there_is_something_to_check():
    names = {p.relative_to(ROOT).as_posix() for p in _sources()}
    assert {"abacus/cli/app.py", "abacus/cli/run.py", "processing/chain.py"} <= names


@pytest.mark.parametrize("source, what", [
    ("import ctypes\n", "imports ctypes"),
    ("from ctypes import CDLL\n", "imports ctypes"),
    ("import importlib\nimportlib.import_module('ctypes')\n", "imports ctypes"),
    ("import os\nos._exit(0)\n", "os._exit"),
    ("def f():\n    import os as o\n    o._exit(3)\n", "o._exit"),
    ("from os import _exit\n", "imports os._exit"),
    ("import os\npid = os.fork()\n", "os.fork"),
    ("import multiprocessing\nctx = multiprocessing.get_context('fork')\n", 'get_context("fork")'),
    ("import multiprocessing as mp\nmp.set_start_method(method='fork')\n", 'set_start_method("fork")'),
    ("from concurrent.futures import ProcessPoolExecutor\npool = ProcessPoolExecutor(2)\n",
     "ProcessPoolExecutor without mp_context"),
    ("import os\nos.environ['OMP_WAIT_POLICY'] = 'PASSIVE'\n", "writes the process' environment"),
    ("import os\nos.environ.setdefault('OPENBLAS_NUM_THREADS', '1')\n", "writes the process' environment"),
    ("import xarray\nxarray.set_options = None\n", "monkey-patches a third-party module"),
    ("import xarray as xr\nxr.core.pycompat._cached['dask'] = False\n", "monkey-patches a third-party module"),
    ("from xarray.namedarray import pycompat\npycompat._cached_modules['dask'] += 1\n",
     "monkey-patches a third-party module"),
    ("def f():\n    import numba\n    numba.config.NUMBA_NUM_THREADS: int = 1\n", "monkey-patches a third-party module"),
    ("import matplotlib\nsetattr(matplotlib, 'use', print)\n", "monkey-patches a third-party module"),
])
def test_the_checker_catches_a_planted_violation(source, what):
    found = violations(source, "planted.py")
    assert len(found) == 1 and found[0].startswith("planted.py:") and what in found[0], found


@pytest.mark.parametrize("source", [
    "import os\nos.environ.get('HOME')\nos.kill(os.getpid(), 0)\n",
    "import sys, warnings\nwarnings.showwarning = print\nsys.unraisablehook = print\n",
    "import multiprocessing\nctx = multiprocessing.get_context('spawn')\n",
    "import multiprocessing\nfrom concurrent.futures import ProcessPoolExecutor\n"
    "pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context('forkserver'))\n",
    "import numpy as np\nx = np.zeros(3)\nx[0] = 1\nx.flags.writeable = False\n",
    "from processing.base import atomic\natomic.ACTIVE = set()\n",
    "from . import plots\nplots.PNG_COMPRESS_LEVEL = 6\n",
    "# os._exit(0) and import ctypes, in a comment\n'''os.fork() in a docstring'''\n",
])
def test_the_checker_lets_ordinary_code_be(source):
    assert violations(source) == []
