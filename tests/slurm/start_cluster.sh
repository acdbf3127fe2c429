#!/usr/bin/env bash
# Start a single-node SLURM cluster on this machine (root, no systemd), for
# tests/test_slurm.py. Idempotent. Exit codes: 0 running, 3 cannot install/start.
set -u
STATE=/var/tmp/plenocal-slurm
HOST=$(hostname -s)

need_install=0
for b in slurmctld slurmd munged sinfo; do command -v "$b" >/dev/null 2>&1 || need_install=1; done
if [ "$need_install" = 1 ]; then
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "SLURM is not installed and cannot be installed (needs root and apt-get)"; exit 3
  fi
  export DEBIAN_FRONTEND=noninteractive
  { apt-get update -qq && apt-get install -y -qq slurmctld slurmd munge; } >/dev/null 2>&1 \
    || { echo "apt-get install slurmctld slurmd munge failed"; exit 3; }
fi

mkdir -p "$STATE/ctld" "$STATE/d" /etc/slurm /run/munge /var/log/munge /var/lib/munge
chown -R munge:munge /run/munge /var/log/munge /var/lib/munge /etc/munge 2>/dev/null || true
if [ ! -s /etc/munge/munge.key ]; then
  mkdir -p /etc/munge
  dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  chown munge:munge /etc/munge/munge.key 2>/dev/null || true
  chmod 400 /etc/munge/munge.key
fi
pgrep -x munged >/dev/null || munged --force 2>/dev/null || su -s /bin/sh munge -c munged \
  || { echo "munged does not start"; exit 3; }

# the node's CPUs as the machine gives them to us (affinity), not as the caller's OpenMP
# setting says: nproc honours OMP_NUM_THREADS, and a test process that pinned its pools to
# one thread made a 1-CPU node, on which every 2-thread job waits for ever (PartitionConfig)
CPUS=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)
MEM=$(( $(free -m | awk '/^Mem:/{print $2}') * 3 / 4 ))
CONF_NEW=$(mktemp)
cat > "$CONF_NEW" <<CONF
ClusterName=plenocal
SlurmctldHost=$HOST
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
SchedulerType=sched/backfill
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
ReturnToService=2
MpiDefault=none
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM State=UNKNOWN
PartitionName=debug Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF
chmod 644 "$CONF_NEW"
# daemons started on another configuration (another node size) keep it until restarted
running_cpus=$(sinfo -h -N -o %c 2>/dev/null | head -1)
if ! cmp -s "$CONF_NEW" /etc/slurm/slurm.conf \
    || { [ -n "$running_cpus" ] && [ "$running_cpus" != "$CPUS" ]; }; then
  bash "$(dirname "$0")/stop_cluster.sh"
  for _ in $(seq 1 30); do
    pgrep -x slurmctld >/dev/null || pgrep -x slurmd >/dev/null || break
    sleep 1
  done
  mv "$CONF_NEW" /etc/slurm/slurm.conf
else
  rm -f "$CONF_NEW"
fi
pgrep -x slurmctld >/dev/null || slurmctld || { echo "slurmctld does not start"; exit 3; }
pgrep -x slurmd >/dev/null || slurmd || { echo "slurmd does not start"; exit 3; }
for _ in $(seq 1 60); do
  state=$(sinfo -h -N -o %T 2>/dev/null | head -1)
  case "$state" in
    idle*|mixed*|alloc*) echo "SLURM up: $HOST $state"; exit 0 ;;
    down*|drain*) scontrol update nodename="$HOST" state=resume >/dev/null 2>&1 ;;
  esac
  sleep 1
done
echo "SLURM node never became idle (state: ${state:-none})"; exit 3
