"""The sampler registry: `--sampler NAME` -> class; a stored run's `sampler` dict -> sampler."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from spinefarm.coordinator.samplers.base import BaseSampler
from spinefarm.coordinator.samplers.cmaes_sampler import CmaEsSampler
from spinefarm.coordinator.samplers.hill_climb import GaussianHillClimbSampler
from spinefarm.coordinator.samplers.random import RandomSampler
from spinefarm.coordinator.samplers.tpe import TpeSampler
from spinefarm.protocol.errors import ConfigError

SAMPLERS: dict[str, type[BaseSampler]] = {
    "paper": GaussianHillClimbSampler,   # the paper's Monte Carlo then sigma = 0.005 hill climbing
    "cmaes": CmaEsSampler,
    "tpe": TpeSampler,
    "random": RandomSampler,
}
DEFAULT_SAMPLER = "cmaes"  # bench/samplers.py: fewest trials to 80 % of the paper's speed on both spines


def sampler_class(name: str) -> type[BaseSampler]:
    try:
        return SAMPLERS[name]
    except KeyError:
        raise ConfigError("unknown sampler", received=name, expected=", ".join(sorted(SAMPLERS))) from None


def make_sampler(name: str, n_params: int, seed: int, *, budget: int, objective: str, sigma: float | None = None,
                 top_k: int = 1, startup_trials: int | None = None, start: Sequence[float] | None = None
                 ) -> BaseSampler:
    """A new run's sampler from the search settings. sigma: the paper sampler's step or CMA-ES's sigma0 (None:
    each one's default); top_k and startup_trials: the paper's (startup_trials also TPE's); start: the first
    enqueued parameter set, where CMA-ES centres its first distribution."""
    cls = sampler_class(name)
    if sigma is not None and cls not in (GaussianHillClimbSampler, CmaEsSampler):
        raise ConfigError(f"--sigma does not apply to the {name} sampler", received=sigma,
                          expected="no --sigma, or --sampler paper or cmaes")
    if cls is GaussianHillClimbSampler:
        startup = budget // 2 if startup_trials is None else startup_trials
        return GaussianHillClimbSampler(n_params, seed, **_given("sigma", sigma), top_k=top_k, startup_trials=startup)
    if cls is TpeSampler:
        return TpeSampler(n_params, seed, startup_trials=10 if startup_trials is None else startup_trials,
                          multi_objective=objective == "pareto")
    if cls is CmaEsSampler:
        return CmaEsSampler(n_params, seed, **_given("sigma0", sigma), mean0=start)
    return cls(n_params, seed)


def _given(keyword: str, value: float | None) -> dict[str, float]:
    """`keyword=value` when a value was given; none given: the sampler's own default."""
    return {} if value is None else {keyword: value}


def sampler_from_dict(d: dict[str, Any], n_params: int) -> BaseSampler:
    """Rebuild a sampler from its describe() output (used on resume; older files carry only `kind`)."""
    name = d.get("name")
    if name is None:
        name = next((n for n, c in SAMPLERS.items() if c.__name__ == d.get("kind")), d.get("kind"))
    return sampler_class(str(name)).from_dict(d, n_params)
