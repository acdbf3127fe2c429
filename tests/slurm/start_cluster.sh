#!/usr/bin/env bash
# Start a single-node SLURM cluster on this machine for tests/test_slurm.py: Debian's
# munge, slurmctld and slurmd (Slurm 22.05), as root, without systemd. Idempotent: a
# cluster it started before is reused.
#
# Installs the packages with apt-get when they are missing (root; a few minutes).
# The configuration (slurm.conf.in filled in) lives in $PLENOCAL_SLURM_STATE
# (default /var/tmp/plenocal-slurm), never in /etc/slurm: clients must be given
# SLURM_CONF=$PLENOCAL_SLURM_STATE/slurm.conf (the last line printed says so).
#
# Exit status: 0 the node is up (idle), 3 SLURM cannot be installed or started here
# (the reason is printed).
set -u
HERE=$(cd "$(dirname "$0")" && pwd)
STATE=${PLENOCAL_SLURM_STATE:-/var/tmp/plenocal-slurm}
CONF=$STATE/slurm.conf
export SLURM_CONF=$CONF

fail() { echo "SLURM unavailable: $*"; exit 3; }
alive() { [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

missing=""
for b in munged slurmctld slurmd sbatch squeue sinfo scontrol; do
  command -v "$b" >/dev/null 2>&1 || missing="$missing $b"
done
if [ -n "$missing" ]; then
  [ "$(id -u)" = 0 ] || fail "missing$missing, and installing needs root"
  command -v apt-get >/dev/null 2>&1 || fail "missing$missing, and there is no apt-get"
  echo "installing slurmctld slurmd munge (apt-get)..."
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >"$STATE.apt.log" 2>&1 \
    && apt-get install -y -qq slurmctld slurmd munge >>"$STATE.apt.log" 2>&1 \
    || fail "apt-get install slurmctld slurmd munge failed: $(tail -3 "$STATE.apt.log")"
fi
[ "$(id -u)" = 0 ] || fail "the test cluster runs its daemons as root"

# munge: the packages create the key; make one if they did not
mkdir -p "$STATE/ctld" "$STATE/d" /run/munge /var/log/munge /var/lib/munge /etc/munge
if [ ! -s /etc/munge/munge.key ]; then
  dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  chmod 400 /etc/munge/munge.key
fi
if id munge >/dev/null 2>&1; then
  chown -R munge:munge /etc/munge /run/munge /var/log/munge /var/lib/munge
fi
if ! munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; then
  if id munge >/dev/null 2>&1; then
    su -s /bin/sh munge -c "munged" 2>/dev/null || munged --force
  else
    munged --force
  fi
  sleep 1
  munge -n </dev/null | unmunge >/dev/null 2>&1 || fail "munged does not start"
fi

HOST=$(hostname -s)
CPUS=$(nproc)
MEM=$(( $(free -m | awk '/^Mem:/{print $2}') - 1024 ))
[ "$MEM" -ge 1024 ] || MEM=1024
sed -e "s|@HOST@|$HOST|g" -e "s|@CPUS@|$CPUS|g" -e "s|@MEM@|$MEM|g" -e "s|@STATE@|$STATE|g" \
  "$HERE/slurm.conf.in" >"$CONF.new"
if ! cmp -s "$CONF.new" "$CONF"; then
  # new or changed configuration: (re)start our cluster from a clean state
  "$HERE/stop_cluster.sh" >/dev/null
  rm -rf "${STATE:?}/ctld" "${STATE:?}/d"
  mkdir -p "$STATE/ctld" "$STATE/d"
fi
mv "$CONF.new" "$CONF"

alive "$STATE/slurmctld.pid" || slurmctld -f "$CONF" \
  || fail "slurmctld does not start: $(tail -3 "$STATE/slurmctld.log" 2>/dev/null)"
alive "$STATE/slurmd.pid" || slurmd -f "$CONF" \
  || fail "slurmd does not start: $(tail -3 "$STATE/slurmd.log" 2>/dev/null)"

state=""
for _ in $(seq 1 60); do
  state=$(sinfo -h -N -n "$HOST" -o %T 2>/dev/null | head -1)
  case "$state" in
    idle*|mixed*|allocated*)
      echo "SLURM up: node $HOST ($CPUS CPUs, $MEM MB) $state"
      echo "SLURM_CONF=$CONF"
      exit 0 ;;
    down*|drain*) scontrol update nodename="$HOST" state=resume >/dev/null 2>&1 ;;
  esac
  sleep 1
done
fail "node $HOST never became idle (state: ${state:-none}); see $STATE/slurmd.log"
