"""Number fields of the scene and controller models: a boolean or a text is not a number.

pydantic's lax mode reads ``True`` as 1.0 and ``"2.5"`` as 2.5, so YAML's ``current: on`` (a boolean in
YAML 1.1) was silently 1 A. These types refuse both with one clear message and otherwise validate as
``float`` / ``int`` (an ``int`` field still takes an integral float such as ``10.0``). Scene files write
``2.5e7`` and ``1e-3``: the scene loader reads them as numbers (YAML 1.2 floats,
:mod:`gyro_sim.scene_text`), not as texts to be coerced.
"""
from __future__ import annotations

from typing import Annotated, Any

from pydantic import BeforeValidator, Field

__all__ = ["BOOLEAN_IS_NOT_A_NUMBER", "TEXT_IS_NOT_A_NUMBER", "real", "count", "Finite", "Positive", "NonNegative"]

BOOLEAN_IS_NOT_A_NUMBER = ("a boolean is not a number (YAML reads true/false, yes/no, on/off as booleans); "
                           "give a number")
TEXT_IS_NOT_A_NUMBER = "a text is not a number (quotes make a text); give a number such as 2.5e7 or 0.001"


def _number(value: Any) -> Any:
    """``value`` unchanged unless it is a boolean or a text: then a ValueError (its message does not quote the
    value: the scene's error formatter does, previewed)."""
    if isinstance(value, bool) or type(value).__name__ == "bool_":  # numpy.bool_ without importing numpy
        raise ValueError(BOOLEAN_IS_NOT_A_NUMBER)
    if isinstance(value, (str, bytes, bytearray)):
        raise ValueError(TEXT_IS_NOT_A_NUMBER)
    return value


def real(**constraints: Any) -> Any:
    """A finite float field (NaN and ±inf refused) with pydantic ``Field`` constraints (``gt``, ``ge``, ``lt``,
    ``le``); no bool, no text."""
    return Annotated[float, BeforeValidator(_number), Field(allow_inf_nan=False, **constraints)]


def count(**constraints: Any) -> Any:
    """An int field with pydantic ``Field`` constraints; no bool, no text (an integral float is taken)."""
    return Annotated[int, BeforeValidator(_number), Field(**constraints)]


Finite = real()
Positive = real(gt=0)
NonNegative = real(ge=0)
