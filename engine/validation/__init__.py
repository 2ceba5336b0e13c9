"""FE validation: linear elasticity solved on fuzzymesh meshes, compared with published solutions.

Cases (``fuzzymesh validate NAME``): ``plate-hole`` (Peterson's stress concentration factor of a
finite-width plate with a central hole in tension, meshed by the ``static-stress`` recipe) and
``sphere`` (Lamé's thick hollow sphere under internal pressure, an octant with symmetry conditions).
See docs/validation.md. Needs the optional ``fe`` extra (scikit-fem, pyamg); the core never imports it.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

from ..errors import FuzzymeshError
from ..plugins import ValidationCase
from ..registry import Registry

# each case's module imports the 'fe' extra, so it is named here and imported when the case is run
CASES = Registry(
    None,
    [],
    ValidationCase,
    noun="validation case",
    lazy={"plate-hole": f"{__name__}.plate_hole:run", "sphere": f"{__name__}.sphere:run"},
)
EXTRA = ("skfem", "pyamg")  # modules of the 'fe' extra: scikit-fem, pyamg


def require_fe() -> None:
    """Raise a one-line FuzzymeshError naming the fix when the 'fe' extra is not installed."""
    missing = []
    for module in EXTRA:
        try:
            importlib.import_module(module)
        except ImportError:
            missing.append({"skfem": "scikit-fem"}.get(module, module))
    if missing:
        raise FuzzymeshError(
            f"validation needs {' and '.join(missing)} (the optional 'fe' extra), not installed",
            fix="pip install 'fuzzymesh[fe]'",
        )


@dataclass
class Row:
    """One compared quantity: computed value, reference value (None: reported only) and its source."""

    quantity: str
    computed: float
    reference: float | None = None
    source: str = ""

    @property
    def error(self) -> float | None:
        return None if self.reference is None else (self.computed - self.reference) / abs(self.reference)


@dataclass
class CaseResult:
    """What a validation case measured: a title, facts about the model and solve, the compared rows."""

    name: str
    title: str
    facts: dict
    rows: list[Row] = field(default_factory=list)

    def row(self, quantity: str) -> Row:
        return next(r for r in self.rows if r.quantity == quantity)

    def table(self) -> str:
        """The case as text: title, facts, then quantity | computed | reference | error."""
        width = max(len(r.quantity) for r in self.rows)
        lines = [
            self.title,
            "; ".join(f"{k} {_fmt(v)}" for k, v in self.facts.items()),
            "",
            f"{'quantity':{width}s}  {'computed':>11s}  {'reference':>11s}  {'error':>8s}  source",
        ]
        for r in self.rows:
            reference = "-" if r.reference is None else f"{r.reference:11.5g}"
            error = "-" if r.error is None else f"{100 * r.error:+7.2f}%"
            lines.append(f"{r.quantity:{width}s}  {r.computed:11.5g}  {reference:>11s}  {error:>8s}  {r.source}")
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "title": self.title,
            "facts": self.facts,
            "rows": [
                {
                    "quantity": r.quantity,
                    "computed": r.computed,
                    "reference": r.reference,
                    "error": r.error,
                    "source": r.source,
                }
                for r in self.rows
            ],
        }


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    if isinstance(value, int):
        return f"{value:,}"
    return str(value)


def run_case(name: str, scale: float = 1.0, seed: int = 0) -> CaseResult:
    """Mesh, solve and compare case ``name`` (a key of CASES); ``scale`` multiplies every target size."""
    if name not in CASES:
        raise FuzzymeshError(f"no validation case named '{name}'", fix=f"known cases: {', '.join(CASES)}")
    require_fe()
    return CASES.get(name)(scale=scale, seed=seed)


__all__ = ["CASES", "CaseResult", "Row", "require_fe", "run_case"]
