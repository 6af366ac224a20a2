#!/bin/bash
# One calib worker for the Slurm task it runs in (started with srun by calib.sbatch and
# workers.sbatch): --slots from SLURM_CPUS_ON_NODE, registered with the coordinator whose
# address is in $CALIB_DIR/coordinator.url, and registered again with the next coordinator
# when that address changes (a coordinator job resubmitted after its time limit).
#
# On SIGTERM (scancel, preemption, `--signal=TERM@60` before the time limit) the worker
# drains: it stops registering, accepts no new work and finishes what it holds (10 s at
# most, within Slurm's KillWait), then exits 0; what it did not take, the others do.
set -euo pipefail
# shellcheck source=deploy/slurm/env.sh
. "$(dirname "$0")/env.sh"

pid=""
drain() {
    echo "worker.sh: $(hostname) task ${SLURM_PROCID:-0}: SIGTERM, draining"
    [ -n "$pid" ] && { kill -TERM "$pid" 2>/dev/null || true; }
    status=0
    [ -n "$pid" ] && { wait "$pid" || status=$?; }
    exit "$status"
}
trap drain TERM INT

url=""
for _ in $(seq 600); do
    url="$(coordinator_url)" && [ -n "$url" ] && break
    sleep 1 & wait $!
done
[ -n "$url" ] || { echo "worker.sh: no coordinator.url in $calib_dir after 10 minutes" >&2; exit 1; }
while true; do
    echo "worker.sh: $(hostname) task ${SLURM_PROCID:-0} registers with $url"
    "$calib" worker --register "$url" --listen "0.0.0.0:${CALIB_WORKER_PORT:-0}" \
        --slots "${SLURM_CPUS_ON_NODE:-1}" "${serve[@]}" "${dial[@]}" &
    pid=$!
    while kill -0 "$pid" 2>/dev/null; do
        sleep 2 & wait $!
        next="$(coordinator_url || true)"
        if [ -n "$next" ] && [ "$next" != "$url" ]; then
            echo "worker.sh: the coordinator moved to $next"
            kill -TERM "$pid" 2>/dev/null || true
            wait "$pid" || true
            url="$next"
            continue 2
        fi
    done
    # The worker ended by itself: its exit status is the task's.
    status=0
    wait "$pid" || status=$?
    exit "$status"
done
