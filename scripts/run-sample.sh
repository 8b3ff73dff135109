#!/usr/bin/env bash
# The README's main command: install what is missing, build, and run the pipeline on the bundled
# sample (samples/explode, an OBJ sequence). Outputs go to out/sample/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/build.sh release
tsah=build/release/apps/tsah
out=out/sample
rm -rf "$out"
mkdir -p "$out"

echo "== import the bundled sample (OBJ sequence)"
$tsah info samples/explode

echo "== resample it into 5 representative frames"
$tsah resample samples/explode -o "$out/explode-5.tanim" --frames 5
$tsah info "$out/explode-5.tanim"

echo "== generate a fresh animation (two groups that pass through each other) and import it"
$tsah generate swap -o "$out/swap/swap_%04d.obj" --triangles 4000 --frames 20 --seed 1
$tsah info "$out/swap" --json
