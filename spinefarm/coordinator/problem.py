"""What a run optimises: a morphology (or the built-in test objective) turned into a RunConfig.

The test objective "sphere" (or "sphere:N" for N parameters) needs no physics: it scores a vector
in microseconds, so the transport and the coordinator can be tested and benchmarked on their own.
"""

from __future__ import annotations

import re
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from spinefarm.protocol.errors import ConfigError
from spinefarm.protocol.keys import check_run_id
from spinefarm.protocol.params import ParamSpace, ParamSpec
from spinefarm.protocol.robust import RobustSpec
from spinefarm.protocol.run import RunConfig
from spinefarm.robot.spaces import param_space

if TYPE_CHECKING:
    from spinefarm.robot.morphology.model import Morphology

SPHERE = re.compile(r"^sphere(?::(\d{1,3}))?$")


def is_test_objective(morphology: str) -> bool:
    return bool(SPHERE.match(morphology))


def sphere_space(morphology: str) -> ParamSpace:
    m = SPHERE.match(morphology)
    if m is None:
        raise ConfigError("not a test objective", received=morphology, expected="sphere or sphere:N")
    n = int(m.group(1) or 8)
    if not 1 <= n <= 256:
        raise ConfigError("test objective dimension out of range", received=n, expected="1 <= N <= 256")
    return ParamSpace(morphology, tuple(ParamSpec(f"x{i}", -1.0, 1.0, "1") for i in range(n)))


def search_space(morphology: str, controller: str | None = None) -> tuple[ParamSpace, str | None]:
    """The parameter space a run of `morphology` (a built-in, a spec file or sphere[:N]) searches, and the name
    of its controller space (None for the test objective)."""
    if is_test_objective(morphology):
        return sphere_space(morphology), None
    from spinefarm.robot.morphology.registry import load_morphology

    morph = load_morphology(morphology)
    name = controller or morph.controllers[0]
    return param_space(morph, name), name


def build_run_config(run_id: str, morphology: str, *, objective: str = "distance", seed: int = 0,
                     controller: str | None = None, duration_s: float | None = None,
                     trial_overrides: dict[str, Any] | None = None, robust: dict[str, Any] | None = None
                     ) -> RunConfig:
    """Resolve `morphology` (a built-in name, a spec file path, or sphere[:N]) into the run object
    workers fetch. Engine-free: neither a simulator nor a compiler is imported here. robust: RobustSpec.to_dict()
    of a robust run (K randomised episodes per parameter set, protocol.robust)."""
    check_run_id(run_id)
    spec = RobustSpec.from_dict(robust)
    if spec.active:
        if is_test_objective(morphology):
            raise ConfigError("robust scoring needs a robot", received=morphology,
                              expected="a morphology (the test objective has no world to randomise)")
        config = build_run_config(run_id, morphology, objective=objective, seed=seed, controller=controller,
                                  duration_s=duration_s, trial_overrides=trial_overrides)
        return replace(config, robust=spec.to_dict())
    if is_test_objective(morphology):
        space = sphere_space(morphology)
        engine = (trial_overrides or {}).get("engine")  # the test objective ignores it; tasks are routed by it
        return RunConfig(run_id, morphology, {}, None, tuple(space.describe()),
                         {"duration_s": duration_s, **({"engine": engine} if engine else {})}, objective, seed,
                         space_hash=space.space_hash())
    from spinefarm.robot.codesign import with_body_search
    from spinefarm.robot.morphology.registry import load_morphology

    return with_body_search(run_config_for(run_id, load_morphology(morphology), objective=objective, seed=seed,
                                           controller=controller, duration_s=duration_s,
                                           trial_overrides=trial_overrides), morphology)


def run_config_for(run_id: str, morphology: Morphology | dict[str, Any], *, objective: str = "distance",
                   seed: int = 0, controller: str | None = None, duration_s: float | None = None,
                   trial_overrides: dict[str, Any] | None = None) -> RunConfig:
    """The run object of a morphology, or of its to_dict() (e.g. the spec stored in a run file)."""
    from spinefarm.robot.morphology.model import Morphology
    from spinefarm.robot.profile import apply_profile
    from spinefarm.robot.trial_config import TrialConfig

    morph = morphology if isinstance(morphology, Morphology) else Morphology.from_dict(morphology)
    space = param_space(morph, controller)
    tc_dict = TrialConfig().to_dict()
    tc_dict.update(trial_overrides or {})
    if duration_s is not None:
        tc_dict["duration_s"] = duration_s
    trial_config = TrialConfig.from_dict(tc_dict)  # validates the overrides, the engine and its options
    apply_profile(morph, trial_config.profile)  # a profile naming a tag the robot lacks fails here, not in workers
    return RunConfig(run_id, morph.name, morph.to_dict(), controller, tuple(space.describe()),
                     trial_config.to_dict(), objective, seed, spec_hash=morph.spec_hash(),
                     space_hash=space.space_hash(), trial_config_hash=trial_config.config_hash())
