#!/usr/bin/env bash
# The whole test suite, as CI runs it (.ci/run): installs the Debian packages, then
#   1. checks clang-format on every tracked C++ file and .editorconfig on every text file,
#   2. builds Release and runs every test; before that build, right after configuring, checks
#      that no function in src/ is over 120 lines (scripts/check_function_size.sh, clang-tidy
#      over compile_commands.json),
#   3. builds RelWithDebInfo with AddressSanitizer + UBSan and runs every test,
#   4. builds with ThreadSanitizer and runs the tests labelled "concurrency",
#   5. builds every fuzzer of fuzz/ with clang's libFuzzer under ASan + UBSan and runs each
#      from its committed corpus for a minute (two at a time),
# and ends with each stage's ctest summary. Every stage runs even when an earlier one failed,
# so one run reports everything; the exit status is non-zero when any stage failed. Each
# stage's build after the first runs in the background at nice 19 while the stage before it
# tests (the pipeline at the end of this file).
#
# Environment (all optional):
#   TESSERA_CI_STAGES   stages to run, default "format release asan tsan fuzz"
#   TESSERA_CI_BUILD    build root, default <repo>/build-ci (one subfolder per stage)
#   TESSERA_CI_JOBS     parallel compile jobs, default $(nproc)
#   TESSERA_CI_TIMEOUT  per-test timeout in seconds, default 300 (sanitizer stages: 3x)
#   TESSERA_CI_FILTER   ctest -R regex, to run a subset while iterating
#   TESSERA_CI_WERROR   ON/OFF for -Werror in the Release stage, default ON
#   TESSERA_CI_FUZZ_SECONDS  seconds each fuzzer runs in the fuzz stage, default 25
set -uo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo" || exit 1

stages=${TESSERA_CI_STAGES:-format release asan tsan fuzz}
fuzz_seconds=${TESSERA_CI_FUZZ_SECONDS:-25}
build_root=${TESSERA_CI_BUILD:-$repo/build-ci}
jobs=${TESSERA_CI_JOBS:-$(nproc)}
timeout_s=${TESSERA_CI_TIMEOUT:-300}
filter=${TESSERA_CI_FILTER:-}
werror=${TESSERA_CI_WERROR:-ON}
test_jobs=2

mkdir -p "$build_root"
# One line per stage result, printed at the end. A file, not a variable: the next stage's
# build runs in a background subshell (see the pipeline at the end) and reports through it.
results=$build_root/ci-results.txt
: >"$results"

log() { printf '\n==== ci: %s\n' "$*"; }
stage_result() {  # stage_result NAME STATUS DETAIL
  printf '%-12s %-4s %s\n' "$1" "$2" "$3" >>"$results"
}

scripts/install-deps.sh || { echo "ci: scripts/install-deps.sh failed" >&2; exit 1; }

# The web tests' npm packages (web/package-lock.json: OpenSeadragon, Leaflet, playwright-core),
# installed by `npm ci` only when the lock file changed since the last install, so a second run
# neither downloads nor rewrites web/node_modules.
web_deps() {
  local stamp=web/node_modules/.tessera-lock.sha256 want
  want=$(sha256sum web/package-lock.json | cut -d' ' -f1)
  if [[ -f $stamp && $(cat "$stamp") == "$want" ]]; then
    echo "ci: web/node_modules matches web/package-lock.json"
    return 0
  fi
  npm ci --prefix web --no-audit --no-fund && echo "$want" >"$stamp"
}
if command -v npm >/dev/null 2>&1; then
  web_deps || { echo "ci: npm ci --prefix web failed" >&2; exit 1; }
fi

# Sanitizer runtime options: fail on the first report, with symbolized stacks.
export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=1:second_deadlock_stack=1}

format_check() {
  log "clang-format check ($(clang-format --version | head -1))"
  local files=() bad=() present=() f
  mapfile -t files < <(git ls-files -- '*.cpp' '*.cc' '*.h' '*.hpp' '*.inl')
  for f in "${files[@]}"; do
    [[ -f $f ]] && present+=("$f")  # not deleted in the working tree while still in the index
  done
  # Forty files per clang-format, one per core: a process per file cost most of the stage. A
  # file that needs formatting gets "FILE:LINE:COL: error: code should be clang-formatted".
  local report status
  report=$(printf '%s\0' "${present[@]}" |
    xargs -0 -P "$jobs" -n 40 clang-format --dry-run --Werror --style=file 2>&1)
  status=$?
  mapfile -t bad < <(printf '%s\n' "$report" |
    sed -nE 's/^(.+):[0-9]+:[0-9]+: (error|warning): code should be clang-formatted.*/\1/p' |
    sort -u)
  if ((status != 0 && ${#bad[@]} == 0)); then
    printf '%s\n' "$report" | head -20
    stage_result format FAIL "clang-format failed (exit $status) without naming a file to format"
  elif ((${#bad[@]})); then
    echo "ci: ${#bad[@]} of ${#files[@]} files need clang-format (fix: clang-format -i FILE):"
    printf '  %s\n' "${bad[@]}"
    stage_result format FAIL "${#bad[@]} of ${#files[@]} files not clang-formatted: ${bad[*]}"
  else
    echo "ci: ${#files[@]} files clang-formatted"
    stage_result format ok "${#files[@]} files clang-formatted"
  fi
}

# .editorconfig, on every tracked text file but the binary test data: LF line ends, a final
# newline, no trailing blanks (Markdown may keep them: two mean a line break), no tab indents.
editorconfig_check() {
  log "editorconfig check"
  local files=() bad=() f
  mapfile -t files < <(git ls-files -z -- ':!fuzz/corpus' ':!tests/data' | xargs -0 grep -Il '' --)
  for f in "${files[@]}"; do
    [[ -f $f ]] || continue
    local why=()
    grep -q $'\r' "$f" && why+=("CR line ends")
    [[ -s $f && -n $(tail -c1 "$f") ]] && why+=("no final newline")
    [[ $f != *.md ]] && grep -qE '[[:blank:]]+$' "$f" && why+=("trailing blanks")
    grep -q $'^\t' "$f" && why+=("tab indentation")
    ((${#why[@]})) && bad+=("$f: $(IFS=,; echo "${why[*]}")")
  done
  if ((${#bad[@]})); then
    printf '  %s\n' "${bad[@]}"
    stage_result editorconfig FAIL "${#bad[@]} of ${#files[@]} files break .editorconfig"
  else
    echo "ci: ${#files[@]} text files follow .editorconfig"
    stage_result editorconfig ok "${#files[@]} text files follow .editorconfig"
  fi
}

# Test executables declared with `tessera_add_test(NAME ... LABELS ... LABEL ...)` in
# tests/**/CMakeLists.txt, so the TSan stage builds only what it runs. Prints nothing when none.
targets_with_label() {
  local files
  mapfile -t files < <(git ls-files -- 'tests/CMakeLists.txt' 'tests/**/CMakeLists.txt')
  ((${#files[@]})) || return 0
  awk -v label="$1" '
    /tessera_add_test\(/ {
      inblock = 1; depth = 0; text = ""
      match($0, /tessera_add_test\([A-Za-z0-9_]+/); name = substr($0, RSTART + 17, RLENGTH - 17)
    }
    inblock {
      text = text " " $0
      depth += gsub(/\(/, "(") - gsub(/\)/, ")")
      if (depth <= 0) {
        inblock = 0
        if (text ~ ("LABELS[^)]*[ \t]" label "([ \t)]|$)")) print name
      }
    }' "${files[@]}"
}

# No function in src/ over 120 lines, by clang-tidy over the configured build's
# compile_commands.json: it needs no build, so it runs before the release build and its
# failure (a list of file:line function lines) does not stop the tests.
function_size_check() {
  local dir=$1 out=$1/function-size.log status line
  log "function size, $jobs jobs ($(clang-tidy --version 2>/dev/null | grep -o 'version.*'))"
  TESSERA_TIDY_JOBS=$jobs scripts/check_function_size.sh "$dir" 2>&1 | tee "$out"
  status=${PIPESTATUS[0]}
  line=$(grep -E '^check_function_size: [0-9]+ files' "$out" | tail -1)
  line=${line#check_function_size: }
  case $status in
    0) stage_result functions ok "no function over 120 lines ($line)" ;;
    1) stage_result functions FAIL "$(grep -c '^  src/' "$out") functions over 120 lines ($line)" ;;
    *) stage_result functions FAIL "clang-tidy missing or could not parse a file (exit $status)" ;;
  esac
}

# Steps run right after a stage's configure, given its build folder.
declare -A after_configure=([release]=function_size_check)

# stage_build NAME BUILD_TYPE SANITIZE LABEL [extra cmake args...]: configures and builds a
# stage in $build_root/NAME. With LABEL, only the test executables carrying it are built (all
# of them if none is found). Writes "ok", "none: WHY" (nothing to test) or "FAIL" to
# $build_root/NAME.built for stage_test.
stage_build() {
  local name=$1 type=$2 sanitize=$3 label=$4
  shift 4
  local dir=$build_root/$name status_file=$build_root/$name.built
  echo FAIL >"$status_file"
  log "$name: configure ($type${sanitize:+, sanitize=$sanitize}) in $dir"
  if ! cmake -S "$repo" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE="$type" \
      -DTESSERA_BUILD_TESTS=ON -DTESSERA_BUILD_TOOLS=ON -DTESSERA_SANITIZE="$sanitize" "$@"; then
    stage_result "$name" FAIL "configure failed"
    return
  fi
  [[ -n ${after_configure[$name]:-} ]] && "${after_configure[$name]}" "$dir"
  local targets=()
  if [[ -n $label ]]; then
    mapfile -t targets < <(targets_with_label "$label")
    if ((${#targets[@]} == 0)); then
      echo "none: no tests labelled $label yet" >"$status_file"
      return
    fi
  fi
  log "$name: build (-j$jobs)${targets[*]:+ targets: ${targets[*]}}"
  if ! cmake --build "$dir" -j "$jobs" ${targets[@]:+--target "${targets[@]}"} -- -k 0; then  # -k 0: report every failing file
    stage_result "$name" FAIL "build failed"
    return
  fi
  echo ok >"$status_file"
}

# stage_test NAME LABEL TIMEOUT: runs the tests of a stage stage_build built.
stage_test() {
  local name=$1 label=$2 timeout=$3
  local dir=$build_root/$name built
  built=$(cat "$build_root/$name.built" 2>/dev/null || echo FAIL)
  case $built in
    ok) ;;
    none:*) stage_result "$name" ok "${built#none: }"; return ;;
    *) return ;;  # stage_build reported the failure
  esac
  log "$name: test${label:+ (label $label)}"
  local args=(--test-dir "$dir" --output-on-failure -j "$test_jobs" --timeout "$timeout"
              --no-tests=ignore)
  [[ -n $label ]] && args+=(-L "$label")
  [[ -n $filter ]] && args+=(-R "$filter")
  local out=$dir/ctest.log status
  ctest "${args[@]}" 2>&1 | tee "$out"
  status=${PIPESTATUS[0]}
  # ctest's own summary: "100% tests passed, 0 tests failed out of N" and "Total Test time".
  local line
  line=$(grep -E 'tests passed|No tests were found' "$out" | tail -1)
  if [[ -n $line ]]; then
    line+=" $(grep -E '^Total Test time' "$out" | tail -1 | sed 's/^Total Test time (real) = */in /')"
  elif ((status == 0)); then
    line="no tests matched${label:+ label $label}${filter:+ filter $filter} (none yet)"
  else
    line="ctest exited $status"
  fi
  if ((status == 0)); then stage_result "$name" ok "$line"; else stage_result "$name" FAIL "$line"; fi
}

# GCC 12's -O2/-O3 -Warray-bounds and -Wstringop-* report false positives inside libstdc++
# (std::copy/memcpy of small vectors); they stay warnings under -Werror. The asan stage checks
# real out-of-bounds accesses at run time.
release_flags=""
if [[ $("${CXX:-c++}" --version 2>/dev/null) == *"Free Software Foundation"* ]]; then
  release_flags="-Wno-error=array-bounds -Wno-error=stringop-overflow -Wno-error=stringop-overread"
fi

# The sanitizer stages compile with -g1 (line tables only): that is all a sanitizer's
# symbolized stack needs, and full -g makes their compiles about 30 % slower. The ASan stage
# also compiles at -O1, as AddressSanitizer's documentation advises: its build is most of CI's
# time, and -O1 takes 16-40 % off its files.
asan_flags=(-DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG")
tsan_flags=(-DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG")

# The fuzzers declared with `tessera_add_fuzzer(NAME ...)` in fuzz/CMakeLists.txt.
fuzzer_names() {
  grep -oE '^tessera_add_fuzzer\([a-z_0-9]+' fuzz/CMakeLists.txt | sed 's/^tessera_add_fuzzer(//'
}

# The fuzz stage: every fuzzer under ASan + UBSan with libFuzzer (clang), each for
# $fuzz_seconds from its committed corpus, two at a time (one per core). New inputs go to a
# scratch folder, so the committed corpus is only read; a crash, a sanitizer report, a timeout
# (10 s for one input) or an RSS over 2 GiB fails the stage, and the reproducer stays in
# build-ci/fuzz/artifacts/ (replay: build-ci/fuzz/fuzz/NAME_fuzzer FILE).
fuzz_build() {
  local dir=$build_root/fuzz names=()
  echo FAIL >"$build_root/fuzz.built"
  log "fuzz: configure (clang, libFuzzer, sanitize=address,undefined) in $dir"
  if ! command -v clang++ >/dev/null 2>&1; then
    stage_result fuzz FAIL "clang++ not found (scripts/install-deps.sh installs clang)"
    return
  fi
  if ! CC=clang CXX=clang++ cmake -S "$repo" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DTESSERA_BUILD_FUZZ=ON -DTESSERA_BUILD_TOOLS=OFF -DTESSERA_SANITIZE=address,undefined \
      "${asan_flags[@]}" >"$dir.configure.log" 2>&1; then
    cat "$dir.configure.log"
    stage_result fuzz FAIL "configure failed"
    return
  fi
  mapfile -t names < <(fuzzer_names)
  log "fuzz: build (-j$jobs) ${names[*]}"
  if ! cmake --build "$dir" -j "$jobs" --target "${names[@]/%/_fuzzer}" -- -k 0; then
    stage_result fuzz FAIL "build failed"
    return
  fi
  echo ok >"$build_root/fuzz.built"
}

fuzz_run() {
  local dir=$build_root/fuzz names=() name
  [[ $(cat "$build_root/fuzz.built" 2>/dev/null) == ok ]] || return  # fuzz_build reported it
  mapfile -t names < <(fuzzer_names)
  mkdir -p "$dir/artifacts"
  local failures=() running=0 pids=() pid_names=()
  for name in "${names[@]}"; do
    local scratch=$dir/scratch/$name
    rm -rf "$scratch" && mkdir -p "$scratch"
    log "fuzz: $name for ${fuzz_seconds} s"
    "$dir/fuzz/${name}_fuzzer" -max_total_time="$fuzz_seconds" -timeout=10 -rss_limit_mb=2048 \
      -print_final_stats=1 -artifact_prefix="$dir/artifacts/$name-" "$scratch" \
      "fuzz/corpus/$name" >"$dir/$name.log" 2>&1 &
    pids+=($!)
    pid_names+=("$name")
    if ((${#pids[@]} >= 2)); then
      wait "${pids[0]}" || failures+=("${pid_names[0]}")
      pids=("${pids[@]:1}")
      pid_names=("${pid_names[@]:1}")
    fi
  done
  local i
  for i in "${!pids[@]}"; do wait "${pids[$i]}" || failures+=("${pid_names[$i]}"); done
  for name in "${names[@]}"; do
    printf '%-16s %s\n' "$name" "$(grep -E '^stat::number_of_executed_units' "$dir/$name.log" | \
      sed 's/.*: */runs: /')"
  done
  if ((${#failures[@]})); then
    for name in "${failures[@]}"; do tail -40 "$dir/$name.log"; done
    stage_result fuzz FAIL "${#failures[@]} of ${#names[@]} fuzzers found a fault: ${failures[*]}"
  else
    stage_result fuzz ok "${#names[@]} fuzzers, ${fuzz_seconds} s each, nothing found"
  fi
}

build_stage() {  # build_stage NAME: the stage's build
  case $1 in
    release)
      stage_build release Release "" "" -DTESSERA_BUILD_BENCH=ON -DTESSERA_WERROR="$werror" \
        -DCMAKE_CXX_FLAGS="$release_flags" ;;
    asan) stage_build asan RelWithDebInfo address,undefined "" "${asan_flags[@]}" ;;
    tsan) stage_build tsan RelWithDebInfo thread concurrency "${tsan_flags[@]}" ;;
    fuzz) fuzz_build ;;
  esac
}
test_stage() {  # test_stage NAME: the stage's tests (the fuzzers' runs for fuzz)
  case $1 in
    release) stage_test release "" "$timeout_s" ;;
    # The kill loops check crash consistency, which the release stage does at 100 points;
    # under the sanitizers 20 points still run every phase of the killed programs.
    asan) TESSERA_KILL_POINTS=${TESSERA_KILL_POINTS:-20} stage_test asan "" $((timeout_s * 3)) ;;
    tsan) stage_test tsan concurrency $((timeout_s * 3)) ;;
    fuzz) fuzz_run ;;
  esac
}

start=$SECONDS
built=()
for stage in $stages; do
  case $stage in
    format) format_check; editorconfig_check ;;
    release | asan | tsan | fuzz) built+=("$stage") ;;
    *) echo "ci: unknown stage '$stage' (known: format release asan tsan fuzz)" >&2; exit 2 ;;
  esac
done

# A pipeline: while one stage's tests run, the next stage's build runs beside them at the
# lowest priority (nice 19), on the CPU the tests leave idle (they wait on servers, browsers,
# children and timeouts much of the time). The scheduler keeps the tests' share of the CPU,
# not of the caches: a CPU-bound ASan test ran 1.3x slower beside two nice-19 compiles. The
# background build's output goes to a log printed when it is waited for, so the run's output
# stays in order.
background_pid=
background_log=
for index in "${!built[@]}"; do
  stage=${built[$index]}
  if ((index == 0)); then
    build_stage "$stage"
  else
    wait "$background_pid"
    cat "$background_log"
  fi
  next=${built[$((index + 1))]:-}
  if [[ -n $next ]]; then
    background_log=$build_root/$next.build.log
    log "$next: configure and build in the background (nice 19) while $stage tests; output in $background_log"
    (renice -n 19 -p "$BASHPID" >/dev/null && build_stage "$next") >"$background_log" 2>&1 &
    background_pid=$!
  fi
  test_stage "$stage"
done

log "summary ($(((SECONDS - start) / 60)) min $(((SECONDS - start) % 60)) s)"
cat "$results"
if grep -qvE '^[^ ]+ +ok ' "$results"; then
  echo "ci: FAILED"
  exit 1
fi
echo "ci: all stages passed"
