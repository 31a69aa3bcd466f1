#!/usr/bin/env bash
# Fetches real scans from Debian packages without installing them (apt-get download, then
# dpkg-deb -x) into a cache outside the source tree. Prints the cache folder.
#   python3-pcl: PCL's tutorial scans (table_scene_lms400.pcd, bun0.pcd, lamppost.pcd) and two
#                organized RGB-D frames (milk_cartoon_all_small_clorox.pcd: Kinect;
#                table_scene_mug_stereo_textured.pcd: stereo), real photos with their clouds
#   opencv-doc:  real range-scan meshes (rs1_normals.ply)
set -euo pipefail
DEST="${PAPS_SAMPLES:-$HOME/.cache/paps/samples}"
mkdir -p "$DEST"
want=(table_scene_lms400.pcd bun0.pcd lamppost.pcd rs1_normals.ply
      milk_cartoon_all_small_clorox.pcd table_scene_mug_stereo_textured.pcd)
have=1
for f in "${want[@]}"; do [ -s "$DEST/$f" ] || have=0; done
if [ $have -eq 0 ]; then
  work=$(mktemp -d)
  trap 'rm -rf "$work"' EXIT
  ( cd "$work" && apt-get download python3-pcl opencv-doc >/dev/null 2>&1 ) || {
    # apt-get download needs package lists; refresh once if they are missing.
    if [ "$(id -u)" -eq 0 ]; then apt-get update -qq; else sudo apt-get update -qq; fi
    ( cd "$work" && apt-get download python3-pcl opencv-doc >/dev/null )
  }
  for deb in "$work"/*.deb; do dpkg-deb -x "$deb" "$work/x"; done
  for f in "${want[@]}"; do
    src=$(find "$work/x" -name "$f" -print -quit)
    [ -n "$src" ] || { echo "fetch_samples: $f not found in the packages" >&2; exit 1; }
    cp "$src" "$DEST/$f.tmp" && mv "$DEST/$f.tmp" "$DEST/$f"
  done
fi
echo "$DEST"
