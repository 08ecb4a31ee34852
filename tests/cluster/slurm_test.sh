#!/usr/bin/env bash
# scripts/slurm-build.sh on a real single-node Slurm cluster (tests/cluster/slurm_cluster.sh).
#
#   slurm_test.sh harness SOURCE_DIR        the job array and the dependent merge with a stand-in
#                                           tessera: N tasks ran, the merge ran after all of
#                                           them, a failing part is retried, a part that keeps
#                                           failing stops the merge and --wait says which
#   slurm_test.sh build SOURCE_DIR TESSERA  an 8-part split build through the cluster is
#                                           byte-identical to a single-machine build
#
# Exit 77 (ctest SKIP_RETURN_CODE) where the cluster cannot be started here: Slurm or munge not
# installed, not root, or (build) a tessera without `merge`. TESSERA_SLURM_TEST_KEEP=1 keeps the
# temporary folder (parts, job logs, daemon logs), which a failure always keeps.
set -euo pipefail

mode=${1:?mode: harness or build}
source_dir=${2:?source directory}
tessera=${3:-}
slurm_build=$source_dir/scripts/slurm-build.sh

skip() {
  echo "SKIP: $*"
  exit 77
}
fail() {
  echo "FAIL: $*" >&2
  exit 1
}

for program in munged munge slurmctld slurmd sbatch scontrol sinfo python3; do
  command -v "$program" >/dev/null || skip "$program not installed (scripts/install-deps.sh installs slurm-wlm and munge)"
done
((EUID == 0)) || skip "slurmd must run as root to start jobs"
if [[ $mode == build ]]; then
  [[ -x $tessera ]] || fail "tessera binary '$tessera' not found"
  "$tessera" merge --help >/dev/null 2>&1 || skip "$tessera has no merge subcommand"
fi

# shellcheck source=tests/cluster/slurm_cluster.sh
source "$(dirname "$0")/slurm_cluster.sh"
work=$(mktemp -d "${TMPDIR:-/tmp}/tessera-slurm.XXXXXX")
cleanup() {
  local status=$?
  slurm_cluster_stop
  if ((status != 0 && status != 77)) || [[ -n ${TESSERA_SLURM_TEST_KEEP:-} ]]; then
    echo "--- files and daemon logs kept in $work" >&2
  else
    rm -rf "$work"
  fi
}
trap cleanup EXIT
trap 'exit 143' TERM INT

# Checked here rather than in a test of its own: it needs no cluster, only the script.
expect_usage_error() {
  local status=0
  "$slurm_build" "$@" >/dev/null 2>"$work/usage.err" || status=$?
  ((status == 2)) || fail "slurm-build.sh $* exited $status, expected 2"
}

# A stand-in for tessera: `build INPUT --part I/N ... -o OUT` writes one line naming the part;
# `merge P1 .. PN -o OUT` concatenates the parts, so the merged file shows that the merge
# found every part, in order. Files named fail-once-I and fail-always-I in the folder make
# part I fail on its first attempt or on all of them, and fail-merge makes the merge exit 3.
write_stub_tessera() {
  local stub=$1
  cat >"$stub" <<'EOF'
#!/usr/bin/env bash
set -euo pipefail
here=$(dirname "$0")
command=$1; shift
args=("$@")
output=${args[-1]}
case $command in
  build)
    part=${args[2]%%/*}
    [[ ! -e $here/fail-always-$part ]] || { echo "stub: part $part fails" >&2; exit 1; }
    if [[ -e $here/fail-once-$part ]]; then
      rm "$here/fail-once-$part"
      echo "stub: part $part fails once" >&2
      exit 1
    fi
    echo "part ${args[2]} of ${args[0]} with ${args[*]:3:${#args[@]}-5}" >"$output.tmp"
    mv "$output.tmp" "$output" ;;
  merge)
    [[ ! -e $here/fail-merge ]] || { echo "stub: merge fails" >&2; exit 3; }
    cat "${args[@]:0:${#args[@]}-2}" >"$output.tmp"
    mv "$output.tmp" "$output" ;;
esac
EOF
  chmod +x "$stub"
}

run_harness() {
  expect_usage_error in.tif out.tess
  expect_usage_error synthetic:64x64 out.tess --parts 0
  expect_usage_error synthetic:64x64 out.tess --parts 2 -- -o elsewhere.tess
  expect_usage_error "$work/missing.tif" "$work/out.tess" --parts 2

  local stub=$work/stub/tessera parts=8
  mkdir -p "$work/stub" "$work/ok" "$work/bad"
  write_stub_tessera "$stub"

  # Part 3 fails once: its task retries it and the whole build still succeeds.
  touch "$work/stub/fail-once-3"
  local ids
  ids=$("$slurm_build" synthetic:64x64 "$work/ok/out.tess" --parts $parts --tessera "$stub" \
    --retries 1 --retry-delay 0 --poll 1 --wait -- --tile 64) ||
    fail "slurm-build.sh --wait exited $? on a build whose parts all succeed"
  { grep -qE '^parts_job=[0-9]+$' <<<"$ids" && grep -qE '^merge_job=[0-9]+$' <<<"$ids"; } ||
    fail "job ids not printed: $ids"
  local expected="" i
  for ((i = 1; i <= parts; i++)); do
    expected+="part $i/$parts of synthetic:64x64 with --tile 64"$'\n'
  done
  [[ $(<"$work/ok/out.tess") == "${expected%$'\n'}" ]] ||
    fail "merged output is not the $parts parts in order: $(<"$work/ok/out.tess")"
  [[ ! -e $work/stub/fail-once-3 ]] || fail "part 3 never ran"
  grep -q "attempt 2" "$work/ok/out.parts/logs/part-3.log" || fail "part 3 was not retried"

  # Part 5 keeps failing: the merge never runs, --wait exits 1 and names the part.
  touch "$work/stub/fail-always-5"
  local status=0
  "$slurm_build" synthetic:64x64 "$work/bad/out.tess" --parts $parts --tessera "$stub" \
    --retries 1 --retry-delay 0 --poll 1 --wait -- --tile 64 >/dev/null 2>"$work/bad.err" ||
    status=$?
  ((status == 1)) || fail "slurm-build.sh --wait exited $status with a failing part, expected 1"
  grep -q "part 5: FAILED" "$work/bad.err" || fail "the failing part is not named: $(<"$work/bad.err")"
  [[ ! -e $work/bad/out.tess ]] || fail "the merge ran although part 5 failed"
  [[ $(grep -c "^part 5/$parts: attempt" "$work/bad/out.parts/logs/part-5.log") == 2 ]] ||
    fail "part 5 was not tried twice (--retries 1)"

  # Rebuilding only the failed part, as --wait's message advises, completes the build.
  rm "$work/stub/fail-always-5"
  "$slurm_build" synthetic:64x64 "$work/bad/out.tess" --parts $parts --tessera "$stub" \
    --only 5 --poll 1 --wait -- --tile 64 >/dev/null 2>"$work/only.err" ||
    fail "slurm-build.sh --only 5 exited $?: $(<"$work/only.err")"
  [[ $(<"$work/bad/out.tess") == "${expected%$'\n'}" ]] ||
    fail "after --only 5 the merged output is not the $parts parts in order"
  [[ $(grep -c "^part 1/$parts: attempt" "$work/bad/out.parts/logs/part-1.log") == 1 ]] ||
    fail "--only 5 ran part 1 again"

  # A failing merge: --wait exits with the merge's own code. The parts were given 2 CPUs each,
  # so they build with 2 threads.
  touch "$work/stub/fail-merge"
  status=0
  "$slurm_build" synthetic:64x64 "$work/ok/again.tess" --parts 2 --tessera "$stub" --poll 1 \
    --sbatch --cpus-per-task=2 --wait >/dev/null 2>"$work/merge.err" || status=$?
  ((status == 3)) || fail "slurm-build.sh --wait exited $status after a merge exiting 3"
  grep -q -- "--threads 2" "$work/ok/again.parts/part-1.tess" ||
    fail "a part given 2 CPUs did not build with --threads 2: $(<"$work/ok/again.parts/part-1.tess")"
  echo "harness: array of $parts tasks, dependent merge, retry, failed part, --only and failed merge as expected"
}

run_build() {
  # Not a multiple of the tile size on either side, so edge tiles fall inside the parts.
  local input=synthetic:1500x1100 options=(--tile 128 --codec jpeg --quality 85)
  "$tessera" build "$input" "${options[@]}" -q -o "$work/single.tess" ||
    fail "single-machine build failed"
  "$slurm_build" "$input" "$work/split.tess" --parts 8 --tessera "$tessera" --poll 1 --wait \
    -- "${options[@]}" -q || fail "split build through Slurm exited $?"
  cmp "$work/single.tess" "$work/split.tess" ||
    fail "the 8-part build through Slurm differs from the single-machine build"
  echo "build: 8 parts through Slurm, merged archive identical to the single-machine build"
}

case $mode in
  harness | build) ;;
  *) fail "unknown mode $mode" ;;
esac
slurm_cluster_start "$work/cluster" || fail "the Slurm cluster did not start"
"run_$mode"
