#!/usr/bin/env bash
# Stop the test cluster that start_cluster.sh started (by the daemons' pid files;
# munged is left running, other services may use it).
STATE=${PLENOCAL_SLURM_STATE:-/var/tmp/plenocal-slurm}
for d in slurmd slurmctld; do
  pidfile=$STATE/$d.pid
  if [ -s "$pidfile" ] && kill -0 "$(cat "$pidfile")" 2>/dev/null; then
    pid=$(cat "$pidfile")
    kill "$pid"
    for _ in $(seq 1 20); do kill -0 "$pid" 2>/dev/null || break; sleep 0.5; done
  fi
  rm -f "$pidfile"
done
exit 0
