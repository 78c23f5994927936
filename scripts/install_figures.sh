#!/usr/bin/env bash
# The install and first-run figures of docs/benchmark.md (issue 31), measured as a new user meets them:
#   1. the README's quick start in a fresh clone (`bash .ci/setup` then the default scene over ROS), wall time of
#      each, and the size of .venv;
#   2. the first run of the default scene and of nutation_oblate, in-process and over ROS, after that setup
#      (wall time of the whole command: start, the first sample and the run; no kernel compiles);
#   3. what an empty numba cache costs the default scene: CPU of a run with NUMBA_CACHE_DIR empty less that of a
#      run with it warm (the compile alone).
# Usage: bash scripts/install_figures.sh [WORKDIR]   (default: a new temporary folder; prints a Markdown table)
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${1:-$(mktemp -d /tmp/gyro_sim-install.XXXXXX)}
mkdir -p "$WORK"
load() { cut -d' ' -f1-3 /proc/loadavg; }
row() { printf '| %s | %s | %s |\n' "$1" "$2" "$3"; }
secs() { local t0=$1; python3 -c "import time; print(f'{time.time() - $t0:.1f} s')"; }

echo "# install figures, $(date -u '+%Y-%m-%d %H:%M UTC'), $(nproc) cores, load at start $(load)"
echo
echo "| step | measured | load (1/5/15 min) |"
echo "|---|---|---|"
git clone -q "$ROOT" "$WORK/clone"
ln -sfn "$ROOT/../shared" "$WORK/shared" 2>/dev/null || true
cd "$WORK/clone"
t0=$(python3 -c 'import time; print(time.time())')
bash .ci/setup >"$WORK/setup.log" 2>&1
row "\`bash .ci/setup\` (fresh clone, pip's cache as this machine has it)" "$(secs "$t0")" "$(load)"
row ".venv size after it" "$(du -sh .venv | cut -f1)" ""
for scene in spinup_thin_shell nutation_oblate; do
    t0=$(python3 -c 'import time; print(time.time())')
    .venv/bin/gyro-sim run $scene --duration 0.05 --out "$WORK/out" --quiet >"$WORK/run.log" 2>&1
    c=$(grep -c "compiling" "$WORK/run.log" || true)
    row "first \`gyro-sim run $scene --duration 0.05\` (start to end; compile lines: $c)" "$(secs "$t0")" "$(load)"
    t0=$(python3 -c 'import time; print(time.time())')
    .venv/bin/gyro-sim run $scene --ros --duration 0.05 --out "$WORK/out" --quiet >"$WORK/ros.log" 2>&1
    c=$(grep -c "compiling" "$WORK/ros.log" || true)
    row "first \`gyro-sim run $scene --ros --duration 0.05\` (two nodes over DDS, start to end; compile lines: $c)" "$(secs "$t0")" "$(load)"
done
t0=$(python3 -c 'import time; print(time.time())')
.venv/bin/gyro-sim run spinup_thin_shell --ros --out "$WORK/out" >"$WORK/quick.log" 2>&1
row "the README's quick-start run (\`gyro-sim run spinup_thin_shell --ros\`, 60 s simulated)" "$(secs "$t0")" "$(load)"
cpu() { /usr/bin/time -f '%U %S' "$@" 2>&1 >/dev/null | tail -1 | awk '{print $1 + $2}'; }
rm -rf "$WORK/nc"
cold=$(NUMBA_CACHE_DIR="$WORK/nc" cpu .venv/bin/gyro-sim run spinup_thin_shell --out "$WORK/out" --quiet)
warm=$(NUMBA_CACHE_DIR="$WORK/nc" cpu .venv/bin/gyro-sim run spinup_thin_shell --out "$WORK/out" --quiet)
row "empty numba cache, default scene in-process: CPU cold − warm (cold $cold s, warm $warm s)" \
    "$(python3 -c "print(f'{$cold - $warm:.1f} s')")" "$(load)"
