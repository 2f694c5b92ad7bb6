#!/usr/bin/env bash
# Regenerate samples/: three synthetic scans (320x240, sensor noise, PNG level 9; about 1.7 MB together) made by
# `v2c synth`, so they are reproducible byte for byte:
#   bracket_planes_cylinders   planes and cylinders only (L bracket: bend fillet, holes in both legs)
#   knob_cone_torus_sphere     cone, torus and sphere (knob: conical neck, rounded rim, spherical cap)
#   turned_unaligned           a block turned about Z on a base plate: unaligned planes and cylinders (label U)
set -euo pipefail
cd "$(dirname "$0")/.."
V2C=${V2C:-.venv/bin/v2c}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

make_sample() {  # name family seed
  "$V2C" synth "$tmp/$1" --n 1 --seed "$3" --families "$2" --size 320x240 --noise sensor --png-compression 9 --quiet
  rm -rf "samples/$1"
  mv "$tmp/$1/scan_00000" "samples/$1"
}

mkdir -p samples
make_sample bracket_planes_cylinders bracket 2
make_sample knob_cone_torus_sphere knob 4
make_sample turned_unaligned turned 1
du -sh samples
