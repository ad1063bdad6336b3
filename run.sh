#!/usr/bin/env bash
# hierloco's two entry points. The first run creates .venv and installs the package with everything it needs.
#   ./run.sh main [hydra overrides...]   the main job: LAT on A1 with the small preset (a few minutes)
#   ./run.sh test [pytest args...]       the test suite
#   ./run.sh bench                       the performance benchmarks
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
# (re)install when the project's dependencies changed since the last install
if [ ! -f .venv/.install-stamp ] || [ pyproject.toml -nt .venv/.install-stamp ]; then
  .venv/bin/python -m pip install --quiet --upgrade pip
  # the CPU wheel first: an unpinned or indirect torch would pull a multi-GB CUDA build
  .venv/bin/python -m pip install --quiet "torch==2.13.0"
  .venv/bin/python -m pip install --quiet -e ".[test]"
  touch .venv/.install-stamp
fi
# headless rendering (rollout videos) needs EGL from Mesa; install it once where we may
if ! ldconfig -p 2>/dev/null | grep -q "libEGL_mesa.so.0"; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libegl1 libegl-mesa0 \
      libgl1-mesa-dri libgbm1 libopengl0 libglvnd0 >/dev/null) || echo "run.sh: could not install EGL (Mesa)" >&2
  else
    echo "run.sh: EGL (Mesa) is missing: install libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 for videos" >&2
  fi
fi
export MUJOCO_GL=${MUJOCO_GL:-egl}
export WANDB_MODE=${WANDB_MODE:-offline}
cmd=${1:-main}
shift || true
case "$cmd" in
  main)  exec .venv/bin/hierloco train lat preset=small "$@" ;;
  demo)  exec .venv/bin/python -m hierloco.demo "$@" ;;
  test)  exec .venv/bin/python -m pytest -q "$@" ;;
  bench) exec .venv/bin/python benchmarks/run_all.py "$@" ;;
  *) echo "usage: ./run.sh {main|test|bench|demo} [args...]" >&2; exit 2 ;;
esac
