#!/usr/bin/env bash
# benchmarks/gpu_check.sh [OUT]: the GPU check of hierloco (docs/gpu.md), in about 10 minutes on one GPU with 16 cores
# (measured for one H200). From the project root:
#
#   bash benchmarks/gpu_check.sh                 # logs and run directories in outputs/gpu_check/
#
# 1. device=cuda in every recipe (tiny presets, at once, a few cores each): LAT with the planner compiled and scoring
#    in bf16, LIB, IK, SAC with its update compiled (CUDA graphs), SAC-SAC; then load_run(device="cuda") of the LAT
#    run, a planner's action, and hierloco.export of it (about 3 min).
# 2. python benchmarks/gpu.py --cpu-reference: the MPC call and the SAC update against their references, LAT at
#    paper scale on A1 with device=cuda, one SAC task at paper scale, the cpu/cuda numerics, and the same LAT run with
#    device=cpu beside it on the other half of the cores, compared task by task (about 6 min). It writes
#    results/bench/gpu.md.
#
# The machine needs CUDA PyTorch; without network the other packages come from a wheel bundle made elsewhere with
# ../shared/tools/gpu-bundle (see its header; BUNDLE=its folder, default .gpu-bundle): no wandb or Ray there, so every
# run logs to CSV and the recipes run one by one. SMOKE=0 skips step 1, BENCH=0 step 2. DEVICE=cpu checks the script
# itself on a machine without a GPU (every step on the CPU, the benchmark at small sizes: it measures nothing).
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-outputs/gpu_check}
BUNDLE=${BUNDLE:-.gpu-bundle}
DEVICE=${DEVICE:-cuda}
PYTHON=${PYTHON:-python3}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1 WANDB_MODE=disabled

if ! $PYTHON -c "import torchrl, tensordict, mujoco, dm_control, hydra, omegaconf, moviepy" 2>/dev/null; then
  if [ ! -d "$BUNDLE" ]; then
    echo "error: hierloco's packages are missing and there is no wheel bundle in $BUNDLE (make one with" \
         "../shared/tools/gpu-bundle $BUNDLE on a machine with network)"; exit 2
  fi
  $PYTHON -m pip install -q --no-index --no-deps --target /tmp/hierloco-site "$BUNDLE"/*.whl || exit 2
  export PYTHONPATH=/tmp/hierloco-site:$PWD/$BUNDLE/dmc
fi
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH}
$PYTHON - "$DEVICE" <<'PY' || exit 2
import os, sys, torch
if sys.argv[1] == "cpu":
    print(f"the script's own check on the CPU: torch {torch.__version__}, {len(os.sched_getaffinity(0))} cores")
else:
    assert torch.cuda.is_available(), "no GPU visible to torch"
    print(f"{torch.cuda.get_device_name()}, torch {torch.__version__}, CUDA {torch.version.cuda}, "
          f"{len(os.sched_getaffinity(0))} cores")
PY

failed=0
if [ "${SMOKE:-1}" != 0 ]; then
  echo "== 1. device=$DEVICE in every recipe (tiny presets), logs in $OUT/smoke"
  mkdir -p "$OUT/smoke"
  common=(preset=tiny "device=$DEVICE" nthread=3 progress=false 'logger.backends=[csv]' 'eval.videos=[]')
  compiled=true
  [ "$DEVICE" = cpu ] && compiled=false  # compiling on a few shared cores takes minutes: the check of the script
  declare -A runs=(
    [lat]="recipes/lat/train.py planner.compile=$compiled planner.precision=bf16"
    [lib]="recipes/lib/train.py"
    [ik]="recipes/ik/train.py"
    [sac]="recipes/sac/train.py sac.compile=$compiled"
    [sac_sac]="recipes/sac_sac/train.py"
  )
  start=$SECONDS
  for name in "${!runs[@]}"; do
    # shellcheck disable=SC2086
    timeout 600 $PYTHON ${runs[$name]} "${common[@]}" "run_dir=$OUT/smoke/$name" >"$OUT/smoke/$name.log" 2>&1 &
  done
  wait
  for name in lat lib ik sac sac_sac; do
    if [ -f "$OUT/smoke/$name/results.csv" ]; then echo "  $name: ok"; else
      echo "  $name: FAILED ($OUT/smoke/$name.log):"; tail -n 3 "$OUT/smoke/$name.log" | sed 's/^/    /'; failed=1; fi
  done
  timeout 300 $PYTHON - "$OUT/smoke/lat" "$OUT/smoke/export" "$DEVICE" <<'PY' || failed=1
import sys, torch, hierloco
from hierloco.envs.tasks import GoalReaching
device = sys.argv[3]
run = hierloco.load_run(sys.argv[1], device=device)
assert next(run.low_level().policy.parameters()).device.type == device
assert next(run.com_model().model.parameters()).device.type == device
planner = run.planner(GoalReaching(), precision="bf16")
state = planner.env.initial_state(episode=torch.arange(8, device=device))
action = planner(state.cpu())["action"]
assert action.device.type == "cpu" and action.shape == (8, 2), action
print(f"  load_run(device={device!r}) and a planner's action: ok")
try:
    import onnxruntime  # noqa: F401  (hierloco's export extra: not in the wheel bundle)
except ImportError:
    print("  hierloco.export: skipped (onnx and onnxruntime are not installed here)")
else:
    hierloco.export(sys.argv[1], sys.argv[2])
    print(f"  hierloco.export of the run trained with device={device}: ok")
PY
  echo "  step 1 took $((SECONDS - start)) s"
fi

if [ "${BENCH:-1}" != 0 ]; then
  echo "== 2. benchmarks/gpu.py --cpu-reference (log: $OUT/bench.log)"
  if [ "$DEVICE" = cpu ]; then check=(--device cpu --small --repeats 5 --out "$OUT/gpu.md"); else check=(); fi
  timeout 900 $PYTHON benchmarks/gpu.py --cpu-reference --work "$OUT/bench" "${check[@]}" 2>&1 | tee "$OUT/bench.log"
  [ "${PIPESTATUS[0]}" = 0 ] || failed=1
fi
[ "$failed" = 0 ] && echo "gpu check: done ($OUT/; the benchmark's report: results/bench/gpu.md on CUDA)" || echo "gpu check: FAILED, see above"
exit $failed
