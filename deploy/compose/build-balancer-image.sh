#!/usr/bin/env bash
# Builds the balancer image nupmpc-haproxy:latest (deploy/container/Containerfile.haproxy)
# on this machine with no registry: on the base image localhost/nupmpc-debian12-base that
# deploy/container/build-image.sh makes (`build-image.sh --base-only` if it is missing), with
# the same podman work-arounds (deploy/container/podman-env.sh). Prints the image size.
#
# Usage: deploy/compose/build-balancer-image.sh
# Environment: NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE (see podman-env.sh)
set -euo pipefail
cd "$(dirname "$0")/../.."
case "${1:-}" in -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;; esac
base_image=localhost/nupmpc-debian12-base
image=localhost/nupmpc-haproxy:latest

nupmpc_podman_tag=build-balancer
# shellcheck source=deploy/container/podman-env.sh
. deploy/container/podman-env.sh
nupmpc_podman_setup
if ! "${podman_base[@]}" image exists "$base_image"; then
  echo "build-balancer: no $base_image: run deploy/container/build-image.sh --base-only" >&2
  exit 1
fi
nupmpc_podman_runtime "$base_image"

# Host network: the build only runs apt-get, and needs no bridge/CNI set-up for it.
start=$(date +%s)
"${podman_run[@]}" build --pull=never --layers --network host "${ulimits[@]}" \
  --build-arg BASE_IMAGE="$base_image" \
  -t "$image" -f deploy/container/Containerfile.haproxy deploy/haproxy
size=$("${podman_base[@]}" image inspect --format '{{.Size}}' "$image")
base_size=$("${podman_base[@]}" image inspect --format '{{.Size}}' "$base_image")
echo "build-balancer: $image in $(( $(date +%s) - start )) s:" \
     "$(( size / 1000000 )) MB (base $(( base_size / 1000000 )) MB)"
