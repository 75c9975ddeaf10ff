#!/usr/bin/env bash
# Creates, or replaces in place, the Secrets the manifests mount (PEM files; keys never
# committed). Run it again with renewed files to rotate them: the kubelet updates the mounted
# files (within about a minute), the replicas re-read theirs by themselves, the balancer on
#   kubectl exec deployment/nupmpc-haproxy -- bash -c 'kill -USR2 1'
# (a reload in place: open streams stay on the old worker until they end).
#
#   deploy/k8s/make-secrets.sh [-n NAMESPACE] --ca CA.pem \
#       --server-cert F --server-key F \
#       --balancer-cert F --balancer-key F \
#       --balancer-client-cert F --balancer-client-key F \
#       --tokens FILE
#
#   nupmpc-ca                   ca.crt: signs the replicas' certificates (the balancer checks
#                               them) and the callers' client certificates (the balancer and
#                               the replicas check them)
#   nupmpc-server-tls           the replicas' certificate: must name nupmpc-replicas (DNS SAN)
#   nupmpc-balancer-tls         what clients see at the Service nupmpc: must name the address
#                               clients dial (e.g. nupmpc.NAMESPACE.svc)
#   nupmpc-balancer-client-tls  the balancer's client certificate to the replicas; its subject
#                               is NUPMPC_TRUSTED_BALANCER_SUBJECT (configmap.yaml)
#   nupmpc-tokens               tokens: the bearer tokens, TOKEN PRINCIPAL [admin] per line
# tests/deploy/k8s_manifest_check.py checks that every Secret the manifests mount is made here.
set -euo pipefail
namespace=() ca="" tokens=""
declare -A file
while [ $# -gt 0 ]; do
  case "$1" in
    -n|--namespace) namespace=(-n "$2"); shift 2 ;;
    --ca) ca="$2"; shift 2 ;;
    --tokens) tokens="$2"; shift 2 ;;
    --server-cert|--server-key|--balancer-cert|--balancer-key|--balancer-client-cert|--balancer-client-key)
      file[${1#--}]="$2"; shift 2 ;;
    -h|--help) sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "make-secrets.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
for option in ca tokens server-cert server-key balancer-cert balancer-key balancer-client-cert balancer-client-key; do
  case "$option" in ca) path=$ca ;; tokens) path=$tokens ;; *) path=${file[$option]:-} ;; esac
  [ -n "$path" ] || { echo "make-secrets.sh: --$option is required" >&2; exit 2; }
  [ -r "$path" ] || { echo "make-secrets.sh: --$option $path: cannot be read" >&2; exit 2; }
done
apply() { kubectl "${namespace[@]}" "$@" --dry-run=client -o yaml | kubectl "${namespace[@]}" apply -f -; }
apply create secret generic nupmpc-ca --from-file=ca.crt="$ca"
apply create secret tls nupmpc-server-tls --cert="${file[server-cert]}" --key="${file[server-key]}"
apply create secret tls nupmpc-balancer-tls --cert="${file[balancer-cert]}" --key="${file[balancer-key]}"
apply create secret tls nupmpc-balancer-client-tls --cert="${file[balancer-client-cert]}" \
  --key="${file[balancer-client-key]}"
apply create secret generic nupmpc-tokens --from-file=tokens="$tokens"
