"""The search over constants: CMA-ES (the `cmaes` package) in the unit cube, mapped to each constant's bounds
(log-spaced when the bounds are positive), from a few starts; the loss is the window error of worker.fit.loss.

A restart's best is kept; the spread over restarts says how well the recordings pin each constant down.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from spinefarm.protocol.errors import ParameterError
from spinefarm.robot.profile import constant


@dataclass(frozen=True)
class Bound:
    """A fitted constant: name (robot.profile), its bounds [low, high] (within its plausible range)."""

    name: str
    low: float
    high: float

    @property
    def log(self) -> bool:
        return self.low > 0.0

    def value(self, u: float) -> float:
        u = min(max(float(u), 0.0), 1.0)
        if self.log:
            return math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        return self.low + u * (self.high - self.low)

    def unit(self, value: float) -> float:
        if self.log:
            u = (math.log(value) - math.log(self.low)) / (math.log(self.high) - math.log(self.low))
        else:
            u = (value - self.low) / (self.high - self.low)
        return min(max(u, 0.0), 1.0)


def parse_fit(text: str) -> list[Bound]:
    """`NAME[=LO:HI],...` -> bounds; without LO:HI the plausible range; bounds outside it refused."""
    out = []
    for item in (s.strip() for s in text.split(",") if s.strip()):
        name, _, rng = item.partition("=")
        c, _ = constant(name)
        lo, hi = c.low, c.high
        if rng:
            try:
                lo, hi = (float(x) for x in rng.split(":"))
            except ValueError as exc:
                raise ParameterError(f"--fit {name}: bounds are not LO:HI", received=rng,
                                     expected="two numbers, e.g. 0.2:1.2") from exc
        if not c.low <= lo < hi <= c.high:
            raise ParameterError(f"--fit {name}: bounds outside its plausible range", received=f"{lo:g}:{hi:g}",
                                 expected=f"LO < HI within [{c.low:g}, {c.high:g}] ({c.source})")
        out.append(Bound(name, lo, hi))
    if not out or len({b.name for b in out}) != len(out):
        raise ParameterError("--fit names no constant or one twice", received=text, expected="NAME[=LO:HI],...")
    return out


@dataclass
class SearchResult:
    """values: the best restart's {name: value}; loss its loss; restarts: each restart's (loss, values);
    evaluations: how many losses were computed."""

    values: dict[str, float]
    loss: float
    restarts: list[tuple[float, dict[str, float]]] = field(default_factory=list)
    evaluations: int = 0

    def spread(self) -> dict[str, dict[str, float]]:
        """Per constant: min, max and relative spread (max - min) / best over the restarts."""
        out = {}
        for name, best in self.values.items():
            vals = [v[name] for _, v in self.restarts]
            out[name] = {"min": min(vals), "max": max(vals),
                         "rel_spread": (max(vals) - min(vals)) / abs(best) if best else math.inf}
        return out


def minimise(losses: Callable[[list[dict[str, float]]], Sequence[float]], bounds: Sequence[Bound],
             start: Mapping[str, float], restarts: int = 3, evaluations: int = 120, seed: int = 0,
             progress: Callable[[int, int], None] | None = None) -> SearchResult:
    """CMA-ES restarts of `evaluations` losses each: the first from `start`, the others from seeded random points;
    `losses` takes a whole generation's candidates at once (the seam where they may be evaluated in parallel,
    in processes or on workers) and returns their losses in order; `progress(done, total)` after each loss."""
    from cmaes import CMA

    rng = np.random.default_rng(seed)
    results, count = [], 0
    for r in range(restarts):
        x0 = np.array([b.unit(start[b.name]) for b in bounds]) if r == 0 else rng.uniform(0.1, 0.9, len(bounds))
        opt = CMA(mean=x0, sigma=0.25, bounds=np.array([[0.0, 1.0]] * len(bounds)), seed=seed + r,
                  population_size=max(6, 4 + int(3 * math.log(len(bounds)))))
        best = (math.inf, x0)
        while count < evaluations * (r + 1):
            xs = [opt.ask() for _ in range(opt.population_size)]
            values = losses([{b.name: b.value(u) for b, u in zip(bounds, x, strict=True)} for x in xs])
            told = []
            for x, value in zip(xs, values, strict=True):
                count += 1
                if progress is not None:
                    progress(min(count, evaluations * restarts), evaluations * restarts)
                told.append((x, value if math.isfinite(value) else 1e9))
                if value < best[0]:
                    best = (value, x)
            opt.tell(told)
        results.append((best[0], {b.name: b.value(u) for b, u in zip(bounds, best[1], strict=True)}))
    loss_best, values = min(results, key=lambda r: r[0])
    return SearchResult(values, loss_best, results, count)
