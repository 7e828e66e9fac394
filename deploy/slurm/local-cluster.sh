#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for testing array-job bakes
# (bake-tool/tests/it/slurm.rs) and for trying the Slurm workflow of docs/DEPLOY.md
# without a real cluster. Everything lives under DIR: its own munge daemon and
# key, slurm.conf, state and logs; nothing in /etc is touched.
#
#   deploy/slurm/local-cluster.sh start DIR   start munged, slurmctld and slurmd;
#                                             prints `export SLURM_CONF=DIR/slurm.conf`
#   deploy/slurm/local-cluster.sh stop DIR    stop them (idempotent)
#
# Needs Debian's slurmctld, slurmd, slurm-client and munge (`.ci/setup` installs
# them) and root: slurmd starts jobs as their submitting user.
set -euo pipefail

usage() { echo "usage: $0 start|stop DIR" >&2; exit 2; }
[ $# -eq 2 ] || usage
cmd=$1
mkdir -p "$2"
dir=$(cd "$2" && pwd)
sbin=/usr/sbin

stop() {
  for pidfile in "$dir/slurmd.pid" "$dir/slurmctld.pid" "$dir/munge/munged.pid"; do
    if [ -f "$pidfile" ]; then
      pid=$(cat "$pidfile")
      kill "$pid" 2>/dev/null || true
      for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
      kill -9 "$pid" 2>/dev/null || true
      rm -f "$pidfile"
    fi
  done
}

start() {
  for exe in munged slurmctld slurmd; do
    [ -x "$sbin/$exe" ] || { echo "local-cluster: $sbin/$exe missing (apt-get install slurmctld slurmd slurm-client munge, or run .ci/setup)" >&2; exit 1; }
  done
  [ "$(id -u)" -eq 0 ] || { echo "local-cluster: must run as root (slurmd starts jobs as their user)" >&2; exit 1; }
  stop
  mkdir -p -m 700 "$dir/munge"
  mkdir -p "$dir/state" "$dir/spool" "$dir/log"
  if [ ! -s "$dir/munge/munge.key" ]; then
    dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none
    chmod 600 "$dir/munge/munge.key"
  fi
  "$sbin/munged" --force --socket="$dir/munge/socket" --key-file="$dir/munge/munge.key" \
    --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" --seed-file="$dir/munge/seed" \
    2>>"$dir/log/munged.err"

  host=$(hostname -s)
  cpus=$(nproc)
  mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)
  # Ports away from the defaults (6817/6818), so a real Slurm on the machine is not disturbed.
  cat >"$dir/slurm.conf" <<CONF
ClusterName=sylvalocal
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge/socket
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool/%n
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmdTimeout=60
InactiveLimit=0
KillWait=5
MinJobAge=300
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
  export SLURM_CONF="$dir/slurm.conf"
  "$sbin/slurmctld" -f "$SLURM_CONF" 2>>"$dir/log/slurmctld.err"
  "$sbin/slurmd" -f "$SLURM_CONF" 2>>"$dir/log/slurmd.err"
  # Wait until the node takes jobs.
  for _ in $(seq 100); do
    state=$(sinfo -h -N -o %T 2>/dev/null || true)
    # (A trailing * means the node does not respond yet.)
    case "$state" in idle|mixed|allocated) echo "export SLURM_CONF=$SLURM_CONF"; return 0;; esac
    sleep 0.2
  done
  echo "local-cluster: the node did not come up (state: ${state:-none}); logs in $dir/log" >&2
  tail -n 20 "$dir/log/"* >&2 || true
  stop
  exit 1
}

case "$cmd" in
  start) start ;;
  stop) stop ;;
  *) usage ;;
esac
