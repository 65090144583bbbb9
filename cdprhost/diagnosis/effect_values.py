"""What a fitted effect's parameters say: their values with 95 % intervals, and whether
they are physical (an effect whose fit needs an impossible value is not admissible)."""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import ValidationError

from cdprhost.calibration.fitting import CableModelFit
from cdprhost.effects.registry import CATALOGUE
from cdprhost.jsonsafe import finite_or_none

Z95 = 1.959963984540054


def effect_parameters(fit: CableModelFit, name: str) -> dict[str, Any]:
    """Fitted vector, standard errors, 95% intervals, and the profile table of one effect."""
    effect = CATALOGUE[name]
    vec, sd = fit.effect_vector(name)
    lo, hi = vec - Z95 * sd, vec + Z95 * sd
    table = effect.to_params(vec, sd if np.all(np.isfinite(sd)) else None)
    natural_lo, natural_hi = effect.to_params(lo), effect.to_params(hi)
    ci = {}
    for key in effect.to_params(vec):
        a, b = np.asarray(natural_lo[key], float), np.asarray(natural_hi[key], float)
        ci[key] = interval(np.minimum(a, b), np.maximum(a, b))
    return {
        "vector_names": list(effect.vector_names),
        "vector": vec.tolist(),
        "stderr": sd.tolist(),
        "ci95_vector": np.stack([lo, hi], axis=1).tolist(),
        "table": table,
        "ci95": ci,
    }


def interval(lo: np.ndarray, hi: np.ndarray) -> list[Any]:
    """[lo, hi] (or a list of them); an unbounded end is None."""
    if lo.ndim == 0:
        return [finite_or_none(float(lo)), finite_or_none(float(hi))]
    return [[finite_or_none(a), finite_or_none(b)] for a, b in zip(lo, hi)]


def admissible(fit: CableModelFit, name: str) -> bool:
    """The fitted parameters form a valid profile table (e.g. EA > 0, |eps| < 0.5)."""
    vec, _ = fit.effect_vector(name)
    try:
        CATALOGUE[name].params_model.model_validate(CATALOGUE[name].to_params(vec))
    except (ValidationError, ValueError):
        return False
    return True


def geometry_parameters(fit: CableModelFit) -> dict[str, Any]:
    q, sd = fit.x_[:12], fit.stderr_[:12]
    return {
        "outlets": q[:9].reshape(3, 3).tolist(),
        "initial_lengths": q[9:12].tolist(),
        "stderr": {"outlets": sd[:9].reshape(3, 3).tolist(), "initial_lengths": sd[9:12].tolist()},
    }
