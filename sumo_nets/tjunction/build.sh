#!/usr/bin/env bash
# Rebuild the tjunction scene: the network from its plain XML sources, then the building polygons.
# Run from anywhere: bash sumo_nets/tjunction/build.sh   (needs eclipse-sumo, sumolib, shapely, soabench)
set -euo pipefail
cd "$(dirname "$0")"
# shellcheck source=../netbuild.sh
source ../netbuild.sh

build_net tjunction

# Buildings: the world box minus the road and pedestrian areas buffered by 1.0 m (mitre joins).
build_buildings tjunction "-60 -50 110 50" 1.0 "the world box minus the paved area + 1.0 m."
