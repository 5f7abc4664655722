"""The documentation builds cleanly and covers what the code defines.

``mkdocs build --strict`` fails on any warning: a broken link, a missing anchor (e.g. a "§3.1.4" section that
docs/method.md lost), a docstring mkdocstrings cannot render, a link to a repository file that does not exist. The
other tests check that the generated blocks written into the pages are current, that the pages name every command,
option, configuration key and CSV column, that the pages say what the code derives for a network of your own, and
that every docs page and "docs/method.md §X" cited in the code exists.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
from repo_paths import ROOT

from soabench.config import NOT_KEYS, Config
from soabench.experiment.runs.store import EPISODE_COLUMNS, STEP_COLUMNS, TIMING_COLUMNS, TRIAL_COLUMNS

pytestmark = pytest.mark.slow  # builds the manual with mkdocs

DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"mkdocs build --strict failed (install the docs: pip install -e '.[docs]'):\n{log}"
    assert "WARNING" not in log, log
    return out


def _text(html_file: Path) -> str:
    return html_file.read_text(encoding="utf-8")


def test_strict_build_produces_every_page(site):
    for page in ("index.html", "method/index.html", "api/index.html", "user-guide/parameters/index.html"):
        assert (site / page).is_file(), page
    for md in DOCS.rglob("*.md"):  # every page file is in the navigation and built
        rel = md.relative_to(DOCS).with_suffix("")
        built = site / (rel.parent if rel.name == "index" else rel) / "index.html"
        assert built.is_file(), md
    api = _text(site / "api/index.html")
    # the API reference is generated from the docstrings, not an empty shell
    for name in ("GMPHDFilter", "SOABirth", "run_experiment", "ospa", "Scans"):
        assert name in api, name


def test_parameter_page_lists_every_config_key_with_its_default(site):
    html = _text(site / "user-guide/parameters/index.html")
    cfg = Config()
    for sec in dataclasses.fields(Config):
        assert f"[{sec.name}]" in html
        if not dataclasses.is_dataclass(getattr(cfg, sec.name)):  # [plugins.<name>]: options of each plugin
            continue
        for f in dataclasses.fields(getattr(cfg, sec.name)):
            row = re.search(rf"<td><code>{re.escape(f.name)}</code></td>\s*<td>(.*?)</td>", html)
            assert row, f"{sec.name}.{f.name} missing from the parameter table"
            default = getattr(getattr(cfg, sec.name), f.name)
            if isinstance(default, float):
                assert repr(default) in row.group(1), (f.name, row.group(1))
    for name in NOT_KEYS:  # not a key: its value has another key
        assert not re.search(rf"<td><code>{re.escape(name.split('.')[1])}</code></td>", html), name


def _hooks():
    spec = importlib.util.spec_from_file_location("soabench_docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_generated_blocks_written_into_the_pages_are_current():
    hooks = _hooks()
    pages = {p.relative_to(ROOT).as_posix() for p in hooks.pages() if "<!-- soabench:" in p.read_text("utf-8")}
    for page in ("user-guide/commands.md", "user-guide/parameters.md", "user-guide/scenes.md", "user-guide/kitti.md"):
        assert f"docs/{page}" in pages, page
    stale = [str(p.relative_to(ROOT)) for p in hooks.stale_pages()]
    assert stale == [], f"generated blocks are stale in {stale}: regenerate with `python docs/hooks.py`"


def test_a_stale_block_is_found_and_rewritten():
    hooks = _hooks()
    page = "# x\n\n<!-- soabench:kitti-keys -->\n| key | default | meaning |\n<!-- /soabench -->\n\nafter\n"
    fresh = hooks.refresh(page)
    assert fresh != page and "`match_gate`" in fresh and fresh.endswith("<!-- /soabench -->\n\nafter\n")
    assert hooks.refresh(fresh) == fresh
    with pytest.raises(ValueError, match="unknown generated block"):
        hooks.refresh("<!-- soabench:nosuch -->\n<!-- /soabench -->\n")


def _parser_commands() -> dict[str, argparse.ArgumentParser]:
    from soabench.cli.main import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_commands_page_shows_every_command_and_option():
    """In the page file (as a code host shows it) and on the built site alike."""
    text = (DOCS / "user-guide" / "commands.md").read_text(encoding="utf-8")
    commands = _parser_commands()
    assert {"check", "import", "export", "kitti", "scenes"} <= set(commands)
    for name, parser in commands.items():
        assert f"### soabench {name}\n" in text and f"usage: soabench {name}" in text, name
        section = text.split(f"### soabench {name}\n", 1)[1].split("\n### soabench ", 1)[0]
        for action in parser._actions:
            for option in action.option_strings:
                assert re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", section), f"{name} {option}"
            for choice in (action.choices or ()) if not action.option_strings else ():
                assert choice in section, f"{name} {choice}"
        assert f"`soabench {name}" in text.split("## What every command shares", 1)[0], f"{name} not in the table"


def test_command_help_is_generated(site):
    html = _text(site / "user-guide/commands/index.html")
    for cmd in _parser_commands():
        assert f"usage: soabench {cmd}" in html, cmd


def test_scenes_page_says_what_a_user_network_gets():
    """The pedestrian model and world box a .net.xml without a scenario gets are the ones scenes.md states."""
    from soabench.scenario import derive, load, shipped_nets

    assert "intersection" in shipped_nets()
    net = next((ROOT / "sumo_nets" / "intersection").glob("*.net.xml"))
    _, cfg = load(str(net), quiet=True)
    text = (DOCS / "user-guide" / "scenes.md").read_text(encoding="utf-8")
    row = next(ln for ln in text.splitlines() if ln.startswith("| a `.net.xml` without `--scenario`"))
    assert f"`{cfg.pedestrian_model}`" in row
    box = text.split("* **world box**", 1)[1].split("\n* ", 1)[0]
    assert f"plus {derive.BOX_MARGIN:g} m on every side" in box and f"grown by {derive.NET_PAD:g} m" in box


def test_pages_cited_in_the_code_exist():
    bad = []
    for path in [*ROOT.glob("soabench/**/*.py"), *ROOT.glob("baselines/*.py"), ROOT / "README.md"]:
        for page in re.findall(r"docs/((?:user-guide/)?[\w-]+\.md)", path.read_text(encoding="utf-8")):
            if not (DOCS / page).is_file():
                bad.append(f"{path.relative_to(ROOT)}: docs/{page}")
    assert not bad, f"citations of docs pages that do not exist: {bad}"


def test_no_page_includes_the_readme():
    for page in DOCS.rglob("*.md"):
        assert "soabench:readme" not in page.read_text(encoding="utf-8"), page


def test_outputs_page_names_every_csv_column():
    text = (DOCS / "user-guide" / "outputs.md").read_text(encoding="utf-8")
    for col in (*TRIAL_COLUMNS, *EPISODE_COLUMNS, *STEP_COLUMNS, *TIMING_COLUMNS):
        assert f"`{col}`" in text, f"column {col!r} is not documented in docs/user-guide/outputs.md"


def _method_ids() -> set[str]:
    return set(re.findall(r'<a id="([\w.-]+)"></a>', (DOCS / "method.md").read_text(encoding="utf-8")))


def test_method_keeps_every_section_and_test_anchor():
    ids = _method_ids()
    for sec in ("s1.2", "s2.6", "s2.12", "s3.0", "s3.1.4", "s3.1.6", "s4.3", "s5.4", "s5.9", "s7"):
        assert sec in ids, sec
    tests = {f"t{n}" for n in range(1, 29)} | {"t19b"}
    assert tests <= ids, sorted(tests - ids)
    assert {f"r{n}" for n in range(1, 30)} <= ids


def test_method_citations_in_the_code_resolve():
    ids = _method_ids()
    cite = re.compile(r"docs/method\.md((?:[ ,;]+§\s?\d+(?:\.\d+)*)*)")
    bad = []
    for path in [ROOT / "README.md", *ROOT.glob("soabench/**/*.py"), *ROOT.glob("baselines/*.py")]:
        for m in cite.finditer(path.read_text(encoding="utf-8")):
            for sec in re.findall(r"§\s?(\d+(?:\.\d+)*)", m.group(1)):
                if f"s{sec}" not in ids:
                    bad.append(f"{path.relative_to(ROOT)}: §{sec}")
    assert not bad, f"citations of sections that docs/method.md does not have: {bad}"


def test_result_pages_show_the_committed_reports(site):
    """Each result set's page shows its report's tables on the site; the page file holds a sentence and a link."""
    hooks = _hooks()
    reports = hooks._included_reports()
    assert set(reports) >= {"results/README.md", "results/intersection/comparison.md", "results/scenes/summary.md"}
    for report, page in reports.items():
        raw = (DOCS / page).read_text(encoding="utf-8")
        assert f"](../../{report})" in raw, page  # on a code host: one click to the report
        table = next(ln for ln in (ROOT / report).read_text(encoding="utf-8").splitlines() if ln.startswith("| "))
        first_cell = table.split("|")[1].strip().replace("`", "")
        html = _text(site / Path(page).with_suffix("") / "index.html")
        assert "<table>" in html and first_cell.split()[0] in html, page
    assert (site / "results/intersection/key_figure.png").is_file()  # a linked repository image is served


def test_a_link_out_of_docs_must_name_a_repository_file():
    hooks = _hooks()
    ok = "see [the suite](../../examples/check/suite.toml) and [x](../method.md)"
    assert [path for _m, path in hooks._repository_links(ok, "user-guide/ci.md")] == ["examples/check/suite.toml"]
    with pytest.raises(ValueError, match="not a file of the repository"):
        list(hooks._repository_links("[gone](../../examples/nothing.toml)", "user-guide/ci.md"))
    shown = hooks._site_links(
        "[results/README.md](../../results/README.md) ![f](../../results/intersection/key_figure.png)", "a/b.md"
    )
    assert shown == "`results/README.md` ![f](../results/intersection/key_figure.png)"  # a path; the served copy


def test_ci_page_documents_every_suite_key_with_its_default():
    """The suite format of docs/user-guide/ci.md names exactly the keys soabench/experiment/campaigns/check.py reads."""
    from soabench.experiment.campaigns import check

    text = (DOCS / "user-guide" / "ci.md").read_text(encoding="utf-8")
    sections = {
        "### `[suite]`": (check.SUITE_KEYS, None),
        "### `[[scenario]]`": (check.SCENARIO_KEYS, check.Scenario(name="x", net="y")),
        "### `[[threshold]]`": (check.THRESHOLD_KEYS, check.Threshold(metric="m")),
    }
    for heading, (keys, defaults) in sections.items():
        table = text.split(heading, 1)[1].split("\n#", 1)[0]
        rows = {
            m.group(1): m.group(2) for m in re.finditer(r"^\| `(\w+)`(?:, `\w+`)* \| [^|]+ \| ([^|]+) \|", table, re.M)
        }
        named = set(re.findall(r"^\| `(\w+)`", table, re.M)) | set(re.findall(r"^\| `\w+`, `(\w+)`", table, re.M))
        assert named == set(keys), (heading, sorted(set(keys) ^ named))
        for key in keys & set(rows) if defaults is not None else ():
            value = getattr(defaults, key)
            if isinstance(value, (tuple, list)):
                shown = "[" + ", ".join(f'"{v}"' if isinstance(v, str) else repr(v) for v in value) + "]"
                assert f"`{shown}`" in rows[key], (key, rows[key])
            elif isinstance(value, float) and key != "abs_tol":
                assert f"`{value!r}`" in rows[key], (key, rows[key])
