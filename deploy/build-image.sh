#!/usr/bin/env bash
# Build the calib container image from the project's own binary, with no registry and no base
# image: a root filesystem holding the binary, the shared libraries `ldd` lists for it, the
# CA bundle and a name-service configuration, imported with `docker import`.
#
#   deploy/build-image.sh [--binary PATH] [--tag NAME:TAG] [--strip]
#
# --binary  the calib binary to package [default: target/release/calib, built with
#           `cargo build --release` when absent]
# --tag     the image's name [default: calib:latest]
# --strip   package a stripped copy: about 20 MB instead of about 100, but panics show no
#           file and line
#
# One image serves every role; the subcommand picks it:
#   docker run --rm calib:latest worker --listen 0.0.0.0:50051
set -euo pipefail
cd "$(dirname "$0")/.."

binary=""
tag="calib:latest"
strip=0
while [ $# -gt 0 ]; do
    case "$1" in
        --binary) binary="$2"; shift 2 ;;
        --tag) tag="$2"; shift 2 ;;
        --strip) strip=1; shift ;;
        -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "build-image.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
if [ -z "$binary" ]; then
    binary=target/release/calib
    [ -x "$binary" ] || cargo build --release --locked
fi
[ -x "$binary" ] || { echo "build-image.sh: $binary is not an executable" >&2; exit 2; }
command -v docker >/dev/null || { echo "build-image.sh: docker is not installed" >&2; exit 2; }

root="$(mktemp -d)"
trap 'rm -rf "$root"' EXIT
mkdir -p "$root/usr/local/bin" "$root/etc/ssl/certs" "$root/tmp" "$root/data"
chmod 1777 "$root/tmp"
cp "$binary" "$root/usr/local/bin/calib"
[ "$strip" = 1 ] && strip "$root/usr/local/bin/calib"
# Every library the dynamic linker loads for the binary, and the linker itself, at the paths
# the binary names them by.
ldd "$binary" | awk '/=> \//{print $3} /^\t\//{print $1}' | sort -u | while read -r lib; do
    mkdir -p "$root$(dirname "$lib")"
    cp -L "$lib" "$root$lib"
done
# Names resolve from the container's /etc/hosts, then DNS (the user network's resolver):
# worker names in compose, headless Services in Kubernetes.
printf 'hosts: files dns\n' > "$root/etc/nsswitch.conf"
printf 'root:x:0:0:root:/:/usr/local/bin/calib\ncalib:x:1000:1000:calib:/data:/usr/local/bin/calib\n' > "$root/etc/passwd"
printf 'root:x:0:\ncalib:x:1000:\n' > "$root/etc/group"
# https:// without --tls-ca trusts the system's roots.
if [ -f /etc/ssl/certs/ca-certificates.crt ]; then
    cp /etc/ssl/certs/ca-certificates.crt "$root/etc/ssl/certs/"
fi

tar -C "$root" --numeric-owner -c . | docker import \
    --change 'ENTRYPOINT ["/usr/local/bin/calib"]' \
    --change 'CMD ["--help"]' \
    --change 'WORKDIR /data' \
    --change 'ENV RUST_LOG=info' \
    --message "calib $("$binary" --version | awk '{print $2}')" \
    - "$tag" >/dev/null
echo "built $tag from $binary ($(docker image inspect -f '{{.Size}}' "$tag" | awk '{printf "%.1f MB", $1/1e6}'))"
