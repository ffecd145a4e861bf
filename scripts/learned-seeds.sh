#!/usr/bin/env bash
# The learned study (`dflat experiment learned`, no seconds study) flown
# under several noise seeds, and what holds across them: the budgets
# "learned p95 <= 1.1x matched" and "never worse than identify" cell by
# cell, and the cells where identify wins, with every seed's figures.
#
#   scripts/learned-seeds.sh            # seeds 1..5 (~40 s each on 2 cores)
#   SEEDS="1 2 3" scripts/learned-seeds.sh
#
# JSON per seed in $OUT (default /tmp/dflat-learned-seeds); needs python3
# (standard library only) for the summary.
set -euo pipefail
cd "$(dirname "$0")/.."
seeds="${SEEDS:-1 2 3 4 5}"
out="${OUT:-/tmp/dflat-learned-seeds}"
mkdir -p "$out"
if ! command -v python3 >/dev/null; then
    echo "skipped: python3 is needed for the summary" >&2
    exit 0
fi
cargo build --release -q
for k in $seeds; do
    echo "seed $k ..." >&2
    target/release/dflat experiment learned --no-seconds --no-progress \
        --seed "$k" --json "$out/learned_s$k.json" > "$out/learned_s$k.txt"
done
python3 - "$out" $seeds <<'EOF'
import json, sys
out, seeds = sys.argv[1], sys.argv[2:]
runs = {k: json.load(open(f"{out}/learned_s{k}.json"))["rows"] for k in seeds}
cells = {}
for k, rows in runs.items():
    for r in rows:
        key = (r["plant"], int(r["vision_hz"]), r["shape"], r["speed"])
        cells.setdefault(key, {})[k] = r
p95 = lambda r, m: r[m]["p95"]
total = sum(len(v) for v in cells.values())
over = [(key, k, p95(r, "learned_window") / p95(r, "matched"))
        for key, per in cells.items() for k, r in per.items()
        if p95(r, "learned_window") > 1.1 * p95(r, "matched")]
worse = [(key, k) for key, per in cells.items() for k, r in per.items()
         if p95(r, "learned_window") > p95(r, "identified")]
print(f"seeds {' '.join(seeds)}: {total} cells (plant, pose rate, shape, speed, seed)")
print(f"learned (window from data) <= 1.1x matched: {total - len(over)} of {total}")
for key, k, ratio in over:
    r = cells[key][k]
    print(f"  over: {key} seed {k}: {ratio:.3f}x (learned {p95(r, 'learned_window'):.4f}, "
          f"matched {p95(r, 'matched'):.4f}, exact {p95(r, 'exact'):.4f}, "
          f"identify {p95(r, 'identified'):.4f} m)")
print(f"learned never worse than identify: {total - len(worse)} of {total}")
shown = sorted({key for key, _ in worse})
if shown:
    print("\n| plant | poses | shape | speed | learned | identify | exact aerodynamics | matched | learned worse than identify |")
    print("|---|---|---|---|---|---|---|---|---|")
    for key in shown:
        per = cells[key]
        col = lambda m: " ".join(f"{p95(per[k], m):.3f}" for k in seeds)
        n = sum(p95(per[k], "learned_window") > p95(per[k], "identified") for k in seeds)
        print(f"| {key[0]} | {key[1]} Hz | {key[2]} | {key[3]:g} m/s | {col('learned_window')} | "
              f"{col('identified')} | {col('exact')} | {col('matched')} | {n} of {len(seeds)} |")
EOF
