"""The ladder: the one concept that decides every evaluation of a run, from its stored rows alone.

rungs.py: the screen's rungs (which stored set is promoted to the next rung, what a sampler reads, when the
search is done); checks.py: the evaluations beside them (the judge of a new best, its perturbed run, audits,
referees, the second engine's opinion), each stored as an evaluation row; keys.py: how those are leased;
ladder.py: Ladder, the seam the coordinator's core asks what to run next, on which worker, at which fidelity,
and tells each result.
"""
