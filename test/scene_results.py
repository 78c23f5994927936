"""Results of every built-in scene as shipped, recorded once, to check that a change of speed leaves them where
they were (within each scene's stated accuracy).

``python test/scene_results.py`` records ``test/data/scene_results.json`` (do it only on purpose: the file is the
record that later code is compared with); ``test_scene_results.py`` runs each scene again and compares.
"""
from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np

RECORD = Path(__file__).parent / "data" / "scene_results.json"
#: instants compared in each run: this many, evenly spaced over its duration (the last one is its end)
CHECKPOINTS = 8


def scene_result(name: str) -> dict:
    """The run of built-in scene ``name`` as shipped, at :data:`CHECKPOINTS` instants: t (s), L (N m s, case
    frame), q (body → case, scalar first) where the run integrates the attitude, and the stated accuracy."""
    from gyro_sim.scenes.scene import load_scene
    from gyro_sim.engine.simulate import run

    scene = load_scene(name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = run(scene)
    idx = np.unique(np.round(np.linspace(0, r.t.size - 1, CHECKPOINTS + 1)[1:]).astype(int))
    q = getattr(r, "q", None)
    has_q = q is not None and np.all(np.isfinite(q[idx]))
    est = r.error_estimate
    return {"t": r.t[idx].tolist(), "L": r.L[idx].tolist(), "L_max": float(np.max(np.linalg.norm(r.L, axis=1))),
            "q": q[idx].tolist() if has_q else None, "rtol": scene.accuracy.rtol,
            "attitude": scene.accuracy.attitude,
            "phase_tol": float(est.phase_tol) if est is not None and est.phase_tol == est.phase_tol else None}


def attitude_angle(q1: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) between unit quaternions, row by row (sign-blind)."""
    d = np.abs(np.sum(np.asarray(q1) * np.asarray(q2), axis=-1))
    return 2 * np.arccos(np.clip(d, 0.0, 1.0))


def main() -> int:
    from gyro_sim.scenes.scene import builtin_scenes

    out = {name: scene_result(name) for name in builtin_scenes()}
    RECORD.write_text(json.dumps(out, indent=1) + "\n")
    print(f"recorded {len(out)} scenes in {RECORD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
