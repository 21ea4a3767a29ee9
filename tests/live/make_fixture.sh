#!/bin/sh
# The fixture of test_rt_live (tests/test_rt_live.cpp), made by nao_toolchain the way a user
# makes it (docs/cameras.md, docs/synth.md):
#   OUT/recording/whole_arm_000/  a held-out synthetic demonstration (run seed 1000001, as
#                                 toolchain/nao demo's): cam0/, cam1/ (OpenPose JSON, 30 Hz) and
#                                 calibration.json, the recording the tests replay;
#   OUT/skeleton.csv              that recording triangulated offline at 10 Hz (--max-gap 0: no gap
#                                 interpolation, as the demo's references), for --reference file:;
#   OUT/model.bin                 with MODEL=train only: a reference-conditioned model of the paper
#                                 architecture (the one nao_rt runs without a compiled-in model),
#                                 trained one epoch on 2 demonstrations per movement (seed 1):
#                                 k-means key poses of real data and the servo inversion its actions
#                                 are the residual of; its network is barely trained, which does not
#                                 matter here (both runs use the same model); its recipe
#                                 OUT/recipe.json (no noisy rollouts).
# usage: make_fixture.sh NAO_TOOLCHAIN OUT MODEL   (MODEL: train or none)
set -eu
tc="$1"
out="$2"
model="$3"
rm -rf "$out"
mkdir -p "$out"
log="$out/fixture.log"
run() {
  echo "+ $*" >>"$log"
  "$@" >>"$log" 2>&1 || { echo "make_fixture.sh: failed: $* (log: $log)" >&2; tail -n 20 "$log" >&2; exit 1; }
}
run "$tc" synth --movement whole_arm --per-movement 1 --seed 1000001 --out "$out/recording"
run "$tc" triangulate --demo "$out/recording/whole_arm_000" --max-gap 0 --out "$out/skeleton.csv"
if [ "$model" = train ]; then
  run "$tc" synth --movement all --per-movement 2 --seed 1 --out "$out/data"
  for demo in "$out"/data/*_[0-9][0-9][0-9]; do
    run "$tc" triangulate --demo "$demo" --max-gap 0 --smooth 0 --bone-fit 0 --out "$demo/skeleton.csv"
    run "$tc" retarget --skeleton "$demo/skeleton.csv" --out "$demo/retarget.csv"
  done
  run "$tc" cluster --data "$out/data"
  # No noisy rollouts (a training method's option: recipe-only).
  printf '{"train": {"noisy-rollouts": 0}}\n' >"$out/recipe.json"
  run "$tc" train --recipe "$out/recipe.json" --config paper --conditioning reference --seed 1 --epochs 1 \
    --data "$out/data" --out "$out/model.bin"
fi
echo "made $out ($(date -u +%FT%TZ))" >>"$log"
touch "$out/complete"
