"""The ladder's defaults are the ones docs/performance.md's measured table names."""

from __future__ import annotations

import re

from spinefarm.cli.engine_auto import default_rungs
from spinefarm.cli.main import build_parser
from tests.coordinator_tests.procs import ROOT


def test_the_defaults_are_the_ones_the_docs_table_names():
    text = (ROOT / "docs" / "performance.md").read_text()
    section = text.split("## A ladder chosen by measurement", 1)[1].split("\n## ", 1)[0]
    rungs, eta = re.search(r"\*\*Defaults: `--rungs ([\d.,]+) --eta (\d+)`\*\*", section).groups()
    assert default_rungs(30.0) == rungs  # the table's trial is 30 s long
    for command in (["search", "tetraspine"], ["coordinator", "tetraspine"]):
        assert build_parser().parse_args(command).eta == int(eta)
    assert f"| **{rungs.replace(',', ', ')}** | **{eta}** |" in section  # the row of the table it comes from
