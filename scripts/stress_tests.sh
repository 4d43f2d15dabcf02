#!/usr/bin/env bash
# The fast test set three times in a row while a CPU-heavy process runs beside it: Cycles
# rendering a sample scene in a loop, at the tests' own priority. A test that waits on time
# instead of on its event, or that asserts a timing, fails here first.
#
#   bash scripts/stress_tests.sh                  # 3 passes of `bash scripts/test.sh`
#   STRESS_PASSES=5 bash scripts/stress_tests.sh tests/viewport   # more passes, other arguments
#
# Prints each pass's result, wall time and load average, and the number of Cycles renders done
# beside it; the exit code is 0 only when every pass passed. The load process is stopped on exit.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

passes="${STRESS_PASSES:-3}"
work="$(mktemp -d "${TMPDIR:-/tmp}/thinfilm-stress.XXXXXX")"
load_pid=""

stop_load() {
    if [ -n "$load_pid" ] && kill -0 "$load_pid" 2>/dev/null; then
        kill "$load_pid" 2>/dev/null || true
        wait "$load_pid" 2>/dev/null || true
    fi
    rm -rf "$work"
}
trap stop_load EXIT

if [ "${THINFILM_SETUP:-1}" != "0" ]; then
    bash scripts/setup.sh
fi

# The load: the principled_film sample scene rendered by Cycles (CPU, all threads) again and
# again, 160×120 at 256 samples (about 10–20 s a render on two cores), each render counted.
.venv/bin/python sample_scenes/make_scenes.py --only principled_film --out "$work" >/dev/null
cat >"$work/load.py" <<'PY'
import pathlib
import sys

import bpy

blend, count_file = sys.argv[1], pathlib.Path(sys.argv[2])
bpy.ops.wm.open_mainfile(filepath=blend)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 256
scene.cycles.use_denoising = False
scene.render.resolution_x, scene.render.resolution_y = 160, 120
scene.render.resolution_percentage = 100
renders = 0
while True:
    bpy.ops.render.render()
    renders += 1
    count_file.write_text(str(renders))
PY
.venv/bin/python "$work/load.py" "$work/principled_film.blend" "$work/renders" >"$work/load.log" 2>&1 &
load_pid=$!
echo "stress: Cycles load running (pid $load_pid): principled_film, 160x120, 256 spp, in a loop"

failed=0
for pass in $(seq 1 "$passes"); do
    if ! kill -0 "$load_pid" 2>/dev/null; then
        echo "stress: the Cycles load process ended early:" >&2
        tail -20 "$work/load.log" >&2
        exit 2
    fi
    before="$(cat "$work/renders" 2>/dev/null || echo 0)"
    start=$(date +%s)
    status=0
    THINFILM_SETUP=0 bash scripts/test.sh "$@" || status=$?
    seconds=$(($(date +%s) - start))
    renders=$(($(cat "$work/renders" 2>/dev/null || echo 0) - before))
    result=$([ "$status" -eq 0 ] && echo PASSED || echo "FAILED (exit $status)")
    echo "stress: pass $pass/$passes $result in $seconds s beside $renders Cycles renders (load average $(cut -d' ' -f1-3 /proc/loadavg))"
    [ "$status" -eq 0 ] || failed=$((failed + 1))
done

if [ "$failed" -ne 0 ]; then
    echo "stress: $failed of $passes passes failed"
    exit 1
fi
echo "stress: all $passes passes passed under load"
