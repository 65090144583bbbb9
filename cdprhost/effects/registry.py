"""The effect catalogue: names -> effect objects, and the model chain over them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import ValidationError

from cdprhost.effects.backlash import Backlash
from cdprhost.effects.base import Effect, MotionContext
from cdprhost.effects.cable_elasticity import CableElasticity
from cdprhost.effects.drift import Drift
from cdprhost.effects.drive_scale import DriveScale

#: Catalogue order is also the order slider effects are applied in prediction.
CATALOGUE: dict[str, Effect] = {
    e.name: e for e in (DriveScale(), Backlash(), Drift(), CableElasticity())
}


def get_effect(name: str) -> Effect:
    try:
        return CATALOGUE[name]
    except KeyError:
        raise KeyError(f"unknown effect '{name}' (known: {', '.join(CATALOGUE)})") from None


def validate_effects(tables: Mapping[str, Mapping[str, Any]]) -> None:
    """Raise ValueError naming effects.<name>.<key> for any problem."""
    problems: list[str] = []
    for name, table in tables.items():
        if name not in CATALOGUE:
            problems.append(f"effects.{name}: unknown effect (known: {', '.join(CATALOGUE)})")
            continue
        try:
            CATALOGUE[name].params_model.model_validate(dict(table))
        except ValidationError as exc:
            for err in exc.errors():
                loc = ".".join(str(p) for p in err["loc"])
                problems.append(f"effects.{name}.{loc}: {err['msg']}")
    if problems:
        raise ValueError("; ".join(problems))


@dataclass(frozen=True)
class EffectChain:
    """An ordered set of active effects with their parameter vectors."""

    effects: tuple[Effect, ...] = ()
    vectors: tuple[np.ndarray, ...] = field(default=())

    @classmethod
    def from_tables(cls, tables: Mapping[str, Mapping[str, Any]]) -> EffectChain:
        names = [n for n in CATALOGUE if n in tables]
        return cls(
            tuple(CATALOGUE[n] for n in names),
            tuple(CATALOGUE[n].parse(dict(tables[n])) for n in names),
        )

    @classmethod
    def from_vectors(cls, names: Sequence[str], vectors: Sequence[np.ndarray]) -> EffectChain:
        order = sorted(range(len(names)), key=lambda i: list(CATALOGUE).index(names[i]))
        return cls(
            tuple(CATALOGUE[names[i]] for i in order),
            tuple(np.asarray(vectors[i], float) for i in order),
        )

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @property
    def has_cable_stage(self) -> bool:
        return any(e.stage == "cable" for e in self.effects)

    def slider_forward(self, s_cmd: np.ndarray, ctx: MotionContext) -> np.ndarray:
        for effect, vec in zip(self.effects, self.vectors):
            if effect.stage == "slider":
                s_cmd = effect.apply(s_cmd, vec, ctx)
        return s_cmd

    def slider_inverse(self, s_act: np.ndarray, ctx: MotionContext) -> np.ndarray:
        for effect, vec in reversed(tuple(zip(self.effects, self.vectors))):
            if effect.stage == "slider":
                s_act = effect.invert(s_act, vec, ctx)
        return s_act

    def stretch(self, u: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        for effect, vec in zip(self.effects, self.vectors):
            if effect.stage == "cable":
                u = effect.stretch(u, tensions, vec)
        return u

    def unstretch(self, length: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        for effect, vec in reversed(tuple(zip(self.effects, self.vectors))):
            if effect.stage == "cable":
                length = effect.unstretch(length, tensions, vec)
        return length

    def to_tables(
        self, stderrs: Sequence[np.ndarray | None] | None = None
    ) -> dict[str, dict[str, Any]]:
        stderrs = stderrs or [None] * len(self.effects)
        return {e.name: e.to_params(v, s) for e, v, s in zip(self.effects, self.vectors, stderrs)}


__all__ = ["CATALOGUE", "EffectChain", "MotionContext", "get_effect", "validate_effects"]
