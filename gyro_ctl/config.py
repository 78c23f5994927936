"""Validated parameters of the control laws (the ``controller`` section of a scene, SI units)."""
from __future__ import annotations

import math
from typing import Literal, Optional, Union

from pydantic import Field, model_validator

from .reorient import ReorientParams

from .numbers import Finite, NonNegative, Positive, real
from .strict_model import StrictModel


_Strict = StrictModel  # (unknown keys refused, immutable: gyro_ctl/strict_model.py)


class SpinupParams(_Strict):
    """Spin-up: ``stator`` driven at field rate = ``target_spin`` (rad/s) with ``current`` (A), optional ramp (A/s)."""

    law: Literal["spinup"] = "spinup"
    """The law's name."""
    stator: str = "z3"
    """Name of the stator that spins the rotor up."""
    target_spin: Finite
    """Target spin, rad/s: the field turns at this rate (the zero-slip asymptote)."""
    current: NonNegative
    """Current amplitude, A."""
    ramp: Optional[Positive] = None
    """The current rises from 0 A at t = 0 at this rate to its value, A/s; None: the full current at once."""


class PsiSwitchingParams(_Strict):
    """ψ-switching [K] (3.1): control stators flip their field direction with sign(u_n · e⊥)."""

    law: Literal["psi_switching"] = "psi_switching"
    """The law's name."""
    control_stators: list[str] = ["z1", "z2"]
    """Names of the control stators (axes normal to the spin axis)."""
    spin_stator: str = "z3"
    """Name of the stator that keeps the rotor spinning."""
    # rad/s, one value or one per control stator; > 0 drives θ → 0, < 0 drives θ → π. Give the control
    # stators different |ν|: at equal rates their cross terms do not average out (resonance)
    nu: Union[Finite, list[Finite]]
    """Control field rate ν, rad/s, one value or one per control stator: > 0 drives θ → 0, < 0 drives θ → π. Give the
    control stators different |ν| (at equal rates their cross terms do not average out)."""
    control_current: NonNegative
    """Current amplitude of the control stators, A."""
    spin_current: NonNegative
    """Current amplitude of the spin stator, A."""
    spin_rate: Finite  # ν0, rad/s
    """Field rate ν0 of the spin stator, rad/s."""
    dead_band: real(ge=0, lt=math.pi / 2) = 1e-3  # rad
    """Nutation angle θ below which (or within this of π) the control fields are off, rad."""

    @model_validator(mode="after")
    def _distinct(self) -> "PsiSwitchingParams":
        if self.spin_stator in self.control_stators:
            raise ValueError(f"spin_stator = {self.spin_stator!r} is also a control stator; they must differ")
        if isinstance(self.nu, list):
            if len(self.nu) != len(self.control_stators):
                raise ValueError(f"nu = {self.nu}: one rate per control stator ({len(self.control_stators)}) or one value")
            if len({math.copysign(1.0, v) for v in self.nu if v != 0}) > 1:
                raise ValueError(f"nu = {self.nu}: the rates must share one sign (it chooses θ → 0 or θ → π)")
        return self

    def rate(self, i: int) -> float:
        """ν of control stator i (rad/s)."""
        return self.nu[i] if isinstance(self.nu, list) else self.nu


class OffParams(_Strict):
    """Off: every stator current is 0 A (rates unchanged)."""

    law: Literal["off"] = "off"
    """The law's name."""


class HoldParams(_Strict):
    """Hold: keep whatever the stators were last commanded (no command is sent)."""

    law: Literal["hold"] = "hold"
    """The law's name."""


class ManualCommand(_Strict):
    """A fixed command of the manual law: current (A) and field rate (rad/s)."""

    current: NonNegative  # A
    """Current amplitude, A."""
    rate: Finite  # rad/s
    """Field rotation rate, rad/s (signed)."""


class ManualParams(_Strict):
    """Manual: fixed commands per stator name, e.g. {z3: {current: 1.0, rate: 3000.0}}."""

    law: Literal["manual"] = "manual"
    """The law's name."""
    commands: dict[str, ManualCommand]
    """Fixed commands by stator name."""


LAW_NAMES = ("spinup", "psi_switching", "off", "hold", "manual", "reorient")


class ControllerConfig(_Strict):
    """``controller:`` section of a scene: the law, its period (s), its parameters and limits.

    ``current_limit`` (A) and ``rate_limit`` (rad/s) clip every command of every law. ``sampling``:
    ``period`` evaluates the law at each tick (as a controller node does over DDS); ``events`` also
    locates the law's switching instants between ticks exactly (in-process runs only; laws
    without switching functions are sampled).
    """

    law: Literal["spinup", "psi_switching", "off", "hold", "manual", "reorient"]
    """The control law: spinup, psi_switching, off, hold, manual or reorient."""
    period: Optional[Positive] = None  # s; default: the output period of the scene
    """Period of the law, s; None: the scene's output period."""
    sampling: Literal["period", "events"] = "period"
    """period: the law runs at each tick; events: its switching instants are also located exactly between ticks (in-
    process runs)."""
    current_limit: Optional[NonNegative] = None  # A
    """Largest current any command may have, A (commands are clipped); None: no clip."""
    rate_limit: Optional[NonNegative] = None  # rad/s
    """Largest |field rate| any command may have, rad/s (clipped); None: no clip."""
    params: Union[SpinupParams, PsiSwitchingParams, OffParams, HoldParams, ManualParams, ReorientParams] = Field(
        discriminator="law")
    """The law's parameters (the class of its law)."""

    @model_validator(mode="before")
    @classmethod
    def _tag(cls, data):
        if isinstance(data, dict) and "law" in data and isinstance(data.get("params", {}), dict):
            data = dict(data)
            data["params"] = {"law": data["law"], **data.get("params", {})}
        return data

    def stators_used(self) -> list[str]:
        return [n for _, _, used in stator_parameters(self.params) for n in used]


def stator_parameters(params) -> list[tuple[str, object, list[str]]]:
    """The law parameters that name stators: (parameter name, its value, the stator names in it)."""
    p = params
    if isinstance(p, SpinupParams):
        return [("stator", p.stator, [p.stator])]
    if isinstance(p, PsiSwitchingParams):
        return [("control_stators", list(p.control_stators), list(p.control_stators)),
                ("spin_stator", p.spin_stator, [p.spin_stator])]
    if isinstance(p, ManualParams):
        return [("commands", list(p.commands), list(p.commands))]
    if isinstance(p, ReorientParams):
        return [("rates", list(p.rates), p.stators_used())]
    return []


def unknown_stators(cfg: ControllerConfig, names) -> str:
    """'' if every stator the law of ``cfg`` names is one of ``names`` (the scene's stators), else the reason:
    the parameter, its value and the allowed names (one check for scene files and the controller node)."""
    names = list(names)
    known = set(names)  # a hostile scene may name thousands: linear, not quadratic
    for pname, value, used in stator_parameters(cfg.params):
        bad = [n for n in used if n not in known]
        if bad:
            return f"{pname} = {value!r}: stator {bad[0]!r} is not defined; allowed: {names or 'none defined'}"
    return ""
