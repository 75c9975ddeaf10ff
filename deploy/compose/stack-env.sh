# shellcheck shell=bash
# Sourced by up.sh, down.sh and smoke.sh (from the repository root): podman for the compose
# stack on this machine, and what the balancer sees.
#   nupmpc_stack_setup          podman-env.sh's setup (podman_base: podman with the storage
#                               options); exports CONTAINERS_CONF if up.sh wrote it
#   nupmpc_stack_runtime IMAGE  the runtime that runs IMAGE (podman-env.sh), written with the
#                               ulimits into CONTAINERS_CONF for `podman kube play`
#   stack_servers [BACKEND]     one line per replica from HAProxy's stats: name, status,
#                               last check, current and total calls (default backend streams)
#   stack_prometheus PATH       the body of Prometheus' answer to GET PATH (status 1 unless 200)
#   stack_prometheus_config_sum the checksum of deploy/prometheus/'s configuration and rules
#                               (the Prometheus image's label io.nupmpc.prometheus-config)
#   stack_make_pki DIR          a CA and the stack's three certificates in DIR (deploy/make-pki.sh)
#   stack_install_secrets DIR   copies DIR's files into the directories the pod mounts
#
# Why a containers.conf: `podman kube play` (4.3) has no --ulimit or --runtime option, and
# the containers it starts would get podman's default nofile=1048576, which the runtime may not
# set under this sandbox's hard limit (crun: "setrlimit RLIMIT_NOFILE: Operation not
# permitted"), and crun, which refuses this cgroup v1/v2 hybrid (podman-env.sh says more).
# containers.conf's default_ulimits and runtime are what kube play honours. The file stays in
# /run: conmon's clean-up (and with it a restart after a crash) runs podman with the same
# environment after this script has exited.
# shellcheck disable=SC2034  # used by the scripts that source this file
stack_yaml=deploy/compose/nupmpc-stack.yaml
stack_pod=nupmpc-stack
stack_conf_dir=/run/nupmpc-compose
# The hostPath volumes of the YAML: what each container's user may read, and nothing else.
stack_secrets_dir=$stack_conf_dir/secrets

nupmpc_stack_setup() {
  nupmpc_podman_tag=${nupmpc_podman_tag:-compose}
  # shellcheck source=deploy/container/podman-env.sh
  . deploy/container/podman-env.sh
  nupmpc_podman_setup
  if [ -f "$stack_conf_dir/containers.conf" ]; then export CONTAINERS_CONF=$stack_conf_dir/containers.conf; fi
}

nupmpc_stack_runtime() {
  nupmpc_podman_runtime "$1" || return 1
  mkdir -p "$stack_conf_dir"
  # ulimits holds "--ulimit" "nofile=N:N" "--ulimit" "nproc=M:M" (podman-env.sh).
  cat >"$stack_conf_dir/containers.conf" <<CONF
# Written by deploy/compose/stack-env.sh for \`podman kube play\` of the nupmpc stack.
[containers]
default_ulimits = ["${ulimits[1]}", "${ulimits[3]}"]
[engine]
runtime = "$NUPMPC_PODMAN_RUNTIME"
CONF
  export CONTAINERS_CONF=$stack_conf_dir/containers.conf
}

# The stats socket is TCP on the pod's loopback (NUPMPC_BALANCER_STATS in the YAML): the
# balancer image has bash, whose /dev/tcp reads it, and no socat or python.
stack_servers() {
  "${podman_base[@]}" exec "$stack_pod-balancer" \
      bash -c 'exec 3<>/dev/tcp/127.0.0.1/50059 && echo "show stat" >&3 && cat <&3' 2>/dev/null |
    awk -F, -v backend="${1:-streams}" '
      NR == 1 { sub(/^# /, ""); for (i = 1; i <= NF; i++) col[$i] = i; next }
      $1 == backend && $2 != "FRONTEND" && $2 != "BACKEND" {
        check = $col["check_status"] == "" ? "-" : $col["check_status"]
        # One word: a server between states is "UP 1/2" (one check of "fall" failed).
        status = $col["status"]; gsub(/ /, "_", status)
        print $2, status, check, $col["scur"], $col["stot"] }'
}

# Prometheus listens on the pod's loopback only (127.0.0.1:9090, not published: see the
# YAML). Its image has bash but no curl or python, so the request is made in its container
# with bash's /dev/tcp: HTTP/1.0, so that the server closes the connection after the answer,
# headers skipped. PATH must be URL-encoded.
read -r -d '' stack_http_get <<'SH' || true
exec 3<>"/dev/tcp/$1/$2" || exit 1
printf 'GET %s HTTP/1.0\r\nHost: %s:%s\r\n\r\n' "$3" "$1" "$2" >&3
IFS= read -r status <&3 || exit 1
case $status in "HTTP/1."?" 200 "*) ;; *) exit 1 ;; esac
while IFS= read -r line <&3 && [ "$line" != $'\r' ]; do :; done
cat <&3
SH
stack_prometheus() {
  "${podman_base[@]}" exec "$stack_pod-prometheus" bash -c "$stack_http_get" bash 127.0.0.1 9090 "$1" 2>/dev/null
}

stack_prometheus_config_sum() {
  cat deploy/prometheus/prometheus.yml deploy/prometheus/nupmpc-alerts.yml | sha256sum | cut -d' ' -f1
}

# The certificates the secure stack needs, for a machine with no CA of its own: the replicas'
# (named localhost, where the balancer dials them in the pod), the balancer's to clients
# (localhost, 127.0.0.1 and this host's name) and its client certificate to the replicas, whose
# subject is the YAML's NUPMPC_TRUSTED_BALANCER_SUBJECT (RFC 2253 lists the RDNs reversed).
stack_make_pki() {  # DIR
  local make=(deploy/make-pki.sh "$1") host
  host=$(hostname)
  "${make[@]}" ca /CN=nupmpc-compose-ca
  "${make[@]}" server replica /CN=localhost DNS:localhost,IP:127.0.0.1
  "${make[@]}" server frontend "/CN=$host" "DNS:localhost,IP:127.0.0.1,DNS:$host"
  "${make[@]}" client balancer-client /O=nupmpc/CN=nupmpc-balancer
}

# The files each container reads, copied from a PKI directory (stack_make_pki's names plus
# the tokens file) with the owner of that container's user (the images' fixed uids: replicas
# 10001, balancer 10002), mode 0400. Each file is written beside its place and renamed into
# it, keys before certificates, so that a replica re-reading its files (and a balancer
# reloading) never sees half a file or a certificate without its key.
stack_install_secrets() {  # PKI_DIR
  local pki=$1 role owner file dir
  local -A files=([replica]="ca.pem tokens replica.pem.key replica.pem"
                  [balancer]="ca.pem frontend.pem.key frontend.pem balancer-client.pem.key balancer-client.pem")
  local -A uid=([replica]=10001 [balancer]=10002)
  for role in replica balancer; do
    for file in ${files[$role]}; do
      [ -r "$pki/$file" ] || { echo "stack-env: no $pki/$file (deploy/compose/README.md: the PKI directory)" >&2; return 1; }
    done
  done
  for role in replica balancer; do
    dir=$stack_secrets_dir/$role owner=${uid[$role]}
    mkdir -p "$dir"
    chown "$owner:$owner" "$dir"
    chmod 0500 "$dir"
    for file in ${files[$role]}; do
      install -m 0400 -o "$owner" -g "$owner" "$pki/$file" "$dir/.$file.new"
      mv -f "$dir/.$file.new" "$dir/$file"
    done
  done
}
