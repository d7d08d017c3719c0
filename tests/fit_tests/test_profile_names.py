"""Profiles by name: `--profile NAME` finds a built-in profile (spinefarm/robot/profiles/NAME.yaml, shipped in the
wheel) as `--profile FILE` finds a user's file, with the same constants; a user's file of that name wins; a name
that is neither is refused in one line naming the built-ins."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import yaml

from spinefarm.cli.main import main
from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.profile import PROFILES_DIR, builtin_profiles, load_profile, profile_path

ROOT = Path(__file__).resolve().parents[2]
MINE = "robot: tetraspine-ntrt\nconstants:\n  ground_friction: 0.7\n  string_damping_n_s_per_m: 12\n"


def test_a_name_finds_the_file_in_the_profiles_folder(tmp_path):
    (tmp_path / "fitted-spine.yaml").write_text(MINE)
    assert builtin_profiles(tmp_path) == ["fitted-spine"]
    by_name = load_profile("fitted-spine", tmp_path)
    assert by_name == load_profile(tmp_path / "fitted-spine.yaml", tmp_path)
    assert by_name == {"ground_friction": 0.7, "string_damping_n_s_per_m": 12.0}


def test_a_users_file_wins_over_a_builtin_of_its_name(tmp_path, monkeypatch):
    folder = tmp_path / "builtins"
    folder.mkdir()
    (folder / "fitted-spine").with_suffix(".yaml").write_text(MINE)
    (tmp_path / "fitted-spine").write_text("constants: {ground_friction: 0.3}\n")
    monkeypatch.chdir(tmp_path)
    assert load_profile("fitted-spine", folder) == {"ground_friction": 0.3}
    assert profile_path("fitted-spine", folder) == Path("fitted-spine")


@pytest.mark.parametrize("name", ["no-such-profile", "no-such-profile.yaml", "sub/no-such-profile"])
def test_neither_a_file_nor_a_builtin_refused_naming_the_builtins(tmp_path, name):
    (tmp_path / "fitted-spine.yaml").write_text(MINE)
    with pytest.raises(ConfigError) as err:
        load_profile(name, tmp_path)
    text = str(err.value)
    assert f"received '{name}'" in text and "expected a YAML file's path or one of ['fitted-spine']" in text
    assert "\n" not in text


def test_the_cli_refuses_an_unknown_profile_name_in_one_line(tmp_path, capsys):
    rec = tmp_path / "r.npz"
    assert main(["trial", "tetraspine-ntrt", "--random-seed", "1", "--duration", "0.05", "--record", str(rec),
                 "--profile", "no-such-profile"]) == 2
    err = capsys.readouterr().err.strip()
    assert "no profile file or built-in profile of that name; received 'no-such-profile'" in err
    assert "\n" not in err and not rec.exists()


def test_the_profiles_folder_ships_in_the_wheel():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "profiles/*.yaml" in data["spinefarm.robot"]
    assert PROFILES_DIR == ROOT / "spinefarm" / "robot" / "profiles"


def test_every_shipped_profile_loads_by_name_as_by_its_path():
    """A profile ships only when its fit passed (docs/fitting.md); whichever ship, each is found by its name and
    names the built-in robot it was fitted to."""
    from spinefarm.robot.morphology.registry import load_morphology

    assert PROFILES_DIR.is_dir() and (PROFILES_DIR / "README.md").is_file()
    for name in builtin_profiles():
        path = PROFILES_DIR / f"{name}.yaml"
        assert load_profile(name) == load_profile(path)
        load_morphology(yaml.safe_load(path.read_text())["robot"])
