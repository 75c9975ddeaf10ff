#!/usr/bin/env bash
# Makes the certificates and bearer tokens of a test or single-machine deployment with openssl
# (P-256 keys, one CA for every role). Each key sits beside its certificate as NAME.pem.key,
# as HAProxy looks for it and as a Kubernetes TLS Secret mounted with items gives it. Every
# file is the caller's only (umask 077). Used by deploy/scaleout-secure-test.sh and the
# compose stack (deploy/compose/up.sh, smoke.sh); a real deployment brings its own CA.
#
#   deploy/make-pki.sh DIR ca SUBJECT                a new CA: DIR/ca.pem, DIR/ca.key
#   deploy/make-pki.sh DIR server NAME SUBJECT SAN   DIR/NAME.pem(.key), serverAuth, signed by
#                                                    DIR's CA; SAN e.g. DNS:localhost,IP:127.0.0.1
#   deploy/make-pki.sh DIR client NAME SUBJECT       the same, clientAuth (an mTLS caller, or the
#                                                    balancer's certificate to the replicas)
#   deploy/make-pki.sh DIR token NAME PRINCIPAL      a random token in DIR/NAME.token, and the line
#                                                    "TOKEN PRINCIPAL" added to DIR/tokens (the
#                                                    server's --auth_tokens_file format)
#   deploy/make-pki.sh DIR subject NAME              prints DIR/NAME.pem's subject, RFC 2253 (what
#                                                    --trusted_balancer_subject and a forwarded
#                                                    x-nupmpc-client-subject hold)
# SUBJECT is openssl's form, e.g. /CN=alice/O=plant. Issuing NAME again replaces it (a
# rotation): the new key is moved into place before the new certificate, so a reader that
# sees the new certificate also sees its key.
set -euo pipefail
case "${1:-}" in -h|--help|"") sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;; esac
umask 077
usage_error() { echo "make-pki.sh: $*" >&2; exit 2; }
[ $# -ge 3 ] || usage_error "DIR ACTION ARGUMENTS... (see --help)"
dir=$1 action=$2
shift 2
mkdir -p "$dir"
newkey=(openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes)

issue() {  # NAME SUBJECT EXTENSIONS
  if [ ! -f "$dir/ca.pem" ] || [ ! -f "$dir/ca.key" ]; then usage_error "no CA in $dir (make-pki.sh $dir ca SUBJECT)"; fi
  printf '%s\n' "$3" >"$dir/$1.ext"
  "${newkey[@]}" -keyout "$dir/$1.new.key" -out "$dir/$1.csr" -subj "$2" 2>/dev/null
  openssl x509 -req -days 30 -in "$dir/$1.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" -CAcreateserial \
    -out "$dir/$1.new.pem" -extfile "$dir/$1.ext" 2>/dev/null
  rm -f "$dir/$1.csr" "$dir/$1.ext"
  mv "$dir/$1.new.key" "$dir/$1.pem.key"
  mv "$dir/$1.new.pem" "$dir/$1.pem"
}

case "$action" in
  ca)
    [ $# -eq 1 ] || usage_error "ca SUBJECT"
    "${newkey[@]}" -x509 -days 30 -keyout "$dir/ca.key" -out "$dir/ca.pem" -subj "$1" 2>/dev/null ;;
  server)
    [ $# -eq 3 ] || usage_error "server NAME SUBJECT SAN"
    issue "$1" "$2" "$(printf 'subjectAltName=%s\nextendedKeyUsage=serverAuth' "$3")" ;;
  client)
    [ $# -eq 2 ] || usage_error "client NAME SUBJECT"
    issue "$1" "$2" 'extendedKeyUsage=clientAuth' ;;
  token)
    [ $# -eq 2 ] || usage_error "token NAME PRINCIPAL"
    # Reissued: the old token's line goes, so the old token stops authenticating.
    if [ -f "$dir/$1.token" ] && [ -f "$dir/tokens" ]; then
      old=$(cat "$dir/$1.token")
      awk -v old="$old" '$1 != old' "$dir/tokens" >"$dir/tokens.new"
      mv "$dir/tokens.new" "$dir/tokens"
    fi
    openssl rand -hex 32 >"$dir/$1.token"
    printf '%s %s\n' "$(cat "$dir/$1.token")" "$2" >>"$dir/tokens" ;;
  subject)
    [ $# -eq 1 ] || usage_error "subject NAME"
    openssl x509 -noout -subject -nameopt RFC2253 -in "$dir/$1.pem" | sed 's/^subject= *//' ;;
  *) usage_error "unknown action $action (see --help)" ;;
esac
