#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, reachable from localhost only, for CI's test of
# the job-array scripts (tests/slurm.rs, docs/DISTRIBUTED.md). Idempotent: run it again and
# it installs, configures or starts only what is missing, then waits until the node is idle.
#
#   tools/slurm/local-cluster.sh          # as root, or with sudo
#
# 1. Debian's slurm-wlm and munge.
# 2. A munge key (if the package made none) and munged, as the munge user.
# 3. /etc/slurm/slurm.conf: cluster "firstshot", one node "localhost" (127.0.0.1) with this
#    machine's CPUs, partition "local"; no accounting, no cgroups (proctrack/linuxproc,
#    task/none), slurmctld and slurmd as root, state in /var/spool, logs in /var/log/slurm.
# 4. slurmctld and slurmd (as node "localhost", whatever the host name).
set -euo pipefail

sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

if ! command -v sbatch >/dev/null || ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
    || ! command -v munged >/dev/null; then
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq slurm-wlm munge >/dev/null
fi

# munge: a key, then the daemon (as its own user, as the package's service would).
if [ ! -s /etc/munge/munge.key ]; then
    $sudo mungekey --create --force 2>/dev/null || $sudo /usr/sbin/create-munge-key -f
fi
$sudo chown munge:munge /etc/munge/munge.key
$sudo chmod 400 /etc/munge/munge.key
$sudo mkdir -p /run/munge /var/log/munge /var/lib/munge
$sudo chown munge:munge /run/munge /var/log/munge /var/lib/munge
if ! munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; then
    $sudo runuser -u munge -- /usr/sbin/munged
    for _ in $(seq 50); do munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.2; done
fi
munge -n </dev/null | unmunge >/dev/null

conf=$(mktemp)
cat >"$conf" <<CONF
# Written by tools/slurm/local-cluster.sh: one node, localhost only.
ClusterName=firstshot
SlurmctldHost=localhost(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MinJobAge=600
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
SlurmctldPort=6817
SlurmdPort=6818
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=local Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
$sudo mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
if ! cmp -s "$conf" /etc/slurm/slurm.conf; then
    $sudo cp "$conf" /etc/slurm/slurm.conf
    $sudo chmod 644 /etc/slurm/slurm.conf
    # A running cluster takes the new configuration.
    scontrol reconfigure >/dev/null 2>&1 || true
fi
rm -f "$conf"

running() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }
if ! running /run/slurmctld.pid; then
    $sudo /usr/sbin/slurmctld
fi
for _ in $(seq 100); do scontrol ping 2>/dev/null | grep -q UP && break; sleep 0.2; done
if ! running /run/slurmd.pid; then
    $sudo /usr/sbin/slurmd -N localhost
fi

# The node must be idle (or already running jobs) before jobs are submitted.
for _ in $(seq 150); do
    state=$(sinfo -h -n localhost -o %T 2>/dev/null || true)
    case "$state" in
        idle* | mixed* | allocated*) break ;;
        down* | drain*) $sudo scontrol update NodeName=localhost State=RESUME >/dev/null 2>&1 || true ;;
    esac
    sleep 0.2
done
state=$(sinfo -h -n localhost -o %T 2>/dev/null || true)
case "$state" in
    idle* | mixed* | allocated*) ;;
    *)
        echo "local Slurm cluster: node localhost is '${state:-unknown}'; the logs:" >&2
        tail -n 20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2 || true
        exit 1
        ;;
esac
echo "local Slurm cluster up: $(sinfo -h -o '%P %D node(s) %c CPUs %T') ($(sbatch --version))"
