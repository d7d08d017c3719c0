"""The engine registry (spinefarm.robot.engines): names, typed settings and abilities as data, held
against the backends, and checked before a run file is written."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import pytest

from spinefarm.protocol.errors import ConfigError
from spinefarm.robot.engines import ENGINES, check_engine_options, engine_names, engine_spec
from spinefarm.robot.trial_config import TrialConfig
from spinefarm.worker.engines.base import BasePhysics, engine_class

ABILITY_METHODS = {"reset": ("reset",), "velocities": ("velocities", "set_velocity"),
                   "compiled_step": ("compiled_worlds",), "snapshot": ("snapshot", "restore"),
                   "set_state": ("set_state",)}


@pytest.mark.parametrize("name", engine_names())
def test_settings_dataclass_matches_the_registry(name):
    spec = engine_spec(name)
    cls = engine_class(name)
    assert cls.name == name
    declared = {f.name: f.default for f in dataclasses.fields(cls.settings_type)}
    assert declared == {o.name: o.default for o in spec.options}
    cls.settings_from_options(spec.defaults())  # the registry's defaults are valid settings


@pytest.mark.parametrize("name", engine_names())
def test_abilities_are_declared_not_guessed(name):
    spec, cls = engine_spec(name), engine_class(name)
    for ability, methods in ABILITY_METHODS.items():
        overridden = all(getattr(cls, m, None) not in (None, getattr(BasePhysics, m, None)) for m in methods)
        assert overridden == spec.can(ability), (name, ability)


def test_options_are_typed():
    check_engine_options("mujoco", {"segment_contacts": "off", "noslip_iterations": 3, "solimp": [0.9, 0.95, 0.001,
                                                                                                  0.5, 2.0]})
    check_engine_options("bullet", {"friction_anchor": False, "solver_iterations": 20})
    bad = [("mujoco", {"segment_contacts": "maybe"}, "segment_contacts"),
           ("mujoco", {"noslip_iterations": 2.5}, "noslip_iterations"),
           ("mujoco", {"islands": "yes"}, "islands"),
           ("bullet", {"erp": 2.0}, "erp"),
           ("bullet", {"segment_contacts": "off"}, "segment_contacts")]
    for engine, options, name in bad:
        with pytest.raises(ConfigError, match=name):
            check_engine_options(engine, options)
    with pytest.raises(ConfigError, match="unknown engine"):
        TrialConfig(engine="ode")
    with pytest.raises(ConfigError, match="friction_anchr"):
        TrialConfig(engine="bullet", engine_options={"friction_anchr": True})


def test_registry_imports_no_simulator():
    code = "import sys, spinefarm.robot.engines, spinefarm.robot.trial_config; " \
           "print(sorted(m for m in ('pybullet', 'mujoco', 'numba') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    assert set(ENGINES) >= {"bullet", "mujoco"}


@pytest.mark.parametrize("option, named", [("segmnt_contacts=off", "segmnt_contacts"),
                                           ("segment_contacts=maybe", "segment_contacts")])
def test_a_misspelt_option_fails_before_a_run_file_is_written(tmp_path, option, named):
    out = tmp_path / "run.h5"
    done = subprocess.run([sys.executable, "-P", "-m", "spinefarm", "search", "tetraspine", "--engine", "mujoco",
                           "--engine-option", option, "--trials", "2", "--workers", "1", "--out", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and named in lines[0] and "expected one of" in lines[0], done.stderr
    assert "'segment_contacts'" in lines[0] or "'auto', 'scene', 'off'" in lines[0]
    assert list(tmp_path.iterdir()) == []
