#!/usr/bin/env bash
# The cluster under faults, on several hosts: a coordinator (its store on a volume) and three
# single-slot workers on a private network. A campaign is submitted with `calib submit`, and
# while it runs:
#   1. a worker is killed (SIGKILL) and stays dead;
#   2. another is cut off the network for 8 s, then reconnected;
#   3. the coordinator is killed (SIGKILL) and started again on its store.
# It then checks that the campaign finished with the runs of a local `calib calibrate`, run
# for run, that no evaluation was lost, and counts the simulations repeated after the
# restart (points the store held at the kill, simulated again): zero expected. Everything it
# made is removed at the end.
#
# The hosts are Docker containers from deploy/compose/docker-compose.yml (the image built
# by deploy/build-image.sh) when a Docker engine answers, and network namespaces otherwise
# (root; a bridge and one veth pair per host, addresses in 10.231.0.0/24 inside them only).
#
#   deploy/fault-test.sh [--binary PATH] [--campaign FILE] [--on docker|netns] [--keep]
#
# --binary    the calib binary to run [default: target/release/calib]
# --campaign  [default: deploy/fault/hx_highfi.toml]
# --on        where the hosts are [default: docker when an engine answers, else netns]
# --keep      leave the cluster up at the end (Docker: remove it with `docker-compose -p
#             PROJECT -f deploy/compose/docker-compose.yml down -v`)
# Exit 0 when every check holds; 1 when one fails (the check is named); 2 on bad usage.
set -euo pipefail
cd "$(dirname "$0")/.."
repo="$PWD"

binary=target/release/calib
campaign=deploy/fault/hx_highfi.toml
on=""
keep=0
while [ $# -gt 0 ]; do
    case "$1" in
        --binary) binary="$2"; shift 2 ;;
        --campaign) campaign="$2"; shift 2 ;;
        --on) on="$2"; shift 2 ;;
        --keep) keep=1; shift ;;
        -h|--help) sed -n '2,26p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "fault-test.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
[ -x "$binary" ] || { echo "fault-test.sh: no calib binary at $binary (--binary)" >&2; exit 2; }
binary="$(cd "$(dirname "$binary")" && pwd)/$(basename "$binary")"
if [ -z "$on" ]; then
    if docker info >/dev/null 2>&1; then on=docker; else on=netns; fi
fi
case "$on" in
    docker) docker info >/dev/null 2>&1 || { echo "fault-test.sh: no Docker engine answers" >&2; exit 2; } ;;
    netns) { [ "$(id -u)" = 0 ] && command -v ip >/dev/null; } || { echo "fault-test.sh: --on netns needs root and ip (iproute2)" >&2; exit 2; } ;;
    *) echo "fault-test.sh: --on docker|netns, not $on" >&2; exit 2 ;;
esac

work="$(mktemp -d)"
calib() { "$binary" "$@"; }
say() { printf 'fault-test: %s\n' "$*"; }
now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN{printf "%.1f", b-a}'; }
field() { python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2], {}, {"d": d}))' "$@"; }

# ---- Docker: containers of the compose file on its private network ----------------------
docker_up() {
    project="calibfault$$"
    tag="calib:fault-$$"
    # A fixed host port for the API: a random one would change when the container
    # restarts, and the client following the campaign could not find it again.
    port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
    export CALIB_IMAGE="$tag" CALIB_PUBLISH="127.0.0.1:$port" CALIB_WORKER_SLOTS=1
    compose=(docker-compose -p "$project" -f "$repo/deploy/compose/docker-compose.yml")
    deploy/build-image.sh --binary "$binary" --tag "$tag" | sed 's/^/fault-test: /'
    local out
    out="$("${compose[@]}" up -d --scale worker=3 2>&1)" || { echo "$out" >&2; fail "docker-compose up"; }
    network="${project}_default"
    coordinator="$("${compose[@]}" ps -q coordinator)"
    mapfile -t workers < <("${compose[@]}" ps -q worker)
    [ "${#workers[@]}" = 3 ] || fail "3 workers expected, ${#workers[@]} up"
    # A killed container stays dead: the fault is a lost host, not a restart.
    docker update --restart=no "${workers[@]}" "$coordinator" >/dev/null
    url="http://127.0.0.1:$port"
    where="containers on network $network"
}
docker_logs() { "${compose[@]}" logs --no-color "$@"; }
docker_coordinator_log() { docker logs "$coordinator" 2>&1; }
docker_kill_worker() { docker kill "${workers[$1]}" >/dev/null; victim="${workers[$1]:0:12}"; }
docker_cut_worker() { docker network disconnect "$network" "${workers[$1]}"; victim="${workers[$1]:0:12}"; }
docker_heal_worker() { docker network connect --alias worker --alias "${workers[$1]:0:12}" "$network" "${workers[$1]}"; }
docker_kill_coordinator() { docker kill "$coordinator" >/dev/null; }
docker_start_coordinator() { docker start "$coordinator" >/dev/null; }
docker_stop_coordinator() { "${compose[@]}" stop -t 30 coordinator >/dev/null 2>&1; }
docker_store_stats() { docker run --rm -v "${project}_store:/data" "$tag" store stats --db /data/store --json; }
docker_down() {
    "${compose[@]}" down -v --remove-orphans >/dev/null 2>&1 || true
    docker image rm -f "$tag" >/dev/null 2>&1 || true
}
docker_keep() { say "kept: docker-compose project $project, image $tag"; }

# ---- Network namespaces: one per host, a bridge in another -------------------------------
netns_up() {
    ns="calibf$$"
    hosts=(c w0 w1 w2 cl)   # coordinator, three workers, the client
    ip netns add "$ns-sw"
    ip -n "$ns-sw" link add br0 type bridge
    ip -n "$ns-sw" link set br0 up
    local i=1 h
    for h in "${hosts[@]}"; do
        ip netns add "$ns-$h"
        ip link add eth0 netns "$ns-$h" type veth peer name "p-$h" netns "$ns-sw"
        ip -n "$ns-sw" link set "p-$h" master br0 up
        ip -n "$ns-$h" addr add "10.231.0.$i/24" dev eth0
        ip -n "$ns-$h" link set eth0 up
        ip -n "$ns-$h" link set lo up
        i=$((i + 1))
    done
    pids=()
    netns_start_coordinator
    for i in 0 1 2; do
        ip netns exec "$ns-w$i" "$binary" --log info worker --listen 0.0.0.0:50051 --slots 1 \
            --register http://10.231.0.1:50050 --advertise "http://10.231.0.$((i + 2)):50051" \
            > "$work/w$i.log" 2>&1 &
        pids[$i]=$!
    done
    url="http://10.231.0.1:50050"
    client=(ip netns exec "$ns-cl")
    where="network namespaces $ns-*"
}
netns_logs() { tail -n 20 "$work"/c.log "$work"/w*.log; }
netns_coordinator_log() { cat "$work/c.log"; }
netns_kill_worker() {
    kill -9 "${pids[$1]}"; wait "${pids[$1]}" 2>/dev/null || true
    victim="w$1 (10.231.0.$(($1 + 2)))"
}
netns_cut_worker() { ip -n "$ns-sw" link set "p-w$1" down; victim="w$1 (10.231.0.$(($1 + 2)))"; }
netns_heal_worker() { ip -n "$ns-sw" link set "p-w$1" up; }
netns_start_coordinator() {
    ip netns exec "$ns-c" "$binary" --log info coordinator --listen 10.231.0.1:50050 \
        --db "$work/store" --api-dir "$work/api" --out "$work/results" >> "$work/c.log" 2>&1 &
    coordinator_pid=$!
}
netns_kill_coordinator() { kill -9 "$coordinator_pid"; wait "$coordinator_pid" 2>/dev/null || true; }
netns_stop_coordinator() { kill -TERM "$coordinator_pid"; wait "$coordinator_pid" 2>/dev/null || true; }
netns_store_stats() { calib store stats --db "$work/store" --json; }
netns_down() {
    kill -9 "${pids[@]}" "${coordinator_pid:-}" 2>/dev/null || true
    wait 2>/dev/null || true
    local h
    for h in sw "${hosts[@]}"; do ip netns del "$ns-$h" 2>/dev/null || true; done
}
netns_keep() { say "kept: namespaces $ns-* (ip netns del each to remove them)"; }

# ------------------------------------------------------------------------------------------
client=()
at_client() { "${client[@]}" "$binary" "$@"; }
fail() {
    printf 'fault-test: FAILED: %s\n' "$*" >&2
    "${on}_logs" 2>/dev/null | tail -n 60 >&2 || true
    exit 1
}
cleanup() {
    local code=$?
    [ -n "${submit_pid:-}" ] && kill "$submit_pid" 2>/dev/null || true
    if [ "$keep" = 1 ]; then
        "${on}_keep"; say "files in $work"
    else
        "${on}_down"
        rm -rf "$work"
    fi
    exit $code
}
trap cleanup EXIT

# The reference: the same campaign in one process.
started=$(now)
calib calibrate "$campaign" --out "$work/local" --db "$work/local-db" --json > "$work/local.json"
name="$(field "$work/local.json" 'd["campaign"]')"
total="$(field "$work/local.json" 'd["evaluations"]')"
say "local run: $total evaluations in $(since "$started") s"

"${on}_up"
for _ in $(seq 150); do at_client health "$url" >/dev/null 2>&1 && break; sleep 0.2; done
at_client health "$url" >/dev/null || fail "the coordinator at $url never served"
for _ in $(seq 150); do
    up="$("${on}_logs" 2>/dev/null | grep -c 'worker up' || true)"
    [ "$up" -ge 3 ] && break
    sleep 0.2
done
# The faults below stop two workers in turn: with fewer than three up, they would prove
# nothing (or stop the campaign for want of workers, not for the fault).
[ "$up" -ge 3 ] || fail "only $up of 3 workers came up within 30 s"
say "cluster up on $where: coordinator at $url, $up workers up"

# Submit, and follow it with `calib submit` itself, through every fault.
started=$(now)
at_client submit "$campaign" --coordinator "$url" --out "$work/cluster" > "$work/submit.out" 2> "$work/submit.err" &
submit_pid=$!

evaluations() {
    at_client status --coordinator "$url" 2>/dev/null | awk -v n="$name" '$3 == n {print $4; exit}'
}
wait_for() { # a fraction of the local run's evaluations
    local goal e
    goal=$(awk -v t="$total" -v f="$1" 'BEGIN{printf "%d", t*f}')
    for _ in $(seq 2400); do
        e="$(evaluations || true)"
        if [ -n "$e" ] && [ "$e" -ge "$goal" ]; then echo "$e"; return 0; fi
        kill -0 "$submit_pid" 2>/dev/null || fail "calib submit ended early: $(tail -3 "$work/submit.err")"
        sleep 0.25
    done
    fail "no progress to $goal evaluations"
}

at="$(wait_for 0.15)"
"${on}_kill_worker" 0
say "killed worker $victim at $at evaluations"

at="$(wait_for 0.30)"
"${on}_cut_worker" 1
say "cut worker $victim off the network at $at evaluations"
sleep 8
"${on}_heal_worker" 1
say "reconnected it 8 s later, at $(evaluations) evaluations"

at="$(wait_for 0.55)"
"${on}_kill_coordinator"
killed=$(now)
say "killed the coordinator at $at evaluations"
"${on}_store_stats" > "$work/stats-before.json" || fail "store stats on the killed coordinator's store"
stored_before="$(field "$work/stats-before.json" 'd["evaluations"]')"
"${on}_start_coordinator"
for _ in $(seq 150); do at_client health "$url" >/dev/null 2>&1 && break; sleep 0.2; done
say "restarted it $(since "$killed") s after the kill; its store held $stored_before evaluations"

wait "$submit_pid" || fail "calib submit failed: $(tail -5 "$work/submit.err")"
submit_pid=""
elapsed="$(since "$started")"
grep -q 'coordinator lost' "$work/submit.err" || fail "calib submit never saw the coordinator go"
result="$work/cluster/$name/result.json"
[ -f "$result" ] || fail "no $result"
"${on}_stop_coordinator"
"${on}_store_stats" > "$work/stats-after.json" || fail "store stats after the campaign"
stored_after="$(field "$work/stats-after.json" 'd["evaluations"]')"
simulated="$(field "$result" 'd["simulated"]')"
cached="$(field "$result" 'd["cached"]')"
evaluated="$(field "$result" 'd["evaluations"]')"
repeated=$((simulated - (stored_after - stored_before)))

say "campaign finished in $elapsed s: $evaluated evaluations (local $total); after the restart $cached from the store, $simulated simulated, $((stored_after - stored_before)) new in the store"
say "repeated simulations after the restart: $repeated"

python3 - "$work/local.json" "$result" <<'PY' || fail "the cluster's runs differ from the local run's"
import json, sys
local, cluster = (json.load(open(p)) for p in sys.argv[1:3])
def runs(r):
    return [(x["method"], x["start"], x["objective"], x["parameters"], x["evaluations"]) for x in r["runs"]]
assert runs(local) == runs(cluster), (runs(local), runs(cluster))
assert local["best"]["parameters"] == cluster["best"]["parameters"]
assert local["best"]["objective"] == cluster["best"]["objective"]
print(f"fault-test: {len(local['runs'])} runs identical to the local run's, best objective {cluster['best']['objective']:.6e}")
PY
[ "$evaluated" = "$total" ] || fail "evaluations: $evaluated on the cluster, $total locally (lost or extra)"
[ "$repeated" = 0 ] || fail "$repeated simulations repeated after the restart"
# What the coordinator saw of each fault, with its times.
"${on}_coordinator_log" | grep -E 'worker taken out|registration expired|worker up|worker added|resuming|resumed|coordinator serving' \
    | sed -E 's/^[^|]*\| //; s/^([0-9T:.-]+)Z? +[A-Z]+ +[a-z_:]+: /\1 /' | sed 's/^/fault-test:   /' || true
say "PASSED on $on"
