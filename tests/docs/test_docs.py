"""The README and the documentation site, checked like code: the README's size and its two
commands, the decision records' form, every command on every page naming real subcommands and
options of `hoh-cosim`, and the pages generated from the code covering all of it."""

from __future__ import annotations

import argparse
import contextlib
import io
import re

import pytest

from hoh_cosim import cli
from hoh_cosim.cosim.clinical import CLINICAL_METRICS
from hoh_cosim.cosim.metric_reference import METRICS
from hoh_cosim.docsite import reference
from hoh_cosim.kinds import KINDS
from hoh_cosim.params import leaves
from tests.docs.commands import DOCS, ROOT, commands, markdown_pages, sh_blocks

README = ROOT / "README.md"
DECISIONS = DOCS / "decisions"


def test_the_readme_is_short_and_starts_with_the_two_fresh_machine_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 200
    first = sh_blocks(README)[0]
    assert first.line == 3, "the README's first block must come right after its title"
    run, test = first.text.splitlines()
    assert run.endswith("hoh-cosim scenarios/circles.yaml")
    assert "pip install ." in run
    assert test.endswith("python -m pytest")
    assert '".[test]"' in test


def test_the_decisions_are_records_of_at_most_80_lines_each_all_in_the_index():
    assert not (DOCS / "decisions.md").exists(), "the notebook is replaced by docs/decisions/"
    records = sorted(DECISIONS.glob("[0-9][0-9][0-9][0-9]-*.md"))
    assert len(records) >= 10
    index = (DECISIONS / "index.md").read_text(encoding="utf-8")
    numbers = []
    for record in records:
        text = record.read_text(encoding="utf-8")
        assert len(text.splitlines()) <= 80, f"{record.name}: {len(text.splitlines())} lines"
        assert re.match(rf"# {record.name[:4]}\. \S", text), f"{record.name}: title"
        assert re.search(r"^- Status: (accepted|superseded by \[\d{4}\])", text, re.M), record.name
        assert f"({record.name})" in index, f"{record.name} is not in the index"
        numbers.append(int(record.name[:4]))
    assert numbers == list(range(1, len(records) + 1)), "numbered 0001, 0002, ... with no gaps"


def _parse(argv: list[str]) -> str | None:
    """None if `hoh-cosim ARGV` parses (argparse alone, nothing run), else argparse's complaint."""
    if argv and not argv[0].startswith("-") and argv[0] not in cli.SUBCOMMANDS:
        argv = ["run", *argv]  # the bare `hoh-cosim SCENARIO.yaml`
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            cli._main_parser().parse_args(argv)
    except SystemExit as exc:
        return None if exc.code == 0 else err.getvalue().strip().splitlines()[-1]
    return None


def _page_commands() -> list[tuple[str, list[str]]]:
    found = []
    for page in markdown_pages():
        for block in sh_blocks(page):
            found += [(block.where, argv) for argv in commands(block) if argv[0] == "hoh-cosim"]
    return found


def test_every_page_shows_hoh_cosim_commands():
    where = {w.split(":")[0] for w, _ in _page_commands()}
    assert "README.md" in where
    assert {f"docs/tutorials/{name}.md" for name in _TUTORIALS} <= where


_TUTORIALS = (
    "first-cosimulation",
    "compare-and-tune",
    "export-fmus",
    "ur5-session",
    "clinical-study",
)


@pytest.mark.parametrize(("where", "argv"), _page_commands(), ids=lambda x: str(x))
def test_each_command_on_a_page_names_real_subcommands_and_options(where, argv):
    problem = _parse(argv[1:])
    assert problem is None, f"{where}: {' '.join(argv)}: {problem}"
    for arg in argv[1:]:  # the repository's own files it names exist
        if re.match(r"^(scenarios|studies)/[\w./-]+\.ya?ml$", arg):
            assert (ROOT / arg).is_file(), f"{where}: {arg} does not exist"


def test_the_parser_check_catches_a_wrong_option_and_a_wrong_subcommand():
    assert _parse(["run", "scenarios/circles.yaml", "--engine", "fmu"]) is None
    assert "unrecognized" in _parse(["run", "scenarios/circles.yaml", "--no-such-option"])
    assert "invalid choice" in _parse(["hw", "rehearsal"])


def _all_parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    return [
        (" ".join(p), parser) for p, parser in reference._walk(cli._main_parser(), ("hoh-cosim",))
    ]


def test_the_command_reference_has_every_command_and_option():
    page = reference.cli_page()
    for name, parser in _all_parsers():
        assert f"## `{name}`" in page
        for action in parser._actions:
            for option in action.option_strings:
                assert option in page, (name, option)


def test_the_parameter_reference_has_every_parameter_of_every_block_with_its_range():
    page = reference.parameters_page()
    for kind in KINDS.values():
        for leaf in leaves(kind.params()):
            row = re.search(
                rf"^\| `{re.escape(leaf.name)}` \|([^\n]*)$",
                page.split(f"## `{kind.name}`")[1],
                re.M,
            )
            assert row, (kind.name, leaf.name)


def test_the_range_probe_reads_the_validation():
    from hoh_cosim.control.admittance import AdmittanceGains

    params = AdmittanceGains()
    by_name = {leaf.name: leaf for leaf in leaves(params)}
    assert reference.accepted_range(params, by_name["slope[1]"]) == "≥ 0"
    assert reference.accepted_range(params, by_name["sigmoid_max_speed[1]"]) == "> 0"
    assert reference.accepted_range(params, by_name["law"]).startswith("one of ")


def test_every_metric_of_the_clinical_set_is_defined():
    assert set(CLINICAL_METRICS) <= set(METRICS)
    page = reference.metrics_page()
    assert all(f"| `{name}` |" in page for name in METRICS)
