"""Vectorised Mamdani inference: min for AND and implication, max aggregation, centroid.

Terms are trapezoids (a, b, c, d) — triangles and shoulders are trapezoids
with b = c, a = b or c = d — evaluated with scikit-fuzzy's ``trapmf``. Inputs
are clipped to their variable's universe. A rule base evaluates arrays of any
length at once and returns every rule's firing degree per input, so callers
can log which rule acted and how strongly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import skfuzzy

from ._numba import numba


@dataclass(frozen=True)
class Term:
    name: str
    points: tuple[float, float, float, float]  # trapezoid a <= b <= c <= d

    def membership(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return skfuzzy.trapmf(x.ravel(), np.asarray(self.points)).reshape(x.shape)


@dataclass(frozen=True)
class Variable:
    name: str
    universe: tuple[float, float]
    terms: dict[str, Term]
    default: float | None = None  # outputs only: the value when no rule fires

    def clip(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.asarray(x, dtype=float), *self.universe)


@dataclass(frozen=True)
class Rule:
    id: str
    conditions: tuple[tuple[str, str], ...]  # (input variable, term), joined by AND
    conclusions: tuple[tuple[str, str], ...]  # (output variable, term)
    source: str = ""  # file:line


@dataclass
class RuleBase:
    id: str
    inputs: dict[str, Variable]
    outputs: dict[str, Variable]
    rules: list[Rule]
    resolution: int = 101  # samples of each output universe for the centroid
    source: str = ""
    extra: dict = field(default_factory=dict)  # other sections of the file (e.g. actions)

    def firing(self, inputs: dict[str, np.ndarray]) -> np.ndarray:
        """Firing degree (n, rules) of every rule for every input row."""
        missing = set(self.inputs) - set(inputs)
        if missing:
            raise ValueError(f"rule base '{self.id}' needs inputs {sorted(missing)}")
        values = {name: var.clip(inputs[name]).ravel() for name, var in self.inputs.items()}
        n = len(next(iter(values.values())))
        cache: dict = {}
        degrees = np.ones((n, len(self.rules)))
        for r, rule in enumerate(self.rules):
            for var, term in rule.conditions:
                if (var, term) not in cache:
                    cache[var, term] = self.inputs[var].terms[term].membership(values[var])
                np.minimum(degrees[:, r], cache[var, term], out=degrees[:, r])
        return degrees

    def evaluate(self, inputs: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Crisp outputs (centroid) and firing degrees (n, rules)."""
        degrees = self.firing(inputs)
        outputs = {name: self._defuzzify(var, degrees) for name, var in self.outputs.items()}
        return outputs, degrees

    def _defuzzify(self, var: Variable, degrees: np.ndarray) -> np.ndarray:
        # rules concluding the same term combine by max before clipping that term
        terms = sorted({t for rule in self.rules for v, t in rule.conclusions if v == var.name})
        strength = np.zeros((len(degrees), len(terms)))
        for r, rule in enumerate(self.rules):
            for v, t in rule.conclusions:
                if v == var.name:
                    k = terms.index(t)
                    np.maximum(strength[:, k], degrees[:, r], out=strength[:, k])
        x = np.linspace(*var.universe, self.resolution)
        shapes = np.array([var.terms[t].membership(x) for t in terms]).reshape(len(terms), len(x))
        return _centroid(strength, shapes, x, float(var.default))


@numba.njit(parallel=True, cache=True)
def _centroid(strength, shapes, x, default):
    """Centroid of max_t min(strength[i, t], shapes[t, :]) sampled at x, for every row i."""
    n, count = strength.shape
    out = np.empty(n)
    for i in numba.prange(n):
        first = 0.0
        area = 0.0
        for k in range(x.shape[0]):
            mu = 0.0
            for t in range(count):
                mu = max(mu, min(strength[i, t], shapes[t, k]))
            first += mu * x[k]
            area += mu
        out[i] = first / area if area > 0 else default
    return out
