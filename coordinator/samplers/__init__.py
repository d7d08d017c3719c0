"""Samplers work in the unit cube of a run's ParamSpace."""

from coordinator.samplers.base import GAUSSIAN, MONTE_CARLO, BaseSampler, Proposal
from coordinator.samplers.hill_climb import GaussianHillClimbSampler
from coordinator.samplers.random import RandomSampler

__all__ = ["GAUSSIAN", "MONTE_CARLO", "BaseSampler", "GaussianHillClimbSampler", "Proposal", "RandomSampler"]


def sampler_from_dict(d: dict, n_params: int) -> BaseSampler:
    """Rebuild a sampler from its describe() output (used on resume)."""
    kind = d.get("kind")
    if kind == "RandomSampler":
        return RandomSampler(n_params, int(d["seed"]))
    if kind == "GaussianHillClimbSampler":
        return GaussianHillClimbSampler(n_params, int(d["seed"]), sigma=float(d["sigma"]),
                                        top_k=int(d["top_k"]), startup_trials=int(d["startup_trials"]))
    from protocol.errors import ConfigError

    raise ConfigError("unknown sampler kind", received=kind,
                      expected="RandomSampler or GaussianHillClimbSampler")
