#!/usr/bin/env bash
# Fit time and peak memory of `gyropath fit` on simulated rides of 0.5, 1.5
# and 6 hours (100 Hz, 1 Hz GPS, 5 s segments), with the path written out.
# Peak memory is the process's maximum resident set (GNU time).
# Usage: benches/long_rides.sh [hours ...]   (needs /usr/bin/time)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --quiet
bin=target/release/gyropath
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
hours=("$@")
[ ${#hours[@]} -gt 0 ] || hours=(0.5 1.5 6)
printf '| ride | rows | load + fit + write | peak memory | fit RMS | iterations (step 1 + 2) |\n'
printf '| --- | --- | --- | --- | --- | --- |\n'
for h in "${hours[@]}"; do
    s=$(awk "BEGIN { print int($h * 3600) }")
    "$bin" simulate --seed 3 --duration "$s" --out "$dir/ride.csv" > /dev/null 2>&1
    /usr/bin/time -f '%e %M' -o "$dir/time" "$bin" fit "$dir/ride.csv" \
        --out "$dir/path.csv" --report "$dir/report.json" > /dev/null 2>&1
    read -r secs kb < "$dir/time"
    python3 - "$h" "$secs" "$kb" "$dir/report.json" <<'PY'
import json, sys
h, secs, kb, rep = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
r = json.load(open(rep))
print(f"| {h} h | {r['rows']:,} | {secs:.2f} s | {kb / 1024:.0f} MB "
      f"| {r['stats']['rms_horizontal_m']:.2f} m | {r['iterations_step1']} + {r['iterations_step2']} |")
PY
done
