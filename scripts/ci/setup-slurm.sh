#!/usr/bin/env bash
# Configure and start a single-node Slurm cluster (slurmctld + slurmd, munge) on localhost, for
# the campaign tests that submit real job arrays (crates/iuq/tests/cli_campaign_slurm.rs).
#
# Idempotent: installs Debian's slurm-wlm and munge when missing, writes /etc/slurm/slurm.conf
# (only if it is not ours already), starts the daemons that are not running, and waits until the
# node accepts jobs. Needs root (CI runs as root). Usage: bash scripts/ci/setup-slurm.sh
set -euo pipefail

log() { echo "setup-slurm: $*"; }

if [ "$(id -u)" != 0 ]; then
  echo "setup-slurm: must run as root" >&2
  exit 1
fi

if ! command -v slurmctld >/dev/null 2>&1 || ! command -v slurmd >/dev/null 2>&1 \
  || ! command -v sbatch >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
  log "installing slurm-wlm and munge"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq slurm-wlm munge >/dev/null
fi

# munge: a key, its directories, the daemon.
mkdir -p /etc/munge /var/lib/munge /var/log/munge /run/munge
if [ ! -s /etc/munge/munge.key ]; then
  log "creating the munge key"
  if command -v mungekey >/dev/null 2>&1; then
    mungekey --create --keyfile=/etc/munge/munge.key --force
  else
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  fi
fi
chown -R munge:munge /etc/munge /var/lib/munge /var/log/munge /run/munge
chmod 0700 /etc/munge /var/lib/munge /var/log/munge
chmod 0755 /run/munge
chmod 0400 /etc/munge/munge.key
if ! pgrep -x munged >/dev/null 2>&1; then
  log "starting munged"
  runuser -u munge -- /usr/sbin/munged
fi
for _ in $(seq 1 50); do
  munge -n >/dev/null 2>&1 && break
  sleep 0.1
done
munge -n | unmunge >/dev/null

# slurm.conf for this host.
node=$(hostname -s)
cpus=$(nproc)
conf=/etc/slurm/slurm.conf
mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
marker="# iuq single-node test cluster: $node $cpus"
if ! grep -qF "$marker" "$conf" 2>/dev/null; then
  log "writing $conf for node $node ($cpus CPUs)"
  cat >"$conf" <<CONF
$marker
ClusterName=iuq-test
SlurmctldHost=$node(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
ReturnToService=2
MaxArraySize=1001
MinJobAge=300
SchedulerParameters=sched_interval=1
NodeName=$node NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
  # A changed configuration needs restarted daemons.
  pkill -x slurmd 2>/dev/null || true
  pkill -x slurmctld 2>/dev/null || true
  sleep 1
fi

if ! pgrep -x slurmctld >/dev/null 2>&1; then
  log "starting slurmctld"
  slurmctld
fi
if ! pgrep -x slurmd >/dev/null 2>&1; then
  log "starting slurmd"
  slurmd
fi

for _ in $(seq 1 60); do
  if scontrol ping >/dev/null 2>&1 && sinfo -h -o %T 2>/dev/null | grep -Eq '^(idle|mixed|allocated)'; then
    break
  fi
  state=$(sinfo -h -o %T 2>/dev/null || true)
  case "$state" in
    down* | drain* | unknown*) scontrol update nodename="$node" state=resume >/dev/null 2>&1 || true ;;
  esac
  sleep 1
done

if ! sinfo -h -o %T | grep -Eq '^(idle|mixed|allocated)'; then
  echo "setup-slurm: the node did not become ready:" >&2
  sinfo >&2 || true
  tail -n 20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2 || true
  exit 1
fi
log "ready: $(sinfo -h -o '%P %D %T %C')"
