#!/usr/bin/env bash
# A farm bake on a real Slurm (run by scripts/test.sh): installs Debian's slurmctld, slurmd,
# slurm-client and munge if missing, starts a single-node cluster without systemd (every
# daemon in the foreground under this script, stopped by PID at exit), writes a 4-shard array
# job with `ptm batch --slurm`, and checks that
#   1. the merged stack and PTM are byte for byte the one-machine bakes;
#   2. a shard forced to fail is reported FAILED by Slurm and the merge job refuses, naming
#      the missing shard; resubmitting bakes only that shard, and the merge then succeeds.
# Config and pitfalls: shared/notes/farm.md. Leaves nothing running and nothing in /etc/slurm.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PTM=${PTM:-$ROOT/target/debug/ptm}
[ -x "$PTM" ] || cargo build -q -p ptm
say() { echo "test-slurm: $*" >&2; }

if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null \
    || ! command -v sbatch >/dev/null || ! command -v munged >/dev/null; then
    if [ "$(id -u)" != 0 ]; then
        say "FAILED: Slurm is not installed and installing it needs root"
        exit 1
    fi
    say "installing slurmctld slurmd slurm-client munge"
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null \
        || { apt-get update -qq && apt-get install -y -qq --no-install-recommends \
                slurmctld slurmd slurm-client munge >/dev/null; }
fi

W=$(mktemp -d /tmp/ptm-slurm.XXXXXX)
MUNGE_PID= CTLD_PID= SLURMD_PID=
cleanup() {
    local rc=$?
    if [ -n "$CTLD_PID" ] && kill -0 "$CTLD_PID" 2>/dev/null; then
        scontrol shutdown >/dev/null 2>&1 || true
        for _ in $(seq 50); do
            kill -0 "$CTLD_PID" 2>/dev/null || kill -0 "$SLURMD_PID" 2>/dev/null || break
            sleep 0.1
        done
    fi
    for p in $SLURMD_PID $CTLD_PID $MUNGE_PID; do kill "$p" 2>/dev/null || true; done
    for p in $SLURMD_PID $CTLD_PID $MUNGE_PID; do wait "$p" 2>/dev/null || true; done
    if [ $rc != 0 ]; then
        say "FAILED (logs follow)"
        tail -n 20 "$W"/log/* "$W"/job/*.log >&2 2>/dev/null || true
    fi
    rm -rf "$W"
    exit $rc
}
trap cleanup EXIT

mkdir -p "$W"/{state,spool,log}
export SLURM_CONF=$W/slurm.conf
cat >"$SLURM_CONF" <<CONF
ClusterName=ci
SlurmctldHost=localhost
SlurmUser=root
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation=$W/state
SlurmdSpoolDir=$W/spool
SlurmctldPidFile=$W/slurmctld.pid
SlurmdPidFile=$W/slurmd.pid
SlurmctldLogFile=$W/log/slurmctld.log
SlurmdLogFile=$W/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerParameters=batch_sched_delay=0,sched_min_interval=0
ReturnToService=2
MpiDefault=none
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$(nproc) RealMemory=1000 State=UNKNOWN
PartitionName=ci Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF

install -d -o munge -g munge -m 755 /run/munge
if [ ! -s /etc/munge/munge.key ]; then
    mungekey -c -f
    chown munge:munge /etc/munge/munge.key
fi
setpriv --reuid=munge --regid=munge --init-groups /usr/sbin/munged -F >"$W/log/munged.out" 2>&1 &
MUNGE_PID=$!
for _ in $(seq 100); do [ -S /run/munge/munge.socket.2 ] && break; sleep 0.05; done
slurmctld -D -i >"$W/log/ctld.out" 2>&1 &
CTLD_PID=$!
slurmd -D -N localhost >"$W/log/slurmd.out" 2>&1 &
SLURMD_PID=$!
for _ in $(seq 150); do [ "$(sinfo -h -o %T 2>/dev/null)" = idle ] && break; sleep 0.1; done
[ "$(sinfo -h -o %T)" = idle ] || { say "node never became idle"; exit 1; }
say "cluster up"

# Two real bakes, 4 shards each: a stack and a streaming ptm6 fit.
cd "$W"
cat >jobs.toml <<TOML
[defaults]
swatch = "builtin:twill"
res = 64
dirs = 24
spp = 4
shards = 4

[[bake]]
output = "out/samples.exr"

[[bake]]
fit = "ptm6"
link = "identity"
output = "out/twill.ptm.exr"
TOML
mkdir -p one
"$PTM" bake --swatch builtin:twill --res 64 --dirs 24 --spp 4 -o one/samples.exr 2>/dev/null
"$PTM" bake --swatch builtin:twill --res 64 --dirs 24 --spp 4 --fit ptm6 --link identity -o one/twill.ptm.exr 2>/dev/null

# Runs job/submit.sh and waits for both jobs; prints "BAKE_JOB MERGE_JOB".
submit() {
    local ids bake merge
    ids=$(bash job/submit.sh)
    bake=$(echo "$ids" | sed -n 's/^bake array \([0-9]*\), merge \([0-9]*\)$/\1/p')
    merge=$(echo "$ids" | sed -n 's/^bake array \([0-9]*\), merge \([0-9]*\)$/\2/p')
    for _ in $(seq 600); do
        [ -z "$(squeue -h -j "$bake,$merge" 2>/dev/null)" ] && break
        sleep 0.1
    done
    [ -z "$(squeue -h -j "$bake,$merge" 2>/dev/null)" ] || { say "jobs still queued after 60 s"; exit 1; }
    echo "$bake $merge"
}
states() { scontrol -o show job "$1" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' | sort | uniq -c | tr -s ' ' | paste -sd, -; }

# 1. A forced failure: shard 2 of the stack bake names a swatch that does not exist.
"$PTM" batch jobs.toml --slurm job --throttle 3 2>/dev/null
cp job/tasks.txt job/tasks.good
sed -i '3s|$| --swatch /nonexistent.obj|' job/tasks.txt
read -r bake merge < <(submit)
s=$(states "$bake")
say "forced failure: bake tasks:$s; merge job: $(states "$merge")"
echo "$s" | grep -q "1 FAILED" || { say "the forced failure was not reported FAILED: $s"; exit 1; }
states "$merge" | grep -q FAILED || { say "the merge job did not fail"; exit 1; }
grep -q "missing part(s) out/samples.part-0002-of-0004.exr" job/merge_"$merge".log \
    || { say "the merge did not refuse the missing shard"; cat job/merge_"$merge".log >&2; exit 1; }
[ ! -e out/samples.exr ] || { say "a merged stack exists despite a missing shard"; exit 1; }
cmp -s out/twill.ptm.exr one/twill.ptm.exr || { say "the complete bake did not merge"; exit 1; }

# 2. Resubmit the fixed job: the complete parts are skipped, shard 2 is baked, both merge.
cp job/tasks.good job/tasks.txt
rm out/twill.ptm.exr
read -r bake merge < <(submit)
say "resubmitted: bake tasks:$(states "$bake"); merge job: $(states "$merge")"
[ "$(states "$bake")" = " 8 COMPLETED" ] || { say "not every task completed"; exit 1; }
[ "$(grep -l "is complete; skipped" job/bake_"$bake"_*.log | wc -l)" = 7 ] \
    || { say "resubmission did not skip the 7 complete parts"; exit 1; }
cmp out/samples.exr one/samples.exr
cmp out/samples.lp one/samples.lp
cmp out/twill.ptm.exr one/twill.ptm.exr
say "ok: 4-shard Slurm arrays merged byte for byte (stack and ptm6); a failed shard was reported, refused at merge, and retried"
