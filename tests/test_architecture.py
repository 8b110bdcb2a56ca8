"""The design, guarded: three layers (abacus -> acoustics, processing; acoustics -> only
processing.base; processing -> neither, and processing.base -> nothing above it), no import
cycles, no reaching into another module's private names, every package shipped."""
from __future__ import annotations

import ast
import re

from .conftest import ROOT

PACKAGES = ("abacus", "acoustics", "processing")


def layer_of(module: str) -> str:
    """The layer a module belongs to: 'abacus', 'acoustics', 'processing.base' or 'processing'."""
    if module == "processing.base" or module.startswith("processing.base."):
        return "processing.base"
    return module.split(".")[0]


#: layer -> the layers it may import (its own included); nothing else of ours
MAY_IMPORT = {
    "abacus": {"abacus", "acoustics", "processing", "processing.base"},
    "acoustics": {"acoustics", "processing.base"},
    "processing": {"processing", "processing.base"},
    "processing.base": {"processing.base"},
}


def _modules():
    """{dotted module name: path} of every module in the packages."""
    out = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _resolve(module: str, level: int, name: str | None, current: str, is_package: bool) -> str:
    if level == 0:
        return module
    base = current.split(".")
    base = base if is_package else base[:-1]
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def _imports(name: str, path):
    """(imported module, line, names, module-level?) for every import statement of a module."""
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    top = {id(n) for n in tree.body}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, node.lineno, [], id(node) in top
        elif isinstance(node, ast.ImportFrom):
            mod = _resolve(node.module or "", node.level, None, name, is_pkg)
            names = [a.name for a in node.names]
            # "from pkg import sub" imports the submodule when it is one
            subs = [f"{mod}.{n}" for n in names if f"{mod}.{n}" in MODULES]
            for target in subs or [mod]:
                yield target, node.lineno, names, id(node) in top


def _graph():
    """Edges between the packages' modules, with the parent packages an import runs (except a
    module's own parents: Python initialises those before the module itself)."""
    graph = {m: set() for m in MODULES}
    for name, path in MODULES.items():
        own = {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}
        for target, *_ in _imports(name, path):
            parts = target.split(".")
            for i in range(1, len(parts) + 1):
                t = ".".join(parts[:i])
                if t in MODULES and t != name and t not in own:
                    graph[name].add(t)
    return graph


def _cycles(graph):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles_among_modules():
    """Imports at any depth (module level or inside functions) and the package __init__ files
    they run form no cycle: every module can be understood, and imported, on its own."""
    assert _cycles(_graph()) == []


def _upward_imports():
    """Imports of a module of ours that its layer may not make, as 'module:line -> target'."""
    bad = []
    for name, path in MODULES.items():
        allowed = MAY_IMPORT[layer_of(name)]
        for target, line, *_ in _imports(name, path):
            if target.split(".")[0] in PACKAGES and layer_of(target) not in allowed:
                bad.append(f"{name}:{line} -> {target}")
    return bad


def test_every_import_respects_the_layers():
    """The rule is by layer, with no list of exceptions: the application joins the two models;
    the forward model uses only processing's base (contract, configuration, file safety, the
    counting volume); processing never needs the simulator or the application."""
    assert _upward_imports() == []


def test_the_layer_rule_is_enforced():
    """The check itself: an upward import would be caught (not a test that cannot fail)."""
    assert layer_of("processing.base.dataset") == "processing.base"
    assert "acoustics" not in MAY_IMPORT[layer_of("processing.detection.detect")]
    assert "processing" not in MAY_IMPORT[layer_of("acoustics.scene.schema")]
    assert "abacus" not in MAY_IMPORT["acoustics"] | MAY_IMPORT["processing"]
    assert "processing" not in MAY_IMPORT["processing.base"]


def test_no_private_names_imported_across_modules():
    bad = []
    for name, path in MODULES.items():
        for target, line, names, _ in _imports(name, path):
            if target.split(".")[0] in PACKAGES and target != name:
                bad += [f"{name}:{line} imports {n} from {target}" for n in names
                        if n.startswith("_") and not n.startswith("__")]
    assert bad == []


def test_no_private_attributes_of_other_modules_are_used():
    """``module._name`` of another of our modules (e.g. ``products._pose``) is a reach-in."""
    bad = []
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text())
        aliases = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                mod = _resolve(node.module or "", node.level, None, name, path.name == "__init__.py")
                for a in node.names:
                    if f"{mod}.{a.name}" in MODULES:
                        aliases[a.asname or a.name] = f"{mod}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in MODULES and a.asname:
                        aliases[a.asname] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                bad.append(f"{name}:{node.lineno} uses {aliases[node.value.id]}.{node.attr}")
    assert bad == []


def test_every_package_folder_ships():
    """pyproject lists its packages (the scenes ship as abacus_scenes): none may be forgotten."""
    text = (ROOT / "pyproject.toml").read_text()
    listed = set(re.findall(r'"([a-z_.]+)"', text.split("packages = [", 1)[1].split("]", 1)[0]))
    on_disk = {name for name, path in MODULES.items() if path.name == "__init__.py"}
    assert on_disk | {"abacus_scenes"} == listed


def test_modules_are_small_and_of_one_concept():
    """House style: modules of one concept, at most ~800 lines (DESIGN.md says 150–600)."""
    long = {name: n for name, path in MODULES.items()
            if (n := len(path.read_text().splitlines())) > 800}
    assert long == {}


def test_no_module_outside_the_contract_indexes_a_group_by_its_name():
    """Group paths are the contract's (processing/base/contract.py): a literal such as
    ``tree["Processing/Counts"]`` elsewhere would go stale when the table moves a group."""
    from processing.base import contract
    names = {getattr(contract, n) for n in contract.__all__ if n.endswith("_GROUP")
             and isinstance(getattr(contract, n), str)} - {"/"}
    names |= {f"{contract.SONAR_GROUP}/{contract.BEAM_GROUP_NAME}"}
    bad = []
    for name, path in MODULES.items():
        if layer_of(name) == "processing.base":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
                    and isinstance(node.slice.value, str)
                    and (node.slice.value in names or node.slice.value.split("/")[0] in names
                         and "/" in node.slice.value)):
                bad.append(f"{name}:{node.lineno} indexes {node.slice.value!r}")
    assert bad == []
