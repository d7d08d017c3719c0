"""Every stored quantity is one line of protocol/columns.toml: a score part added there reaches the trial's and
the episode's result, their messages and both tables of the run file, with no other edit."""

import json
import subprocess
import sys
import textwrap

# Run in a fresh interpreter whose columns.toml reader adds one score part before spinefarm reads it.
_ADDED_PART = textwrap.dedent("""
    import json, tomllib
    loads = tomllib.loads
    def with_a_new_part(text):
        catalogue = loads(text)
        catalogue["score"]["peak_tension_n"] = ["f8", "N", "largest string tension of the trial"]
        return catalogue
    tomllib.loads = with_a_new_part

    from dataclasses import fields
    from spinefarm.protocol.results import TrialResult
    from spinefarm.protocol.robust import EpisodeResult
    from spinefarm.storage.episodes import EPISODE_COLUMNS
    from spinefarm.storage.schema import COLUMNS

    failed = TrialResult.failed("error: x", seed=3)
    message = failed.to_dict()
    print(json.dumps({
        "trial_fields": [f.name for f in fields(TrialResult)],
        "episode_fields": [f.name for f in fields(EpisodeResult)],
        "trial_columns": [c.name for c in COLUMNS],
        "episode_columns": [c.name for c in EPISODE_COLUMNS],
        "message": sorted(message),
        "round_trip": TrialResult.from_dict(json.loads(json.dumps(message))).seed,
    }))
""")


def test_a_score_part_is_one_line_of_the_catalogue() -> None:
    run = subprocess.run([sys.executable, "-c", _ADDED_PART], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    seen = json.loads(run.stdout)
    for where in ("trial_fields", "episode_fields", "trial_columns", "episode_columns", "message"):
        assert "peak_tension_n" in seen[where], where
    assert seen["round_trip"] == 3

