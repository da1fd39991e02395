"""Minimal stand-in for report.py (helper C's branch) until it is merged: the contract's
Candidate and DiagnosisReport with summary() and to_dict(); no analyses, no plot."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


def _f(v: Any) -> Any:
    v = float(v)
    return v if np.isfinite(v) else None


@dataclass(frozen=True)
class Candidate:
    effect: str
    gap_closed: float
    p_value: float
    model: Any
    params: dict[str, float]
    n_extra: int
    estimation_rmse: float
    validation_rmse: float
    criterion: float
    signature_removed: bool

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "gap_closed": _f(self.gap_closed),
            "p_value": _f(self.p_value),
            "model": self.model.to_dict(),
            "params": {k: _f(v) for k, v in self.params.items()},
            "n_extra": self.n_extra,
            "estimation_rmse": _f(self.estimation_rmse),
            "validation_rmse": _f(self.validation_rmse),
            "criterion": _f(self.criterion),
            "signature_removed": bool(self.signature_removed),
        }


@dataclass
class DiagnosisReport:
    best_effect: str
    ranking: list[Candidate]
    regimes: Any
    tests: Any
    spectrum: Any
    drift: Any
    noise_std: float
    noise_std_estimated: bool
    nominal_validation_rmse: float
    gap: float
    warmup: int
    u_val: Any
    y_val: Any
    y_nominal: Any
    y_best: Any
    elapsed: float
    details: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> str:
        lines = [
            f"best effect: {self.best_effect}",
            f"nominal validation RMSE {self.nominal_validation_rmse:.4g}, noise std "
            f"{self.noise_std:.4g} ({'estimated' if self.noise_std_estimated else 'given'}), gap (MSE) {self.gap:.3g}",
        ]
        for c in self.ranking:
            lines.append(f"  {c.effect:<18} gap closed {c.gap_closed:6.2f}  p {c.p_value:.2g}  BIC {c.criterion:.1f}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "best_effect": self.best_effect,
            "ranking": [c.to_dict() for c in self.ranking],
            "noise_std": _f(self.noise_std),
            "noise_std_estimated": self.noise_std_estimated,
            "nominal_validation_rmse": _f(self.nominal_validation_rmse),
            "gap": _f(self.gap),
            "warmup": self.warmup,
            "elapsed": self.elapsed,
        }
