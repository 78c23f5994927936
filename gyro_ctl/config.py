"""Validated parameters of the control laws (the ``controller`` section of a scene, SI units)."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Optional, Union

from pydantic import BaseModel, ConfigDict, Field, model_validator

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SpinupParams(_Strict):
    """Spin-up: ``stator`` driven at field rate = ``target_spin`` (rad/s) with ``current`` (A), optional ramp (A/s)."""

    law: Literal["spinup"] = "spinup"
    stator: str = "z3"
    target_spin: Finite
    current: NonNegative
    ramp: Optional[Positive] = None


class PsiSwitchingParams(_Strict):
    """ψ-switching [K] (3.1): control stators flip their field direction with sign(u_n · e⊥)."""

    law: Literal["psi_switching"] = "psi_switching"
    control_stators: list[str] = ["z1", "z2"]
    spin_stator: str = "z3"
    nu: Finite  # rad/s; > 0 drives θ → 0, < 0 drives θ → π
    control_current: NonNegative
    spin_current: NonNegative
    spin_rate: Finite  # ν0, rad/s
    dead_band: Annotated[float, Field(ge=0, lt=math.pi / 2, allow_inf_nan=False)] = 1e-3  # rad

    @model_validator(mode="after")
    def _distinct(self) -> "PsiSwitchingParams":
        if self.spin_stator in self.control_stators:
            raise ValueError(f"spin_stator = {self.spin_stator!r} is also a control stator; they must differ")
        return self


class ControllerConfig(_Strict):
    """``controller:`` section of a scene: the law, its period (s) and its parameters."""

    law: Literal["spinup", "psi_switching"]
    period: Optional[Positive] = None  # s; default: the output period of the scene
    params: Union[SpinupParams, PsiSwitchingParams] = Field(discriminator="law")

    @model_validator(mode="before")
    @classmethod
    def _tag(cls, data):
        if isinstance(data, dict) and isinstance(data.get("params"), dict) and "law" in data:
            data = dict(data)
            data["params"] = {"law": data["law"], **data["params"]}
        return data

    def stators_used(self) -> list[str]:
        p = self.params
        if isinstance(p, SpinupParams):
            return [p.stator]
        return [*p.control_stators, p.spin_stator]
