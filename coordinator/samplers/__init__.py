"""Samplers work in the unit cube of a run's ParamSpace; the registry names them for `--sampler`."""

from coordinator.samplers.base import CMAES, GAUSSIAN, MONTE_CARLO, TPE, BaseSampler, Proposal
from coordinator.samplers.cmaes_sampler import CmaEsSampler
from coordinator.samplers.hill_climb import GaussianHillClimbSampler
from coordinator.samplers.random import RandomSampler
from coordinator.samplers.registry import DEFAULT_SAMPLER, SAMPLERS, make_sampler, sampler_class, sampler_from_dict
from coordinator.samplers.tpe import TpeSampler

__all__ = ["CMAES", "DEFAULT_SAMPLER", "GAUSSIAN", "MONTE_CARLO", "SAMPLERS", "TPE", "BaseSampler",
           "CmaEsSampler", "GaussianHillClimbSampler", "Proposal", "RandomSampler", "TpeSampler", "make_sampler",
           "sampler_class", "sampler_from_dict"]
