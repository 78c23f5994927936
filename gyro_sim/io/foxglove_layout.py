"""The Foxglove layout of a run: a 3D view and plots of the topics that a live run (``gyro-sim run --live``), a
recorded bag and ``foxglove_bridge`` on the ROS nodes all carry, under the same names and in the same encoding.

``config/foxglove_layout.json`` (installed as ``share/gyro_sim/config/``) is :func:`layout` of the stators the
built-in scenes use (:data:`STANDARD_STATORS`: z1, z2, z3 along the case axes); ``gyro-sim run SCENE --live``
writes the scene's own next to its plot. Panels:

* 3D: ``gyro_rotor`` and ``gyro_l_frame`` turning in ``gyro_case`` (``/tf``, ``/tf_static``);
* spin Ω_b,z (``/gyro/imu``) and each stator's signed field rate ν (``/gyro/stators.velocity``), rad/s;
* slip of each stator's field over the rotor, ν − Ω·u (rad/s), as :func:`gyro_sim.io.plotting.slip`: Ω the rotor's
  angular velocity in the case frame (R(q) Ω_b from ``/gyro/imu``), u the stator's axis (the z axis of frame
  ``gyro_stator_<name>`` on ``/tf_static``; until that arrives, the layout's own copy of the scene's axes); none
  (a gap) while the stator carries no current;
* nutation angle θ (``/gyro/euler.vector.y``), rad;
* kinetic moment (angular momentum) L in the case frame and |L|, N·m·s;
* stator currents (``/gyro/stators.effort``), A.

Series of a stator are labelled with its name; they read the k-th entry of ``/gyro/stators`` arrays, whose
``name`` lists the stators in the scene's order. |L|, θ and the slip come from a user script in the layout
(TypeScript, output ``/studio_script/gyro_derived``). The format is the one the Foxglove app exports (Layouts →
Export): ``configById`` (panel id ``<type>!<suffix>`` → settings), a ``layout`` mosaic of the ids,
``userNodes`` (the user scripts).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Sequence, Union

from gyro_sim.io.messages import (FRAME_CASE, FRAME_L, FRAME_ROTOR, FRAME_STATOR_PREFIX, TOPIC_EULER, TOPIC_IMU,
                                  TOPIC_KINETIC_MOMENT, TOPIC_STATORS, TOPIC_TF_STATIC)

__all__ = ["STANDARD_STATORS", "SCRIPT_OUTPUT", "layout", "scene_layout", "script_source", "layout_text",
           "write_layout"]

#: (name, axis u in the case frame) of the stators of the built-in scenes: the shipped layout's
STANDARD_STATORS: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("z1", (1.0, 0.0, 0.0)), ("z2", (0.0, 1.0, 0.0)), ("z3", (0.0, 0.0, 1.0)))
#: the topic of the layout's user script (Foxglove's user scripts publish under /studio_script/)
SCRIPT_OUTPUT = "/studio_script/gyro_derived"

_SCRIPT = """\
// gyro_sim: |L|, theta in degrees and the slip of each stator's field over the rotor, nu - Omega.u (rad/s), from
// the topics that live runs (gyro-sim run --live), bags and foxglove_bridge on the ROS nodes all carry. Omega: the
// rotor's angular velocity in the case frame, R(q) Omega_b (/gyro/imu: orientation = attitude body -> case,
// angular_velocity = Omega_b in the body frame); u: the stator's axis in the case frame, the z axis of frame
// gyro_stator_<name> (/tf_static), until that arrives the scene's axes below. NaN (a gap) while a stator carries
// no current, as gyro_sim's PNG plot. Emits on each /gyro/stators message, with the latest sample of the others.
type Vec = [number, number, number];
type Quat = { x: number; y: number; z: number; w: number };
type Output = {
  L_norm: number;
  spin: number;
  theta_deg: number;
  field_rate: number[];
  slip: number[];
};

export const inputs = __INPUTS__;
export const output = __OUTPUT__;

// the stator axes u (case frame, unit) of the scene this layout was made for, by stator name
const axes: Record<string, Vec> = __AXES__;
let omega: Vec = [NaN, NaN, NaN];
let L_norm = NaN;
let spin = NaN;
let theta_deg = NaN;

// q v q* for a unit quaternion q (x, y, z, w): v + 2w (q_v x v) + 2 q_v x (q_v x v)
function rotate(q: Quat, v: Vec): Vec {
  const tx = 2 * (q.y * v[2] - q.z * v[1]);
  const ty = 2 * (q.z * v[0] - q.x * v[2]);
  const tz = 2 * (q.x * v[1] - q.y * v[0]);
  return [
    v[0] + q.w * tx + (q.y * tz - q.z * ty),
    v[1] + q.w * ty + (q.z * tx - q.x * tz),
    v[2] + q.w * tz + (q.x * ty - q.y * tx),
  ];
}

export default function script(event: { topic: string; message: any }): Output | undefined {
  const m = event.message;
  if (event.topic === __KM__) {
    L_norm = Math.hypot(m.vector.x, m.vector.y, m.vector.z);
  } else if (event.topic === __IMU__) {
    const w = m.angular_velocity;
    spin = w.z;
    omega = rotate(m.orientation, [w.x, w.y, w.z]);
  } else if (event.topic === __EULER__) {
    theta_deg = (m.vector.y * 180) / Math.PI;
  } else if (event.topic === __TF_STATIC__) {
    for (const tr of m.transforms) {
      if (tr.child_frame_id.startsWith(__PREFIX__)) {
        axes[tr.child_frame_id.slice(__PREFIX__.length)] = rotate(tr.transform.rotation, [0, 0, 1]);
      }
    }
  } else if (event.topic === __STATORS__) {
    const names: string[] = Array.from(m.name as ArrayLike<string>);
    const rates: number[] = Array.from(m.velocity as ArrayLike<number>);
    const currents: number[] = Array.from(m.effort as ArrayLike<number>);
    const slip = rates.map((nu, k) => {
      const u = axes[names[k]];
      if (u === undefined || currents[k] === 0) return NaN;
      return nu - (omega[0] * u[0] + omega[1] * u[1] + omega[2] * u[2]);
    });
    return { L_norm, spin, theta_deg, field_rate: rates, slip };
  }
  return undefined;
}
"""

_PLOT = {"showXAxisLabels": True, "showYAxisLabels": True, "showLegend": True, "legendDisplay": "floating",
         "showPlotValuesInLegend": True, "isSynced": True, "xAxisVal": "timestamp", "sidebarDimension": 240}


def _series(path: str, label: str) -> dict:
    return {"value": path, "enabled": True, "timestampMethod": "receiveTime", "label": label}


def _plot(title: str, series: list) -> dict:
    return {"foxglovePanelTitle": title, "paths": series, **_PLOT}


def _three_d() -> dict:
    return {
        "foxglovePanelTitle": f"rotor ({FRAME_ROTOR}, {FRAME_L} in {FRAME_CASE})",
        "cameraState": {"perspective": True, "distance": 4.5, "phi": 60, "thetaOffset": 45,
                        "targetOffset": [0, 0, 0], "target": [0, 0, 0], "targetOrientation": [0, 0, 0, 1],
                        "fovy": 45, "near": 0.01, "far": 5000},
        "followMode": "follow-pose", "followTf": FRAME_CASE,
        "scene": {"transforms": {"showLabel": True, "axisScale": 1.5}},
        "transforms": {f"frame:{f}": {"visible": True} for f in (FRAME_CASE, FRAME_ROTOR, FRAME_L)},
        "topics": {},
        "layers": {"grid": {"visible": True, "layerId": "foxglove.Grid", "instanceId": "grid", "frameId": FRAME_CASE,
                            "size": 4, "divisions": 8, "lineWidth": 1, "color": "#248eff80",
                            "position": [0, 0, 0], "rotation": [0, 0, 0], "order": 1}},
        "imageMode": {},
    }


def _unit(name: str, axis: Sequence[float]) -> list[float]:
    v = [float(a) for a in axis]
    n = math.sqrt(sum(a * a for a in v))
    if len(v) != 3 or not (math.isfinite(n) and n > 0):
        raise ValueError(f"stator {name!r}: axis {list(axis)!r} must be 3 finite numbers, not all zero")
    return [a / n for a in v]


def script_source(stators: Sequence[tuple[str, Sequence[float]]]) -> str:
    """The layout's user script (TypeScript) for stators (name, axis u in the case frame)."""
    names = {
        "__INPUTS__": json.dumps([TOPIC_KINETIC_MOMENT, TOPIC_IMU, TOPIC_EULER, TOPIC_TF_STATIC, TOPIC_STATORS]),
        "__OUTPUT__": json.dumps(SCRIPT_OUTPUT), "__KM__": json.dumps(TOPIC_KINETIC_MOMENT),
        "__IMU__": json.dumps(TOPIC_IMU), "__EULER__": json.dumps(TOPIC_EULER),
        "__TF_STATIC__": json.dumps(TOPIC_TF_STATIC), "__STATORS__": json.dumps(TOPIC_STATORS),
        "__PREFIX__": json.dumps(FRAME_STATOR_PREFIX),
        "__AXES__": json.dumps({str(name): _unit(name, axis) for name, axis in stators}),
    }
    src = _SCRIPT
    for key, value in names.items():
        src = src.replace(key, value)
    return src


def layout(stators: Sequence[tuple[str, Sequence[float]]] = STANDARD_STATORS) -> dict:
    """The layout (the dict of the app's exported JSON) for stators given as (name, axis u in the case frame),
    in the scene's order."""
    names = [str(name) for name, _ in stators]
    rates = [_series(f"{TOPIC_STATORS}.velocity[{k}]", f"field rate ν, {n}") for k, n in enumerate(names)]
    config = {
        "3D!gyro_rotor": _three_d(),
        "Plot!spin": _plot("spin Ω_b,z and field rates ν (rad/s)",
                           [_series(f"{TOPIC_IMU}.angular_velocity.z", "spin (body z)")] + rates),
        "Plot!slip": _plot("slip ν − Ω·u of each stator's field over the rotor (rad/s)",
                           [_series(f"{SCRIPT_OUTPUT}.slip[{k}]", n) for k, n in enumerate(names)]),
        "Plot!theta": _plot("nutation angle θ (rad)", [_series(f"{TOPIC_EULER}.vector.y", "θ")]),
        "Plot!L": _plot("kinetic moment (angular momentum) L, case frame (N·m·s)",
                        [_series(f"{SCRIPT_OUTPUT}.L_norm", "|L|")]
                        + [_series(f"{TOPIC_KINETIC_MOMENT}.vector.{c}", f"L {c}") for c in "xyz"]),
        "Plot!currents": _plot("stator currents (A)",
                               [_series(f"{TOPIC_STATORS}.effort[{k}]", n) for k, n in enumerate(names)]),
    }
    return {
        "configById": config,
        "globalVariables": {},
        "userNodes": {"gyro_derived": {"name": "gyro_sim: |L|, θ and slip ν − Ω·u",
                                       "sourceCode": script_source(stators)}},
        "linkedGlobalVariables": [],
        "playbackConfig": {"speed": 1},
        "layout": {"direction": "row", "splitPercentage": 40, "first": "3D!gyro_rotor",
                   "second": {"direction": "column", "splitPercentage": 33,
                              "first": {"direction": "row", "first": "Plot!spin", "second": "Plot!slip"},
                              "second": {"direction": "column", "splitPercentage": 50,
                                         "first": {"direction": "row", "first": "Plot!theta", "second": "Plot!L"},
                                         "second": "Plot!currents"}}},
    }


def scene_layout(scene) -> dict:
    """:func:`layout` for a scene's stators (names and axes as the scene gives them)."""
    return layout([(st.name, st.axis) for st in scene.stators])


def layout_text(value: dict) -> str:
    """A layout as the JSON text of the file (2-space indent, UTF-8 characters kept, a final newline)."""
    return json.dumps(value, indent=2, ensure_ascii=False) + "\n"


def write_layout(scene, path: Union[str, os.PathLike]) -> Path:
    """Write :func:`scene_layout` of ``scene`` to ``path`` whole (a temporary file, then a rename); missing
    parent folders are made. Returns the path written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(layout_text(scene_layout(scene)), encoding="utf-8")
    os.replace(tmp, path)
    return path
