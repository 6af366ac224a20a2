# Sourced by the Slurm scripts of this folder (not run): where calib, its files and its
# secrets are, and the security flags every calib command of a job takes. See README.md.
#
#   CALIB          the calib binary [default: calib on PATH]
#   CALIB_DIR      the deployment's folder: store/, results/, api/, logs/ and the running
#                  coordinator's address in coordinator.url [default: calib/ in the folder
#                  sbatch was run from]
#   CALIB_SECRETS  folder of the secrets [default: ~/.calib]: token (the cluster's bearer
#                  token), tls.crt and tls.key (the certificate coordinator and workers
#                  present; it must name every node's host name) and ca.crt (the CA clients
#                  trust). Each is used when present; a token without TLS is refused by calib
#                  over the network (set CALIB_PLAINTEXT_TOKEN=1 to send it anyway).
#   CALIB_HOST     the name other nodes reach this node by [default: hostname]
#   CALIB_LOG      calib's log filter [default: info: workers up and taken out, campaigns
#                  resumed, in the logs]

calib="${CALIB:-calib}"
command -v "$calib" >/dev/null || { echo "calib: no calib binary ($calib); set CALIB" >&2; exit 2; }
calib_dir="${CALIB_DIR:-${SLURM_SUBMIT_DIR:-$PWD}/calib}"
mkdir -p "$calib_dir/logs"
secrets="${CALIB_SECRETS:-$HOME/.calib}"
host="${CALIB_HOST:-$(hostname)}"
export RUST_LOG="${CALIB_LOG:-info}"

# serve: what a server presents; dial: what a client trusts and presents.
serve=()
dial=()
scheme=http
if [ -f "$secrets/tls.crt" ] && [ -f "$secrets/tls.key" ]; then
    serve+=(--tls-cert "$secrets/tls.crt" --tls-key "$secrets/tls.key")
    scheme=https
fi
[ -f "$secrets/ca.crt" ] && dial+=(--tls-ca "$secrets/ca.crt")
[ -f "$secrets/token" ] && dial+=(--token-file "$secrets/token")
[ "${CALIB_PLAINTEXT_TOKEN:-0}" = 1 ] && dial+=(--allow-plaintext-token)

# The address of the coordinator running for this folder, once it has written it.
coordinator_url() { cat "$calib_dir/coordinator.url" 2>/dev/null; }
