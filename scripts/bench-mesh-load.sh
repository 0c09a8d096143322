#!/usr/bin/env bash
# Mesh load time of high-valence OBJs: 3 vertices and `f 1 2 3` repeated 10k,
# 20k and 40k times (every edge shared by every face), beside 20k separate triangles. Prints
# the load time of the mesh (parse, normals, subdivision, sparse points) from `relume render`'s
# "loaded mesh" log line; the render itself (8x8) is not timed. Near-linear growth in the faces
# is the target; before the fix these took 2.3 s / 11 s / 34 s.
#
#   cargo build --release && scripts/bench-mesh-load.sh
set -euo pipefail
bin=${RELUME:-target/release/relume}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cat > "$dir/scene.json" <<'EOF'
{"meshes": [{"obj": "mesh.obj", "sparse_points": 16}],
 "light": {"position": [0.2, 0.2, 1], "direction": [0, 0, -1], "inner_angle_deg": 20,
           "outer_angle_deg": 30, "intensity": [1, 1, 1]},
 "camera": {"position": [0.3, 0.3, 2], "target": [0.3, 0.3, 0], "fov_y_deg": 40, "width": 8, "height": 8},
 "settings": {"tuning": {"rsm_resolution": 8}}}
EOF
load_ms() {
  RUST_LOG=relume=info "$bin" render "$dir/scene.json" --out "$dir/out.png" 2>&1 \
    | sed 's/\x1b\[[0-9;]*m//g' | grep 'loaded mesh' | grep -o 'elapsed_ms=[0-9.]*' | cut -d= -f2
}
for faces in 10000 20000 40000; do
  awk -v n="$faces" 'BEGIN { print "v 0 0 0\nv 1 0 0\nv 0 1 0"; for (i = 0; i < n; i++) print "f 1 2 3" }' > "$dir/mesh.obj"
  printf '%6d faces on 3 vertices:      %8.1f ms\n' "$faces" "$(load_ms)"
done
awk 'BEGIN { for (i = 0; i < 20000; i++) { x = (i % 200) * 0.01; y = int(i / 200) * 0.01;
  printf "v %g %g 0\nv %g %g 0\nv %g %g 0\nf %d %d %d\n", x, y, x + 0.005, y, x, y + 0.005, 3*i+1, 3*i+2, 3*i+3 } }' > "$dir/mesh.obj"
printf '%6d separate triangles:      %8.1f ms\n' 20000 "$(load_ms)"
