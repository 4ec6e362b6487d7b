#!/usr/bin/env bash
# A real one-node Slurm cluster on localhost (Debian's slurm-wlm + munge), for testing the
# workflow's Slurm profile (profiles/slurm) end to end.
#
#   tools/slurm/slurm_local_cluster.sh install             apt-get install slurm-wlm/munge, pip install the plugin
#   tools/slurm/slurm_local_cluster.sh up DIR              start munged, slurmctld, slurmd with state under DIR
#                                                      (SLURM_LOCAL_ACCOUNTING=1: also MariaDB + slurmdbd, so
#                                                      that sacct works; SLURM_LOCAL_MINJOBAGE=N: MinJobAge, 600)
#   tools/slurm/slurm_local_cluster.sh down DIR            cancel the cluster's jobs, stop exactly the PIDs `up` started
#   tools/slurm/slurm_local_cluster.sh with-cluster -- CMD ...
#                                                      up in a fresh temp dir, run CMD with SLURM_CONF exported,
#                                                      tear down on exit (also on failure or Ctrl-C)
#   tools/slurm/slurm_local_cluster.sh run-compare [ARGS]  with-cluster + tools/slurm/slurm_compare.py ARGS: the `fast`
#                                                      workflow locally and through profiles/slurm with the same
#                                                      config and seed, compared; a failing member; a killed and
#                                                      resumed head process (see that file)
#
# Nothing is written to /etc: slurm.conf, the munge key and socket, state and logs all live under DIR.
# Commands on the head reach the cluster through SLURM_CONF=DIR/slurm.conf; commands inside a job find
# the same file through the link /run/slurm/conf -> DIR (where a configless slurmd publishes its
# configuration), which `down` removes. While no cluster runs, nothing names a controller, so the
# Slurm plugin's `scontrol` call at every `snakemake` start fails at once instead of waiting ~10 s.
#
# The daemons run in the foreground (-F / -D) as background jobs of this shell, so $! is the daemon's own
# PID; `down` stops only the PIDs recorded in DIR/pids (checking each one's command name first, in case
# the PID was reused), never by process name.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"

log() { printf '[slurm-local %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }
die() { log "ERROR: $*"; exit 1; }

free_port() {
    python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1]); s.close()'
}

cmd_install() {
    local missing=()
    for b in munged mungekey slurmctld slurmd sbatch squeue scontrol sinfo; do
        command -v "$b" >/dev/null 2>&1 || missing+=("$b")
    done
    if ((${#missing[@]})); then
        log "installing slurm-wlm and munge (missing: ${missing[*]})"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -q >/dev/null
        apt-get install -y -q slurm-wlm slurmctld slurmd slurm-client munge >/dev/null
    fi
    if [[ "${SLURM_LOCAL_ACCOUNTING:-0}" == 1 ]] && ! command -v slurmdbd >/dev/null 2>&1; then
        log "installing slurmdbd and mariadb-server (SLURM_LOCAL_ACCOUNTING=1)"
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurmdbd mariadb-server >/dev/null
    fi
    if ! python3 -c 'import snakemake_executor_plugin_slurm' 2>/dev/null; then
        log "installing snakemake-executor-plugin-slurm (the project's [slurm] extra)"
        python3 -m pip install -q -e "${REPO}[slurm]"
    fi
}

# A failed bring-up stops what it had started before giving up.
up_failed() {
    cmd_down "$1" || true
    die "$2"
}

# Link /run/slurm/conf -> DIR (see cmd_up). Refuses when the machine has a Slurm configuration of
# its own; replaces a stale link left by a test cluster that is gone.
publish_conf() {
    local dir="$1" old
    [[ -e /etc/slurm/slurm.conf ]] && { log "/etc/slurm/slurm.conf exists: this machine has its own Slurm"; return 1; }
    if [[ -L /run/slurm/conf ]]; then
        old="$(readlink /run/slurm/conf)"
        if [[ -f "$old/pids" ]]; then
            log "/run/slurm/conf -> $old: another test cluster is running"; return 1
        fi
        rm -f /run/slurm/conf
    elif [[ -e /run/slurm/conf ]]; then
        log "/run/slurm/conf exists and is not a test cluster's link"; return 1
    fi
    mkdir -p /run/slurm
    ln -s "$dir" /run/slurm/conf
}

# Accounting (SLURM_LOCAL_ACCOUNTING=1): MariaDB on 127.0.0.1, slurmdbd in front of it, the cluster
# registered. Sets ACCOUNTING_CONF to the slurm.conf lines that point slurmctld at slurmdbd.
ACCOUNTING_CONF="AccountingStorageType=accounting_storage/none"
start_accounting() {
    local dir="$1" sock="$2" db_port dbd_port i
    for b in mariadb-install-db mariadbd mariadb slurmdbd sacctmgr; do
        command -v "$b" >/dev/null 2>&1 || up_failed "$dir" "$b not found (run 'SLURM_LOCAL_ACCOUNTING=1 $0 install')"
    done
    db_port="$(free_port)"
    dbd_port="$(free_port)"
    mkdir -p "$dir/mysql"
    mariadb-install-db --no-defaults --datadir="$dir/mysql" --user=root --skip-test-db \
        --auth-root-authentication-method=socket >"$dir/log/mariadb-install.out" 2>&1 ||
        up_failed "$dir" "mariadb-install-db failed (see $dir/log/mariadb-install.out)"
    mariadbd --no-defaults --datadir="$dir/mysql" --user=root --bind-address=127.0.0.1 --port="$db_port" \
        --socket="$dir/mysql/mysqld.sock" --pid-file="$dir/mysql/mysqld.pid" \
        --log-error="$dir/log/mariadb.log" --skip-log-bin </dev/null >"$dir/log/mariadb.out" 2>&1 &
    echo "$! mariadbd" >>"$dir/pids"
    for ((i = 0; i < 300; i++)); do
        mariadb --no-defaults -S "$dir/mysql/mysqld.sock" -u root -e 'SELECT 1' >/dev/null 2>&1 && break
        sleep 0.1
    done
    mariadb --no-defaults -S "$dir/mysql/mysqld.sock" -u root -e "
        CREATE USER 'slurm'@'127.0.0.1' IDENTIFIED BY 'slurmlocal';
        GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';" ||
        up_failed "$dir" "MariaDB did not start (see $dir/log/mariadb.log)"
    # slurmdbd reads slurmdbd.conf from the directory of SLURM_CONF; it must be private to SlurmUser.
    cat >"$dir/slurmdbd.conf" <<EOF
AuthType=auth/munge
AuthInfo=socket=$sock
DbdHost=localhost
DbdPort=$dbd_port
SlurmUser=root
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$db_port
StorageUser=slurm
StoragePass=slurmlocal
StorageLoc=slurm_acct_db
PidFile=$dir/slurmdbd.pid
LogFile=$dir/log/slurmdbd.log
EOF
    chmod 600 "$dir/slurmdbd.conf"
    # AccountingStoragePass names the munge socket for connections to slurmdbd (AuthInfo does not).
    ACCOUNTING_CONF="AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=localhost
AccountingStoragePort=$dbd_port
AccountingStoragePass=$sock"
    # A first slurm.conf for sacctmgr (cmd_up writes the full one next).
    printf 'ClusterName=fdemlocal\nSlurmctldHost=localhost\nAuthType=auth/munge\nAuthInfo=socket=%s\n%s\n' "$sock" "$ACCOUNTING_CONF" \
        >"$dir/slurm.conf"
    SLURM_CONF="$dir/slurm.conf" slurmdbd -D </dev/null >"$dir/log/slurmdbd.out" 2>&1 &
    echo "$! slurmdbd" >>"$dir/pids"
    for ((i = 0; i < 100; i++)); do
        SLURM_CONF="$dir/slurm.conf" timeout 5 sacctmgr -i add cluster fdemlocal >/dev/null 2>&1 && break
        sleep 0.1
    done
    SLURM_CONF="$dir/slurm.conf" timeout 5 sacctmgr -n list cluster format=cluster 2>/dev/null | grep -q fdemlocal ||
        up_failed "$dir" "slurmdbd did not register the cluster (see $dir/log/slurmdbd.log)"
}

# Start the daemons; writes DIR/slurm.conf, DIR/pids, DIR/env.
cmd_up() {
    local dir="${1:?usage: up DIR}"
    mkdir -p "$dir"
    dir="$(cd "$dir" && pwd)"
    [[ -e "$dir/pids" ]] && die "$dir/pids exists: a cluster may still run there (run 'down $dir' first)"
    for b in munged mungekey slurmctld slurmd sinfo setpriv; do
        command -v "$b" >/dev/null 2>&1 || die "$b not found (run '$0 install')"
    done
    local t0=$SECONDS
    chmod 755 "$dir"
    mkdir -p "$dir/munge" "$dir/state" "$dir/spool" "$dir/log"
    : >"$dir/pids"

    # munge: own key, socket and files under DIR/munge, daemon running as user munge.
    mungekey --create --keyfile="$dir/munge/munge.key" >/dev/null
    chown -R munge:munge "$dir/munge"
    chmod 711 "$dir/munge" # munged wants execute permission for all on its socket's directory
    chmod 400 "$dir/munge/munge.key"
    local sock="$dir/munge/munge.socket"
    setpriv --reuid=munge --regid=munge --init-groups \
        munged --foreground --socket="$sock" --key-file="$dir/munge/munge.key" \
        --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" \
        --seed-file="$dir/munge/munged.seed" </dev/null >"$dir/log/munged.out" 2>&1 &
    echo "$! munged" >>"$dir/pids"
    local i
    for ((i = 0; i < 100; i++)); do [[ -S "$sock" ]] && break; sleep 0.1; done
    [[ -S "$sock" ]] || { cat "$dir/log/munged.out" >&2; up_failed "$dir" "munged did not create $sock"; }

    if [[ "${SLURM_LOCAL_ACCOUNTING:-0}" == 1 ]]; then
        start_accounting "$dir" "$sock"
    fi

    local cpus mem_mb ctld_port slurmd_port min_job_age="${SLURM_LOCAL_MINJOBAGE:-600}"
    cpus="$(nproc)"
    # Declare 90% of the physical memory: slurmd drains a node whose RealMemory exceeds what it finds.
    mem_mb="$(awk '/^MemTotal:/ {printf "%d", $2 / 1024 * 0.9}' /proc/meminfo)"
    ctld_port="$(free_port)"
    slurmd_port="$(free_port)"
    while [[ "$slurmd_port" == "$ctld_port" ]]; do slurmd_port="$(free_port)"; done

    cat >"$dir/slurm.conf" <<EOF
# One-node test cluster written by tools/slurm/slurm_local_cluster.sh; lives and dies with $dir.
ClusterName=fdemlocal
SlurmctldHost=localhost
SlurmUser=root
SlurmdUser=root
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$sock
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
DefMemPerCPU=1000
$ACCOUNTING_CONF
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
# Finished jobs stay visible to squeue for 10 minutes: the Snakemake plugin's squeue status
# command needs MinJobAge >= 3 x slurm-init-seconds-before-status-checks.
MinJobAge=$min_job_age
ReturnToService=2
# Kill a timed-out job 5 s after its SIGTERM (default 30 s).
KillWait=5
SlurmctldTimeout=30
SlurmdTimeout=60
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
    export SLURM_CONF="$dir/slurm.conf"
    printf 'export SLURM_CONF=%q\n' "$SLURM_CONF" >"$dir/env"

    slurmctld -D -i -f "$SLURM_CONF" </dev/null >"$dir/log/slurmctld.out" 2>&1 &
    echo "$! slurmctld" >>"$dir/pids"
    # Slurm commands inside a job must find this slurm.conf without SLURM_CONF: the Snakemake
    # jobstep executor strips every SLURM_* variable, SLURM_CONF included, from the environment of
    # the `srun` it runs inside each job. Publish the file where a configless slurmd publishes its
    # configuration on a real node, /run/slurm/conf/slurm.conf (Slurm's client look-up order:
    # SLURM_CONF, /etc/slurm/slurm.conf, /run/slurm/conf/slurm.conf); `down` removes the link.
    publish_conf "$dir" || up_failed "$dir" "cannot publish /run/slurm/conf"
    slurmd -D -N localhost -f "$SLURM_CONF" </dev/null >"$dir/log/slurmd.out" 2>&1 &
    echo "$! slurmd" >>"$dir/pids"

    local state=""
    for ((i = 0; i < 300; i++)); do
        state="$(sinfo -h -N -n localhost -o %t 2>/dev/null || true)"
        [[ "$state" == idle ]] && break
        sleep 0.1
    done
    if [[ "$state" != idle ]]; then
        log "node state '$state' after 30 s; logs:"
        tail -n 20 "$dir"/log/*.log "$dir"/log/*.out >&2 || true
        up_failed "$dir" "cluster did not come up"
    fi
    log "cluster up in $((SECONDS - t0)) s: $(sinfo -h -o '%P %D %c cpus %m MB %t') (SLURM_CONF=$SLURM_CONF)"
}

# Is PID alive (not a zombie) and running the program NAME? (guards against PID reuse)
pid_is() {
    local pid="$1" name="$2" comm state
    [[ "$pid" =~ ^[0-9]+$ && -r "/proc/$pid/comm" ]] || return 1
    comm="$(cat "/proc/$pid/comm" 2>/dev/null)" || return 1
    state="$(awk '/^State:/ {print $2}' "/proc/$pid/status" 2>/dev/null)" || return 1
    [[ "$comm" == "$name"* && "$state" != Z ]]
}

cmd_down() {
    local dir="${1:?usage: down DIR}"
    [[ -f "$dir/pids" ]] || { log "no $dir/pids: nothing to stop"; return 0; }
    dir="$(cd "$dir" && pwd)"
    export SLURM_CONF="$dir/slurm.conf"
    # Cancel whatever still runs on this cluster, so that no slurmstepd outlives its slurmd.
    if [[ -f "$SLURM_CONF" ]] && pid_is "$(awk '$2=="slurmctld"{print $1}' "$dir/pids")" slurmctld; then
        local left
        left="$(squeue -h -t PENDING,RUNNING,COMPLETING -o %i 2>/dev/null | wc -l || echo 0)"
        if ((left > 0)); then
            log "cancelling $left job(s) still on the cluster"
            scancel --user="$(id -un)" 2>/dev/null || true
            local i
            for ((i = 0; i < 150; i++)); do
                left="$(squeue -h -t PENDING,RUNNING,COMPLETING -o %i 2>/dev/null | wc -l || echo 0)"
                ((left == 0)) && break
                sleep 0.2
            done
        fi
    fi
    # Stop the daemons in reverse start order: slurmd, slurmctld, munged.
    local pid name
    while read -r pid name; do
        [[ -n "$pid" ]] || continue
        if pid_is "$pid" "$name"; then
            kill -TERM "$pid" 2>/dev/null || true
            local i
            for ((i = 0; i < 100; i++)); do pid_is "$pid" "$name" || break; sleep 0.1; done
            if pid_is "$pid" "$name"; then
                log "$name ($pid) ignored SIGTERM for 10 s; SIGKILL"
                kill -KILL "$pid" 2>/dev/null || true
            fi
        fi
    done < <(tac "$dir/pids")
    # The configless slurmd's published configuration: remove it when it is this cluster's.
    if [[ -L /run/slurm/conf ]] && [[ "$(readlink /run/slurm/conf)" == "$dir" ]]; then
        rm -f /run/slurm/conf
        rmdir /run/slurm 2>/dev/null || true
    fi
    rm -f "$dir/pids"
    log "cluster in $dir stopped"
}

WITH_CLUSTER_DIR=""

# EXIT trap of with-cluster: tear down (also after a failure or a signal), keep the exit status.
with_cluster_exit() {
    local rc=$?
    trap - EXIT INT TERM
    if [[ -n "$WITH_CLUSTER_DIR" ]]; then
        cmd_down "$WITH_CLUSTER_DIR" || true
        if [[ -n "${KEEP_SLURM_DIR:-}" ]]; then
            log "kept $WITH_CLUSTER_DIR (KEEP_SLURM_DIR is set)"
        else
            rm -rf "$WITH_CLUSTER_DIR"
        fi
    fi
    exit "$rc"
}

cmd_with_cluster() {
    [[ "${1:-}" == "--" ]] && shift
    (($#)) || die "usage: with-cluster -- CMD [ARGS...]"
    WITH_CLUSTER_DIR="$(mktemp -d /tmp/slurm-local.XXXXXX)"
    trap with_cluster_exit EXIT
    trap 'exit 130' INT
    trap 'exit 143' TERM
    cmd_up "$WITH_CLUSTER_DIR"
    export SLURM_CONF="$WITH_CLUSTER_DIR/slurm.conf"
    export SLURM_LOCAL_DIR="$WITH_CLUSTER_DIR"
    "$@"
}

cmd_run_compare() {
    cmd_with_cluster "${PYTHON:-python3}" "$HERE/slurm_compare.py" "$@"
}

main() {
    local sub="${1:-}"
    shift || true
    case "$sub" in
        install) cmd_install "$@" ;;
        up) cmd_up "$@" ;;
        down) cmd_down "$@" ;;
        with-cluster) cmd_with_cluster "$@" ;;
        run-compare) cmd_run_compare "$@" ;;
        *) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0" >&2; exit 2 ;;
    esac
}

main "$@"
