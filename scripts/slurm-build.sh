#!/usr/bin/env bash
# Builds one archive on a Slurm cluster: the parts of a split build as a job array, then their
# merge as a job that starts only when every part succeeded (docs/cluster.md).
set -euo pipefail

usage() {
  cat <<'EOF'
Usage: scripts/slurm-build.sh INPUT OUT.tess --parts N [options] [-- BUILD_OPTIONS...]

Submits `tessera build INPUT --part I/N BUILD_OPTIONS -o WORKDIR/part-I.tess` for I = 1..N as
one Slurm job array (sbatch --array=1-N), and `tessera merge WORKDIR/part-1.tess ...
-o OUT.tess` as a job that depends on it (--dependency=afterok). Prints the two job ids as
`parts_job=ID` and `merge_job=ID`.

INPUT, OUT.tess, WORKDIR and the tessera binary must be on a file system that every compute
node sees at the same path (NFS, Lustre, GPFS, CephFS...): the parts are written by one node
and read by another. Paths are made absolute before submission.

Options:
  --parts N           number of parts (required), 1..10000
  --workdir DIR       where parts, job scripts and logs go (default: OUT.tess's name with
                      .parts instead of .tess, next to it)
  --tessera PATH      the tessera binary (default: `tessera` on PATH)
  --retries K         a part build that fails is run again up to K times within its task
                      (default 2); a node failure makes Slurm requeue the task (--requeue)
  --retry-delay S     seconds between such attempts (default 10)
  --only LIST         submit only these parts (Slurm array syntax, e.g. 3,5-6), to rebuild
                      the ones that failed; the merge still takes all N
  --sbatch ARG        an extra sbatch argument for both jobs, repeatable
                      (e.g. --sbatch --partition=batch --sbatch --time=2:00:00)
  --wait              block until the merge ends; exit with its status
  --poll S            seconds between job state checks with --wait (default 5)
  -h, --help          this help

Exit codes: 0 submitted (with --wait: the archive is built); 1 a part or the merge failed (with
--wait: the merge's own exit code where it ran and failed); 2 bad command line.
EOF
}

die_usage() {
  echo "slurm-build: $*" >&2
  echo "slurm-build: see scripts/slurm-build.sh --help" >&2
  exit 2
}
die() {
  echo "slurm-build: $*" >&2
  exit 1
}
note() { echo "slurm-build: $*" >&2; }

is_uint() { [[ $1 =~ ^[0-9]+$ ]]; }

input="" output="" parts="" workdir="" tessera="" retries=2 retry_delay_s=10 only=""
wait_for_merge=0 poll_s=5
sbatch_args=() build_options=() positionals=()
while (($#)); do
  case $1 in
    -h | --help) usage; exit 0 ;;
    --parts) (($# >= 2)) || die_usage "--parts needs a value"; parts=$2; shift 2 ;;
    --workdir) (($# >= 2)) || die_usage "--workdir needs a value"; workdir=$2; shift 2 ;;
    --tessera) (($# >= 2)) || die_usage "--tessera needs a value"; tessera=$2; shift 2 ;;
    --retries) (($# >= 2)) || die_usage "--retries needs a value"; retries=$2; shift 2 ;;
    --retry-delay) (($# >= 2)) || die_usage "--retry-delay needs a value"; retry_delay_s=$2; shift 2 ;;
    --only) (($# >= 2)) || die_usage "--only needs a value"; only=$2; shift 2 ;;
    --sbatch) (($# >= 2)) || die_usage "--sbatch needs a value"; sbatch_args+=("$2"); shift 2 ;;
    --wait) wait_for_merge=1; shift ;;
    --poll) (($# >= 2)) || die_usage "--poll needs a value"; poll_s=$2; shift 2 ;;
    --) shift; build_options=("$@"); break ;;
    -*) die_usage "unknown option $1" ;;
    *) positionals+=("$1"); shift ;;
  esac
done

((${#positionals[@]} == 2)) || die_usage "expected INPUT and OUT.tess, got ${#positionals[@]} arguments"
input=${positionals[0]}
output=${positionals[1]}
[[ -n $parts ]] || die_usage "--parts N is required"
{ is_uint "$parts" && ((10#$parts >= 1 && 10#$parts <= 10000)); } || die_usage "--parts $parts: expected 1..10000"
parts=$((10#$parts))
{ is_uint "$retries" && ((10#$retries <= 100)); } || die_usage "--retries $retries: expected 0..100"
is_uint "$retry_delay_s" || die_usage "--retry-delay $retry_delay_s: expected whole seconds"
{ is_uint "$poll_s" && ((10#$poll_s >= 1)); } || die_usage "--poll $poll_s: expected 1 or more seconds"
[[ -z $only || $only =~ ^[0-9]+(-[0-9]+)?(,[0-9]+(-[0-9]+)?)*$ ]] ||
  die_usage "--only $only: expected a list such as 3,5-6"
for index in ${only//[,-]/ }; do
  ((10#$index >= 1 && 10#$index <= parts)) || die_usage "--only $only: part $index is not in 1..$parts"
done
for option in "${build_options[@]}"; do
  case $option in
    -o | --output | --output=* | --part | --part=*)
      die_usage "build option $option: the script sets the part and its output itself" ;;
  esac
done

# Absolute paths, since the jobs start in whatever directory the node gives them. A source
# such as synthetic:WxH is not a file and is passed as it is.
absolute() { realpath -m -- "$1"; }
if [[ -e $input ]]; then
  input=$(absolute "$input")
elif [[ $input != *:* ]]; then
  die_usage "$input: no such file"
fi
[[ $output == *.tess ]] || die_usage "$output: the output's name must end in .tess"
output=$(absolute "$output")
[[ -d $(dirname "$output") ]] || die_usage "$output: its directory does not exist"
[[ -n $workdir ]] || workdir=${output%.tess}.parts
workdir=$(absolute "$workdir")
if [[ -z $tessera ]]; then
  tessera=$(command -v tessera) || die_usage "tessera is not on PATH; give --tessera PATH"
fi
[[ -x $tessera && ! -d $tessera ]] || die_usage "$tessera: not an executable file"
tessera=$(absolute "$tessera")
command -v sbatch >/dev/null || die "sbatch not found: this needs a Slurm client (Debian: slurm-client)"

mkdir -p "$workdir/logs" || die "$workdir: cannot create"

# The job scripts carry every value baked in (printf %q), so a job does not depend on the
# submitting shell's environment beyond what sbatch exports.
part_script=$workdir/part.sbatch
{
  echo '#!/usr/bin/env bash'
  echo '# One part of a split build; written by scripts/slurm-build.sh.'
  echo 'set -uo pipefail'
  printf 'tessera=%q input=%q workdir=%q parts=%q retries=%q retry_delay_s=%q\n' \
    "$tessera" "$input" "$workdir" "$parts" "$retries" "$retry_delay_s"
  printf 'build_options=('
  ((${#build_options[@]})) && printf ' %q' "${build_options[@]}"
  printf ' )\n'
  cat <<'EOF'
part=${SLURM_ARRAY_TASK_ID:?not started as a Slurm array task}
# Slurm gives the task its CPUs; without --threads the build would use every core of the node.
threads=()
if [[ -n ${SLURM_CPUS_PER_TASK:-} && " ${build_options[*]-} " != *" --threads"* ]]; then
  threads=(--threads "$SLURM_CPUS_PER_TASK")
fi
attempt=0
while true; do
  attempt=$((attempt + 1))
  echo "part $part/$parts: attempt $attempt on $(hostname)"
  # ${a[@]+"${a[@]}"}: an empty array under set -u, which bash before 4.4 calls unbound.
  "$tessera" build "$input" --part "$part/$parts" ${build_options[@]+"${build_options[@]}"} \
    ${threads[@]+"${threads[@]}"} -o "$workdir/part-$part.tess"
  status=$?
  if ((status == 0)); then exit 0; fi
  echo "part $part/$parts: tessera build exited $status on attempt $attempt" >&2
  # A bad command line fails the same way every time.
  if ((status == 2 || attempt > retries)); then exit "$status"; fi
  sleep "$retry_delay_s"
done
EOF
} >"$part_script"

merge_script=$workdir/merge.sbatch
{
  echo '#!/usr/bin/env bash'
  echo '# The merge of a split build; written by scripts/slurm-build.sh.'
  echo 'set -uo pipefail'
  printf 'tessera=%q workdir=%q output=%q parts=%q\n' "$tessera" "$workdir" "$output" "$parts"
  cat <<'EOF'
# Every part by name, not a glob: a missing one is then an error of the merge, and a stale
# part-9.tess from an earlier build with more parts is not picked up.
part_files=()
for ((i = 1; i <= parts; i++)); do part_files+=("$workdir/part-$i.tess"); done
"$tessera" merge "${part_files[@]}" -o "$output"
status=$?
# Kept next to the parts for --wait, in case slurmctld has forgotten the job by then.
echo "$status" >"$workdir/merge.status"
exit "$status"
EOF
} >"$merge_script"
chmod +x "$part_script" "$merge_script"
rm -f "$workdir/merge.status"

array_spec=${only:-1-$parts}
common=(--parsable --requeue --open-mode=append "${sbatch_args[@]}")
parts_job=$(sbatch "${common[@]}" --job-name=tessera-parts --array="$array_spec" \
  --output="$workdir/logs/part-%a.log" "$part_script") || die "sbatch of the parts failed"
parts_job=${parts_job%%;*}  # --parsable prints ID or ID;CLUSTER
merge_job=$(sbatch "${common[@]}" --job-name=tessera-merge --dependency="afterok:$parts_job" \
  --kill-on-invalid-dep=yes --output="$workdir/logs/merge.log" "$merge_script") || {
  scancel "$parts_job" 2>/dev/null || true
  die "sbatch of the merge failed (parts job $parts_job cancelled)"
}
merge_job=${merge_job%%;*}
echo "parts_job=$parts_job"
echo "merge_job=$merge_job"
note "parts: job $parts_job, array $array_spec of $parts, logs $workdir/logs/part-I.log"
note "merge: job $merge_job after all parts succeed, writes $output, log $workdir/logs/merge.log"

((wait_for_merge)) || exit 0

# The field NAME=VALUE of one job's `scontrol show job -o` line.
job_field() { grep -oE "(^| )$2=[^ ]*" <<<"$1" | head -1 | cut -d= -f2-; }

# Names each part task that did not complete, with the end of its log.
report_failed_parts() {
  local line task state
  while IFS= read -r line; do
    task=$(job_field "$line" ArrayTaskId)
    state=$(job_field "$line" JobState)
    [[ -n $task && $state != COMPLETED ]] || continue
    note "part $task: $state (exit $(job_field "$line" ExitCode)), log $workdir/logs/part-$task.log:"
    tail -n 3 "$workdir/logs/part-$task.log" 2>/dev/null | sed 's/^/    /' >&2 || true
  done < <(scontrol show job -o "$parts_job" 2>/dev/null)
}

while true; do
  line=$(scontrol show job -o "$merge_job" 2>/dev/null) || line=""
  state=$(job_field "$line" JobState)
  reason=$(job_field "$line" Reason)
  case $state in
    COMPLETED)
      note "done: $output"
      exit 0 ;;
    PENDING)
      # Where kill-on-invalid-dep is not honoured, the merge would wait for ever.
      if [[ $reason == DependencyNeverSatisfied ]]; then
        scancel "$merge_job" 2>/dev/null || true
        report_failed_parts
        die "parts failed; merge job $merge_job cancelled (rebuild them with --only LIST)"
      fi ;;
    RUNNING | CONFIGURING | COMPLETING | REQUEUED | REQUEUE_FED | REQUEUE_HOLD | RESIZING | \
      SUSPENDED | SIGNALING | STAGE_OUT | STOPPED) ;;
    "")
      # slurmctld forgets finished jobs after MinJobAge; the merge leaves its status behind.
      [[ -f $workdir/merge.status ]] || die "merge job $merge_job is unknown to slurmctld and left no status"
      status=$(<"$workdir/merge.status")
      ((status == 0)) && { note "done: $output"; exit 0; }
      die "merge failed with exit $status, log $workdir/logs/merge.log" ;;
    *)
      if [[ $reason == Dependency* || $reason == *DependencyNeverSatisfied* ]] ||
        [[ ! -f $workdir/merge.status ]]; then
        report_failed_parts
        die "merge job $merge_job $state without running: a part failed (rebuild it with --only LIST)"
      fi
      status=$(<"$workdir/merge.status")
      note "merge job $merge_job $state, exit $status, log $workdir/logs/merge.log:"
      tail -n 3 "$workdir/logs/merge.log" 2>/dev/null | sed 's/^/    /' >&2 || true
      ((status != 0)) && exit "$status"
      exit 1 ;;
  esac
  sleep "$poll_s"
done
