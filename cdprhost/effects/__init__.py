"""The effect catalogue (spec/machine-model.md): one module per physical effect.

Adding an effect = one module implementing :class:`cdprhost.effects.base.Effect`
plus one line in :data:`cdprhost.effects.registry.CATALOGUE`.
"""

from cdprhost.effects.base import Effect, MotionContext
from cdprhost.effects.registry import CATALOGUE, EffectChain, get_effect

__all__ = ["CATALOGUE", "Effect", "EffectChain", "MotionContext", "get_effect"]
