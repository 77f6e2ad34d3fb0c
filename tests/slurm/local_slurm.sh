#!/usr/bin/env bash
# A one-node Slurm cluster on localhost for the test suite (Debian 12's slurm-wlm and munge), in a
# private folder: its own munge key and socket, slurm.conf with this machine's real CPUs and
# memory (slurmd -C), slurmctld and slurmd on free ports. Nothing outside the folder is touched,
# so it runs beside a real cluster's daemons without meeting them.
#
#   source tests/slurm/local_slurm.sh
#   local_slurm_missing      # prints the tools that are not installed (nothing when all are)
#   local_slurm_start DIR    # exports SLURM_CONF; returns 1 with a message if it cannot start
#   local_slurm_stop DIR     # stops the daemons (idempotent; call it from a trap)
#
# Sourced, not run: the caller's shell gets SLURM_CONF, so sbatch/squeue/sacct talk to this one.

local_slurm_free_port() {  # a TCP port nothing listens on, from the ephemeral range's lower end
  local port
  for port in $(shuf -i 20000-29999 -n 40); do
    if ! (exec 3<>"/dev/tcp/127.0.0.1/$port") 2> /dev/null; then
      echo "$port"
      return 0
    fi
  done
  return 1
}

local_slurm_missing() {
  local tool missing=()
  for tool in munged slurmctld slurmd sbatch squeue sinfo scontrol; do
    command -v "$tool" > /dev/null || missing+=("$tool")
  done
  echo "${missing[*]}"
}

local_slurm_start() {
  local dir="$1" missing
  missing="$(local_slurm_missing)"
  if [[ -n "$missing" ]]; then
    echo "local_slurm: not installed: $missing (Debian: apt-get install slurm-wlm munge)" >&2
    return 1
  fi
  mkdir -p "$dir"/{munge,spool,state,log}
  chmod 700 "$dir" "$dir/munge"
  dir="$(cd "$dir" && pwd)"
  # munge: a fresh key, and a socket in the folder (the system's munged, if any, is not used).
  dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
  chmod 400 "$dir/munge/munge.key"
  munged --force --key-file="$dir/munge/munge.key" --socket="$dir/munge/socket" \
    --pid-file="$dir/munge/munged.pid" --log-file="$dir/log/munged.log" \
    --seed-file="$dir/munge/seed" 2> "$dir/log/munged.err" || {
    echo "local_slurm: munged did not start: $(cat "$dir/log/munged.err")" >&2
    return 1
  }
  local node ctld_port slurmd_port user
  node="$(slurmd -C | head -n 1)"  # NodeName=HOST CPUs=N ... RealMemory=M (this machine's own)
  node="${node/NodeName=$(hostname -s)/NodeName=localhost}"
  ctld_port="$(local_slurm_free_port)" && slurmd_port="$(local_slurm_free_port)" || {
    echo "local_slurm: no free port" >&2
    return 1
  }
  user="$(id -un)"
  cat > "$dir/slurm.conf" <<CONF
ClusterName=digitize-test
SlurmctldHost=localhost
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=$user
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge/socket
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/slurmd-%n
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
KillWait=5
$node State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF="$dir/slurm.conf"
  slurmctld -i -f "$SLURM_CONF" 2> "$dir/log/slurmctld.err" || {
    echo "local_slurm: slurmctld did not start: $(cat "$dir/log/slurmctld.err")" >&2
    return 1
  }
  slurmd -f "$SLURM_CONF" -N localhost 2> "$dir/log/slurmd.err" || {
    echo "local_slurm: slurmd did not start: $(cat "$dir/log/slurmd.err")" >&2
    return 1
  }
  local i
  for i in $(seq 1 60); do  # up to 30 s for the node to come up idle
    if sinfo -h -N -o '%T' 2> /dev/null | grep -qE '^(idle|mixed|allocated)'; then return 0; fi
    sleep 0.5
  done
  echo "local_slurm: the node did not come up; slurmctld log:" >&2
  tail -n 20 "$dir/log/slurmctld.log" >&2
  return 1
}

local_slurm_stop() {
  local dir="$1" pidfile pid i
  local pids=()
  [[ -d "$dir" ]] || return 0
  # Every pid before any kill: a daemon removes its pid file as it exits, so a file read after
  # the kills can be gone between the test and the read (seen: the test failing in its cleanup).
  for pidfile in "$dir/slurmd.pid" "$dir/slurmctld.pid" "$dir/munge/munged.pid"; do
    pid="$(cat "$pidfile" 2> /dev/null)" && [[ -n "$pid" ]] && pids+=("$pid")
  done
  for pid in "${pids[@]}"; do
    kill "$pid" 2> /dev/null || true
  done
  for pid in "${pids[@]}"; do
    for i in $(seq 1 20); do
      kill -0 "$pid" 2> /dev/null || break
      sleep 0.25
    done
    kill -9 "$pid" 2> /dev/null || true
  done
  return 0
}
