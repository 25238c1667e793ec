"""The README's quick starts are the example files the suite runs, character for character,
and its commands are real ``plumeswarm`` commands."""

from __future__ import annotations

import re

from tests.support.procs import REPO, run_cli

README = (REPO / "README.md").read_text()


def test_every_python_block_of_the_readme_is_an_example_file_it_links() -> None:
    linked_block = r"\(examples/(\w+\.py)\)(?:(?!```).)*?```python\n(.*?)```"
    blocks = re.findall(linked_block, README, re.DOTALL)
    assert [name for name, _ in blocks] == ["swarm_script.py", "gymnasium_policy.py"]
    for name, code in blocks:
        assert code == (REPO / "examples" / name).read_text(), name
    assert README.count("```python") == len(blocks)


def test_the_quick_start_commands_exist() -> None:
    for line in re.findall(r"^plumeswarm (.+?)\s+#", README, re.MULTILINE):
        args = line.split()
        res = run_cli([*args[:1], "--help"], timeout_s=60)
        assert res.returncode == 0, (line, res.stderr)
    res = run_cli(["scenario", "check", "filament"], timeout_s=60)  # `plumeswarm up filament`
    assert res.returncode == 0, res.stderr
