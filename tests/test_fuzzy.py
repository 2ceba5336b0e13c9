"""The vectorised Mamdani engine against scikit-fuzzy's reference control system."""

import numpy as np
import pytest
import skfuzzy
from skfuzzy import control

from engine.fuzzy import Rule, RuleBase, Term, Variable
from engine.knowledge import load_knowledge


def three_label_base():
    def variable(name, lo, hi, points, default=None):
        return Variable(name, (lo, hi), {label: Term(label, p) for label, p in points.items()}, default)

    p = variable(
        "p", 1.0, 2.0, {"SMALL": (1, 1, 1.05, 1.15), "MEDIUM": (1.05, 1.15, 1.25, 1.4), "LARGE": (1.25, 1.4, 2, 2)}
    )
    q = variable(
        "q",
        0.0,
        1.0,
        {"SMALL": (0, 0, 0.1, 0.3), "MEDIUM": (0.1, 0.3, 0.5, 0.7), "LARGE": (0.5, 0.7, 1, 1)},
        default=0.0,
    )
    rules = [Rule(f"r-{t}", (("p", t),), (("q", t),)) for t in ("SMALL", "MEDIUM", "LARGE")]
    return RuleBase("test", {"p": p}, {"q": q}, rules, resolution=1001)


def reference(base, values):
    p = control.Antecedent(np.linspace(1, 2, 1001), "p")
    q = control.Consequent(np.linspace(0, 1, 1001), "q")
    for antecedent, var in ((p, base.inputs["p"]), (q, base.outputs["q"])):
        for label, term in var.terms.items():
            antecedent[label] = skfuzzy.trapmf(antecedent.universe, np.array(term.points))
    system = control.ControlSystemSimulation(
        control.ControlSystem([control.Rule(p[t], q[t]) for t in ("SMALL", "MEDIUM", "LARGE")])
    )
    out = []
    for v in values:
        system.input["p"] = v
        system.compute()
        out.append(system.output["q"])
    return np.array(out)


def test_centroid_matches_scikit_fuzzy_control():
    base = three_label_base()
    values = np.array([1.0, 1.02, 1.1, 1.2, 1.3, 1.45, 1.7, 2.0])
    ours = base.evaluate({"p": values})[0]["q"]
    assert ours == pytest.approx(reference(base, values), abs=2e-3)


def test_firing_degrees_are_the_term_memberships():
    base = three_label_base()
    _, firing = base.evaluate({"p": np.array([1.0, 1.1, 1.3, 1.9])})
    assert firing == pytest.approx(np.array([[1, 0, 0], [0.5, 0.5, 0], [0, 2 / 3, 1 / 3], [0, 0, 1]]))


def test_inputs_outside_the_universe_are_clipped():
    base = three_label_base()
    out = base.evaluate({"p": np.array([0.2, 1.0, 7.0, 2.0])})[0]["q"]
    assert out[0] == out[1] and out[2] == out[3]


def test_and_takes_the_minimum_of_the_clauses():
    lo = Term("LO", (0, 0, 0.2, 0.6))
    hi = Term("HI", (0.4, 0.8, 1, 1))
    a = Variable("a", (0, 1), {"LO": lo, "HI": hi})
    b = Variable("b", (0, 1), {"LO": lo, "HI": hi})
    out = Variable("o", (0, 1), {"LO": lo, "HI": hi}, default=0.5)
    base = RuleBase(
        "and",
        {"a": a, "b": b},
        {"o": out},
        [
            Rule("both-high", (("a", "HI"), ("b", "HI")), (("o", "HI"),)),
            Rule("any-low", (("a", "LO"),), (("o", "LO"),)),
        ],
    )
    _, firing = base.evaluate({"a": np.array([0.9, 0.6]), "b": np.array([0.5, 1.0])})
    assert firing[:, 0] == pytest.approx([0.25, 0.5])


def test_shipped_population_rules_order_the_priorities():
    kb = load_knowledge()
    delete = kb.rulebases["population.delete"]
    overlap = np.linspace(0.8, 3.5, 200)
    q = delete.evaluate({"overlap": overlap})[0]["q"]
    assert np.all(np.diff(q) >= -1e-9), "more overlap never lowers the deletion priority"
    threshold = delete.extra["action"]["threshold"]
    assert q[overlap <= 1.05].max() < threshold < q[overlap >= 1.6].min()
    insert = kb.rulebases["population.insert"]
    vacancy = np.linspace(1, 6, 100)
    qi = insert.evaluate({"vacancy": vacancy})[0]["q"]
    assert np.all(np.diff(qi) >= -1e-9)
    assert qi[0] < insert.extra["action"]["threshold"] < qi[-1]
