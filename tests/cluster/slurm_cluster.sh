# A throwaway single-node Slurm cluster on loopback, for tests (sourced, not run).
#
#   slurm_cluster_start DIR   writes a munge key and slurm.conf under DIR, starts munged,
#                             slurmctld and slurmd, and returns once the node is idle
#   slurm_cluster_stop        stops the three daemons (safe to call twice, and from a trap)
#
# After start, SLURM_CONF points at the generated slurm.conf, so sbatch, squeue, scontrol and
# sinfo talk to this cluster only; nothing under /etc is read or written. The daemons run in
# the foreground (-D / -F) as background children of the caller, so their process ids are
# known without pid-file races. Needs root (slurmd starts jobs through slurmstepd as the
# submitting user) and Debian's slurm-wlm and munge.

slurm_cluster_pids=()

# Seconds allowed for the daemons to come up and the node to report idle.
slurm_cluster_start_timeout_s=${SLURM_CLUSTER_START_TIMEOUT_S:-30}

slurm_cluster_log() { echo "slurm-cluster: $*" >&2; }

# Two free TCP ports on 127.0.0.1: the kernel picks them (bind to port 0) and they are
# released just before the daemons bind them; a clash in between makes a daemon fail to start,
# which the readiness poll reports.
slurm_cluster_free_ports() {
  python3 - <<'EOF'
import socket
socks = [socket.socket() for _ in range(2)]
for s in socks:
    s.bind(("127.0.0.1", 0))
print(" ".join(str(s.getsockname()[1]) for s in socks))
EOF
}

# The node's CPUs and memory as slurmd measures them. The node claims at least
# slurm_cluster_min_cpus CPUs (SlurmdParameters=config_overrides keeps slurmd from draining it
# for having fewer): the tests' jobs are small, and one wave of 8 tasks instead of four on a
# 2-core machine keeps the test short; what they check is order and outcome, not throughput.
slurm_cluster_min_cpus=${SLURM_CLUSTER_MIN_CPUS:-8}
slurm_cluster_node_resources() {
  local line
  line=$(slurmd -C 2>/dev/null | head -1)
  local cpus mem
  cpus=$(grep -oE 'CPUs=[0-9]+' <<<"$line" | cut -d= -f2)
  mem=$(grep -oE 'RealMemory=[0-9]+' <<<"$line" | cut -d= -f2)
  [[ -n $cpus && -n $mem ]] || { cpus=$(nproc); mem=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024)); }
  echo "$((cpus > slurm_cluster_min_cpus ? cpus : slurm_cluster_min_cpus)) $mem"
}

slurm_cluster_write_config() {
  local dir=$1 ctld_port=$2 slurmd_port=$3 cpus=$4 mem_mib=$5
  cat >"$dir/slurm.conf" <<EOF
ClusterName=tessera-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/munge.socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/run/slurmctld.pid
SlurmdPidFile=$dir/run/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
SchedulerParameters=batch_sched_delay=0
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
SlurmdParameters=config_overrides
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mib State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
}

# Polls COMMAND (a string for eval) until it succeeds or the start deadline passes.
slurm_cluster_poll() {
  local what=$1 command=$2 deadline=$((SECONDS + slurm_cluster_start_timeout_s))
  until eval "$command" >/dev/null 2>&1; do
    if ((SECONDS >= deadline)); then
      slurm_cluster_log "$what not ready after ${slurm_cluster_start_timeout_s} s"
      return 1
    fi
    sleep 0.2
  done
}

slurm_cluster_start() {
  local dir=$1
  mkdir -p "$dir"/{munge,state,spool,run,log}
  chmod 700 "$dir" "$dir/munge"
  dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  chmod 400 "$dir/munge/munge.key"

  local ports resources
  ports=$(slurm_cluster_free_ports) || return 1
  resources=$(slurm_cluster_node_resources)
  # shellcheck disable=SC2086
  slurm_cluster_write_config "$dir" $ports $resources
  export SLURM_CONF=$dir/slurm.conf

  local socket=$dir/munge/munge.socket
  munged -F --force --socket="$socket" --key-file="$dir/munge/munge.key" \
    --pid-file="$dir/run/munged.pid" --log-file="$dir/log/munged.log" \
    --seed-file="$dir/munge/munged.seed" 2>>"$dir/log/munged.stderr" &
  slurm_cluster_pids+=($!)
  slurm_cluster_poll munged "munge -S '$socket' -n | unmunge -S '$socket'" || return 1

  slurmctld -D -c -f "$SLURM_CONF" 2>>"$dir/log/slurmctld.stderr" &
  slurm_cluster_pids+=($!)
  slurm_cluster_poll slurmctld "scontrol ping | grep -q UP" || {
    tail -20 "$dir/log/slurmctld.log" "$dir/log/slurmctld.stderr" >&2
    return 1
  }

  slurmd -D -N localhost -f "$SLURM_CONF" 2>>"$dir/log/slurmd.stderr" &
  slurm_cluster_pids+=($!)
  slurm_cluster_poll "node localhost" "sinfo -h -n localhost -o %T | grep -qx idle" || {
    sinfo -N -l >&2
    tail -20 "$dir/log/slurmd.log" "$dir/log/slurmd.stderr" >&2
    return 1
  }
  slurm_cluster_log "up in $dir (SLURM_CONF=$SLURM_CONF, $(sinfo -h -o '%c CPUs, %m MiB'))"
}

# Cancels what is still queued or running (a test that failed half-way), then stops the
# daemons in reverse order of start: slurmd first, munged last, as both Slurm daemons
# authenticate through it. Job steps run under slurmstepd, outside slurmd, so they are
# cancelled and waited for (with a deadline) rather than orphaned.
slurm_cluster_stop() {
  local i pid
  if ((${#slurm_cluster_pids[@]} >= 2)) && [[ -n ${SLURM_CONF:-} ]]; then
    scancel --user="$(id -un)" 2>/dev/null || true
    local deadline=$((SECONDS + 10))
    while [[ -n $(squeue -h -t PENDING,RUNNING,COMPLETING -o %i 2>/dev/null) ]] &&
      ((SECONDS < deadline)); do
      sleep 0.2
    done
  fi
  for ((i = ${#slurm_cluster_pids[@]} - 1; i >= 0; i--)); do
    pid=${slurm_cluster_pids[i]}
    kill -TERM "$pid" 2>/dev/null || continue
    local deadline=$((SECONDS + 10))
    while kill -0 "$pid" 2>/dev/null && ((SECONDS < deadline)); do sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  done
  slurm_cluster_pids=()
}
