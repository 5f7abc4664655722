"""The README is the front door: short, its Quickstart is what CI runs, and one click reaches each manual page.

docs/ is the manual (tests/repository/test_docs.py); the README says what the benchmark is, shows the two Quickstart
commands that `.ci/run` runs, and links each "what you can do" example to its page.
"""

from __future__ import annotations

import re
import subprocess

import pytest
from repo_paths import ROOT

README = ROOT / "README.md"
MAX_LINES = 150
QUICKSTART = {
    "run": "pip install . && soabench run --net intersection",
    "test": 'pip install -e ".[test]" && pytest',
}
#: the four examples of "What you can do" and the manual page each must link to
EXAMPLES = {
    "your own streets": "docs/user-guide/scenes.md",
    "your method": "docs/user-guide/birth-model.md",
    "a tracker": "docs/user-guide/tracker.md",
    "CI": "docs/user-guide/ci.md",
    "real data": "docs/user-guide/kitti.md",
}


def _readme() -> str:
    return README.read_text(encoding="utf-8")


def _ci_awk_program() -> str:
    """The awk program with which `.ci/run` finds a Quickstart command in the README."""
    text = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    m = re.search(r"awk -v tag=\"<!-- quickstart-\$1 -->\" '([^']+)' README\.md", text)
    assert m, ".ci/run no longer finds the Quickstart commands with the awk program this test knows"
    return m.group(1)


def test_readme_is_short():
    n = len(_readme().splitlines())
    assert n <= MAX_LINES, f"README.md has {n} lines; the front door keeps to {MAX_LINES}: move the rest into docs/"


@pytest.mark.parametrize("name", sorted(QUICKSTART))
def test_ci_runs_the_readme_quickstart(name):
    """`.ci/run`'s own awk program, run on the README, finds exactly the Quickstart command."""
    out = subprocess.run(
        ["awk", "-v", f"tag=<!-- quickstart-{name} -->", _ci_awk_program(), str(README)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert out == QUICKSTART[name]


def test_install_page_shows_the_same_quickstart():
    page = (ROOT / "docs" / "user-guide" / "install.md").read_text(encoding="utf-8")
    for command in QUICKSTART.values():
        assert f"```bash\n{command}\n```" in page, command
        assert f"```bash\n{command}\n```" in _readme(), command


def _links(text: str) -> list[str]:
    return re.findall(r"\]\(([^)\s]+)\)", text)


def test_every_relative_link_of_the_readme_resolves():
    bad = []
    for target in _links(_readme()):
        if re.match(r"^[a-z]+://", target):
            continue
        path, _, anchor = target.partition("#")
        if not (ROOT / path).exists():
            bad.append(target)
        elif anchor:
            headings = (ROOT / path).read_text(encoding="utf-8")
            slugs = {
                re.sub(r"[^\w\- ]", "", h).strip().lower().replace(" ", "-")
                for h in re.findall(r"^#+ (.*)$", headings, re.M)
            }
            if anchor not in slugs:
                bad.append(target)
    assert not bad, f"README links that do not resolve: {bad}"


def test_each_example_links_its_manual_page_in_one_click():
    section = _readme().split("## What you can do", 1)[1].split("\n## ", 1)[0]
    paragraphs = [p for p in section.split("\n\n") if p.startswith("**")]
    assert len(paragraphs) >= 4
    links = _links(section)
    for what, page in EXAMPLES.items():
        assert page in links, f"the example for {what} does not link to {page}"
        assert (ROOT / page).is_file(), page
    for paragraph in paragraphs:  # every example names its page right where it is described
        assert any(link.startswith("docs/user-guide/") for link in _links(paragraph)), paragraph[:60]


def test_readme_keeps_the_key_figure_citation_and_licence():
    text = _readme()
    assert "](results/intersection/key_figure.png)" in text and (ROOT / "results/intersection/key_figure.png").is_file()
    assert "](results/README.md)" in text
    for heading in ("## Quickstart", "## What you can do", "## Results", "## How to cite", "## Licence"):
        assert heading in text, heading
