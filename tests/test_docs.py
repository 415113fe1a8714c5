"""The documentation: the site builds with warnings as errors, every relative link of README.md
and docs/*.md resolves to a file of the repository, and the committed figures and benchmark
tables are what the docs say they are."""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
#: [text](target) and ![alt](target); the target up to a space or the closing parenthesis
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _markdown_files() -> list[Path]:
    return [REPO / "README.md", *sorted(DOCS.glob("*.md"))]


def relative_links(text: str) -> list[str]:
    """The relative link targets of a Markdown text, code blocks and code spans left out, the
    anchor cut off (a target that is only an anchor gives nothing)."""
    text = FENCE.sub("", text)
    text = re.sub(r"`[^`\n]*`", "", text)
    out = []
    for target in LINK.findall(text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I) or target.startswith("#"):
            continue
        out.append(target.split("#", 1)[0])
    return out


def test_site_builds_strict(tmp_path):
    # the test extra installs the docs build; only a development venv made without it skips,
    # never CI
    for module in ("mkdocs", "mkdocstrings_handlers.python", "pymdownx"):
        if os.environ.get("CI"):
            importlib.import_module(module)
        else:
            pytest.importorskip(module)
    site = tmp_path / "site"
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                           str(site)], cwd=REPO, capture_output=True, text=True, timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "WARNING" not in out, out
    # the API reference is generated from the docstrings, and the schema pages are in
    api = (site / "api" / "api" / "index.html").read_text(encoding="utf-8")
    assert "meshphase.api.result.Result" in api and "Parameters" in api
    assert ":func:" not in api
    assert (site / "data_schemas" / "scene" / "index.html").is_file()
    perf = (site / "performance" / "index.html").read_text(encoding="utf-8")
    assert "meshphase bench io --quick" in perf and "--8&lt;--" not in perf


@pytest.mark.parametrize("path", _markdown_files(), ids=lambda p: p.name)
def test_relative_links_resolve(path):
    missing = [t for t in relative_links(path.read_text(encoding="utf-8"))
               if not (path.parent / t).resolve().is_file()]
    assert not missing, f"{path.relative_to(REPO)}: links to no file: {missing}"
    for target in relative_links(path.read_text(encoding="utf-8")):
        assert (path.parent / target).resolve().is_relative_to(REPO)


def test_relative_links_finds_and_skips():
    text = ("[a](docs/a.md#x) ![f](figures/f.png) [web](https://x.org/a.md) [top](#here) "
            "`[code](no.md)`\n```\n[fenced](no.md)\n```\n")
    assert relative_links(text) == ["docs/a.md", "figures/f.png"]
    assert relative_links("") == []


def test_relative_links_sees_a_broken_link(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("[gone](nothing_here.md)\n", encoding="utf-8")
    assert [t for t in relative_links(page.read_text()) if not (tmp_path / t).is_file()] \
        == ["nothing_here.md"]


def test_readme_fits_on_a_screen_and_keeps_the_set_up_commands():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    test_cmd = 'python3 -m pip install -e ".[test]" && python3 -m pytest'
    assert f"    {test_cmd}\n" in text
    assert "    python3 -m pip install -e . && meshphase demo\n" in text
    # .ci/run runs the same command, pip quietened
    assert test_cmd.replace("install -e", "install -q -e") in ci


def test_docs_state_no_history():
    dated = re.compile(r"\b20\d\d-\d\d-\d\d\b|\bissue \d+|\bsession\b", re.I)
    for path in [*_markdown_files(), *sorted((DOCS / "bench").glob("*.md"))]:
        hits = dated.findall(path.read_text(encoding="utf-8"))
        assert not hits, f"{path.relative_to(REPO)}: {hits}"


def test_figures_are_small_and_used():
    figures = sorted((DOCS / "figures").glob("*.png"))
    assert figures
    method = (DOCS / "method.md").read_text(encoding="utf-8")
    for fig in figures:
        assert fig.stat().st_size < 200_000, fig.name
        assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", fig.name
        assert f"figures/{fig.name}" in method, fig.name


def test_bench_tables_name_their_command():
    perf = (DOCS / "performance.md").read_text(encoding="utf-8")
    included = re.findall(r'^--8<-- "docs/bench/([^"]+)"$', perf, re.M)
    tables = sorted(p.name for p in (DOCS / "bench").glob("*.md"))
    assert tables and sorted(included) == tables
    for name in tables:
        first = (DOCS / "bench" / name).read_text(encoding="utf-8").splitlines()[0]
        assert re.fullmatch(r"Produced by `meshphase bench [a-z][^`]*`:", first), (name, first)


def test_bench_table_stamp_is_removed():
    make = _load("make_tables", DOCS / "bench" / "make_tables.py")
    line = "2 CPUs, Python 3.11.7, numpy 2.4.6, 2026-12-07T19:34:06+00:00."
    assert make.STAMP.sub("", line) == "2 CPUs, Python 3.11.7, numpy 2.4.6."
    assert make.STAMP.sub("", "") == ""
    assert make.STAMP.sub("", "seed 2026, 12 h") == "seed 2026, 12 h"


def test_sphinx_roles_become_inline_code():
    roles = _load("sphinx_roles", DOCS / "_ext" / "sphinx_roles.py")
    assert roles.plain_roles(":func:`~meshphase.io.read` and :mod:`.io`") == "`read` and `.io`"
    assert roles.plain_roles(":py:class:`meshphase.Result`") == "`meshphase.Result`"
    assert roles.plain_roles("") == ""
    # no role: the text as it was, even with colons and backticks
    assert roles.plain_roles("a: `b` :not a role:") == "a: `b` :not a role:"
    with pytest.raises(TypeError):
        roles.plain_roles(None)
