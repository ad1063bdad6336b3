#!/bin/bash
# One perturbation at a time (LAT and IK, seed 0; ./run.sh [robot], default a1): each of the hardware gap's five
# options at its default, the other four at the nominal robot's values.
# Writes results/hardware_<robot>_factors/<option>/.
ROBOT=${1:-a1}
cd "$(dirname "$0")/../.."
# nominal: the simulated robots' (A1, Daisy) contacts have sliding friction 1.0 (the floor's, the larger of two)
NOM_mass_scale=1.0; NOM_foot_friction=1.0; NOM_motor_strength=1.0; NOM_servo_latency=0.0; NOM_com_noise='[0.0,0.0,0.0]'
DEF_mass_scale=1.1; DEF_foot_friction=0.5; DEF_motor_strength=0.8
DEF_servo_latency=0.02; DEF_com_noise='[0.02,0.03,0.05]'
for f in mass_scale foot_friction motor_strength servo_latency com_noise; do
  args=()
  for g in mass_scale foot_friction motor_strength servo_latency com_noise; do
    if [ $f = $g ]; then v=DEF_$g; else v=NOM_$g; fi
    args+=("+hardware.$g=${!v}")
  done
  echo "=== $f: ${args[*]}"
  .venv/bin/python recipes/hardware/run.py "robots=[$ROBOT]" 'methods=[lat,ik]' 'seeds=[0]' "${args[@]}" \
    out_dir=results/hardware_${ROBOT}_factors/$f 2>&1 | grep -v "^study:"
done
echo ALLDONE
