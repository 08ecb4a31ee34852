#!/usr/bin/env bash
# HTTP tile server load test (issue 5, item 7; issue 34, item 6): `tessera serve` next to nginx
# serving the same tile bytes as plain files, both on loopback, plain HTTP and HTTPS, all
# measured by wrk in one run.
#
#   1. an archive (synthetic 8192 x 8192, 256-px JPEG q85 tiles, no border) is built once into
#      $TESSERA_BENCH_DIR/serve (reused when present);
#   2. tessera serve starts on an ephemeral port; every encoded tile of every level is fetched
#      from it once into files at the same URL paths (tiles/<archive>/<image>/<level>/<x>/<y>),
#      which both warms the page cache and gives nginx the identical bytes;
#   3. nginx starts on loopback with its own config, pid and logs in a temp folder, with a
#      plain and a TLS port; a second tessera serve runs with --tls-cert; both TLS servers use
#      one self-signed P-256 certificate made by openssl for the run;
#   4. wrk (random tiles from the list, --latency, keep-alive) runs against each server at each
#      count of --connections (default 64 and 1000), plain and TLS, alternating tessera and
#      nginx; then (unless --no-slow) at 64 connections while a helper holds 1000 slow clients
#      (partial headers, one byte every few seconds, reconnecting when closed) on the plain
#      servers;
#      with --rate R the load is paced instead of saturating: each connection waits a random
#      (exponential) delay before each request, so that all of them together offer about R
#      requests/s (--tls-rate for the TLS runs, default R / 2); p99 then measures the latency
#      clients see at a load both servers sustain, not the queue of a saturated closed loop
#      (at saturation Little's law makes the mean latency connections / throughput);
#   5. a table of requests/s, MB/s, p50/p99 latency and each server's CPU time per request
#      (user + system, from /proc: steadier than throughput on a shared machine), and the
#      tessera/nginx ratios, against the targets (issue 34: at 1000 connections throughput
#      >= 1.0x nginx and p99 < 50 ms, TLS on and off; issue 5: p99 < 20 ms at 64
#      connections, < 100 ms with 1000 slow clients).
#
# Both servers get the same number of worker threads (--threads, default: all cores). The
# machine is shared: the 1-minute load average is printed before every run.
#
#   bench/serve_bench.sh [--duration 10] [--threads N] [--connections "64 1000"] [--no-tls]
#                        [--no-slow] [--rate R] [--tls-rate R] [--build-dir build]
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-bench}/serve
BUILD_DIR=$REPO/build
DURATION=10
THREADS=$(nproc)
CONNECTIONS="64 1000"
TLS=1
SLOW=1
RATE=0
TLS_RATE=
while (($#)); do
  case $1 in
    --duration) DURATION=$2; shift 2 ;;
    --threads) THREADS=$2; shift 2 ;;
    --connections) CONNECTIONS=$2; shift 2 ;;
    --no-tls) TLS=0; shift ;;
    --no-slow) SLOW=0; shift ;;
    --rate) RATE=$2; shift 2 ;;
    --tls-rate) TLS_RATE=$2; shift 2 ;;
    --build-dir) BUILD_DIR=$2; shift 2 ;;
    -h|--help) sed -n '2,34p' "$0"; exit 0 ;;
    *) echo "serve_bench: unknown option $1" >&2; exit 2 ;;
  esac
done

[[ $RATE =~ ^[0-9]+$ && ${TLS_RATE:-0} =~ ^[0-9]+$ ]] ||
  { echo "serve_bench: --rate and --tls-rate take requests per second" >&2; exit 2; }
TLS_RATE=${TLS_RATE:-$((RATE / 2))}
TESSERA=$BUILD_DIR/src/tools/tessera
for tool in "$TESSERA" nginx wrk curl python3 openssl; do
  command -v "$tool" >/dev/null || [[ -x $tool ]] || { echo "serve_bench: $tool not found" >&2; exit 1; }
done
NGINX=$(command -v nginx)

mkdir -p "$WORK"
ARCHIVE=$WORK/bench.tess
if [[ ! -s $ARCHIVE ]]; then
  echo "serve_bench: building $ARCHIVE"
  "$TESSERA" build synthetic:8192x8192:2 -o "$ARCHIVE" --tile 256 --codec jpeg --quality 85 --quiet
fi

RUN=$(mktemp -d /tmp/tessera-serve-bench.XXXXXX)
# nginx workers started by root run as an unprivileged user: they must be able to read the tiles.
chmod 755 "$RUN"
PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
  if [[ -f $RUN/nginx.pid ]]; then kill "$(cat "$RUN/nginx.pid")" 2>/dev/null || true; fi
  wait 2>/dev/null || true
  rm -rf "$RUN"
}
trap cleanup EXIT

# tessera serve: the port comes from its first line, read through a FIFO kept open for the
# whole run. Sets STARTED_PID and STARTED_PORT.
start_tessera() {  # name [serve options...]
  local name=$1 fd line
  shift
  mkfifo "$RUN/$name.out"
  "$TESSERA" serve "$ARCHIVE" --port 0 --threads "$THREADS" "$@" >"$RUN/$name.out" 2>"$RUN/$name.err" &
  STARTED_PID=$!
  PIDS+=($STARTED_PID)
  exec {fd}<"$RUN/$name.out"
  read -r line <&"$fd"
  STARTED_PORT=${line##*:}
  echo "serve_bench: $line (threads $THREADS)"
}

start_tessera tessera
TESSERA_PID=$STARTED_PID
TESSERA_PORT=$STARTED_PORT

# One self-signed certificate for both TLS servers (wrk does not verify it).
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 1 -subj /CN=127.0.0.1 \
  -keyout "$RUN/key.pem" -out "$RUN/cert.pem" 2>/dev/null
chmod 644 "$RUN/key.pem"
if ((TLS)); then
  start_tessera tessera-tls --tls-cert "$RUN/cert.pem" --tls-key "$RUN/key.pem"
  TESSERA_TLS_PORT=$STARTED_PORT
  TESSERA_TLS_PID=$STARTED_PID
fi

# Tile list and files: every encoded tile (204 = uniform or empty, no payload, skipped).
python3 - "$TESSERA_PORT" "$RUN" <<'EOF'
import http.client, json, os, sys
port, run = int(sys.argv[1]), sys.argv[2]
conn = http.client.HTTPConnection("127.0.0.1", port)
def get(path):
    conn.request("GET", path)
    r = conn.getresponse()
    return r.status, r.read()
status, body = get("/bench/info.json")
info = json.loads(body)
paths = []
for image in info["images"]:
    for level in image["levels"]:
        for y in range(level["tiles_y"]):
            for x in range(level["tiles_x"]):
                path = f"/bench/{image['index']}/{level['level']}/{x}/{y}"
                status, payload = get(path)
                if status != 200:
                    continue
                out = os.path.join(run, "tiles" + path)
                os.makedirs(os.path.dirname(out), exist_ok=True)
                with open(out, "wb") as f:
                    f.write(payload)
                paths.append(path)
with open(os.path.join(run, "paths.txt"), "w") as f:
    f.write("\n".join(paths) + "\n")
total = sum(os.path.getsize(os.path.join(run, "tiles" + p)) for p in paths)
print(f"serve_bench: {len(paths)} encoded tiles, {total / len(paths) / 1024:.1f} KiB on average")
EOF

chmod -R a+rX "$RUN/tiles"

# nginx: its own config, pid and logs; the tiles as files; the same number of workers.
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
NGINX_PORT=$(free_port)
NGINX_TLS_PORT=$(free_port)
mkdir -p "$RUN/nginx-tmp"
cat >"$RUN/nginx.conf" <<EOF
worker_processes $THREADS;
pid $RUN/nginx.pid;
error_log $RUN/nginx-error.log warn;
worker_rlimit_nofile 20000;
events { worker_connections 8192; }
http {
  access_log off;
  sendfile on;
  tcp_nopush on;
  keepalive_requests 1000000;
  client_body_temp_path $RUN/nginx-tmp;
  proxy_temp_path $RUN/nginx-tmp;
  fastcgi_temp_path $RUN/nginx-tmp;
  uwsgi_temp_path $RUN/nginx-tmp;
  scgi_temp_path $RUN/nginx-tmp;
  default_type application/octet-stream;
  ssl_certificate $RUN/cert.pem;
  ssl_certificate_key $RUN/key.pem;
  ssl_protocols TLSv1.2 TLSv1.3;
  ssl_session_cache shared:bench:1m;
  server {
    listen 127.0.0.1:$NGINX_PORT;
    listen 127.0.0.1:$NGINX_TLS_PORT ssl;
    root $RUN/tiles;
    add_header Cache-Control "public, max-age=31536000, immutable";
  }
}
EOF
"$NGINX" -c "$RUN/nginx.conf" -p "$RUN" -g 'daemon on;'
curl -sf -o /dev/null "http://127.0.0.1:$NGINX_PORT$(head -1 "$RUN/paths.txt")" ||
  { echo "serve_bench: nginx does not serve the tiles" >&2; cat "$RUN/nginx-error.log" >&2; exit 1; }

cat >"$RUN/random_tiles.lua" <<'EOF'
local paths = {}
for line in io.lines(os.getenv("TILE_LIST")) do paths[#paths + 1] = line end
math.randomseed(os.time() + (tonumber(tostring({}):sub(8), 16) or 0))
request = function()
  return wrk.format("GET", paths[math.random(#paths)])
end
-- Paced runs (PACE_MS > 0): an exponential wait before each request, so the connections'
-- requests together arrive as a Poisson stream of about connections / PACE_MS per ms rather
-- than in step.
local pace_ms = tonumber(os.getenv("PACE_MS") or "0")
if pace_ms > 0 then
  delay = function()
    return math.floor(-pace_ms * math.log(1 - math.random()) + 0.5)
  end
end
EOF

# The slow clients: N connections that each send a partial header and then one more header
# byte every few seconds, reconnecting when the server closes them.
cat >"$RUN/slow_clients.py" <<'EOF'
import selectors, socket, sys, time
port, count = int(sys.argv[1]), int(sys.argv[2])
sel = selectors.DefaultSelector()
socks = {}
def open_one():
    s = socket.create_connection(("127.0.0.1", port))
    s.setblocking(False)
    s.send(b"GET /bench/0/0/0/0 HTTP/1.1\r\nHost: x\r\nX-Slow: ")
    sel.register(s, selectors.EVENT_READ)
    socks[s] = time.monotonic()
for _ in range(count):
    open_one()
print("ready", flush=True)
reconnects = 0
while True:
    for key, _ in sel.select(timeout=1.0):
        s = key.fileobj
        try:
            data = s.recv(4096)
        except OSError:
            data = b""
        if not data:
            sel.unregister(s); s.close(); del socks[s]; reconnects += 1
            open_one()
    now = time.monotonic()
    for s, last in list(socks.items()):
        if now - last > 3:
            try:
                s.send(b"a")
            except OSError:
                pass
            socks[s] = now
EOF

# CPU time (user + system, clock ticks) of the given processes, from /proc.
cpu_ticks() {
  local total=0 pid
  for pid in "$@"; do total=$((total + $(awk '{print $14 + $15}' "/proc/$pid/stat"))); done
  echo "$total"
}
CLK_TCK=$(getconf CLK_TCK)
NGINX_WORKERS=$(pgrep -P "$(cat "$RUN/nginx.pid")" | tr '\n' ' ')

RESULTS=$RUN/results.txt
: >"$RESULTS"
# Besides wrk's figures, the server's CPU time per request: on a shared machine throughput
# follows the load of the moment, while CPU per request moves much less.
run_wrk() {  # name port connections scheme pid...
  local name=$1 port=$2 conns=$3 scheme=$4
  shift 4
  local wrk_threads=$((THREADS < 4 ? THREADS : 4)) ticks rate=$RATE pace_ms=0
  [[ $scheme == https ]] && rate=$TLS_RATE
  ((rate > 0)) && pace_ms=$(python3 -c "print($conns * 1000 / $rate)")
  echo "serve_bench: $name, $conns connections, ${DURATION}s$( ((rate > 0)) && echo ", paced at $rate requests/s"), load average $(cut -d' ' -f1 /proc/loadavg)"
  ticks=$(cpu_ticks "$@")
  PACE_MS=$pace_ms TILE_LIST=$RUN/paths.txt wrk -t"$wrk_threads" -c"$conns" -d"${DURATION}s" --latency \
    -s "$RUN/random_tiles.lua" "$scheme://127.0.0.1:$port" >"$RUN/wrk.txt" 2>&1
  ticks=$(($(cpu_ticks "$@") - ticks))
  python3 - "$name" "$conns" "$RUN/wrk.txt" "$ticks" "$CLK_TCK" >>"$RESULTS" <<'EOF'
import re, sys
name, conns, path = sys.argv[1], sys.argv[2], sys.argv[3]
cpu_seconds = int(sys.argv[4]) / int(sys.argv[5])
text = open(path).read()
def latency(label):
    m = re.search(r"^\s+%s\s+([\d.]+)(us|ms|s)\s*$" % label, text, re.M)
    if not m: return float("nan")
    return float(m.group(1)) * {"us": 1e-3, "ms": 1.0, "s": 1e3}[m.group(2)]
rps = float(re.search(r"Requests/sec:\s+([\d.]+)", text).group(1))
mbs = re.search(r"Transfer/sec:\s+([\d.]+)(\w+)", text)
mb = float(mbs.group(1)) * {"B": 1e-6, "KB": 1.024e-3, "MB": 1.048576, "GB": 1073.741824}[mbs.group(2)]
errors = re.search(r"Socket errors: (.*)", text)
non2xx = re.search(r"Non-2xx or 3xx responses: (\d+)", text)
requests = int(re.search(r"(\d+) requests in", text).group(1))
cpu_us = cpu_seconds * 1e6 / requests if requests else float("nan")
print(f"{name}\t{conns}\t{rps:.0f}\t{mb:.1f}\t{latency('50%'):.2f}\t{latency('99%'):.2f}\t"
      f"{errors.group(1) if errors else '-'}\t{non2xx.group(1) if non2xx else 0}\t{cpu_us:.1f}")
EOF
  tail -1 "$RESULTS"
}

if ((TLS)); then
  curl -sfk -o /dev/null "https://127.0.0.1:$NGINX_TLS_PORT$(head -1 "$RUN/paths.txt")" ||
    { echo "serve_bench: nginx does not serve the tiles over TLS" >&2; exit 1; }
fi
for conns in $CONNECTIONS; do
  run_wrk tessera "$TESSERA_PORT" "$conns" http "$TESSERA_PID"
  # shellcheck disable=SC2086 # one argument per worker
  run_wrk nginx "$NGINX_PORT" "$conns" http $NGINX_WORKERS
  if ((TLS)); then
    run_wrk tessera-tls "$TESSERA_TLS_PORT" "$conns" https "$TESSERA_TLS_PID"
    # shellcheck disable=SC2086
    run_wrk nginx-tls "$NGINX_TLS_PORT" "$conns" https $NGINX_WORKERS
  fi
done

for target in tessera nginx; do
  ((SLOW)) || break
  port=$TESSERA_PORT
  [[ $target == nginx ]] && port=$NGINX_PORT
  mkfifo "$RUN/slow.$target"
  python3 "$RUN/slow_clients.py" "$port" 1000 >"$RUN/slow.$target" &
  slow_pid=$!
  PIDS+=($slow_pid)
  exec 4<"$RUN/slow.$target"
  read -r _ <&4
  pids=$TESSERA_PID
  [[ $target == nginx ]] && pids=$NGINX_WORKERS
  # shellcheck disable=SC2086
  run_wrk "$target+1000slow" "$port" 64 http $pids
  kill "$slow_pid" 2>/dev/null || true
  exec 4<&-
done

# Memory: the server's peak and current resident set after all runs (1000 slow clients
# included), from /proc.
rss() { awk -v k="$1" '$1 == k ":" {printf "%.1f MiB", $2 / 1024}' "/proc/$TESSERA_PID/status"; }
echo
echo "tessera serve memory: peak RSS $(rss VmHWM), now $(rss VmRSS)"
echo
echo "| server | connections | requests/s | MB/s | p50 ms | p99 ms | socket errors | non-2xx | server CPU us/request |"
echo "|---|---:|---:|---:|---:|---:|---|---:|---:|"
awk -F'\t' '{printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", $1, $2, $3, $4, $5, $6, $7, $8, $9}' "$RESULTS"
echo
awk -F'\t' -v conns_list="$CONNECTIONS" -v tls="$TLS" -v slow="$SLOW" -v rate="$RATE" \
    -v tls_rate="$TLS_RATE" '
  { rps[$1 "@" $2] = $3; p99[$1 "@" $2] = $6; cpu[$1 "@" $2] = $9 }
  END {
    n = split(conns_list, conns, " ")
    for (i = 1; i <= n; ++i) {
      k = conns[i]
      for (t = 0; t <= tls; ++t) {
        suffix = t ? "-tls" : ""
        if (rate > 0) printf "paced at %s requests/s: ", t ? tls_rate : rate
        printf "%s at %s connections: throughput tessera/nginx %.2f, p99 tessera %s ms, nginx %s ms, CPU per request tessera/nginx %.2f\n", t ? "TLS  " : "plain", k, rps["tessera" suffix "@" k] / rps["nginx" suffix "@" k], p99["tessera" suffix "@" k], p99["nginx" suffix "@" k], cpu["tessera" suffix "@" k] / cpu["nginx" suffix "@" k]
      }
    }
    print "targets: at 1000 connections throughput >= 1.0x nginx and p99 < 50 ms, TLS on and off; p99 < 20 ms at 64"
    if (slow) printf "tessera p99 at 64 connections with 1000 slow clients: %s ms (target < 100); nginx: %s ms\n", p99["tessera+1000slow@64"], p99["nginx+1000slow@64"]
  }' "$RESULTS"
