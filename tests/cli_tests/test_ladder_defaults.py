"""The ladders' defaults are the ones docs/performance.md's measured tables name: the default ladder (the
Tetraspine's table) and each built-in's row of the per-robot table, read from the docs, not from the code."""

from __future__ import annotations

import re

from spinefarm.cli.main import build_parser
from spinefarm.cli.run_setup import search_settings
from spinefarm.protocol.settings import JudgePolicy
from spinefarm.robot.morphology.registry import builtin_names, load_ladder
from spinefarm.robot.morphology.specladder import DEFAULT_LADDER
from tests.coordinator_tests.procs import ROOT

PER_ROBOT = "| robot | ladder of a 30 s trial | eta | from |"


def _section() -> str:
    text = (ROOT / "docs" / "performance.md").read_text()
    return text.split("## A ladder chosen by measurement", 1)[1].split("\n## ", 1)[0]


def _per_robot(section: str) -> dict[str, tuple[str, int]]:
    """robot -> (rungs of a 30 s trial as --rungs takes them, eta), one row per group of robots."""
    rows: dict[str, tuple[str, int]] = {}
    for line in section.split(PER_ROBOT, 1)[1].splitlines()[2:]:
        if not line.startswith("|"):
            break
        robots, rungs, eta, _ = (c.strip() for c in line.strip().strip("|").split("|"))
        for name in re.findall(r"`([\w-]+)`", robots):
            rows[name] = (rungs.replace(" ", ""), int(eta))
    return rows


def test_the_default_is_the_one_the_docs_table_names():
    section = _section()
    rungs, eta = re.search(r"\*\*Defaults: `--rungs ([\d.,]+) --eta (\d+)`\*\*", section).groups()
    assert (DEFAULT_LADDER.rungs(30.0), DEFAULT_LADDER.eta) == (rungs, int(eta))  # the table's trial is 30 s long
    for command in (["search", "tetraspine", "--rungs", rungs], ["coordinator", "tetraspine", "--rungs", rungs]):
        args = build_parser().parse_args(command)  # --rungs without --eta: the default eta
        durations = tuple(float(x) for x in rungs.split(","))
        assert search_settings(args, durations, 60.0, JudgePolicy(), None).eta == int(eta)
    assert f"| **{rungs.replace(',', ', ')}** | **{eta}** |" in section  # the row of the table it comes from


def test_each_builtins_ladder_is_the_one_the_per_robot_table_names():
    rows = _per_robot(_section())
    assert set(rows) == set(builtin_names()), sorted(set(rows) ^ set(builtin_names()))
    for name, (rungs, eta) in rows.items():
        ladder = load_ladder(name)
        assert (ladder.rungs(30.0), ladder.eta) == (rungs, eta), name


def test_a_builtins_measured_ladder_names_a_command_the_docs_quote():
    """A built-in's `ladder:` block with a `source` names the bench command of a docs table (the line breaks of
    the docs aside); the tetrahedral complex's is the 27-gait sample's."""
    quoted = " ".join(_section().split())
    measured = {n: load_ladder(n).source for n in builtin_names() if load_ladder(n).source}
    assert set(measured) == {"tetrahedral-complex"}
    for name, command in measured.items():
        assert command.startswith("python bench/ladder.py") and f"`{command} --jobs 2`" in quoted, name
