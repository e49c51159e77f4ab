"""The README and docs/ as a user reads them: within their sizes, every link resolving, every
command marked runnable running as shown, the generated references current, and every
command's --help saying its exit codes.

A command block is marked runnable by an HTML comment on the line before its fence:

    <!-- runnable -->            every line of the next ```bash block exits 0
    <!-- runnable exit=2 -->     ... exits 2

Each line runs in a scratch folder that holds links to configs/ and docs/, so relative paths
read as in a clone and nothing is written into the clone; a leading `.venv/bin/` and a console script's name
are taken from this interpreter's environment.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
ARCHIVE = DOCS / "archive"
README_MAX_BYTES = 8 * 1024
PAGE_MAX_BYTES = 25 * 1024
COMMANDS = ("am-run", "am-trials", "am-vehicle", "am-demo", "simulator", "companion", "ground-station")


def pages() -> list[Path]:
    """README and every docs page outside the archive."""
    return [ROOT / "README.md", *sorted(p for p in DOCS.rglob("*.md") if ARCHIVE not in p.parents)]


def all_markdown() -> list[Path]:
    return [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted(DOCS.rglob("*.md"))]


def test_the_readme_is_at_most_8_kb():
    size = (ROOT / "README.md").stat().st_size
    assert size <= README_MAX_BYTES, f"README.md is {size} bytes > {README_MAX_BYTES}"


def test_no_page_outside_the_archive_is_over_25_kb():
    big = {str(p.relative_to(ROOT)): p.stat().st_size for p in pages() if p.stat().st_size > PAGE_MAX_BYTES}
    assert not big, f"pages over {PAGE_MAX_BYTES} bytes: {big}"


def test_the_current_pages_do_not_speak_of_the_projects_history():
    """Issue numbers and the journal belong in docs/archive/; the current pages say what is."""
    found = []
    for p in pages():
        for i, line in enumerate(p.read_text().splitlines(), 1):
            if re.search(r"\bissue \d+|\bthe (\w+ )?issue\b|used for nothing else|never used before", line, re.I):
                found.append(f"{p.relative_to(ROOT)}:{i}: {line.strip()[:80]}")
    assert not found, "\n".join(found)


def test_nothing_outside_the_archive_links_into_it_but_the_index():
    """The archive is a record, not a dependency: only the docs index points at it."""
    found = []
    for p in pages():
        if p == DOCS / "index.md":
            continue
        for target in _links(p.read_text()):
            if "archive/" in target:
                found.append(f"{p.relative_to(ROOT)} -> {target}")
    assert not found, found


def _links(text: str) -> list[str]:
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # code blocks hold no links
    text = re.sub(r"`[^`\n]*`", "", text)
    return re.findall(r"\]\(([^)\s]+)\)", text)


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces as hyphens."""
    s = re.sub(r"[`*_]", "", heading.strip().lower())
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return {_slug(m) for m in re.findall(r"^#+ (.+)$", text, flags=re.M)}


@pytest.mark.parametrize("page", all_markdown(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_resolves(page):
    broken = []
    for target in _links(page.read_text()):
        if re.match(r"[a-z]+:", target):  # http(s), mailto: not checked offline
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(f"{target}: no heading #{anchor}")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def runnable_blocks() -> list[tuple[str, int, str, int]]:
    """(page, line, command, expected exit code) of every line of every runnable block."""
    out = []
    for p in all_markdown():
        lines = p.read_text().splitlines()
        for i, line in enumerate(lines):
            m = re.match(r"<!-- runnable(?: exit=(\d+))? -->", line.strip())
            if not m:
                continue
            assert lines[i + 1].startswith("```"), f"{p}:{i + 1}: a runnable mark not followed by a code block"
            j = i + 2
            while not lines[j].startswith("```"):
                cmd = lines[j].strip()
                if cmd and not cmd.startswith("#"):
                    out.append((str(p.relative_to(ROOT)), j + 1, cmd, int(m.group(1) or 0)))
                j += 1
    return out


def test_the_docs_mark_commands_runnable():
    pages_with = {page for page, *_ in runnable_blocks()}
    assert "README.md" in pages_with and len(pages_with) >= 3, pages_with


def _resolve(cmd: str) -> list[str]:
    argv = shlex.split(cmd)
    exe = argv[0].removeprefix(".venv/bin/")
    bindir = Path(sys.executable).parent
    if exe in ("python", "python3"):
        return [sys.executable, *argv[1:]]
    found = shutil.which(exe, path=str(bindir)) or shutil.which(exe)
    assert found, f"{exe}: not installed next to {sys.executable}"
    return [found, *argv[1:]]


@pytest.mark.parametrize("page,line,cmd,code", runnable_blocks(), ids=lambda x: x if isinstance(x, str) else None)
def test_a_runnable_command_runs_as_the_docs_show(page, line, cmd, code, tmp_path):
    for name in ("configs", "docs"):
        (tmp_path / name).symlink_to(ROOT / name)
    r = subprocess.run(_resolve(cmd), cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "100"})
    assert r.returncode == code, f"{page}:{line}: {cmd}: exit {r.returncode}, expected {code}\n{r.stderr[-2000:]}"


def test_the_scenario_reference_is_what_the_loader_takes():
    from amcore.config_reference import render
    page = DOCS / "reference" / "scenario_toml.md"
    assert page.read_text() == render(), (
        "docs/reference/scenario_toml.md is out of date: python -m amcore.config_reference > "
        "docs/reference/scenario_toml.md")


def _help(cmd: str, *sub: str) -> str:
    r = subprocess.run([*_resolve(cmd), *sub, "--help"], capture_output=True, text=True, timeout=60,
                       env={**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "100"})
    assert r.returncode == 0, r.stderr
    return r.stdout


HELPS = [(c,) for c in COMMANDS] + [("ground-station", s) for s in ("record", "review", "keys")]


@pytest.mark.parametrize("argv", HELPS, ids=" ".join)
def test_every_help_says_its_exit_codes_and_the_reference_lists_every_option(argv):
    text = _help(*argv)
    assert "Exit codes:" in " ".join(text.split()), f"{' '.join(argv)} --help gives no exit codes"
    ref = (DOCS / "reference" / "commands.md").read_text()
    section = ref.split(f"## `{' '.join(argv)}`", 1)
    assert len(section) == 2, f"docs/reference/commands.md has no section ## `{' '.join(argv)}`"
    body = section[1].split("\n## ", 1)[0]
    options = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", text)) - {"--help"}
    missing = sorted(o for o in options if o not in body)
    assert not missing, f"docs/reference/commands.md, {' '.join(argv)}: options not described: {missing}"


def test_the_foxglove_layout_names_topics_and_fields_the_log_has():
    """Every message path of docs/foxglove/amstack_layout.json is a topic of the recorder's
    contract for the default scenario's AMs, and its field is a field of that topic's message."""
    import json

    from amcore.config import DEFAULT_SCENARIO, load_scenario
    from ground_station import contract
    from telemetry import binary

    layout = json.loads((DOCS / "foxglove" / "amstack_layout.json").read_text())
    sysids = [am.sysid for am in load_scenario(DEFAULT_SCENARIO).ams]
    fields = {contract.OBJECT_STATE_TOPIC: binary.OBJECT}
    for s in sysids:
        fields[contract.controller_topic(s)] = binary.CONTROLLER
        fields[contract.contact_topic(s)] = binary.CONTACT
        fields[contract.truth_topic(s)] = binary.AM_TRUTH
    whole = {d.topic.format(sysid=s) for d in contract.DERIVED for s in sysids}  # Foxglove's types, shown whole
    paths = []
    for cfg in layout["configById"].values():
        paths += [p["value"] for p in cfg.get("paths", [])]
        paths += [cfg[k] for k in ("topicPath", "topicToRender") if k in cfg]
        paths += list(cfg.get("topics", {}))
    assert paths
    for path in paths:
        topic, _, field = path.partition(".")
        if not field:
            assert topic in whole or topic in fields, path
            continue
        assert topic in fields, f"{path}: no such topic in the log"
        name = re.sub(r"\[\d+\]$", "", field)
        assert name in {f.name for f in fields[topic].fields}, f"{path}: {fields[topic].name} has no field {name}"


def test_the_files_users_expect_are_there_and_agree():
    """LICENSE is the BSD 3-Clause text pyproject.toml declares; CITATION.cff is valid YAML that
    cites the paper with its DOI and this software with its version; CHANGELOG.md exists."""
    import tomllib

    yaml = pytest.importorskip("yaml")

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"]["text"] == "BSD-3-Clause"
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License") and "Neither the name of the copyright holder" in text
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["license"] == "BSD-3-Clause" and cff["version"] == meta["version"]
    paper = cff["preferred-citation"]
    assert "Collaborative Grasping" in paper["title"] and paper["year"] == 2023
    assert re.fullmatch(r"10\.\d{4,9}/\S+", paper["doi"]), paper["doi"]
    assert {a["family-names"] for a in paper["authors"]} == {"Jeong", "Kim"}
    assert "## [Unreleased]" in (ROOT / "CHANGELOG.md").read_text()


def test_the_guides_example_scenarios_load():
    """Each scenario a guide ships (docs/guides/*.toml) loads from any folder (its vehicle path is
    relative to it), and a team's object share is what its comment says (flying one whole is a
    run of minutes: the guide gives the command and the verdict it measured)."""
    from amcore.config import load_scenario

    examples = sorted((DOCS / "guides").glob("*.toml"))
    assert examples
    for path in examples:
        spec = load_scenario(path)
        share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
        assert f"{share:.1f} N" in path.read_text(), f"{path.name}: each AM carries {share:.2f} N"
