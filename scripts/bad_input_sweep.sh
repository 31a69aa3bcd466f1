#!/usr/bin/env bash
# Runs every paps command on damaged and degenerate inputs and prints one line per run: exit
# code, wall time, peak memory, files left behind, and the first error or warning line.
#   scripts/bad_input_sweep.sh [PAPS=build/apps/paps/paps] [WORK=/tmp/paps_bad_inputs]
# SKIP=REGEX leaves out the inputs whose names match (e.g. SKIP=bomb for a binary that would
# try to allocate what the bomb files promise: up to 24 GB).
# A good line has exit 0 with an output, or exit 1 with one clear error and no output; exit
# codes of 124 (timeout after 120 s) or above 128 (a signal) are failures, counted at the end.
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PAPS=$(realpath "${1:-$ROOT/build/apps/paps/paps}")
WORK=${2:-/tmp/paps_bad_inputs}
rm -rf "$WORK"; mkdir -p "$WORK/in" "$WORK/out"
python3 - "$WORK/in" <<'PY'
import math, os, random, struct, sys
d = sys.argv[1]; rnd = random.Random(1)
def f32(v): return struct.unpack('<f', struct.pack('<f', v))[0] if math.isfinite(v) and abs(v) < 3e38 else v
def pcd(name, pts):
    with open(os.path.join(d, name), 'w') as f:
        f.write("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                "WIDTH %d\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA ascii\n" % (len(pts), len(pts)))
        for p in pts: f.write("%r %r %r\n" % tuple(f32(v) for v in p))
xy = [(rnd.random(), rnd.random()) for _ in range(2000)]
wave = [(x, y, 0.1 * math.sin(5 * x)) for x, y in xy]
pcd('empty.pcd', []); pcd('allnan.pcd', [(math.nan,) * 3] * 100); pcd('one.pcd', [(1, 2, 3)])
pcd('three.pcd', [(rnd.random(), rnd.random(), rnd.random()) for _ in range(3)])
pcd('ten.pcd', [(rnd.random(), rnd.random(), rnd.random()) for _ in range(10)])
pcd('identical.pcd', [(1, 2, 3)] * 1000)
pcd('line.pcd', [(t, 2 * t, 3 * t) for t in (rnd.random() for _ in range(1000))])
pcd('plane.pcd', [(x, y, 0) for x, y in xy])
pcd('huge.pcd', [(x * 1e30, y * 1e30, 0) for x, y in xy]); pcd('tiny.pcd', [(x * 1e-30, y * 1e-30, 0) for x, y in xy])
pcd('someinf.pcd', [(math.inf,) * 3 if i % 7 == 0 else p for i, p in enumerate(wave)])
pcd('somenan.pcd', [(math.nan,) * 3 if i % 3 == 0 else p for i, p in enumerate(wave)])
pcd('outlier.pcd', wave[:5] + [(1e30, 1e30, 1e30)] + wave[6:])
pcd('farclusters.pcd', [(x, y, 0) for x, y in xy] + [(x + 1e6, y + 1e6, 0) for x, y in xy])
open(os.path.join(d, 'garbage.pcd'), 'wb').write(bytes(rnd.randrange(256) for _ in range(5000)))
s = open(os.path.join(d, 'plane.pcd')).read()
open(os.path.join(d, 'truncated.pcd'), 'w').write(s[:len(s) // 2])
open(os.path.join(d, 'badcount.pcd'), 'w').write(s.replace('POINTS 2000', 'POINTS 5000'))
open(os.path.join(d, 'zerobytes.pcd'), 'w').close()
head = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
open(os.path.join(d, 'bomb_binary.pcd'), 'wb').write((head + "WIDTH 2000000000\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2000000000\nDATA binary\n").encode() + bytes(1000))
open(os.path.join(d, 'bomb_ascii.pcd'), 'w').write(head + "WIDTH 2000000000\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2000000000\nDATA ascii\n1 2 3\n")
open(os.path.join(d, 'bomb_packed.pcd'), 'wb').write((head + "WIDTH 10\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 10\nDATA binary_compressed\n").encode() + struct.pack('<II', 16, 0x0fffffff) + bytes(100))
open(os.path.join(d, 'bomb.ply'), 'wb').write(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n" + bytes(100))
ply = "ply\nformat ascii 1.0\nelement vertex 2000\nproperty float x\nproperty float y\nproperty float z\nend_header\n" + "".join("%f %f 0\n" % p for p in xy)
open(os.path.join(d, 'truncated.ply'), 'w').write(ply[:3000])
open(os.path.join(d, 'zerobytes.ply'), 'w').close()
PY
bad=0; runs=0
for IN in "$WORK"/in/* "$WORK/in/missing.pcd"; do
  name=$(basename "$IN")
  if [ -n "${SKIP:-}" ] && [[ $name =~ $SKIP ]]; then continue; fi
  for c in "denoise" "denoise --method bilateral" "curvature" "enhance --alpha0 2" "compress" \
           "superres --factor 4" "superres --factor 4 --method apss" "superres --factor 4 --method rimls"; do
    set -- $c; cmd=$1; shift
    out="$WORK/out/o.pcd"; [ "$cmd" = compress ] && out="$WORK/out/o.paps"
    rm -f "$WORK"/out/*
    /usr/bin/time -f "%e %M" -o "$WORK/time" timeout 120 "$PAPS" "$cmd" "$IN" "$out" "$@" --quiet > "$WORK/log" 2>&1
    rc=$?
    read -r secs kb < <(tail -1 "$WORK/time" | grep -E '^[0-9.]+ [0-9]+$' || echo "? ?")
    left=$(ls "$WORK/out" | tr '\n' ' ')
    msg=$(grep -m1 -i 'error\|warning\|terminate' "$WORK/log" | cut -c1-120)
    printf "%-16s %-34s exit %-3s %6s s %8s KB  out: %-7s %s\n" "$name" "$c" "$rc" "$secs" "$kb" "${left:--}" "$msg"
    runs=$((runs + 1))
    if [ $rc -ge 124 ] || { [ $rc -ne 0 ] && [ -n "$left" ]; }; then bad=$((bad + 1)); fi
  done
done
echo "$runs runs, $bad failures (crash, timeout, or output left by a failed run)"
[ $bad -eq 0 ]
