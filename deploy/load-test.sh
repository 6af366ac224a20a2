#!/usr/bin/env bash
# Load on the compose cluster, measured (figures for docs/deployment.md; not run by the test suite):
#   1. throughput and scaling efficiency from 1 to 3 single-slot workers on hx_highfi
#      (differential evolution: generations of 20 points keep every worker busy);
#   2. 20 campaigns of 8 starts each submitted at once against 3 workers: every one must
#      finish; the coordinator's peak memory (VmHWM of its process); then every campaign
#      run again with `calib calibrate` on the coordinator's store must simulate nothing.
#
#   deploy/load-test.sh [--binary PATH] [--campaigns N] [--skip-scaling]
#
# --binary     the calib binary to package [default: target/release/calib]
# --campaigns  how many campaigns at once [default: 20]
set -euo pipefail
cd "$(dirname "$0")/.."
repo="$PWD"
binary=target/release/calib
campaigns=20
scaling=1
while [ $# -gt 0 ]; do
    case "$1" in
        --binary) binary="$2"; shift 2 ;;
        --campaigns) campaigns="$2"; shift 2 ;;
        --skip-scaling) scaling=0; shift ;;
        -h|--help) sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "load-test.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
binary="$(cd "$(dirname "$binary")" && pwd)/$(basename "$binary")"
work="$(mktemp -d)"
tag="calib:load-$$"
project=""
say() { printf 'load-test: %s\n' "$*"; }
now() { date +%s.%N; }
field() { python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2], {}, {"d": d}))' "$@"; }
compose() { docker-compose -p "$project" -f "$repo/deploy/compose/docker-compose.yml" "$@"; }
down() { [ -n "$project" ] && compose down -v --remove-orphans >/dev/null 2>&1 || true; }
cleanup() { down; docker image rm -f "$tag" >/dev/null 2>&1 || true; rm -rf "$work"; }
trap cleanup EXIT

deploy/build-image.sh --binary "$binary" --tag "$tag" | sed 's/^/load-test: /'
export CALIB_IMAGE="$tag" CALIB_WORKER_SLOTS=1

up() { # workers
    project="calibload$$n$1"
    port="$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
    export CALIB_PUBLISH="127.0.0.1:$port"
    compose up -d --scale worker="$1" >/dev/null 2>&1
    url="http://127.0.0.1:$port"
    for _ in $(seq 150); do "$binary" health "$url" >/dev/null 2>&1 && break; sleep 0.2; done
    for _ in $(seq 150); do
        [ "$(compose logs --no-color coordinator | grep -c 'worker up' || true)" -ge "$1" ] && break
        sleep 0.2
    done
}

if [ "$scaling" = 1 ]; then
    sed -e '0,/^name = .*/s//name = "load_scaling"/' \
        -e 's#^file = .*#file = "'"$repo"'/examples/data/hx_highfi.csv"#' \
        -e 's/^methods = .*/methods = ["differential-evolution"]/' \
        -e 's/^starts = .*/starts = 1/' -e 's/^max_evaluations = .*/max_evaluations = 400/' \
        deploy/fault/hx_highfi.toml > "$work/scaling.toml"
    rate1=""
    for n in 1 2 3; do
        up "$n"
        started=$(now)
        "$binary" submit "$work/scaling.toml" --coordinator "$url" --out "$work/scaling-$n" --json > "$work/scaling-$n.json" 2>/dev/null
        elapsed=$(awk -v a="$started" -v b="$(now)" 'BEGIN{print b-a}')
        simulated="$(field "$work/scaling-$n.json" 'd["simulated"]')"
        rate=$(awk -v s="$simulated" -v e="$elapsed" 'BEGIN{printf "%.2f", s/e}')
        [ -z "$rate1" ] && rate1="$rate"
        say "$(printf 'hx_highfi on %d worker(s): %d simulations in %.1f s, %s/s, efficiency %.2f' "$n" "$simulated" "$elapsed" "$rate" "$(awk -v r="$rate" -v r1="$rate1" -v n="$n" 'BEGIN{print r/(r1*n)}')")"
        down
    done
fi

# Many campaigns at once.
up 3
coordinator="$(compose ps -q coordinator)"
pid="$(docker inspect -f '{{.State.Pid}}' "$coordinator")"
ids=()
for i in $(seq "$campaigns"); do
    sed -e "0,/^name = .*/s//name = \"load_$i\"/" \
        -e 's#^file = .*#file = "'"$repo"'/examples/data/furuta_clean.csv"#' \
        -e 's/^methods = .*/methods = ["nelder-mead", "powell"]/' \
        -e 's/^starts = .*/starts = 8/' -e 's/^max_evaluations = .*/max_evaluations = 400/' \
        -e "s/^seed = .*/seed = $i/" examples/furuta.toml > "$work/load_$i.toml"
done
started=$(now)
for i in $(seq "$campaigns"); do
    ids+=("$("$binary" submit "$work/load_$i.toml" --coordinator "$url" --detach)")
done
peak=0
while :; do
    states="$("$binary" status --coordinator "$url")"
    rss=$(awk '/VmHWM/{print $2}' "/proc/$pid/status")
    [ "$rss" -gt "$peak" ] && peak=$rss
    running=$(grep -c ' running ' <<<"$states" || true)
    [ "$running" = 0 ] && break
    sleep 0.5
done
elapsed=$(awk -v a="$started" -v b="$(now)" 'BEGIN{printf "%.1f", b-a}')
finished=$(grep -c ' finished ' <<<"$states" || true)
evaluations=$(awk '{s+=$4} END{print s}' <<<"$states")
say "$campaigns campaigns of 8 starts at once on 3 workers: $finished finished in $elapsed s, $evaluations evaluations; coordinator peak memory $((peak / 1024)) MiB"
[ "$finished" = "$campaigns" ] || { say "FAILED: $finished of $campaigns finished"; echo "$states" >&2; exit 1; }

# The store is consistent: every campaign again, on the coordinator's store, simulates nothing.
compose stop -t 30 coordinator >/dev/null 2>&1
again=0
for i in $(seq "$campaigns"); do
    simulated=$(docker run --rm -v "${project}_store:/data" -v "$work:$work" -v "$repo/examples:$repo/examples:ro" \
        "$tag" calibrate "$work/load_$i.toml" --db /data/store --out /tmp/out --json 2>/dev/null \
        | python3 -c 'import json,sys; print(json.load(sys.stdin)["simulated"])')
    again=$((again + simulated))
done
say "every campaign run again on the coordinator's store: $again simulations"
[ "$again" = 0 ] || { say "FAILED: the store missed $again evaluations"; exit 1; }
say "PASSED"
