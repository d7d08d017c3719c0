"""The README's one way to run a trial from Python, run as a user would copy it: it gives what the command
line gives for the same gait file, and over its 30 s the figure docs/reproducibility.md quotes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from spinefarm.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def readme_block() -> str:
    text = (ROOT / "README.md").read_text()
    start = text.index("the one way to run a trial from Python")
    return re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)


def run_block(code: str, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    monkeypatch.chdir(ROOT)  # the block opens examples/ by a relative path, as from a clone's root
    capsys.readouterr()
    exec(compile(code, "README.md", "exec"), {"__name__": "__readme__"})
    return capsys.readouterr().out.split()


def test_the_readme_block_gives_what_the_command_line_gives(capsys, monkeypatch):
    block = readme_block()
    assert "duration_s=30.0" in block
    distance_m, speed_cm_s, cot, status = run_block(block.replace("duration_s=30.0", "duration_s=1.5"), capsys,
                                                    monkeypatch)
    assert main(["trial", "tetraspine", "--params", "examples/gaits/tetraspine.json", "--duration", "1.5",
                 "--json"]) == 0
    expected = json.loads(capsys.readouterr().out)
    assert status == "complete"
    assert float(distance_m) == expected["distance_m"] and float(speed_cm_s) == expected["speed_cm_s"]
    assert float(cot) == expected["cot"]
    assert float(distance_m) > 0.01  # 1.5 s of a gait that walks ~10 cm/s: not a robot standing still


@pytest.mark.slow
def test_the_readme_block_prints_the_documented_figure(capsys, monkeypatch):
    quoted = re.search(r"Tetraspine (\d+\.\d+) m", (ROOT / "docs" / "reproducibility.md").read_text()).group(1)
    assert float(run_block(readme_block(), capsys, monkeypatch)[0]) == float(quoted)
