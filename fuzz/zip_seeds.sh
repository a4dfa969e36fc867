#!/usr/bin/env bash
# Seeds for the zip_upload target: small uploads the coordinator accepts,
# made from the bundled examples (an ASF with the start of an AMC, the start of
# a BVH), each stored and deflated. Writes into corpus/zip_upload (or $1).
set -euo pipefail
cd "$(dirname "$0")"
out="$(realpath -m "${1:-corpus/zip_upload}")"
examples=../examples/data
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"
cp "$examples/HDM_bd.asf" "$work/"
head -n 200 "$examples/HDM_bd_kickLFront1Reps_001_120.amc" >"$work/HDM_bd_kick.amc"
# The BVH's hierarchy and its first 10 frames.
awk '/^Frames:/ { print "Frames: 10"; next }
     { print }
     /^Frame Time/ { start = NR }
     start && NR >= start + 10 { exit }' "$examples/16_11_walk_veer_left.bvh" >"$work/walk.bvh"
cd "$work"
zip -q -0 "$out/stored_amc.zip" HDM_bd.asf HDM_bd_kick.amc
zip -q -9 "$out/deflated_amc.zip" HDM_bd.asf HDM_bd_kick.amc
zip -q -0 "$out/stored_bvh.zip" walk.bvh
zip -q -9 "$out/deflated_bvh.zip" walk.bvh
ls -l "$out"
