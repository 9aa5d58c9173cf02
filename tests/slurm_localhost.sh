#!/usr/bin/env bash
# The real thing: a one-node Slurm cluster on localhost (munge, slurmctld, slurmd from Debian's
# slurm-wlm and munge packages) runs the job array `study slurm` writes for the smoke study with 4
# shards and the dependent merge job; the merged table must equal the single-process run.
# Stops every daemon it started, whatever happens. Needs root (CI runs as root) and target/release/study.
#
# usage: tests/slurm_localhost.sh [SHARDS]
set -euo pipefail
cd "$(dirname "$0")/.."
shards=${1:-4}
study=$(realpath target/release/study)
work=$(mktemp -d /tmp/vshake-slurm.XXXXXX)
chmod 755 "$work"
export SLURM_CONF="$work/slurm.conf"
host=$(hostname -s)

started=()
cleanup() {
  set +e
  [ -f "$work/conf_ok" ] && scancel --user=root >/dev/null 2>&1
  for pidfile in "$work/slurmd.pid" "$work/slurmctld.pid" "$work/munged.pid"; do
    if [ -f "$pidfile" ]; then kill "$(cat "$pidfile")" 2>/dev/null; fi
  done
  sleep 1
  for p in "${started[@]}"; do kill -9 "$p" 2>/dev/null; done
  if [ "${keep:-0}" != 1 ]; then rm -rf "$work"; fi
}
trap cleanup EXIT

echo "-- munge"
mkdir -p /run/munge "$work/munge"
chown munge:munge /run/munge "$work/munge"
chmod 755 /run/munge
[ -s /etc/munge/munge.key ] || { mungekey --create --force; chown munge:munge /etc/munge/munge.key; chmod 400 /etc/munge/munge.key; }
runuser -u munge -- munged --pid-file="$work/munge/munged.pid" --log-file="$work/munge/munged.log" --seed-file="$work/munge/munged.seed"
cp "$work/munge/munged.pid" "$work/munged.pid"
munge -n | unmunge >/dev/null && echo "munge works"

echo "-- slurmctld and slurmd on $host"
mkdir -p "$work/state" "$work/spool"
cpus=$(nproc)
cat > "$SLURM_CONF" <<CONF
ClusterName=vshakeci
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=ci Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
touch "$work/conf_ok"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF" -N "$host"
for i in $(seq 1 60); do
  if sinfo -h -o "%T" 2>/dev/null | grep -qE "^idle"; then break; fi
  sleep 1
done
sinfo
sinfo -h -o "%T" | grep -qE "^idle" || { echo "the node did not come up"; tail -20 "$work/slurmctld.log" "$work/slurmd.log"; exit 1; }

echo "-- the generated job array ($shards shards) and merge job"
"$study" slurm studies/smoke.toml --shards "$shards" --partition ci --cpus 1 --time 00:10:00 --dir "$work/job"
bash "$work/job/submit.sh"
for i in $(seq 1 300); do
  [ -z "$(squeue -h 2>/dev/null)" ] && break
  sleep 1
done
squeue
ls "$work/job/shards" "$work/job/logs"
tail -n 3 "$work"/job/logs/*.out
test -s "$work/job/smoke.parquet" || { echo "no merged table"; cat "$work"/job/logs/*.out; tail -20 "$work/slurmctld.log"; exit 1; }
test "$(ls "$work/job/shards" | grep -c '\.parquet$')" = "$shards"

echo "-- the merged table against the single-process run"
"$study" run studies/smoke.toml --out "$work/single.parquet" -q
python3 tests/check_merge.py "$work/single.parquet" "$work/job/smoke.parquet"

echo "-- a task stopped before its time limit requeues itself and resumes its shard"
# Slurm sends the batch shell SIGTERM ahead of the time limit (--signal=B:TERM@300); here the same
# signal is sent at once with scancel, while shard 0 of the gains sweep is running.
"$study" slurm studies/gains_sweep.toml --shards 2 --partition ci --cpus 1 --time 00:10:00 --dir "$work/requeue"
bash "$work/requeue/submit.sh"
tmp0="$work/requeue/shards/gains_sweep.shard-0-of-2.partial.parquet.tmp"
for i in $(seq 1 120); do [ -e "$tmp0" ] && break; sleep 0.5; done
# A shard of the sweep runs for about 3 s on one core: signal it early, once some chunks are done
# (their rows are what the requeued task keeps), so that it is still running when signalled.
sleep 0.5
task0=$(squeue -h -o "%i %T" | awk '$1 ~ /_0$/ && $2 == "RUNNING" {print $1}')
test -n "$task0" || { echo "shard 0 is not running"; squeue; exit 1; }
scancel --signal=TERM --batch "$task0"
# Slurm holds a requeued job for about 2 minutes (its EligibleTime, "Reason=BeginTime"), as a
# cluster would; here the test releases it at once, so that CI does not wait (the log checks
# below still require the requeue and the resume).
for i in $(seq 1 60); do scontrol show job "$task0" 2>/dev/null | grep -q "Reason=BeginTime" && break; sleep 0.5; done
if scontrol show job "$task0" | grep -q "Reason=BeginTime"; then scontrol update JobId="$task0" StartTime=now; fi
for i in $(seq 1 300); do
  [ -z "$(squeue -h 2>/dev/null)" ] && break
  sleep 1
done
squeue
cat "$work/requeue/logs/shard-0.out"
grep -q "requeueing to resume" "$work/requeue/logs/shard-0.out" || { echo "shard 0 did not requeue"; exit 1; }
grep -q "kept from" "$work/requeue/logs/shard-0.out" || { echo "the requeued shard 0 did not resume"; exit 1; }
test -s "$work/requeue/gains_sweep.parquet" || { echo "no merged table"; cat "$work"/requeue/logs/*.out; exit 1; }
"$study" run studies/gains_sweep.toml --out "$work/gains_single.parquet" -q
python3 tests/check_merge.py "$work/gains_single.parquet" "$work/requeue/gains_sweep.parquet"
