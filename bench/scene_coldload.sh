#!/usr/bin/env bash
# Cold load of a textured scene (issue 28's targets; docs/scenes.md, "Cold load"), in one run on
# this machine, on the same scene and the same views:
#
#   tessera   tessera-scene-coldload tessera: open the scene archive and run SceneStreamer's
#             60 Hz frame loop on a still camera until the view is at full quality
#   perfile   tessera-scene-coldload perfile: the view's models (.ac) and textures (.png, .jpg)
#             from their own files, each read and decoded separately as a viewer does
#   all       the same for every model and texture of the scene (a viewer that loads it all)
#   noparse   (local, with --sides) perfile reading the models without parsing their geometry:
#             the lower bound of a viewer whose models cost nothing to parse (glTF buffers)
#
# Cold: before each run the files it reads leave the page cache (posix_fadvise DONTNEED, checked
# with mincore; no root needed). Locally both sides read the files; over HTTP each client
# reaches its server through tessera-link-proxy (bench/link_proxy.cpp; this kernel has no netem)
# at the link's rate and RTT: the archive served by `tessera serve` and by nginx, the separate
# files by nginx. The proxy counts the bytes, the servers' access logs the requests.
#
# The scene: Debian's flightgear-data-models (fetched as tests/scene/real_scene_test.cpp does,
# into BUILD/scene-data), every usable model placed twice on a grid (tessera-scene-coldload
# prepare), built with 128-px JPEG tiles.
#
#   bench/scene_coldload.sh                       # 2 repeats, local and 20mbit:40ms
#   bench/scene_coldload.sh --repeat 1 --views street --no-http --sides tessera
# Environment: TESSERA_BENCH_DIR (default /tmp/tessera-bench), TESSERA_BUILD_DIR (default
# build/), TESSERA_FGDATA (an unpacked Models folder).
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${TESSERA_BENCH_DIR:-/tmp/tessera-bench}/scene-coldload
BUILD_DIR=${TESSERA_BUILD_DIR:-$REPO/build}
REPEAT=2
VIEWS="street oblique overview"
LINKS="20mbit:40ms"
LOCAL=1
HTTP=1
SIDES="tessera perfile all"
while [[ $# -gt 0 ]]; do
  case $1 in
    --repeat) REPEAT=$2; shift 2 ;;
    --views) VIEWS=$2; shift 2 ;;
    --links) LINKS=$2; shift 2 ;;
    --no-http) HTTP=0; shift ;;
    --no-local) LOCAL=0; shift ;;
    --sides) SIDES=$2; shift 2 ;;
    -h|--help) sed -n '2,25p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "scene_coldload: unknown option $1" >&2; exit 2 ;;
  esac
done

TESSERA=$BUILD_DIR/src/tools/tessera
PROXY=$BUILD_DIR/bench/tessera-link-proxy
COLDLOAD=$BUILD_DIR/bench/tessera-scene-coldload
for tool in "$TESSERA" "$PROXY" "$COLDLOAD"; do
  [[ -x $tool ]] || { echo "scene_coldload: $tool missing: build it (-DTESSERA_BUILD_BENCH=ON)" >&2; exit 1; }
done

# ---- the data and the scene, once
MODELS=${TESSERA_FGDATA:-}
if [[ -z $MODELS ]]; then
  CACHE=$BUILD_DIR/scene-data/flightgear-data-models
  MODELS=$CACHE/usr/share/games/flightgear/Models
  if [[ ! -d $MODELS ]]; then
    mkdir -p "$CACHE"
    (cd "$CACHE" && apt-get download flightgear-data-models && dpkg-deb -x flightgear-data-models_*.deb . &&
      rm -f flightgear-data-models_*.deb)
  fi
fi
SCENE=$WORK/fg
if [[ ! -f $SCENE/sf.tess ]]; then
  "$COLDLOAD" prepare --models "$MODELS" --work "$SCENE"
fi

RUN=$WORK/run-$(date -u +%Y%m%dT%H%M%SZ)
mkdir -p "$RUN"
ln -sfn "$RUN" "$WORK/latest"
RESULTS=$RUN/results.jsonl
pids=()
cleanup() {
  local pid
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap cleanup EXIT

{
  echo "date: $(date -u +%FT%TZ)"
  echo "commit: $(git -C "$REPO" rev-parse --short HEAD)"
  echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(nproc) cores"
  echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "cache drop: posix_fadvise(POSIX_FADV_DONTNEED) on every file a run reads, checked with mincore"
  echo "scene: $(stat -c %s "$SCENE/sf.tess") bytes of archive, $(wc -l < "$SCENE/files.txt") separate files"
} | tee "$RUN/machine.txt"

has() { [[ " $SIDES " == *" $1 "* ]]; }

record() {  # record LINK SERVER N [PROXY_BYTES REQUESTS] < JSON line
  python3 -c '
import json, sys
r = json.loads(sys.stdin.read())
r.update(link=sys.argv[1], server=sys.argv[2], run=int(sys.argv[3]))
if len(sys.argv) > 5:
    r.update(link_bytes=int(sys.argv[4] or 0), requests=int(sys.argv[5]))
print(json.dumps(r))' "$@" | tee -a "$RESULTS"
}

tessera_run() {  # tessera_run URI
  "$COLDLOAD" tessera --archive "$1" --view "$view" --drop "$SCENE/sf.tess"
}
perfile_run() {  # perfile_run STG_URI [--all | --no-model-parse]
  if [[ ${2:-} == --all ]]; then
    "$COLDLOAD" perfile --stg "$1" --all --drop-list "$SCENE/files.txt"
  else
    "$COLDLOAD" perfile --stg "$1" --archive "$SCENE/sf.tess" --placements "$SCENE/placements.tsv" \
      --view "$view" --drop-list "$SCENE/files.txt" ${2:+"$2"}
  fi
}

# ---- local disk: the sides alternate within each repeat
if ((LOCAL)); then
  for ((n = 1; n <= REPEAT; ++n)); do
    for view in $VIEWS; do
      if has tessera; then tessera_run "$SCENE/sf.tess" | record local disk "$n"; fi
      if has perfile; then perfile_run "$SCENE/sf.stg" | record local disk "$n"; fi
      if has noparse; then perfile_run "$SCENE/sf.stg" --no-model-parse | record local disk "$n"; fi
    done
    if has all; then perfile_run "$SCENE/sf.stg" --all | record local disk "$n"; fi
  done
fi

# ---- HTTP through the link proxy
source "$REPO/bench/link/servers.sh"
if ((HTTP)); then
  command -v nginx > /dev/null || "$REPO/bench/install_peers.sh"
  "$TESSERA" serve "$SCENE/sf.tess" --port 0 --access-log "$RUN/serve-access.log" \
    > "$RUN/serve.out" 2> "$RUN/serve.err" &
  pids+=($!)
  SERVE_PORT=$(port_of "$RUN/serve.out")
  start_nginx "$RUN" "$SCENE" sf.stg

  http_run() {  # http_run LINK SERVER N SIDE [--all]
    local link=$1 server=$2 n=$3 side=$4 upstream log out proxy_pid proxy_port before json
    case $server in
      serve) upstream=$SERVE_PORT; log=$RUN/serve-access.log ;;
      nginx) upstream=$NGINX_PORT; log=$RUN/nginx-access.log ;;
    esac
    out=$RUN/proxy-$side-$server-${link//:/_}-$n-$view${5:-}.out
    "$PROXY" --upstream "127.0.0.1:$upstream" --rate "${link%%:*}" --rtt "${link#*:}" > "$out" &
    proxy_pid=$!
    proxy_port=$(port_of "$out")
    before=$(wc -l < "$log" 2>/dev/null || echo 0)
    if [[ $side == tessera ]]; then
      json=$(tessera_run "http://127.0.0.1:$proxy_port/sf.tess")
    else
      json=$(perfile_run "http://127.0.0.1:$proxy_port/sf.stg" "${5:-}")
    fi
    kill -TERM "$proxy_pid"; wait "$proxy_pid" || true
    local carried requests
    carried=$(proxy_carried "$out")
    requests=$(( $(wc -l < "$log") - before ))
    echo "$json" | record "$link" "$server" "$n" "$carried" "$requests"
  }

  for link in $LINKS; do
    for ((n = 1; n <= REPEAT; ++n)); do
      for view in $VIEWS; do
        if has tessera; then http_run "$link" serve "$n" tessera; fi
        if has perfile; then http_run "$link" nginx "$n" perfile; fi
        if has tessera; then http_run "$link" nginx "$n" tessera; fi
      done
      # Every file of the scene is the same whatever the view: once per link.
      if ((n == 1)) && has all; then view=all; http_run "$link" nginx "$n" perfile --all; fi
    done
  done
fi

python3 - "$RESULTS" <<'PY' | tee "$RUN/report.md"
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
def med(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None
groups = {}
for r in rows:
    groups.setdefault((r["link"], r["view"], r["side"], r["server"]), []).append(r)
print("| link | view | side | server | runs | time (median, range) | bytes | reads/requests | vs per-file time | vs per-file requests |")
print("|---|---|---|---|---:|---:|---:|---:|---:|---:|")
for (link, view, side, server), runs in groups.items():
    t = med(r["seconds"] for r in runs)
    lo, hi = min(r["seconds"] for r in runs), max(r["seconds"] for r in runs)
    b = med(r.get("link_bytes", r["bytes"]) for r in runs)
    q = med(r["requests"] for r in runs)
    base = groups.get((link, view, "perfile", "nginx" if link != "local" else "disk"))
    ratio_t = ratio_q = "-"
    if side == "tessera" and base:
        ratio_t = f"{med(x['seconds'] for x in base) / t:.1f}x"
        ratio_q = f"{med(x['requests'] for x in base) / q:.1f}x"
    print(f"| {link} | {view} | {side} | {server} | {len(runs)} | {t:.2f} s ({lo:.2f}-{hi:.2f}) | "
          f"{b / 1e6:.1f} MB | {q:.0f} | {ratio_t} | {ratio_q} |")
PY
echo "scene_coldload: results in $RUN"
