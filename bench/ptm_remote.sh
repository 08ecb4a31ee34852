#!/usr/bin/env bash
# Remote refinement with ptm (issue 6, item 4; Marvie & Bouatouch, parts I and III): the bytes a
# client fetches over a simulated link to refine an overview into a full-detail 1920x1080 view,
# for the same image stored as ptm, PNG, WebP-lossless, zstd and JPEG (q85, for scale: lossy).
# A ptm child is coded against its parent, so a client holding the parent level fetches only
# the child's residual payload. Prints a Markdown table (docs/benchmarks.md).
#
#   bench/ptm_remote.sh [REPEATS]     # default 2; medians are reported
#
# Flight (keyframe file): the whole image in view for 4 s, long enough for its levels to arrive
# at every codec's size; then a jump into the centre at 1 texel per pixel, held for 10 s.
# "Refinement" is what the loader read from the jump to the first frame at full detail after
# it: the finer levels of the view, which for ptm are residuals against the levels the client
# holds. "To full detail" adds the overview's bytes. A second flight starts cold at the centre at
# 1 texel per pixel and holds for 6 s: "cold start" is the time to its first frame at full
# detail, where a dependent codec's levels cannot all be read at once. Link 20 Mbit/s with a 40 ms RTT (`tessera fly --link`, the
# simulated link of docs/runtime.md), loader settings of tuneForRemoteSource.
#
# Inputs: synthetic:4096x4096:2:3, and /usr/share/backgrounds/gnome/wood-d.webp from Debian
# package gnome-backgrounds (a 4096x4096 photograph, fetched with apt-get download and turned
# into PNG by dwebp from package webp, installed here when missing). The codec study's map
# (earth.jpg, 2048x1024) is left out: a 1920x1080 view of it is at full detail already.
#
# Environment: TESSERA (default build/src/tools/tessera), PTM_REMOTE_DIR (work folder, default
# /tmp/tessera-ptm-remote), LINK (default 20mbit:40ms).
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
TESSERA=${TESSERA:-$REPO/build/src/tools/tessera}
WORK=${PTM_REMOTE_DIR:-/tmp/tessera-ptm-remote}
LINK=${LINK:-20mbit:40ms}
REPEATS=${1:-2}
# codec[:effort]; ptm:1 is ptm's fastest-decoding mode (nearest parent, zstd; docs/codecs.md).
CODECS=(ptm ptm:1 png webp zstd jpeg)
mkdir -p "$WORK/src"
# Archives are kept between runs, but only for the tessera binary that built them: a changed
# encoder must not be measured through a stale archive.
stamp=$(sha256sum "$TESSERA" | cut -d' ' -f1)
if [[ $(cat "$WORK/tessera.sha256" 2>/dev/null) != "$stamp" ]]; then
  rm -f "$WORK"/*.tess
  echo "$stamp" >"$WORK/tessera.sha256"
fi

if ! command -v dwebp >/dev/null 2>&1; then
  sudo_cmd=()
  [[ $(id -u) -eq 0 ]] || sudo_cmd=(sudo)
  "${sudo_cmd[@]}" apt-get install -y -q webp >/dev/null
fi
if [[ ! -f $WORK/src/wood.png ]]; then
  (cd "$WORK/src" && apt-get download gnome-backgrounds >/dev/null 2>&1)
  dpkg-deb -x "$WORK"/src/gnome-backgrounds_*.deb "$WORK/src/x"
  dwebp -quiet "$WORK/src/x/usr/share/backgrounds/gnome/wood-d.webp" -o "$WORK/src/wood.png"
fi

declare -A INPUT=([synthetic]=synthetic:4096x4096:2:3 [wood]=$WORK/src/wood.png)
declare -A SIZE=([synthetic]="4096 4096" [wood]="4096 4096")
IMAGES=(synthetic wood)

for image in "${IMAGES[@]}"; do
  read -r w h <<<"${SIZE[$image]}"
  # Overview: the whole image in a 1920x1080 view; then the centre at 1 texel per pixel.
  python3 - "$w" "$h" >"$WORK/$image.path" <<'EOF'
import sys
w, h = int(sys.argv[1]), int(sys.argv[2])
overview = max(w / 1920, h / 1080, 1.0)
for t, tpp, jump in [(0, overview, ""), (4, overview, ""), (4, 1, "0 jump"), (14, 1, "")]:
    print(f"{t} {w / 2} {h / 2} {tpp} {jump}")
EOF
  printf '0 %s %s 1\n6 %s %s 1\n' $((w / 2)) $((h / 2)) $((w / 2)) $((h / 2)) >"$WORK/$image-cold.path"
  for spec in "${CODECS[@]}"; do
    codec=${spec/:/-e}
    effort=()
    [[ $spec == *:* ]] && effort=(--effort "${spec#*:}")
    archive=$WORK/$image-$codec.tess
    [[ -f $archive ]] ||
      "$TESSERA" build "${INPUT[$image]}" -o "$archive" --codec "${spec%%:*}" "${effort[@]}" --quiet
    for r in $(seq 1 "$REPEATS"); do
      "$TESSERA" fly "$archive" --link "$LINK" --path "$WORK/$image.path" --viewport 1920x1080 \
        --fps 30 --loader-priority nice -q --out "$WORK/run-$image-$codec-$r"
      "$TESSERA" fly "$archive" --link "$LINK" --path "$WORK/$image-cold.path" \
        --viewport 1920x1080 --fps 30 --loader-priority nice -q --out "$WORK/cold-$image-$codec-$r"
    done
  done
done

python3 - "$WORK" "$REPEATS" "$LINK" "${IMAGES[@]}" -- "${CODECS[@]/:/-e}" <<'EOF'
import csv, json, os, statistics, sys
work, repeats, link = sys.argv[1], int(sys.argv[2]), sys.argv[3]
rest = sys.argv[4:]
images, codecs = rest[:rest.index("--")], rest[rest.index("--") + 1:]
JUMP_MS = 4000

def flight(image, codec, r):
    d = f"{work}/run-{image}-{codec}-{r}"
    rows = list(csv.DictReader(open(f"{d}/frames.csv")))
    before = [int(x["bytes_read"]) for x in rows if float(x["t_ms"]) < JUMP_MS]
    full = [x for x in rows if float(x["t_ms"]) >= JUMP_MS and int(x["desired_level"]) == 0
            and float(x["coverage_desired"]) >= 1.0]
    summary = json.load(open(f"{d}/summary.json"))
    if not full:
        return None
    start = before[-1] if before else 0
    return {"overview": start, "refine": int(full[0]["bytes_read"]) - start,
            "total": int(full[0]["bytes_read"]), "ms": float(full[0]["t_ms"]) - JUMP_MS,
            "parents": summary["parents_queued"], "fallbacks": summary["parent_fallbacks"],
            "failures": summary["load_failures"]}

def cold_start(image, codec, r):
    rows = csv.DictReader(open(f"{work}/cold-{image}-{codec}-{r}/frames.csv"))
    full = [float(x["t_ms"]) for x in rows
            if int(x["desired_level"]) == 0 and float(x["coverage_desired"]) >= 1.0]
    return full[0] if full else None

def med(values):
    return statistics.median(values) if values else None

mib = lambda b: f"{b / 2**20:.2f}"
print(f"Link {link}; medians of {repeats} flights.\n")
print("| image | codec | archive MiB | overview bytes | refinement bytes | to full detail | vs ptm | full detail after the jump | cold start to full detail | parents queued / fallbacks |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
for image in images:
    base = None
    for codec in codecs:
        runs = [f for f in (flight(image, codec, r) for r in range(1, repeats + 1)) if f]
        size = os.path.getsize(f"{work}/{image}-{codec}.tess")
        colds = [c for c in (cold_start(image, codec, r) for r in range(1, repeats + 1))
                 if c is not None]
        cold = f"{med(colds) / 1000:.2f} s" if len(colds) == repeats else "never"
        if not runs:
            print(f"| {image} | {codec} | {mib(size)} | - | - | - | - | never | {cold} | - |")
            continue
        refine = med([f["refine"] for f in runs])
        if codec == "ptm":
            base = refine
        ratio = f"{refine / base:.2f}x" if base else "-"
        print(f"| {image} | {codec} | {mib(size)} | {mib(med([f['overview'] for f in runs]))} MiB "
              f"| {mib(refine)} MiB | {mib(med([f['total'] for f in runs]))} MiB | {ratio} "
              f"| {med([f['ms'] for f in runs]) / 1000:.2f} s | {cold} "
              f"| {max(f['parents'] for f in runs)} / {max(f['fallbacks'] for f in runs)} |")
EOF
