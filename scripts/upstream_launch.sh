#!/usr/bin/env bash
# The launch file under the real upstream `ros2 launch` on a machine without a ROS install (issue 30).
#
# ros2/launch, ros2/launch_ros, ros2/ros2cli and ros2/rosidl_runtime_py are pure Python but have no PyPI wheels.
# This script builds a scratch venv (never the project's .venv) with the project installed non-editable
# (`pip install '.[ros]'`, the ROS 2 wheels), those sources installed with `pip install --no-deps`, and a stub
# `composition_interfaces.srv` (no wheel; launch_ros imports it, plain nodes never use it). Then it runs
#   1. test_packaging.py's launch tests, among them test_launch_file_with_upstream_launch (skipped in .venv);
#   2. `ros2 launch gyro_sim gyro_sim.launch.py scene:=spinup_thin_shell record:=BAG` to its end, and prints the
#      rotor's spin rate read back from the bag at 3 s and at the end (the scene's own law, spinup: about 80 rad/s
#      at 3 s; before issue 30 the launch file ran psi_switching's parameters: 2.1 rad/s).
# Nothing of these sources is copied into the project.
#
# Usage: bash scripts/upstream_launch.sh [WORKDIR] [SRC]
#   WORKDIR  the scratch folder (default: a new temporary one); the venv is WORKDIR/venv
#   SRC      a folder holding checkouts launch/ launch_ros/ ros2cli/ rosidl_runtime_py/ (default: `git clone
#            --depth 1 -b rolling` of each from github.com/ros2 into WORKDIR/src)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${1:-$(mktemp -d /tmp/gyro_sim-upstream.XXXXXX)}
SRC=${2:-$WORK/src}
mkdir -p "$WORK" "$SRC"
for repo in launch launch_ros ros2cli rosidl_runtime_py; do
    [ -d "$SRC/$repo" ] || git clone -q --depth 1 -b rolling "https://github.com/ros2/$repo" "$SRC/$repo"
done
VENV=$WORK/venv
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
PIP=("$VENV/bin/pip" install -q --disable-pip-version-check)
echo "[upstream] installing the project and the ROS 2 wheels into $VENV"
GYRO_SIM_PRECOMPILE=spinup_thin_shell "${PIP[@]}" "$ROOT[ros]" osrf-pycommon lark importlib-metadata catkin_pkg \
    psutil netifaces packaging pyyaml pytest wheel setuptools
for pkg in launch/launch launch/launch_xml launch/launch_yaml launch_ros/launch_ros launch_ros/ros2launch \
           rosidl_runtime_py ros2cli/ros2cli ros2cli/ros2pkg ros2cli/ros2node ros2cli/ros2topic ros2cli/ros2param \
           ros2cli/ros2service ros2cli/ros2run; do
    "${PIP[@]}" --no-deps --no-build-isolation "$SRC/$pkg"
done
SITE=$("$VENV/bin/python" -c 'import site; print(site.getsitepackages()[0])')
if ! "$VENV/bin/python" -c 'import composition_interfaces.srv' 2>/dev/null; then
    mkdir -p "$SITE/composition_interfaces"
    : >"$SITE/composition_interfaces/__init__.py"
    cat >"$SITE/composition_interfaces/srv.py" <<'EOF'
"""Stub (no wheel of composition_interfaces): lets launch_ros import; plain nodes never call these services."""


class _Service:
    class Request:
        pass

    class Response:
        pass


class LoadNode(_Service):
    pass


class UnloadNode(_Service):
    pass


class ListNodes(_Service):
    pass
EOF
fi
export AMENT_PREFIX_PATH=$VENV PATH=$VENV/bin:$PATH
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$((100 + RANDOM % 100))} ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
echo "[upstream] 1. the launch tests under the real launch/launch_ros"
(cd "$ROOT" && "$VENV/bin/python" -m pytest -q -p no:cacheprovider test/test_packaging.py -k launch -rs)
echo "[upstream] 2. ros2 launch gyro_sim gyro_sim.launch.py scene:=spinup_thin_shell (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
BAG=$WORK/launch_bag
rm -rf "$BAG"
timeout 600 ros2 launch gyro_sim gyro_sim.launch.py scene:=spinup_thin_shell record:="$BAG" | tee "$WORK/launch.log"
"$VENV/bin/python" - "$BAG" <<'EOF'
import sys

import numpy as np

from gyro_sim.io.results import read_bag

r = read_bag(sys.argv[1])
w = np.linalg.norm(r.omega_b, axis=1)
i = int(np.searchsorted(r.t, 3.0))
print(f"[upstream] bag {sys.argv[1]}: |omega| {w[i]:.1f} rad/s at t = {r.t[i]:g} s, {w[-1]:.1f} rad/s at t = {r.t[-1]:g} s")
EOF
