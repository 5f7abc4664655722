#!/usr/bin/env bash
# Rebuild the grid_block scene: the network from its plain XML sources, then the building polygons.
# Run from anywhere: bash sumo_nets/grid_block/build.sh   (needs eclipse-sumo, sumolib, shapely, soabench)
set -euo pipefail
cd "$(dirname "$0")"
# shellcheck source=../netbuild.sh
source ../netbuild.sh

build_net grid_block

# Buildings: the world box minus the road and pedestrian areas buffered by 1.0 m (mitre joins).
build_buildings grid_block "80 80 220 220" 1.0 "the world box minus the paved area + 1.0 m."
