#!/usr/bin/env bash
# Stop the test cluster started by start_cluster.sh (by its pid files).
STATE=/var/tmp/plenocal-slurm
for d in slurmd slurmctld; do
  [ -s "$STATE/$d.pid" ] && kill "$(cat "$STATE/$d.pid")" 2>/dev/null
done
exit 0
