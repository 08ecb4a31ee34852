#!/usr/bin/env bash
# Builder vs peers: `tessera build` against `vips tiffsave --tile --pyramid`, `vips dzsave`
# (folder and --container zip) and `gdal_translate -of COG`, one after another in one run, on the
# same uncompressed tiled TIFF inputs (tessera-make-tiff): JPEG q85 with 256-px tiles and 4:2:0
# chroma for every tool, plus a lossless row. For each: wall time and peak RSS (/usr/bin/time -v),
# megapixels/s, output bytes, ratios to Tessera, and PSNR of level 0 against the source
# (tessera-psnr, streamed). Prints a Markdown table and writes it to the bench folder.
#
# Usage: bench/build_vs_peers.sh [options]
#   --sizes "32768 16384"  square input sides in px (default: 1 GP and 268 MP)
#   --input FILE           use this TIFF instead of generated ones (repeatable)
#   --real                 real content instead of the synthetic source: Debian's xplanet-images
#                          earth.jpg (a 2048x1024 satellite map) replicated to each size
#   --peers "A B"          peer rows to run (default: all): tiffsave dzsave dzsave-zip gdal
#   --bound                add the build's speed limit: every tile JPEG-encoded on all cores,
#                          nothing else timed (tessera-encode-bound), and Tessera's time over it
#   --dir DIR              work folder for inputs, outputs and results (default out/bench)
#   --no-tessera           peers only (also automatic when `tessera build` is not usable)
#   --no-peers             Tessera only
#   --no-lossless          JPEG rows only
#   --keep                 keep every output (default: delete each after measuring it)
#   --runs N               run each command N times and report the run of median wall time
#                          (default 3; peak RSS is the highest of the N)
# Environment: TESSERA_BENCH_BUILD (build folder, default build-bench), TESSERA_BIN,
# TESSERA_PSNR_BIN, TESSERA_MAKE_TIFF_BIN, TESSERA_BOUND_BIN (use these binaries instead of building them),
# TESSERA_BENCH_JOBS (compile jobs, default nproc), TESSERA_BENCH_REVISION (the Tessera revision
# to name in the report when TESSERA_BIN comes from another checkout).
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
command_line=bench/build_vs_peers.sh
if (($#)); then command_line+=$(printf ' %q' "$@"); fi
sizes=(32768 16384)
inputs=()
bench_dir=$repo/out/bench
run_tessera=auto
run_peers=1
run_lossless=1
keep=0
runs=3
real=0
peers="tiffsave dzsave dzsave-zip gdal"
bound=0
while (($#)); do
  case $1 in
    --sizes) read -r -a sizes <<<"$2"; shift 2 ;;
    --input) inputs+=("$(realpath "$2")"); shift 2 ;;
    --real) real=1; shift ;;
    --peers) peers=$2; shift 2 ;;
    --bound) bound=1; shift ;;
    --dir) bench_dir=$2; shift 2 ;;
    --no-tessera) run_tessera=0; shift ;;
    --no-peers) run_peers=0; shift ;;
    --no-lossless) run_lossless=0; shift ;;
    --keep) keep=1; shift ;;
    --runs) runs=$2; shift 2 ;;
    -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "build_vs_peers: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

build_dir=${TESSERA_BENCH_BUILD:-$repo/build-bench}
jobs=${TESSERA_BENCH_JOBS:-$(nproc)}
mkdir -p "$bench_dir"
bench_dir=$(realpath "$bench_dir")
log_dir=$bench_dir/logs
mkdir -p "$log_dir"

# ---- tools -----------------------------------------------------------------------------------
"$repo/scripts/install-deps.sh"
"$repo/bench/install_peers.sh"

tessera=${TESSERA_BIN:-}
psnr=${TESSERA_PSNR_BIN:-}
make_tiff=${TESSERA_MAKE_TIFF_BIN:-}
bound_bin=${TESSERA_BOUND_BIN:-}
if [[ -z $tessera || -z $psnr || ( -z $make_tiff && $real == 0 ) || ( -z $bound_bin && $bound == 1 ) ]]; then
  cmake -S "$repo" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DTESSERA_BUILD_TOOLS=ON \
    -DTESSERA_BUILD_BENCH=ON -DTESSERA_BUILD_TESTS=OFF >"$log_dir/configure.log" 2>&1 ||
    { cat "$log_dir/configure.log"; exit 1; }
  # One target at a time, so a tool that does not build yet only disables its own rows.
  build_target() {  # build_target BINARY TARGET... -> the binary's path, or nothing on failure
    local binary=$1 target
    shift
    for target in "$@"; do
      if cmake --build "$build_dir" -j "$jobs" --target "$target" >"$log_dir/build-$target.log" 2>&1
      then
        find "$build_dir" -type f -perm -u+x -name "$binary" -not -path '*/CMakeFiles/*' -print -quit
        return 0
      fi
    done
    echo "build_vs_peers: $binary did not build (see $log_dir/build-$target.log)" >&2
  }
  [[ -n $tessera ]] || tessera=$(build_target tessera tessera_cli)
  [[ -n $psnr ]] || psnr=$(build_target tessera-psnr tessera_psnr)
  if ((bound)) && [[ -z $bound_bin ]]; then
    bound_bin=$(build_target tessera-encode-bound tessera_encode_bound)
  fi
  if [[ -z $make_tiff ]] && ((${#inputs[@]} == 0)) && ((!real)); then
    make_tiff=$(build_target tessera-make-tiff tessera_make_tiff tessera-make-tiff)
  fi
fi
if [[ $run_tessera == auto ]]; then
  run_tessera=0
  if [[ -n $tessera ]] && "$tessera" build --help 2>&1 | grep -q -- --codec; then run_tessera=1; fi
  ((run_tessera)) || echo "build_vs_peers: \`tessera build\` not usable yet: peer rows only" >&2
fi
[[ -n $psnr ]] || echo "build_vs_peers: no tessera-psnr: PSNR column left empty" >&2

# ---- inputs ----------------------------------------------------------------------------------
if ((${#inputs[@]} == 0)) && ((real)); then
  earth=$bench_dir/earth.jpg
  if [[ ! -s $earth ]]; then
    fetch=$(mktemp -d)
    (cd "$fetch" && apt-get download xplanet-images >/dev/null 2>&1) ||
      { echo "build_vs_peers: apt-get download xplanet-images failed" >&2; exit 1; }
    dpkg-deb -x "$fetch"/xplanet-images_*.deb "$fetch/x"
    cp "$fetch/x/usr/share/xplanet/images/earth.jpg" "$earth"
    rm -rf "$fetch"
  fi
  for side in "${sizes[@]}"; do
    input=$bench_dir/real-${side}x${side}.tif
    if [[ ! -s $input ]]; then
      echo "build_vs_peers: writing $input (earth.jpg replicated)"
      # Tiled like the synthetic inputs; BigTIFF past 4 GiB.
      big=""
      ((side * side * 3 > 4000000000)) && big=",bigtiff"
      vips replicate "$earth" "$input[tile,tile-width=256,tile-height=256$big]" \
        $(((side + 2047) / 2048)) $(((side + 1023) / 1024)) >"$log_dir/make-real-$side.log" 2>&1 ||
        { cat "$log_dir/make-real-$side.log"; exit 1; }
      if ((side % 2048 || side % 1024)); then
        vips crop "$input" "$input.crop.tif[tile,tile-width=256,tile-height=256$big]" 0 0 "$side" "$side" &&
          mv "$input.crop.tif" "$input"
      fi
    fi
    inputs+=("$input")
  done
fi
if ((${#inputs[@]} == 0)); then
  [[ -n $make_tiff ]] || { echo "build_vs_peers: no tessera-make-tiff and no --input" >&2; exit 1; }
  for side in "${sizes[@]}"; do
    input=$bench_dir/input-${side}x${side}.tif
    if [[ ! -s $input ]]; then
      echo "build_vs_peers: writing $input"
      "$make_tiff" "$input" "${side}x${side}" --channels 3 --tile 256 >"$log_dir/make-$side.log" 2>&1 ||
        { cat "$log_dir/make-$side.log"; exit 1; }
    fi
    inputs+=("$input")
  done
fi

# ---- measuring -------------------------------------------------------------------------------
threads=$(nproc)
rows=()  # "input|tool|codec|wall_s|rss_kib|bytes|psnr|chroma|load|command"
bounds=()  # "input|encode_s|load"

# Filters read their whole input: an early exit would kill the writer with SIGPIPE, which
# pipefail turns into a failure.
tiff_chroma() {  # photometric and chroma subsampling of page 0 of a JPEG-in-TIFF
  tiffinfo "$1" 2>/dev/null | awk '
    /^=== TIFF directory 1/ { done = 1 }
    done { next }
    /Photometric Interpretation:/ { p = $NF }
    /YCbCr Subsampling:/ { h = $3; v = $4; sub(",", "", h) }
    END {
      if (p == "YCbCr") { if (h == "") { h = 2; v = 2 }  # TIFF default
        print (h == 2 && v == 2) ? "4:2:0" : (h == 1 && v == 1) ? "4:4:4" : h "x" v " YCbCr" }
      else print p }'
}

# Elapsed wall seconds in a /usr/bin/time -v report.
wall_of() {
  awk -F': ' '/Elapsed \(wall clock\)/ { n = split($2, t, ":"); s = 0;
    for (i = 1; i <= n; i++) s = s * 60 + t[i]; printf "%.2f", s }' "$1"
}

# measure INPUT TOOL CODEC OUTPUT PSNR_TARGET CHROMA -- COMMAND...
# OUTPUT: what to size (a file, or a folder plus its .dzi); PSNR_TARGET: what tessera-psnr
# reads ("" for none, "=ROW" to copy another row's figure).
measure() {
  local input=$1 tool=$2 codec=$3 output=$4 psnr_target=$5 chroma=$6
  shift 7
  local id
  id=$(basename "${input%.*}")-$(tr -c 'a-zA-Z0-9' '_' <<<"$tool $codec" | sed 's/_*$//')
  local tfile=$log_dir/$id.time lfile=$log_dir/$id.log
  local load
  load=$(cut -d' ' -f1 /proc/loadavg)
  echo "build_vs_peers: [$(date +%H:%M:%S)] $tool ($codec) on $(basename "$input"), load $load"
  local cmd
  cmd=$(printf '%q ' "$@")
  cmd=${cmd% }
  echo "  $cmd"
  local run walls=() failed=0
  for ((run = 1; run <= runs; ++run)); do
    rm -rf "$output" "${output%.dzi}_files" "${output%.dzi}.zip"
    # No dirty pages from the previous run: Tessera fsyncs its output, and must not pay for
    # the write-back of what a peer left in the page cache (the peers do not fsync).
    sync
    if ! /usr/bin/time -v -o "$tfile.$run" "$@" >"$lfile" 2>&1; then
      failed=1
      break
    fi
    walls+=("$(wall_of "$tfile.$run") $run")
  done
  if ((failed)); then
    echo "build_vs_peers: FAILED, see $lfile" >&2
    tail -5 "$lfile" >&2
    rows+=("$(basename "$input")|$tool|$codec|FAIL|||||$load|$cmd")
    return
  fi
  local median_run all_walls
  median_run=$(printf '%s\n' "${walls[@]}" | sort -n | sed -n "$(((runs + 1) / 2))p" | cut -d' ' -f2)
  all_walls=$(printf '%s\n' "${walls[@]}" | cut -d' ' -f1 | paste -sd' ')
  cp "$tfile.$median_run" "$tfile"
  if [[ ! -e $output ]]; then
    echo "build_vs_peers: FAILED, $output was not written, see $lfile" >&2
    rows+=("$(basename "$input")|$tool|$codec|FAIL|||||$load|$cmd")
    return
  fi
  local wall rss bytes psnr_db=""
  wall=$(wall_of "$tfile")
  rss=$(cat "$tfile".[0-9]* | awk -F': ' '/Maximum resident set size/ { if ($2 > m) m = $2 } END { print m }')
  if [[ $output == *.dzi ]]; then
    bytes=$(du -sbc "$output" "${output%.dzi}_files" | tail -1 | cut -f1)
  else
    bytes=$(du -sb "$output" | cut -f1)
  fi
  [[ $chroma == tiff ]] && chroma=$(tiff_chroma "$output")
  [[ $chroma == dz ]] && chroma=$(vipsheader -f jpeg-chroma-subsample \
    "$(find "${output%.dzi}_files" -name '0_0.jpg' | sort -V | tail -1)" 2>/dev/null || echo "?")
  if [[ $psnr_target == =* ]]; then
    psnr_db=${psnr_target}
  elif [[ -n $psnr_target && -n $psnr ]]; then
    psnr_db=$("$psnr" "$input" "$psnr_target" 2>>"$lfile" |
      sed -n 's/^psnr_db=\([^ ]*\).*/\1/p' || true)
    [[ -n $psnr_db ]] || psnr_db="error"
  fi
  echo "  wall ${wall} s (median of: $all_walls), peak RSS $((rss / 1024)) MiB, $bytes bytes, PSNR ${psnr_db:-n/a} dB, chroma $chroma"
  rows+=("$(basename "$input")|$tool|$codec|$wall|$rss|$bytes|$psnr_db|$chroma|$load|$cmd")
  ((keep)) || rm -rf "$output" "${output%.dzi}_files"
}

for input in "${inputs[@]}"; do
  out=$bench_dir/out-$(basename "${input%.*}")
  mkdir -p "$out"
  # JPEG q85, 256-px tiles, 4:2:0 chroma everywhere.
  if ((run_tessera)); then
    measure "$input" tessera "jpeg q85" "$out/tessera.tess" "$out/tessera.tess" "4:2:0" -- \
      "$tessera" build "$input" -o "$out/tessera.tess" --tile 256 --codec jpeg --quality 85 \
      --threads "$threads" --quiet
  fi
  if ((bound)) && [[ -n $bound_bin ]]; then
    echo "build_vs_peers: [$(date +%H:%M:%S)] encode bound on $(basename "$input"), load $(cut -d' ' -f1 /proc/loadavg)"
    bound_json=$("$bound_bin" "$input" --tile 256 --quality 85 --threads "$threads" --runs "$runs")
    echo "  $bound_json"
    bounds+=("$(basename "$input")|$(sed -n 's/.*"encode_s_median": \([0-9.]*\).*/\1/p' <<<"$bound_json")|$(sed -n 's/.*"encode_cpu_s": \([0-9.]*\).*/\1/p' <<<"$bound_json")|$(cut -d' ' -f1 /proc/loadavg)")
  fi
  if ((run_peers)) && [[ " $peers " == *" tiffsave "* ]]; then
    measure "$input" "vips tiffsave" "jpeg q85" "$out/vips.tif" "$out/vips.tif" tiff -- \
      vips tiffsave "$input" "$out/vips.tif" --tile --pyramid --compression jpeg --Q 85 \
      --tile-width 256 --tile-height 256
  fi
  dz_psnr="" dz_chroma=""
  if ((run_peers)) && [[ " $peers " == *" dzsave "* ]]; then
    # The zip row writes the same tiles as the folder row, so it shares its PSNR; keep the
    # folder until the zip row has run, then measure the zip (its own wall and RSS).
    keep_was=$keep
    keep=1
    measure "$input" "vips dzsave" "jpeg q85" "$out/dz.dzi" "$out/dz.dzi" dz -- \
      vips dzsave "$input" "$out/dz" --tile-size 256 --overlap 0 --suffix '.jpg[Q=85]'
    keep=$keep_was
    dz_psnr="=$(IFS='|' read -r -a f <<<"${rows[-1]}"; echo "${f[6]}")"
    dz_chroma=$(IFS='|' read -r -a f <<<"${rows[-1]}"; echo "${f[7]}")
    ((keep)) || rm -rf "$out/dz.dzi" "$out/dz_files"
  fi
  if ((run_peers)) && [[ " $peers " == *" dzsave-zip "* ]]; then
    measure "$input" "vips dzsave --container zip" "jpeg q85" "$out/dz.zip" "$dz_psnr" \
      "${dz_chroma:-?}" -- \
      vips dzsave "$input" "$out/dz.zip" --tile-size 256 --overlap 0 --suffix '.jpg[Q=85]' \
      --container zip
  fi
  if ((run_peers)) && [[ " $peers " == *" gdal "* ]]; then
    # GDAL: YCbCr 4:2:0 is what the COG driver writes for 3-band JPEG (checked per run by
    # tiffinfo below); QUALITY and OVERVIEW_QUALITY both 85; box-filtered overviews like the
    # others; all cores for compression, as vips and Tessera use all cores.
    measure "$input" "gdal COG" "jpeg q85" "$out/gdal.tif" "$out/gdal.tif" tiff -- \
      gdal_translate -q -of COG -co COMPRESS=JPEG -co QUALITY=85 -co OVERVIEW_QUALITY=85 \
      -co BLOCKSIZE=256 -co RESAMPLING=AVERAGE -co NUM_THREADS=ALL_CPUS "$input" "$out/gdal.tif"
  fi
  if ((run_lossless)); then
    if ((run_tessera)); then
      measure "$input" tessera "png" "$out/tessera-png.tess" "$out/tessera-png.tess" "-" -- \
        "$tessera" build "$input" -o "$out/tessera-png.tess" --tile 256 --codec png \
        --threads "$threads" --quiet
      measure "$input" tessera "webp lossless" "$out/tessera-webp.tess" \
        "$out/tessera-webp.tess" "-" -- \
        "$tessera" build "$input" -o "$out/tessera-webp.tess" --tile 256 --codec webp \
        --threads "$threads" --quiet
    fi
    if ((run_peers)); then
      # Horizontal predictor on both peers (vips' default; GDAL's PREDICTOR=YES); BigTIFF for
      # vips since a lossless 1-GP pyramid may pass 4 GiB (GDAL switches by itself).
      measure "$input" "vips tiffsave" "deflate" "$out/vips-deflate.tif" \
        "$out/vips-deflate.tif" "-" -- \
        vips tiffsave "$input" "$out/vips-deflate.tif" --tile --pyramid --compression deflate \
        --predictor horizontal --tile-width 256 --tile-height 256 --bigtiff
      measure "$input" "gdal COG" "deflate" "$out/gdal-deflate.tif" "$out/gdal-deflate.tif" "-" -- \
        gdal_translate -q -of COG -co COMPRESS=DEFLATE -co PREDICTOR=YES -co BLOCKSIZE=256 \
        -co RESAMPLING=AVERAGE -co NUM_THREADS=ALL_CPUS "$input" "$out/gdal-deflate.tif"
    fi
  fi
done

# ---- report ----------------------------------------------------------------------------------
pixels_of() {  # level-0 pixels of the input whose file name is $1
  local i
  for i in "${inputs[@]}"; do
    if [[ $(basename "$i") == "$1" ]]; then
      tiffinfo "$i" 2>/dev/null | awk '/Image Width/ && !n++ { printf "%d", $3 * $6 }'
    fi
  done
}

report=$bench_dir/build_vs_peers-$(date +%Y%m%d-%H%M%S).md
{
  echo "### Builder vs peers, $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo
  echo "Machine: $(lscpu | awk -F': *' '/^Model name/ && !n++ { print $2 }'), $(nproc) cores," \
    "$(free -g | awk '/^Mem:/ { print $2 }') GiB RAM, $(sed -n "s/^PRETTY_NAME=//p" /etc/os-release | tr -d \")," \
    "kernel $(uname -r)."
  echo "Tools: $(vips --version), $(gdalinfo --version | cut -d, -f1)," \
    "tessera ${TESSERA_BENCH_REVISION:-$(git -C "$repo" rev-parse --short HEAD 2>/dev/null || echo '?')}."
  echo "Command: \`$command_line\`"
  echo "Each row: the run of median wall time of $runs (\`sync\` before each run), the highest"
  echo "peak RSS of the $runs."
  echo
  echo "| input | tool | codec | wall s | MP/s | peak RSS MiB | output bytes | wall ÷ Tessera | bytes ÷ Tessera | PSNR dB | chroma | load |"
  echo "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|"
  for row in "${rows[@]}"; do
    IFS='|' read -r in tool codec wall rss bytes psnr_db chroma load cmd <<<"$row"
    pixels=$(pixels_of "$in")
    # Reference row: Tessera JPEG for lossy rows, Tessera PNG for lossless rows.
    ref_codec="jpeg q85"
    [[ $codec == "jpeg q85" ]] || ref_codec="png"
    ref_wall="" ref_bytes=""
    for r in "${rows[@]}"; do
      IFS='|' read -r rin rtool rcodec rwall _ rbytes _ <<<"$r"
      if [[ $rin == "$in" && $rtool == tessera && $rcodec == "$ref_codec" && $rwall != FAIL ]]; then
        ref_wall=$rwall ref_bytes=$rbytes
      fi
    done
    if [[ $wall == FAIL ]]; then
      echo "| $in | $tool | $codec | failed | | | | | | | | $load |"
      continue
    fi
    mps=$(awk -v p="$pixels" -v w="$wall" 'BEGIN { if (p > 0 && w > 0) printf "%.1f", p / 1e6 / w }')
    wr="—" br="—"
    if [[ -n $ref_wall ]]; then
      wr=$(awk -v a="$wall" -v b="$ref_wall" 'BEGIN { printf "%.2f", a / b }')
      br=$(awk -v a="$bytes" -v b="$ref_bytes" 'BEGIN { printf "%.2f", a / b }')
    fi
    echo "| $in | $tool | $codec | $wall | $mps | $((rss / 1024)) | $bytes | $wr | $br | ${psnr_db:-—} | $chroma | $load |"
  done
  for b in "${bounds[@]}"; do
    IFS='|' read -r in encode_s encode_cpu load <<<"$b"
    for r in "${rows[@]}"; do
      IFS='|' read -r rin rtool rcodec rwall _ <<<"$r"
      if [[ $rin == "$in" && $rtool == tessera && $rcodec == "jpeg q85" && $rwall != FAIL ]]; then
        # The build's CPU seconds, from the run of median wall time: on a busy machine wall
        # time depends on how many threads compete for the cores (the build has one more).
        build_cpu=$(awk -F': ' '/User time|System time/ { s += $2 } END { printf "%.2f", s }' \
          "$log_dir/$(basename "${in%.*}")-tessera_jpeg_q85.time")
        echo
        echo "Encode bound on $in (every stored tile JPEG-encoded on $threads threads, nothing else" \
          "timed; load $load): $encode_s s wall, $encode_cpu CPU-s. Tessera's build:" \
          "$(awk -v a="$rwall" -v b="$encode_s" 'BEGIN { printf "%.2f", a / b }')x the bound's wall" \
          "time, $build_cpu CPU-s ($(awk -v a="$build_cpu" -v b="$encode_cpu" 'BEGIN { printf "%.2f", a / b }')x)."
      fi
    done
  done
  echo
  echo "Commands, in the order run:"
  echo
  for row in "${rows[@]}"; do
    IFS='|' read -r _ _ _ _ _ _ _ _ _ cmd <<<"$row"
    echo "    ${cmd//$bench_dir/\$BENCH}"
  done
} >"$report"
echo
cat "$report"
echo
echo "build_vs_peers: report written to $report"
