#!/usr/bin/env bash
# Stops and removes the compose stack. The pod is stopped first, so that every container
# gets SIGTERM (the replicas drain: NUPMPC_DRAIN_DELAY_S NOT_SERVING, then in-flight solves)
# and its exit code can be read before `podman kube down` removes it. Exit status 1 if a
# container did not exit 0 (137: killed after podman's 10 s stop timeout). The containers'
# copies of the certificates and tokens (up.sh) are removed with it; --pki's files stay.
#
# Usage: deploy/compose/down.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
case "${1:-}" in -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;; esac
# shellcheck source=deploy/compose/stack-env.sh
. deploy/compose/stack-env.sh
nupmpc_podman_quiet=1 nupmpc_stack_setup
if ! "${podman_base[@]}" pod exists "$stack_pod"; then
  rm -rf "$stack_secrets_dir"
  echo "down: no pod $stack_pod"
  exit 0
fi
start=$(date +%s%N)
"${podman_base[@]}" pod stop "$stack_pod" >/dev/null
stopped=$(awk -v a="$start" -v b="$(date +%s%N)" 'BEGIN { printf "%.1f", (b - a) / 1e9 }')
codes=$("${podman_base[@]}" ps -a --filter "pod=$stack_pod" --format '{{.Names}} {{.ExitCode}}' |
        sed -n "s/^$stack_pod-//p" | sort)
"${podman_base[@]}" kube down "$stack_yaml" >/dev/null
rm -rf "$stack_secrets_dir"
echo "down: pod $stack_pod stopped in $stopped s and removed; exit codes: $(paste -sd, <<<"$codes" | sed 's/,/, /g')"
awk '$2 != 0 { exit 1 }' <<<"$codes"
