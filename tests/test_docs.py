"""The documentation says what the code does: README.md and docs/ checked against the repository.

* Every block of command output is generated (scripts/readme_numbers.py) and rerun here: the
  page must show what a fresh run prints (numbers within a small relative tolerance, wall times
  masked). Quick commands in the fast suite, slow ones under ``-m slow``.
* Blocks summarising committed results agree with reports/.
* Every relative link resolves, to a file and, where it names one, to a heading.
* No page, docstring, help text or data note points to a file that is not in the repository.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "readme_numbers.py"


def _script(name: str):
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        return __import__(name)
    finally:
        sys.path.pop(0)


rn = _script("readme_numbers")
PAGES = rn.pages()


# ----------------------------------------------------------------------------- generated blocks


def test_every_generated_block_is_known_filled_and_where_expected():
    found = rn.block_bodies()  # raises on a block that appears twice
    assert set(found) <= set(rn.BLOCKS), sorted(set(found) - set(rn.BLOCKS))
    assert set(rn.BLOCKS) <= set(found), f"blocks on no page: {sorted(set(rn.BLOCKS) - set(found))}"
    for name, (page, body) in found.items():
        assert body.strip(), (
            f"{page.name}: block {name} is empty: run python scripts/readme_numbers.py"
        )


def test_report_blocks_agree_with_committed_reports():
    """Blocks made from reports/ (calibration, coverage, proof, benchmarks, timings) are what the
    script makes of the committed files."""
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--check"], cwd=ROOT, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_regenerate_replaces_only_the_block_body():
    text = "a\n<!-- generated: __t -->\nold\n<!-- end generated: __t -->\nb\n"
    rn.BLOCKS["__t"] = rn.report_block(lambda: "new\n")
    try:
        out, changed = rn.regenerate(text, {"__t"})
    finally:
        del rn.BLOCKS["__t"]
    assert out == "a\n<!-- generated: __t -->\nnew\n<!-- end generated: __t -->\nb\n"
    assert changed == ["__t"]


RUN_BLOCKS = [n for n, b in rn.BLOCKS.items() if b.kind == "run"]


@pytest.mark.parametrize("name", RUN_BLOCKS)
def test_run_block_shows_the_commands_the_script_runs(name):
    _, body = rn.block_bodies()[name]
    assert [c for c, _ in rn.parse_run_body(body)] == list(rn.BLOCKS[name].commands)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """One scratch copy of the data for all run blocks, and the output of each block run so far
    (a block that reads another's output, e.g. check after fit, runs after it)."""
    return rn.make_workspace(tmp_path_factory.mktemp("docs-workspace")), {}


def _fresh(name: str, workspace) -> list[tuple[str, list[str]]]:
    folder, done = workspace
    if name not in done:
        block = rn.BLOCKS[name]
        for req in block.requires:
            _fresh(req, workspace)
        done[name] = [(c, rn.run_command(c, folder, block.statuses)[0]) for c in block.commands]
    return done[name]


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=pytest.mark.slow) if rn.BLOCKS[n].slow else n for n in RUN_BLOCKS],
)
def test_run_block_is_what_a_fresh_run_prints(name, workspace):
    """The page shows what the command prints today; a stale block fails here. Regenerate with
    ``python scripts/readme_numbers.py --only NAME``."""
    page, body = rn.block_bodies()[name]
    shown = dict(rn.parse_run_body(body))
    problems = []
    for command, lines in _fresh(name, workspace):
        problems += rn.compare_lines(shown[command], lines)
    where = f"{page.relative_to(ROOT)}, block {name}"
    assert not problems, f"{where} differs from a fresh run:\n" + "\n".join(problems)


@pytest.mark.parametrize(
    "page, run, same",
    [
        (["x0 8.38 % [8.15, 8.62]"], ["x0 8.38 % [8.15, 8.62]"], True),
        (["a_P 13000.9"], ["a_P 13001.0"], True),  # one unit of the last digit shown
        (["a_P 13000.9"], ["a_P 13080.0"], False),
        (["R-hat 1.001 ESS 6294"], ["R-hat 1.001 ESS 6300"], True),  # relative 1e-3
        (["R-hat 1.000 ESS 7146"], ["R-hat 1.000 ESS 7124"], True),  # another CPU: 3e-3
        (["R-hat 1.001 ESS 6294"], ["R-hat 1.001 ESS 6400"], False),
        (["fit 11.5 s, report 15.1 s"], ["fit 92.0 s, report 19.9 s"], True),  # wall times masked
        (["b_P: point -110220 +/- 1.36e+03"], ["b_P: point -110220 +/- 1.37e+03"], True),
        (["b_P: point -110220 +/- 1.36e+03"], ["b_P: point -110220 +/- 1.46e+03"], False),
        (["OK: all agree"], ["FAIL: 1 of 22 blocks disagree"], False),
        (["a", "... (2 more lines)"], ["a", "b", "c"], True),
        (["a", "... (2 more lines)"], ["a", "b"], False),
        (["a"], ["a", "b"], False),
    ],
)
def test_compare_lines(page, run, same):
    assert (rn.compare_lines(page, run) == []) is same


# ----------------------------------------------------------------------------- links


LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")


def _slugs(md: Path) -> set[str]:
    """The anchors mkdocs gives the headings of a page (Python-Markdown's toc slugify)."""
    from markdown.extensions.toc import slugify

    text = re.sub(r"```.*?```", "", md.read_text(encoding="utf-8"), flags=re.S)
    heads = re.findall(r"^#{1,6}\s+(.*?)\s*$", text, flags=re.M)
    return {slugify(re.sub(r"[`*]", "", h), "-") for h in heads}


def _links(md: Path) -> list[str]:
    text = md.read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # code is not Markdown
    text = re.sub(r"^(?: {4}|\t).*$", "", text, flags=re.M)
    return [a or b for a, b in LINK.findall(text)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    broken = []
    for target in _links(page):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in _slugs(dest):
            broken.append(f"{target}: no heading with the anchor #{anchor}")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def test_link_checker_finds_a_broken_link(tmp_path):
    page = tmp_path / "p.md"
    (tmp_path / "q.md").write_text("# A heading\n")
    page.write_text("[ok](q.md#a-heading) [bad](q.md#nothing) [gone](r.md) ![img](s.png)\n")
    assert _links(page) == ["q.md#a-heading", "q.md#nothing", "r.md", "s.png"]
    assert _slugs(tmp_path / "q.md") == {"a-heading"}


# ----------------------------------------------------------------------------- references


#: Files of the project's specification that are not in this repository: say the thing itself.
OUTSIDE = re.compile(r"CONTRACT\.md|PHYSICS\.md|STYLE\.md|HELPERS\.md|\bshared/|/work/")
#: A path into the repository's folders, as a page or docstring would name it.
PATH = re.compile(
    r"(?<![\w/.-])((?:uq|tests|scripts|fits|data|docs|reports|benchmarks|requirements)/"
    r"[\w./-]*\.(?:py|md|json|csv|toml|png|html|nc|txt|sh|css))\b"
)
#: A dotted name of a private module, e.g. uq._models.cubic_fit.fit_test.
DOTTED = re.compile(r"\buq\.(_\w+(?:\.\w+)*)")


def _texts():
    """(where, text) of every page, docstring and help text, data note and script to scan."""
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md", *PAGES[1:]]
    files += [p for p in (ROOT / "uq").rglob("*") if p.suffix in (".py", ".html", ".css", ".csv")]
    files += [p for p in (ROOT / "data").rglob("*") if p.suffix in (".md", ".toml")]
    files += [p for p in (ROOT / "fits").rglob("*") if p.suffix in (".md", ".toml", ".py")]
    files += [*(ROOT / "scripts").glob("*.py"), *(ROOT / "benchmarks").glob("*.py")]
    for f in sorted(set(files)):
        text = f.read_text(encoding="utf-8", errors="replace")
        if f.suffix == ".csv":  # only its comment lines are prose
            text = "\n".join(ln for ln in text.splitlines() if ln.startswith("#"))
        yield str(f.relative_to(ROOT)), text


def _resolves(dotted: str) -> bool:
    """Does ``uq.<dotted>`` name a module of the package, or a name its package defines?"""
    here = ROOT / "uq"
    for part in dotted.split("."):
        if (here / part).is_dir():
            here = here / part
            continue
        if (here / f"{part}.py").exists():
            return True  # a module; what follows is an attribute of it
        init = here / "__init__.py"
        return init.exists() and re.search(rf"\b{part}\b", init.read_text()) is not None
    return True


def _output(rel: str) -> bool:
    """A file the commands write (git ignores it), e.g. the main job's reports/n50/report.html."""
    proc = subprocess.run(["git", "check-ignore", "-q", rel], cwd=ROOT, capture_output=True)
    return proc.returncode == 0


def test_nothing_points_outside_the_repository():
    bad = []
    for where, text in _texts():
        bad += [f"{where}: {m[0]}" for m in OUTSIDE.finditer(text)]
        if where == "CHANGELOG.md":  # history may name files that have since moved
            continue
        bad += [
            f"{where}: {m[1]} does not exist"
            for m in PATH.finditer(text)
            if not (ROOT / m[1]).exists() and "*" not in m[1] and not _output(m[1])
        ]
        bad += [
            f"{where}: uq.{m[1]} is no module" for m in DOTTED.finditer(text) if not _resolves(m[1])
        ]
    assert not bad, "references to what is not in the repository:\n" + "\n".join(sorted(set(bad)))


def test_reference_checker_catches_what_it_must():
    assert OUTSIDE.search("see PHYSICS.md, sampling note") and OUTSIDE.search("shared/paper/x.txt")
    assert PATH.search("stated in `uq/_stand.py`")[1] == "uq/_stand.py"
    assert not (ROOT / "uq/_stand.py").exists() and not (ROOT / "tests/test_stand.py").exists()
    assert _resolves("_models.cubic_fit.fit_test") and _resolves("_inference")
    assert not _resolves("_models.nonexistent_module.f") and not _resolves("_reference")
    assert _resolves("_API") and _output("reports/n50/report.html") and not _output("README.md")


def test_help_texts_point_nowhere_outside():
    """Every command's --help, as a user sees it."""
    from uq._cli.main import COMMANDS, build_parser

    for name, _, _ in COMMANDS:
        text = build_parser([name])._uq_commands[name].format_help()
        assert not OUTSIDE.search(text), f"uq {name} --help: {OUTSIDE.search(text)[0]}"


# ----------------------------------------------------------------------------- README, site, citation


def test_readme_is_short_and_says_what_matters():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 200
    for must in (
        "bash scripts/main.sh",
        "bash scripts/test.sh",
        "RECONSTRUCTED",
        "The experimental method for determining the isobaric",
        "docs/figures/fig2_force.png",
        "docs/reading-the-report.md",
    ):
        assert must in text, must


def test_api_reference_lists_every_public_name():
    import uq

    hooks = _script("mkdocs_hooks")
    text = hooks.reference_markdown()
    for name in uq.__all__:
        if name != "__version__":
            assert f"## `uq.{name}`" in text, name
    for _, path in hooks.public_names():  # each directive names an object that exists
        module, _, attr = path.rpartition(".")
        assert hasattr(__import__(module, fromlist=[attr]), attr), path


def test_doctests_become_code_blocks():
    hooks = _script("mkdocs_hooks")
    text = "Intro.\n\n>>> x = [1][0]\n>>> x\n1\n\nAfter.\n    >>> y\n    2"
    assert hooks.fence_doctests(text) == (
        "Intro.\n\n```pycon\n>>> x = [1][0]\n>>> x\n1\n```\n\nAfter.\n"
        "    ```pycon\n    >>> y\n    2\n    ```"
    )


def test_citation_file_names_the_software_and_the_paper():
    import yaml

    import uq

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["version"] == uq.__version__
    assert cff["license"] == "MIT" and "MIT" in (ROOT / "LICENSE").read_text()
    (paper,) = cff["references"]
    assert paper["title"].startswith("The experimental method for determining the isobaric")
    assert [a["family-names"] for a in paper["authors"]] == ["Korneyev", "Korneyev", "Shalay"]
