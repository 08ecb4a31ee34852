#!/usr/bin/env bash
# HTTP/1.1 against HTTP/2 over TLS (issue 34, item 4): Tessera's client (`tessera fly URL`)
# reading one archive through tessera-link-proxy (bench/link_proxy.cpp, the link model of
# link_bench.sh) from
#
#   nginx-h2      nginx, TLS with HTTP/2 offered by ALPN (the client's default)
#   nginx-h1      the same nginx, the client limited to HTTP/1.1 (TESSERA_HTTP2=0)
#   serve-tls     `tessera serve --tls-cert` (HTTP/1.1 inside TLS)
#
# with a self-signed certificate made here and trusted through TESSERA_CA_FILE. Per run: time
# to full detail of one 1920x1080 view at the image centre (from the open), the connections
# the client opened and which version they spoke, the most requests it had on the wire at
# once, and its requests in all (summary.json's "link").
#
#   bench/http2_bench.sh                        # 8192^2 image, 20mbit:40ms, each client twice
#   bench/http2_bench.sh --size 16384 --links "20mbit:40ms 2mbit:150ms" --repeat 3
# Environment: TESSERA_BENCH_DIR (default /tmp/tessera-bench), TESSERA_BUILD_DIR (default build/).
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-bench}/http2
BUILD_DIR=${TESSERA_BUILD_DIR:-$REPO/build}
SIZE=8192
LINKS="20mbit:40ms"
REPEAT=2
while [[ $# -gt 0 ]]; do
  case $1 in
    --size) SIZE=$2; shift 2 ;;
    --links) LINKS=$2; shift 2 ;;
    --repeat) REPEAT=$2; shift 2 ;;
    -h|--help) sed -n '2,18p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "http2_bench: unknown option $1" >&2; exit 2 ;;
  esac
done

TESSERA=$BUILD_DIR/src/tools/tessera
PROXY=$BUILD_DIR/bench/tessera-link-proxy
MAKE_TIFF=$BUILD_DIR/bench/tessera-make-tiff
for tool in "$TESSERA" "$PROXY" "$MAKE_TIFF"; do
  [[ -x $tool ]] || { echo "http2_bench: $tool missing: build with -DTESSERA_BUILD_BENCH=ON" >&2; exit 1; }
done

RUN=$WORK/run-$(date -u +%Y%m%dT%H%M%SZ)
WWW=$WORK/www-$SIZE
mkdir -p "$RUN"
ln -sfn "$RUN" "$WORK/latest"
pids=()
cleanup() {
  local pid
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT

if [[ ! -f $WWW/image.tess ]]; then
  mkdir -p "$WWW"
  "$MAKE_TIFF" "$WWW/source.tif" "${SIZE}x${SIZE}" --seed 2
  "$TESSERA" build "$WWW/source.tif" -o "$WWW/image.tess.part" --codec jpeg --quality 85 \
    --tile 256 --border 1 --quiet
  rm "$WWW/source.tif"
  mv "$WWW/image.tess.part" "$WWW/image.tess"
fi
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 2 -subj /CN=127.0.0.1 \
  -addext subjectAltName=IP:127.0.0.1 -keyout "$RUN/key.pem" -out "$RUN/cert.pem" 2> /dev/null

source "$REPO/bench/link/servers.sh"
NGINX_LISTEN_FLAGS="ssl http2" NGINX_SCHEME=https start_nginx "$RUN" "$WWW" image.tess \
  "ssl_certificate $RUN/cert.pem; ssl_certificate_key $RUN/key.pem;"
"$TESSERA" serve "$WWW/image.tess" --port 0 --tls-cert "$RUN/cert.pem" --tls-key "$RUN/key.pem" \
  > "$RUN/serve.out" 2> "$RUN/serve.err" &
pids+=($!)
SERVE_PORT=$(port_of "$RUN/serve.out")
CX=$((SIZE / 2)); CY=$((SIZE / 2))

run_client() {  # run_client LINK CLIENT N: one JSON line into results.jsonl
  local link=$1 client=$2 n=$3 upstream=$NGINX_PORT http2=1 out proxy_pid proxy_port
  [[ $client == serve-tls ]] && upstream=$SERVE_PORT
  [[ $client == nginx-h1 ]] && http2=0
  out=$RUN/$client-${link//:/_}-$n
  mkdir -p "$out"
  "$PROXY" --upstream "127.0.0.1:$upstream" --rate "${link%%:*}" --rtt "${link#*:}" \
    > "$out/proxy.out" &
  proxy_pid=$!
  proxy_port=$(port_of "$out/proxy.out")
  printf '0 %s %s 1\n10 %s %s 1\n' "$CX" "$CY" "$CX" "$CY" > "$out/view.path"
  TESSERA_CA_FILE=$RUN/cert.pem TESSERA_HTTP2=$http2 "$TESSERA" fly \
    "https://127.0.0.1:$proxy_port/image.tess" --path "$out/view.path" --viewport 1920x1080 \
    --fps 60 --cache-mib 512 --out "$out" > "$out/fly.txt" 2>&1
  kill -TERM "$proxy_pid"; wait "$proxy_pid" || true
  python3 - "$out/summary.json" "$link" "$client" "$n" >> "$RUN/results.jsonl" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
full = s["jumps"][0]["full_detail_ms"]
link = s["link"]
print(json.dumps({"link": sys.argv[2], "client": sys.argv[3], "n": int(sys.argv[4]),
                  "full_detail_ms": s.get("open_ms", 0) + full if full is not None and full >= 0 else None,
                  **{k: link[k] for k in ("connections", "http1_connections", "http2_connections",
                                          "max_in_flight", "requests", "bytes_received")}}))
PY
  tail -1 "$RUN/results.jsonl"
}

echo "http2_bench: ${SIZE}^2, links $LINKS, $REPEAT run(s) each; $(uptime)"
for link in $LINKS; do
  for ((n = 1; n <= REPEAT; ++n)); do
    for client in nginx-h2 nginx-h1 serve-tls; do run_client "$link" "$client" "$n"; done
  done
done
python3 - "$RUN/results.jsonl" <<'PY' | tee "$RUN/report.md"
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| link | client | full detail ms (median) | connections (h1/h2) | max in flight | requests |")
print("|---|---|---|---|---|---|")
for link in dict.fromkeys(r["link"] for r in rows):
    for client in dict.fromkeys(r["client"] for r in rows):
        rs = [r for r in rows if r["link"] == link and r["client"] == client]
        full = [r["full_detail_ms"] for r in rs if r["full_detail_ms"] is not None]
        med = lambda k: statistics.median(r[k] for r in rs)
        print(f"| {link} | {client} | {statistics.median(full):.0f} ({', '.join(f'{x:.0f}' for x in full)}) "
              f"| {med('connections'):.0f} ({med('http1_connections'):.0f}/{med('http2_connections'):.0f}) "
              f"| {med('max_in_flight'):.0f} | {med('requests'):.0f} |")
PY
