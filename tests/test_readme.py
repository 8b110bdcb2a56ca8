"""The README's two set-up commands, and CI running the second one verbatim."""
from __future__ import annotations

import re

from .conftest import ROOT


def _readme_commands():
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```sh\n(.*?)```", text, re.S).group(1)
    return [line for line in block.splitlines() if line.strip()]


def test_readme_starts_with_exactly_two_commands():
    text = (ROOT / "README.md").read_text()
    first_block = text.index("```sh")
    assert text[:first_block].strip().startswith("# abacus")
    assert len(text[:first_block].strip().splitlines()) == 1  # nothing before the commands
    cmds = _readme_commands()
    assert len(cmds) == 2
    assert "abacus run scenes/default.yaml" in cmds[0]
    assert "pytest" in cmds[1]


def test_ci_runs_the_readme_test_command_verbatim():
    ci = (ROOT / ".ci" / "run").read_text()
    assert _readme_commands()[1] in ci.splitlines()


def test_the_first_command_writes_where_a_fresh_checkout_can():
    """`abacus run -o X` refuses a missing parent folder (a typo must not write elsewhere), so
    the README's run may name -o only under a folder a fresh checkout has."""
    words = _readme_commands()[0].split("&&")[-1].split()
    if "-o" in words:
        out = ROOT / words[words.index("-o") + 1]
        assert out.parent.is_dir() and not out.exists()
