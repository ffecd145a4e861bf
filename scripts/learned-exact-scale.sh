#!/usr/bin/env bash
# The learned study's *exact* flights with the plants' aerodynamics scaled
# in the controller's residual (`dflat experiment learned --exact-scale S`;
# the plants and the other flights unchanged), under several noise seeds:
# how the L and the planner's streams answer a drag the model under- (or
# over-) predicts, beside identify and the matched plant
# (docs/results.md, "What the L's corner rewards").
#
#   scripts/learned-exact-scale.sh                  # scales 1 and 0.85, seeds 1..5 (~40 s a run)
#   SCALES="1 0.85 0.7" SEEDS="1 2 3" scripts/learned-exact-scale.sh
#
# JSON per run in $OUT (default /tmp/dflat-learned-exact-scale); needs
# python3 (standard library only) for the summary.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds="${SEEDS:-1 2 3 4 5}"
scales="${SCALES:-1 0.85}"
out="${OUT:-/tmp/dflat-learned-exact-scale}"
mkdir -p "$out"
if ! command -v python3 >/dev/null; then
    echo "skipped: python3 is needed for the summary" >&2
    exit 0
fi
cargo build --release -q
for s in $scales; do
    for k in $seeds; do
        echo "scale $s, seed $k ..." >&2
        target/release/dflat experiment learned --no-seconds --no-progress \
            --seed "$k" --exact-scale "$s" --json "$out/exact_${s}_s$k.json" > /dev/null
    done
done
python3 - "$out" "$scales" "$seeds" <<'EOF'
import json, sys
out, scales, seeds = sys.argv[1], sys.argv[2].split(), sys.argv[3].split()
runs = {(s, k): json.load(open(f"{out}/exact_{s}_s{k}.json"))["rows"]
        for s in scales for k in seeds}
def rng(xs, d=2):
    return f"{min(xs):.{d}f}–{max(xs):.{d}f}"
first = runs[(scales[0], seeds[0])]
keys = [(r["plant"], int(r["vision_hz"]), r["shape"], r["speed"]) for r in first]
def row(s, k, key):
    for r in runs[(s, k)]:
        if (r["plant"], int(r["vision_hz"]), r["shape"], r["speed"]) == key:
            return r
    raise KeyError(key)
p95 = lambda r, m: r[m]["p95"]
print(f"seeds {' '.join(seeds)}; ranges over the seeds")
print("\nThe L, p95 over the matched plant's:\n")
head = " | ".join(f"exact × {s}" for s in scales)
print(f"| plant | poses | speed | identify | {head} | exact × {scales[-1]} better than identify |")
print("|---|---|---|---|" + "---|" * len(scales) + "---|")
for key in keys:
    if key[2] != "L":
        continue
    ident = [p95(row(scales[0], k, key), "identified") / p95(row(scales[0], k, key), "matched") for k in seeds]
    cols = []
    for s in scales:
        cols.append(rng([p95(row(s, k, key), "exact") / p95(row(s, k, key), "matched") for k in seeds]))
    wins = sum(p95(row(scales[-1], k, key), "exact") < p95(row(scales[-1], k, key), "identified") for k in seeds)
    print(f"| {key[0]} | {key[1]} Hz | {key[3]:g} m/s | {rng(ident)} | {' | '.join(cols)} | {wins} of {len(seeds)} |")
print("\nThe streams (eight, racing line), p95 in m over every plant, pose rate and speed:\n")
print(f"| flight | " + " | ".join(f"exact × {s}" for s in scales) + " | identify | matched |")
print("|---|" + "---|" * len(scales) + "---|---|")
streams = [key for key in keys if key[2] != "L"]
for shape in sorted({key[2] for key in streams}):
    ks = [key for key in streams if key[2] == shape]
    cols = [rng([p95(row(s, k, key), "exact") for key in ks for k in seeds], 3) for s in scales]
    ident = rng([p95(row(scales[0], k, key), "identified") for key in ks for k in seeds], 3)
    matched = rng([p95(row(scales[0], k, key), "matched") for key in ks for k in seeds], 3)
    print(f"| {shape} | {' | '.join(cols)} | {ident} | {matched} |")
EOF
