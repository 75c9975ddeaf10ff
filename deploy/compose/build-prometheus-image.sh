#!/usr/bin/env bash
# Builds the monitoring image nupmpc-prometheus:latest (deploy/container/Containerfile.prometheus:
# Debian's prometheus with deploy/prometheus/'s configuration and alert rules) on this machine
# with no registry: on the base image localhost/nupmpc-debian12-base that
# deploy/container/build-image.sh makes (`build-image.sh --base-only` if it is missing), with
# the same podman work-arounds (deploy/container/podman-env.sh). Run it again after editing
# deploy/prometheus/ (up.sh warns when the image's copy differs). Prints the image size.
#
# Usage: deploy/compose/build-prometheus-image.sh
# Environment: NUPMPC_PODMAN_RUNTIME, NUPMPC_PODMAN_STORAGE (see podman-env.sh)
set -euo pipefail
cd "$(dirname "$0")/../.."
case "${1:-}" in -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;; esac
base_image=localhost/nupmpc-debian12-base
image=localhost/nupmpc-prometheus:latest

# shellcheck source=deploy/compose/stack-env.sh
. deploy/compose/stack-env.sh
nupmpc_podman_tag=build-prometheus
# shellcheck source=deploy/container/podman-env.sh
. deploy/container/podman-env.sh
nupmpc_podman_setup
if ! "${podman_base[@]}" image exists "$base_image"; then
  echo "build-prometheus: no $base_image: run deploy/container/build-image.sh --base-only" >&2
  exit 1
fi
nupmpc_podman_runtime "$base_image"

# Host network: the build only runs apt-get, and needs no bridge/CNI set-up for it.
# The checksum label is applied at commit (after buildah's layer cache), so it is always this
# tree's; up.sh compares it with deploy/prometheus/.
start=$(date +%s)
"${podman_run[@]}" build --pull=never --layers --network host "${ulimits[@]}" \
  --build-arg BASE_IMAGE="$base_image" \
  --label io.nupmpc.prometheus-config="$(stack_prometheus_config_sum)" \
  -t "$image" -f deploy/container/Containerfile.prometheus deploy/prometheus
size=$("${podman_base[@]}" image inspect --format '{{.Size}}' "$image")
base_size=$("${podman_base[@]}" image inspect --format '{{.Size}}' "$base_image")
version=$("${podman_run[@]}" run --rm --network none "${ulimits[@]}" --entrypoint /usr/bin/prometheus "$image" --version 2>&1 |
          sed -n '1s/^prometheus, version \([^ ]*\).*/\1/p')
echo "build-prometheus: $image (Prometheus ${version:-?}) in $(( $(date +%s) - start )) s:" \
     "$(( size / 1000000 )) MB (base $(( base_size / 1000000 )) MB)"
