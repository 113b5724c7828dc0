#!/usr/bin/env bash
# A throwaway single-node Slurm cluster on this machine, for the Slurm test and for trying
# `dem ensemble --profile slurm` without a cluster. Needs root and Debian's slurm-wlm and munge
# (scripts/install-deps.sh installs them). Everything lives in DIR (config, state, logs, pid
# files): /etc/slurm is not touched. Configuration and pitfalls: ../shared/notes/slurm.md.
#
#   eval "$(bash scripts/slurm-local.sh start DIR)"   # starts munged (if needed), slurmctld, slurmd;
#                                                    # prints `export SLURM_CONF=DIR/slurm.conf`
#   bash scripts/slurm-local.sh stop DIR              # stops what start started
set -euo pipefail
cmd=${1:-}; dir=${2:-}
[ -n "$cmd" ] && [ -n "$dir" ] || { echo "usage: $0 start|stop DIR" >&2; exit 2; }
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
conf="$dir/slurm.conf"

stop() {
  for f in "$dir/slurmd.pid" "$dir/slurmctld.pid"; do
    [ -f "$f" ] && kill "$(cat "$f")" 2>/dev/null || true
  done
  if [ -f "$dir/munged.started" ] && [ -f /run/munge/munged.pid ]; then
    kill "$(cat /run/munge/munged.pid)" 2>/dev/null || true
    rm -f "$dir/munged.started"
  fi
  sleep 0.5
  for f in "$dir/slurmd.pid" "$dir/slurmctld.pid"; do
    [ -f "$f" ] && kill -9 "$(cat "$f")" 2>/dev/null || true
    rm -f "$f"
  done
}

start() {
  [ "$(id -u)" = 0 ] || { echo "slurm-local.sh: needs root (the Slurm daemons run as root here)" >&2; exit 1; }
  for b in slurmctld slurmd munged sbatch srun; do
    command -v "$b" >/dev/null || [ -x "/usr/sbin/$b" ] || {
      echo "slurm-local.sh: $b not found: install slurm-wlm and munge (bash scripts/install-deps.sh)" >&2; exit 1; }
  done
  mkdir -p "$dir/state" "$dir/spool" "$dir/log"
  # munge: authentication of every Slurm message; reuse a running munged.
  if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    mkdir -p /run/munge /var/log/munge /var/lib/munge
    chown munge:munge /run/munge /var/log/munge /var/lib/munge 2>/dev/null || true
    chmod 0755 /run/munge
    [ -f /etc/munge/munge.key ] || { /usr/sbin/mungekey --create 2>/dev/null || /usr/sbin/create-munge-key -f; chown munge:munge /etc/munge/munge.key; }
    su -s /bin/sh munge -c /usr/sbin/munged
    touch "$dir/munged.started"
    for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.1; done
  fi
  local host node
  host=$(hostname -s)
  node=$(/usr/sbin/slurmd -C | head -n1)
  cat > "$conf" <<CONF
ClusterName=demlocal
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SchedulerParameters=batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF="$conf"
  /usr/sbin/slurmctld -f "$conf"
  /usr/sbin/slurmd -f "$conf"
  # "idle" in sinfo can be stale saved state: a real job is the readiness test.
  if ! timeout 60 srun -n1 -t 1 true; then
    echo "slurm-local.sh: Slurm did not run a job within 60 s; logs in $dir/log" >&2
    stop
    exit 1
  fi
  echo "export SLURM_CONF=$conf"
}

case "$cmd" in
  start) start ;;
  stop) stop ;;
  *) echo "usage: $0 start|stop DIR" >&2; exit 2 ;;
esac
