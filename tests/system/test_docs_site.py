"""The documentation site has a page for every command (``make docs`` builds it, strict)."""

from __future__ import annotations

import re

import yaml

from tests.support.procs import REPO, run_cli


def _commands() -> set[str]:
    res = run_cli(["--help"])
    assert res.returncode == 0, res.stderr
    listed: set[str] = set()
    in_commands = False
    for line in res.stdout.splitlines():
        if line.strip() == "Commands:":
            in_commands = True
        elif in_commands and line.startswith("  ") and line.strip():
            listed.add(line.split()[0])
    return listed


def _nav_pages(node: object) -> list[str]:
    if isinstance(node, str):
        return [node]
    if isinstance(node, list):
        return [p for item in node for p in _nav_pages(item)]
    if isinstance(node, dict):
        return [p for value in node.values() for p in _nav_pages(value)]
    return []


def test_every_command_has_a_page_in_the_navigation() -> None:
    config = yaml.load((REPO / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    pages = set(_nav_pages(config["nav"]))
    for command in sorted(_commands()):
        page = f"cli/{command}.md"
        assert page in pages, f"{page} is not in mkdocs.yml's nav"
        text = (REPO / "docs" / page).read_text()
        assert re.search(rf"^\s+:command: {command}$", text, re.M), f"{page} documents {command}"
        assert f":prog_name: plumeswarm {command}" in text


def test_every_page_of_the_docs_folder_is_in_the_navigation() -> None:
    config = yaml.load((REPO / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    pages = set(_nav_pages(config["nav"]))
    on_disk = {str(p.relative_to(REPO / "docs")) for p in (REPO / "docs").rglob("*.md")}
    assert on_disk - pages == set(), "pages left out of the site's navigation"
