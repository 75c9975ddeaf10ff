#!/usr/bin/env bash
# Builds the nupmpc image (deploy/container/Containerfile) on this machine from Debian
# packages only, with no container registry:
#   1. the base image localhost/nupmpc-debian12-base, if missing: a minimal Debian 12 root
#      file system by `mmdebstrap --variant=minbase bookworm` from the Debian mirror this
#      host's apt uses, imported with `podman import`;
#   2. `podman build --pull=never` of the Containerfile on that base, tagged nupmpc:VERSION
#      and nupmpc:latest (VERSION: project(VERSION) of CMakeLists.txt, the server's version).
#
# Usage: deploy/container/build-image.sh [--base-only] [--rebuild-base] [--smoke] [--help]
#   --base-only     only make (or keep) the base image
#   --rebuild-base  make the base image again even if it exists (e.g. for security updates)
#   --smoke         afterwards run deploy/container/run-image-smoke.sh on the new image
# Environment:
#   NUPMPC_CPU_BASELINE   x86-64 psABI level of the binaries (default x86-64-v3, deploy/README.md)
#   JOBS                  parallel compile jobs in the build stage (default 2)
#   NUPMPC_PODMAN_RUNTIME OCI runtime (default: the first of runc, crun that runs a container)
#   NUPMPC_PODMAN_STORAGE podman storage driver, overlay or vfs (default: overlay if it works)
#   NUPMPC_DEBIAN_MIRROR, NUPMPC_DEBIAN_SECURITY_MIRROR  (default: from /etc/apt/sources*)
#
# Sandboxes (cgroup v1, low hard limits, no overlay mounts) are handled, and every work-around
# is printed as it is chosen: see deploy/container/podman-env.sh.
# Needs root (mmdebstrap's root mode, rootful podman storage).
set -euo pipefail
cd "$(dirname "$0")/../.."
self=deploy/container/build-image.sh

base_only=0 rebuild_base=0 smoke=0
for arg in "$@"; do
  case "$arg" in
    --base-only) base_only=1 ;;
    --rebuild-base) rebuild_base=1 ;;
    --smoke) smoke=1 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "$self: unknown argument $arg (see --help)" >&2; exit 2 ;;
  esac
done

say() { echo "build-image: $*"; }
die() { echo "build-image: $*" >&2; exit 1; }

for tool in podman mmdebstrap; do
  command -v "$tool" >/dev/null || die "$tool is missing (apt-get install podman mmdebstrap uidmap runc catatonit)"
done
[ "$(id -u)" -eq 0 ] || die "run as root (mmdebstrap root mode and rootful podman storage)"

base_image=localhost/nupmpc-debian12-base
version=$(sed -n 's/^project(nupmpc VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
[ -n "$version" ] || die "no project(nupmpc VERSION ...) in CMakeLists.txt"
baseline=${NUPMPC_CPU_BASELINE:-x86-64-v3}
jobs=${JOBS:-2}

# --- podman in restricted environments (podman-env.sh says why) ---------------------------
nupmpc_podman_tag=build-image
# shellcheck source=deploy/container/podman-env.sh
. deploy/container/podman-env.sh
nupmpc_podman_setup

# --- 1. the base image -------------------------------------------------------------------
# The host's Debian mirror (deb822 .sources or one-line sources.list), else deb.debian.org.
host_uris=$({ cat /etc/apt/sources.list /etc/apt/sources.list.d/*.sources /etc/apt/sources.list.d/*.list 2>/dev/null || true; } |
  sed -n -e 's/^URIs:[[:space:]]*//p' -e 's/^deb[[:space:]]\+\(\[[^]]*\][[:space:]]\+\)\{0,1\}\([^[:space:]]*\)[[:space:]]\+bookworm.*/\2/p')
mirror=${NUPMPC_DEBIAN_MIRROR:-$(echo "$host_uris" | grep -m1 -E '/debian/?$' || echo http://deb.debian.org/debian)}
security=${NUPMPC_DEBIAN_SECURITY_MIRROR:-$(echo "$host_uris" | grep -m1 -E '/debian-security/?$' || echo http://deb.debian.org/debian-security)}

make_base() {
  local work tarball start old_id
  old_id=$("${podman_base[@]}" image inspect --format '{{.Id}}' "$base_image" 2>/dev/null || true)
  work=$(mktemp -d /var/tmp/nupmpc-base.XXXXXX)
  tarball=$work/rootfs.tar
  start=$(date +%s)
  say "base: mmdebstrap --variant=minbase bookworm from $mirror (+ bookworm-updates, $security bookworm-security)"
  # The dpkg path-excludes stay in the image (/etc/dpkg/dpkg.cfg.d/99mmdebstrap), as in
  # debian:12-slim: later apt-get installs skip documentation too. mmdebstrap removes the
  # package lists and the .deb cache at the end by itself. The merged-usr hook makes the /usr
  # symlinks the way debootstrap (and debian:12-slim) does; without it bookworm's essential
  # set pulls the usrmerge package and with it the whole of perl (47 MB).
  if ! mmdebstrap --variant=minbase --components=main \
        --hook-dir=/usr/share/mmdebstrap/hooks/merged-usr \
        --dpkgopt='path-exclude=/usr/share/man/*' --dpkgopt='path-exclude=/usr/share/info/*' \
        --dpkgopt='path-exclude=/usr/share/doc/*' --dpkgopt='path-include=/usr/share/doc/*/copyright' \
        --dpkgopt='path-exclude=/usr/share/locale/*' --dpkgopt='path-exclude=/usr/share/lintian/*' \
        --aptopt='Acquire::Languages "none"' \
        bookworm "$tarball" \
        "deb $mirror bookworm main" "deb $mirror bookworm-updates main" \
        "deb $security bookworm-security main" >"$work/mmdebstrap.log" 2>&1; then
    tail -n 20 "$work/mmdebstrap.log" >&2
    die "mmdebstrap failed (log: $work/mmdebstrap.log)"
  fi
  say "base: root file system $(( $(stat -c %s "$tarball") / 1048576 )) MB in $(( $(date +%s) - start )) s; podman import"
  "${podman_base[@]}" import --quiet --message "mmdebstrap --variant=minbase bookworm ($mirror)" \
      --change 'CMD ["/bin/bash"]' --change 'ENV LANG=C.UTF-8' \
      "$tarball" "$base_image:latest" >/dev/null
  "${podman_base[@]}" tag "$base_image:latest" "$base_image:bookworm-$(date +%Y%m%d)"
  rm -rf "$work"
  # The base this replaced, if nothing else uses it (images built on it keep it otherwise).
  if [ -n "$old_id" ] && [ "$old_id" != "$("${podman_base[@]}" image inspect --format '{{.Id}}' "$base_image")" ]; then
    "${podman_base[@]}" rmi "$old_id" >/dev/null 2>&1 || true
  fi
}

if [ "$rebuild_base" = 1 ] || ! "${podman_base[@]}" image exists "$base_image:latest"; then
  make_base
else
  say "base: $base_image exists (created $("${podman_base[@]}" image inspect --format '{{.Created}}' "$base_image" | cut -d. -f1); --rebuild-base to refresh)"
fi
nupmpc_podman_runtime "$base_image" || exit 1
runtime=$NUPMPC_PODMAN_RUNTIME
say "OCI runtime: $runtime"
if [ "$base_only" = 1 ]; then
  say "base: $base_image, $(( $("${podman_base[@]}" image inspect --format '{{.Size}}' "$base_image") / 1000000 )) MB"
  exit 0
fi

# --- 2. the image ------------------------------------------------------------------------
revision=$(git rev-parse --short=12 HEAD 2>/dev/null || true)
if [ -n "$revision" ] && [ -n "$(git status --porcelain --untracked-files=no 2>/dev/null)" ]; then
  revision=$revision-dirty
fi
source_url=$(git remote get-url origin 2>/dev/null || true)

# Network: the build stages only run apt-get. Host networking avoids needing a working
# bridge/CNI set-up (iptables, netns), which sandboxes often lack.
# Labels: the Containerfile sets them from the build args, but buildah 1.28 reuses a cached
# LABEL layer when only an ARG's value changed (a new commit or version kept the old
# labels); --label is applied at commit, after the cache, so the values here always win.
say "image: nupmpc:$version (CPU baseline $baseline, -j$jobs, base $base_image, runtime $runtime)"
start=$(date +%s)
"${podman_run[@]}" build --pull=never --layers --network host "${ulimits[@]}" \
  --ignorefile deploy/container/Containerfile.dockerignore \
  --build-arg BASE_IMAGE="$base_image" \
  --build-arg NUPMPC_CPU_BASELINE="$baseline" \
  --build-arg JOBS="$jobs" \
  --build-arg NUPMPC_VERSION="$version" \
  --build-arg NUPMPC_REVISION="$revision" \
  --build-arg NUPMPC_SOURCE="$source_url" \
  --label org.opencontainers.image.version="$version" \
  --label org.opencontainers.image.revision="$revision" \
  --label org.opencontainers.image.source="$source_url" \
  --label io.nupmpc.cpu-baseline="$baseline" \
  -t "nupmpc:$version" -t nupmpc:latest \
  -f deploy/container/Containerfile .
build_s=$(( $(date +%s) - start ))

size=$("${podman_base[@]}" image inspect --format '{{.Size}}' nupmpc:latest)
base_size=$("${podman_base[@]}" image inspect --format '{{.Size}}' "$base_image")
say "built nupmpc:$version and nupmpc:latest in ${build_s} s"
say "image size: $(( size / 1000000 )) MB (base $(( base_size / 1000000 )) MB, target <= 150 MB)"
if [ "$smoke" = 1 ]; then
  echo
  NUPMPC_PODMAN_RUNTIME=$runtime NUPMPC_PODMAN_STORAGE=$NUPMPC_PODMAN_STORAGE \
    exec deploy/container/run-image-smoke.sh "nupmpc:$version"
fi
