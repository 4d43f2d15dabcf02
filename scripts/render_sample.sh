#!/usr/bin/env bash
# The main job, end to end on a fresh machine: set up the venv, generate the soap-bubble sample
# scene, bake its material and render it headlessly with the thin-film shader.
#   bash scripts/render_sample.sh [scene]     → out/<scene>.png and out/<scene>.exr
# Scenes: soap_bubble (default), oil_slick, coated_car_window, anodised_titanium, beetle_shell,
# principled_film.
set -euo pipefail
cd "$(dirname "$0")/.."
scene="${1:-soap_bubble}"
bash scripts/setup.sh
.venv/bin/python sample_scenes/make_scenes.py --only "$scene" --out sample_scenes/out
.venv/bin/python scripts/thinfilm_headless.py "sample_scenes/out/$scene.blend" bake
.venv/bin/python scripts/thinfilm_headless.py "sample_scenes/out/$scene.blend" render --out "out/$scene.png"
echo "done: out/$scene.png (display-referred) and out/$scene.exr (scene-linear)"
