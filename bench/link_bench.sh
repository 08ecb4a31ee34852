#!/usr/bin/env bash
# Remote streaming over a slow link (issue 5, item 6), in one run on this machine: for each
# link (default 20 Mbit/s with 40 ms RTT, and 2 Mbit/s with 150 ms RTT), the time to a complete
# first view and to full detail of one fixed 1920x1080 view, the bytes that crossed the link
# and the requests the server saw, for
#
#   tessera-serve   Tessera's client (tessera fly URL) against `tessera serve`
#   tessera-nginx   Tessera's client against nginx serving the .tess file statically
#   osd-nginx       OpenSeadragon (npm) in headless Chromium against Deep Zoom tiles of the same
#                   image made by `vips dzsave` and served by nginx
#
# The image is one synthetic RGB TIFF (tessera-make-tiff), turned into a Tessera archive
# (JPEG q85, 256-px tiles, border 1) and a Deep Zoom folder (JPEG q85, 256-px tiles, overlap 1):
# the same pixels, codec, quality and tile size on both sides.
#
# The link: this kernel has no netem (`tc qdisc add dev X root netem` answers "Specified qdisc
# kind is unknown"), so each client reaches its server through tessera-link-proxy
# (bench/link_proxy.cpp): one FIFO serialiser per direction at the link rate, shared by all the
# client's connections, half the RTT each way and a round trip per new connection. The proxy
# counts the bytes it carried; the servers' access logs count the requests.
#
# The view: centred on the image at 1 texel per pixel (full detail is level 0). Times run from
# the moment the client starts opening the image (archive header / .dzi request) to
#   first complete: every pixel of the view covered by some level (Tessera: fully_covered;
#                   OpenSeadragon: the first level all of whose visible tiles have loaded),
#   full detail:    every visible tile of the level the client chose (Tessera: the desired
#                   level; OpenSeadragon: its "fully loaded" event).
#
#   bench/link_bench.sh                  # 16384 x 16384 image, both links, each client once
#   bench/link_bench.sh --repeat 3 --links 20mbit:40ms
# Environment: TESSERA_BENCH_DIR (work dir, default /tmp/tessera-bench), TESSERA_BUILD_DIR
# (CMake build with tools and benchmarks, default build/).
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-bench}/link
BUILD_DIR=${TESSERA_BUILD_DIR:-$REPO/build}
SIZE=16384
LINKS="20mbit:40ms 2mbit:150ms"
REPEAT=1
VIEWPORT=1920x1080

while [[ $# -gt 0 ]]; do
  case $1 in
    --size) SIZE=$2; shift 2 ;;
    --links) LINKS=$2; shift 2 ;;
    --repeat) REPEAT=$2; shift 2 ;;
    -h|--help) sed -n '2,30p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "link_bench: unknown option $1" >&2; exit 2 ;;
  esac
done

TESSERA=$BUILD_DIR/src/tools/tessera
PROXY=$BUILD_DIR/bench/tessera-link-proxy
MAKE_TIFF=$BUILD_DIR/bench/tessera-make-tiff
for tool in "$TESSERA" "$PROXY" "$MAKE_TIFF"; do
  [[ -x $tool ]] || { echo "link_bench: $tool missing: build with -DTESSERA_BUILD_BENCH=ON" >&2; exit 1; }
done

"$REPO/bench/install_peers.sh"
"$REPO/scripts/install-deps.sh"
[[ -d $REPO/web/node_modules/openseadragon ]] || npm ci --prefix "$REPO/web" --no-audit --no-fund

mkdir -p "$WORK"
RUN=$WORK/run-$(date -u +%Y%m%dT%H%M%SZ)
mkdir -p "$RUN"
ln -sfn "$RUN" "$WORK/latest"
WWW=$WORK/www-$SIZE
pids=()
cleanup() {
  local pid
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT

# ---- the image, once per size
if [[ ! -f $WWW/.done ]]; then
  rm -rf "$WWW"; mkdir -p "$WWW"
  echo "link_bench: making the ${SIZE}x${SIZE} image, its archive and its Deep Zoom pyramid"
  "$MAKE_TIFF" "$WWW/source.tif" "${SIZE}x${SIZE}" --seed 2
  "$TESSERA" build "$WWW/source.tif" -o "$WWW/image.tess" --codec jpeg --quality 85 --tile 256 \
    --border 1 --quiet
  vips dzsave "$WWW/source.tif" "$WWW/image" --tile-size 256 --overlap 1 --suffix '.jpg[Q=85]'
  rm "$WWW/source.tif"
  touch "$WWW/.done"
fi

# ---- servers on loopback
source "$REPO/bench/link/servers.sh"
"$TESSERA" serve "$WWW/image.tess" --port 0 --access-log "$RUN/serve-access.log" \
  > "$RUN/serve.out" 2> "$RUN/serve.err" &
pids+=($!)
SERVE_PORT=$(port_of "$RUN/serve.out")
start_nginx "$RUN" "$WWW" image.dzi 'add_header Access-Control-Allow-Origin * always;'

# ---- the view: image centre, full detail, held long enough for the slowest link
CX=$((SIZE / 2)); CY=$((SIZE / 2))

run_client() {  # run_client LINK CLIENT N: one measurement, one JSON line into results.jsonl
  local link=$1 client=$2 n=$3 upstream log rate rtt out proxy_pid proxy_port
  rate=${link%%:*}; rtt=${link#*:}
  case $client in
    tessera-serve) upstream=$SERVE_PORT; log=$RUN/serve-access.log ;;
    *) upstream=$NGINX_PORT; log=$RUN/nginx-access.log ;;
  esac
  out=$RUN/$client-${link//:/_}-$n
  mkdir -p "$out"
  "$PROXY" --upstream "127.0.0.1:$upstream" --rate "$rate" --rtt "$rtt" > "$out/proxy.out" &
  proxy_pid=$!
  proxy_port=$(port_of "$out/proxy.out")
  local requests_before
  requests_before=$(wc -l < "$log" 2>/dev/null || echo 0)
  local hold_s=20
  [[ $rate == 2mbit ]] && hold_s=60
  case $client in
    tessera-*)
      printf '0 %s %s 1\n%s %s %s 1\n' "$CX" "$CY" "$hold_s" "$CX" "$CY" > "$out/view.path"
      "$TESSERA" fly "http://127.0.0.1:$proxy_port/image.tess" --path "$out/view.path" \
        --viewport "$VIEWPORT" --fps 60 --cache-mib 512 --out "$out" > "$out/fly.txt" 2>&1
      python3 - "$out/summary.json" "$out/frames.csv" > "$out/result.json" <<'PY'
import csv, json, sys
s = json.load(open(sys.argv[1]))
open_ms = s.get("open_ms", 0)
full = s["jumps"][0]["full_detail_ms"]
# Bytes read by the first frame at full detail: what the view itself cost (the flight goes on
# to load the rest of the clip regions, as a viewer does while the user looks).
at_full = next((int(r["bytes_read"]) for r in csv.DictReader(open(sys.argv[2]))
                if float(r["coverage_desired"]) >= 1.0), None)
print(json.dumps({"first_complete_ms": open_ms + s["startup_ms"] if s["startup_ms"] is not None else None,
                  "full_detail_ms": open_ms + full if full is not None and full >= 0 else None,
                  "open_ms": open_ms, "bytes_at_full_detail": at_full}))
PY
      ;;
    osd-nginx)
      node "$REPO/bench/link/osd.mjs" --dzi "http://127.0.0.1:$proxy_port/image.dzi" --x "$CX" \
        --y "$CY" --tpp 1 --viewport "$VIEWPORT" --timeout-s 300 > "$out/result.json"
      ;;
  esac
  kill -TERM "$proxy_pid"; wait "$proxy_pid" || true
  local carried requests
  carried=$(proxy_carried "$out/proxy.out")
  requests=$(( $(wc -l < "$log") - requests_before ))
  python3 - "$out/result.json" "$link" "$client" "$n" "$carried" "$requests" >> "$RUN/results.jsonl" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
r.update(link=sys.argv[2], client=sys.argv[3], run=int(sys.argv[4]),
         bytes_to_client=int(sys.argv[5] or 0), requests=int(sys.argv[6]))
print(json.dumps(r))
PY
  tail -1 "$RUN/results.jsonl"
}

{
  echo "date: $(date -u +%FT%TZ)"
  echo "commit: $(git -C "$REPO" rev-parse --short HEAD)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(nproc) cores"
  echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "image: ${SIZE}x${SIZE}, view ${VIEWPORT} at (${CX}, ${CY}), 1 texel per pixel"
  echo "nginx: $(nginx -v 2>&1 | cut -d/ -f2), vips: $(vips --version), chromium: $(chromium --version 2>/dev/null | head -1)"
} | tee "$RUN/machine.txt"

for link in $LINKS; do
  for ((n = 1; n <= REPEAT; ++n)); do
    for client in tessera-serve tessera-nginx osd-nginx; do
      run_client "$link" "$client" "$n"
    done
  done
done

python3 - "$RUN/results.jsonl" <<'PY' | tee "$RUN/report.md"
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None
def fmt(ms):
    return "-" if ms is None else f"{ms / 1000:.2f} s"
print("| link | client | first complete view | full detail | vs OpenSeadragon | bytes read by full detail | bytes to client, whole run | requests, whole run |")
print("|---|---|---|---|---|---|---|---|")
for link in dict.fromkeys(r["link"] for r in rows):
    by = {}
    for r in rows:
        if r["link"] == link: by.setdefault(r["client"], []).append(r)
    osd_full = median(r["full_detail_ms"] for r in by.get("osd-nginx", []))
    for client, runs in by.items():
        first = median(r["first_complete_ms"] for r in runs)
        full = median(r["full_detail_ms"] for r in runs)
        ratio = f"{full / osd_full:.2f}x" if full and osd_full else "-"
        size = median(r["bytes_to_client"] for r in runs)
        requests = median(r["requests"] for r in runs)
        # OpenSeadragon stops at full detail: everything it fetched was for the view.
        at_full = median(r.get("bytes_at_full_detail", r["bytes_to_client"]) for r in runs)
        print(f"| {link} | {client} | {fmt(first)} | {fmt(full)} | {ratio} | "
              f"{at_full / 1e6:.2f} MB | {size / 1e6:.2f} MB | {requests:.0f} |")
PY
echo "link_bench: results in $RUN"
