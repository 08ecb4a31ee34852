#!/usr/bin/env bash
# Adaptive scheduling over a simulated link (Marvie & Bouatouch, part III): `tessera fly
# --link` with the adaptive policy on and off, on a jump path (time to a complete first view,
# time to full detail after each jump) and a pan (coverage while moving), at 20 Mbit/s with a
# 40 ms round trip and 2 Mbit/s with 150 ms. Prints a Markdown table (docs/runtime.md).
#
#   bench/adaptive_link.sh [REPEATS]      # default 3 repeats; medians are reported
#
# Environment: TESSERA (the tessera binary, default build/src/tools/tessera), ADAPTIVE_DIR
# (work folder, default /tmp/tessera-adaptive). The archive is
# `tessera build synthetic:16384x16384` (256-px JPEG tiles, 23.8 MiB), built once.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
TESSERA=${TESSERA:-$REPO/build/src/tools/tessera}
WORK=${ADAPTIVE_DIR:-/tmp/tessera-adaptive}
REPEATS=${1:-3}
ARCHIVE=$WORK/s.tess
mkdir -p "$WORK"
[[ -f $ARCHIVE ]] || "$TESSERA" build synthetic:16384x16384 -o "$ARCHIVE"

for link in 20mbit:40ms 2mbit:150ms; do
  for adaptive in on off; do
    for r in $(seq 1 "$REPEATS"); do
      # Jumps: five spots, 6 s each. Pan: 10 s at 1000 px/s, FHD at full resolution.
      # Niceness-5 loaders: the machine is shared, and idle-priority loaders would wait for
      # other processes' work (docs/runtime.md).
      "$TESSERA" fly "$ARCHIVE" --link "$link" --adaptive "$adaptive" --path jump \
        --duration 30 --fps 30 --loader-priority nice -q --out "$WORK/$link-$adaptive-jump-$r"
      "$TESSERA" fly "$ARCHIVE" --link "$link" --adaptive "$adaptive" --path pan --speed 1000 \
        --duration 10 --fps 30 --loader-priority nice -q --out "$WORK/$link-$adaptive-pan-$r"
    done
  done
done

python3 - "$WORK" "$REPEATS" <<'EOF'
import csv, json, statistics, sys
work, repeats = sys.argv[1], int(sys.argv[2])
def load(link, adaptive, path, r):
    return json.load(open(f"{work}/{link}-{adaptive}-{path}-{r}/summary.json"))
def med(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None
def fmt(v, unit=""):
    return "-" if v is None else (f"{v:.0f}{unit}" if abs(v) >= 10 else f"{v:.2f}{unit}")
print("| link | adaptive | first complete view ms | first full detail ms | full detail after a jump ms (median) | jumps at full detail | pan: frames at full detail | pan: finest level covering the view (median) | transferred MiB (jumps + pan) | reads cancelled |")
print("|---|---|---|---|---|---|---|---|---|---|")
for link in ["20mbit:40ms", "2mbit:150ms"]:
    for adaptive in ["on", "off"]:
        startup, first, after, reached, pan_full, moved, transferred, cancelled = ([] for _ in range(8))
        for r in range(1, repeats + 1):
            j, p = load(link, adaptive, "jump", r), load(link, adaptive, "pan", r)
            startup.append(j["startup_ms"])
            first.append(j["jumps"][0]["full_detail_ms"])
            later = [x["full_detail_ms"] for x in j["jumps"][1:]]
            after.append(med(later))
            reached.append(sum(x is not None for x in later))
            pan_full.append(p["frames_full_detail_pct"])
            rows = list(csv.DictReader(open(f"{work}/{link}-{adaptive}-pan-{r}/frames.csv")))
            moved.append(statistics.median(int(x["finest_full_level"]) for x in rows))
            transferred.append((j["link"]["bytes_received"] + p["link"]["bytes_received"]) / 2**20)
            cancelled.append(j["reads_cancelled"] + p["reads_cancelled"])
        print(f"| {link} | {adaptive} | {fmt(med(startup))} | {fmt(med(first))} | {fmt(med(after))} "
              f"| {fmt(med(reached))} of {len(j['jumps']) - 1} | {fmt(med(pan_full), '%')} "
              f"| {fmt(med(moved))} | {fmt(med(transferred))} | {fmt(med(cancelled))} |")
EOF
