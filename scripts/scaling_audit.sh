#!/usr/bin/env bash
# Runs every paps command on large adversarial clouds (valid input that is hard for the
# neighbour searches) and prints one line per run: exit code, wall time, peak memory, the
# output's point count and the first error line.
#   scripts/scaling_audit.sh [PAPS=build/apps/paps/paps] [WORK=/tmp/paps_scaling] [N=200000]
# TIMEOUT=S (default 300) bounds each run; ONLY=REGEX keeps the inputs whose names match;
# COMMANDS="denoise reconstruct ..." runs only those (default: all, listed in the loop below).
# PEERS=1 also runs `paps bench files` on the same inputs (ours and the PCL/CGAL peers, each
# bounded by TIMEOUT; a peer that does not finish is reported, not counted as a failure).
# SKIP_OURS=1 skips the commands (with PEERS=1: the peers only).
# The inputs (N points each, float32 binary PCD, seeded):
#   line      points 1 mm apart on a line (no surface)
#   piles     20 positions, each stored N / 20 times
#   twin      two copies of a lattice plane 1e-6 apart
#   cluster   N / 2 points in a 1 cm cube beside N / 2 over a 1 km x 1 km plane
#   utm       a 1 m lattice plane at (5e5, 5e6, 100): float steps of 0.5 m there
#   outliers  a 1 m lattice plane with 1% of its points moved 1e6 m away
#   cube      uniform in a unit cube (no surface)
# Exit code 124 is a timeout; above 128 a signal. Both are counted at the end.
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PAPS=$(realpath "${1:-$ROOT/build/apps/paps/paps}")
WORK=${2:-/tmp/paps_scaling}
N=${3:-200000}
TIMEOUT=${TIMEOUT:-300}
ONLY=${ONLY:-.}
mkdir -p "$WORK/in" "$WORK/out"
python3 - "$WORK/in" "$N" <<'PY'
import math, os, random, struct, sys
d, n = sys.argv[1], int(sys.argv[2]); rnd = random.Random(1)
def pcd(name, pts):
    path = os.path.join(d, name)
    with open(path + '.tmp', 'wb') as f:
        f.write(("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                 "WIDTH %d\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA binary\n" % (len(pts), len(pts))).encode())
        f.write(struct.pack('<%df' % (3 * len(pts)), *[c for p in pts for c in p]))
    os.replace(path + '.tmp', path)
def lattice(m, size, at=(0.0, 0.0, 0.0)):
    s = math.ceil(math.sqrt(m)); step = size / max(1, s - 1)
    return [(at[0] + (k % s) * step, at[1] + (k // s) * step, at[2]) for k in range(m)]
pcd('line.pcd', [(k * 1e-3, 0.0, 0.0) for k in range(n)])
pos = [(rnd.random(), rnd.random(), rnd.random()) for _ in range(20)]
pcd('piles.pcd', [p for p in pos for _ in range(n // 20)])
h = n // 2; s = math.ceil(math.sqrt(h)); plane = lattice(h, 0.003 * (s - 1))
pcd('twin.pcd', plane + [(x, y, z + 1e-6) for x, y, z in plane])
pcd('cluster.pcd', [(rnd.uniform(0, 0.01), rnd.uniform(0, 0.01), rnd.uniform(0, 0.01)) for _ in range(h)] +
    [(rnd.uniform(0, 1000), rnd.uniform(0, 1000), 0.0) for _ in range(n - h)])
pcd('utm.pcd', lattice(n, 1.0, (500000.0, 5000000.0, 100.0)))
pts = lattice(n, 1.0)
for k in rnd.sample(range(n), n // 100):
    v = [rnd.gauss(0, 1) for _ in range(3)]; r = math.sqrt(sum(c * c for c in v)) or 1.0
    pts[k] = tuple(1e6 * c / r for c in v)
pcd('outliers.pcd', pts)
pcd('cube.pcd', [(rnd.random(), rnd.random(), rnd.random()) for _ in range(n)])
PY
points() { head -c 400 "$1" 2>/dev/null | tr -d '\0' | awk '/^POINTS/{print $2; exit}'; }
fails=0
printf '%-9s %-14s %4s %9s %9s %9s  %s\n' input command exit seconds 'peak MB' points 'first error'
inputs=()
for in in "$WORK"/in/*.pcd; do
  name=$(basename "$in" .pcd)
  [[ $name =~ $ONLY ]] || continue
  inputs+=("$in")
  [ "${SKIP_OURS:-0}" = 1 ] && continue
  for cmd in ${COMMANDS:-denoise bilateral curvature enhance superres apss rimls compress decompress reconstruct}; do
    out="$WORK/out/$name.$cmd.pcd"
    case $cmd in
      denoise) args=(denoise "$in" "$out") ;;
      bilateral) args=(denoise "$in" "$out" --method bilateral) ;;
      curvature) args=(curvature "$in" "$out") ;;
      enhance) args=(enhance "$in" "$out" --alpha0 2) ;;
      superres) args=(superres "$in" "$out" --factor 2) ;;
      apss|rimls) args=(superres "$in" "$out" --factor 2 --method "$cmd") ;;
      compress) out="$WORK/out/$name.paps"; args=(compress "$in" "$out") ;;
      decompress) [ -f "$WORK/out/$name.paps" ] || continue; args=(decompress "$WORK/out/$name.paps" "$out") ;;
      # Merged into 20,000 cells first (the default max_points); output: a mesh, its facets counted.
      reconstruct) out="$WORK/out/$name.reconstruct.ply"; args=(reconstruct "$in" "$out") ;;
    esac
    [ "$cmd" = decompress ] || rm -f "$out"
    /usr/bin/time -f '%e %M' -o "$WORK/time.txt" timeout "$TIMEOUT" "$PAPS" "${args[@]}" --quiet \
      > "$WORK/stdout.txt" 2> "$WORK/stderr.txt"
    rc=$?
    read -r secs kb < <(tail -1 "$WORK/time.txt")
    err=$(grep -m1 -iE 'error|terminate|abort' "$WORK/stderr.txt" | cut -c1-110)
    n=-; [ "$cmd" = compress ] && [ -f "$out" ] && n="$(stat -c %s "$out") B"
    [ "$cmd" != compress ] && [ "$cmd" != reconstruct ] && [ -f "$out" ] && n=$(points "$out")
    [ "$cmd" = reconstruct ] && [ -f "$out" ] && n="$(head -c 400 "$out" | tr -d '\0' | awk '/^element face/{print $3; exit}') f"
    [ $rc -eq 124 ] || [ $rc -gt 128 ] && fails=$((fails + 1))
    [ $rc -eq 124 ] && secs=">$TIMEOUT"
    printf '%-9s %-14s %4s %9s %9s %9s  %s\n' "$name" "$cmd" "$rc" "$secs" "$(( ${kb:-0} / 1024 ))" "$n" "$err"
  done
done
echo "timeouts or signals: $fails"
if [ "${PEERS:-0}" = 1 ]; then
  echo
  "$PAPS" bench files "${inputs[@]}" --out "$WORK/peers" --timeout "$TIMEOUT" || fails=$((fails + 1))
fi
[ $fails -eq 0 ]
