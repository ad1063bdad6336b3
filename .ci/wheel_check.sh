#!/usr/bin/env bash
# hierloco as users install it: the wheel built from this checkout, installed (not editable) into a fresh virtual
# environment, runs a tiny recipe and a tiny study through the `hierloco` command, from a folder outside the
# checkout. The dependencies come from .venv (./run.sh installed them), so nothing is downloaded twice.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
root=$PWD
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
.venv/bin/python -m pip wheel --quiet --no-deps --no-build-isolation . -w "$work/dist"
python3 -m venv "$work/venv"
deps=$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
fresh=$("$work/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
echo "$deps" > "$fresh/hierloco-dependencies.pth"   # torch, mujoco, torchrl, ... (not hierloco: no .pth of .venv runs)
"$work/venv/bin/python" -m pip install --quiet --no-deps --no-index "$work"/dist/hierloco-*.whl
cd "$work"
where=$("$work/venv/bin/python" -c 'import hierloco, hierloco.recipes.lat; print(hierloco.__file__)')
case "$where" in "$work/venv/"*) ;; *) echo "wheel check: hierloco imported from $where, not the wheel" >&2; exit 1 ;; esac
if "$work/venv/bin/python" -c 'import recipes' 2>/dev/null; then echo "wheel check: a top-level recipes package" >&2; exit 1; fi
export MUJOCO_GL=${MUJOCO_GL:-disable} WANDB_MODE=offline
"$work/venv/bin/hierloco" train lat --help > /dev/null
"$work/venv/bin/hierloco" train lat preset=tiny progress=false run_dir=runs/lat_tiny logger.backends=[csv] > train.log
test -f runs/lat_tiny/results.csv
"$work/venv/bin/hierloco" study compare preset=tiny 'methods=[lat]' 'robots=[a1]' 'seeds=[0]' \
  out_dir=study > study.log
test -f study/comparison.md
echo "wheel check: the wheel's hierloco ran a tiny LAT run and a tiny study ($(wc -l < study/comparison.md) table lines)"
cd "$root"
