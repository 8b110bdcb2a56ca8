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


def _tour_commands():
    text = (ROOT / "README.md").read_text()
    block = text[text.index("## A short tour"):]
    block = re.search(r"```sh\n(.*?)```", block, re.S).group(1)
    return [line.split("#")[0].split() for line in block.splitlines() if line.strip()]


def _outputs(words):
    """The paths a tour command writes: after -o/--output, --plots, --csv, and convert's second
    argument."""
    out = [words[i + 1] for i, w in enumerate(words[:-1]) if w in ("-o", "--output", "--plots", "--csv")]
    if words[1:2] == ["convert"]:
        out.append(words[3])
    return out


def test_the_tour_writes_under_one_ignored_folder_and_reads_what_ships():
    """Every file the tour writes lies under tour/, which it makes first and .gitignore
    covers; every file it reads is in the repository or written by an earlier line."""
    cmds = _tour_commands()
    assert cmds[0] == ["mkdir", "-p", "tour"]
    assert "/tour/" in (ROOT / ".gitignore").read_text().splitlines()
    written = set()
    for words in cmds[1:]:
        assert words[0] == "abacus", words
        outs = _outputs(words)
        assert all(o.startswith("tour/") for o in outs), words
        for w in words[2:]:
            if "/" in w and w not in outs and not w.startswith("tour/"):
                assert (ROOT / w).exists(), f"{w} (read by {' '.join(words)}) is not in the repository"
            elif w.startswith("tour/") and w not in outs:
                assert w in written, f"{w} is read before a line writes it"
        written.update(outs)


def test_the_tours_recording_converts_and_is_small(tmp_path):
    """The sample recording the tour converts ships (≲ 1 MB) and its line runs verbatim."""
    import os
    import subprocess
    import sys
    line = next(w for w in _tour_commands() if w[1:2] == ["convert"])
    src = ROOT / line[2]
    assert src.stat().st_size < 1_000_000
    (tmp_path / "tour").mkdir()
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    r = subprocess.run([sys.executable, "-m", "abacus", *line[1:]], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / line[3]).stat().st_size > 0
