"""Samplers work in the unit cube of a run's ParamSpace; the registry names them for `--sampler`."""

from spinefarm.coordinator.samplers.base import CMAES, GAUSSIAN, MONTE_CARLO, TPE, BaseSampler, Proposal
from spinefarm.coordinator.samplers.cmaes_sampler import CmaEsSampler
from spinefarm.coordinator.samplers.hill_climb import GaussianHillClimbSampler
from spinefarm.coordinator.samplers.random import RandomSampler
from spinefarm.coordinator.samplers.registry import (
           DEFAULT_SAMPLER,
           SAMPLERS,
           make_sampler,
           sampler_class,
           sampler_from_dict,
)
from spinefarm.coordinator.samplers.tpe import TpeSampler

__all__ = ["CMAES", "DEFAULT_SAMPLER", "GAUSSIAN", "MONTE_CARLO", "SAMPLERS", "TPE", "BaseSampler",
           "CmaEsSampler", "GaussianHillClimbSampler", "Proposal", "RandomSampler", "TpeSampler", "make_sampler",
           "sampler_class", "sampler_from_dict"]
