#!/usr/bin/env bash
# The main job on real data: installs what is missing, builds, fetches the sample scans,
# denoises the real laser scan table_scene_lms400.pcd with similarity denoising, and
# runs the quick denoising bench, which writes before/after pictures to demo_out/, and the
# quick Local Probing Fields bench (a plate under wires; pictures of a wire seen end-on), and
# the quick optimal-transport bench (feature recovery after PCL Poisson, a cube reconstructed),
# and registers photos of the synthetic street to its LiDAR cloud (paps register), colours the
# cloud from them and relights its shadows (paps colorize, paps shadows), and registers a real
# Kinect photo back to its own cloud from a wrong start (paps rgbd-photo, paps register).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
SAMPLES=$(bash scripts/fetch_samples.sh)
mkdir -p demo_out
./build/apps/paps/paps denoise "$SAMPLES/table_scene_lms400.pcd" demo_out/table_scene_denoised.pcd
./build/apps/paps/paps bench denoise --quick --samples "$SAMPLES" --out demo_out
./build/apps/paps/paps bench lpf --quick --shapes plate-wires --out demo_out
./build/apps/paps/paps bench transport --quick --out demo_out
# Chapter 4: photos of a street with GPS-like pose errors, registered to the LiDAR cloud.
./build/apps/paps/paps make-street demo_out/street --photos 4
./build/apps/paps/paps register demo_out/street/street.pcd demo_out/street/photos_gps.txt \
  demo_out/street/photos_registered.txt --truth demo_out/street/photos_true.txt --quiet
# ... then coloured from the registered photos, its shadows detected and relit (the scene's sun).
./build/apps/paps/paps colorize demo_out/street/street.pcd demo_out/street/photos_registered.txt \
  demo_out/street/coloured.pcd --quiet
./build/apps/paps/paps shadows demo_out/street/coloured.pcd demo_out/street/photos_registered.txt \
  demo_out/street/relit.pcd --sun 0.5,-0.35,0.8 --quiet
# ... and a real Kinect frame (PCL's tutorial data): camera and true pose recovered from the grid,
# then the photo registered back from a wrong start (shading lit from the frame's up, +y; a
# room, so a 10 cm translation band; NMI, the metric that works on RGB-D shading: on this start
# MIDHOG only gets from 14.0 to 12.3 px, see docs/registration.md).
./build/apps/paps/paps rgbd-photo "$SAMPLES/milk_cartoon_all_small_clorox.pcd" demo_out/kinect --perturb 3,0.03
./build/apps/paps/paps register demo_out/kinect/cloud.pcd demo_out/kinect/photo_start.txt \
  demo_out/kinect/photo_registered.txt --truth demo_out/kinect/photo.txt --light 0,1,0.3 --band 0.1 \
  --metric nmi --quiet
echo "demo: pictures and table in $(pwd)/demo_out"
