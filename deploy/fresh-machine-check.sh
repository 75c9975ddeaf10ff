#!/usr/bin/env bash
# The README's set-up, verbatim, on a truly fresh machine: a minimal Debian 12 root file
# system (mmdebstrap --variant=minbase bookworm: no git, no compiler, no CA certificates, no
# /etc/hosts), entered with chroot (proc, sys, dev mounted; nothing added by hand), this
# checkout's committed HEAD cloned from a local path, then the README's commands as they
# stand in README.md: get the code, deploy/main.sh, deploy/test.sh. Prints each command's exit
# code, wall time and last lines. Not in CI: about 30 minutes on 2 cores.
#   deploy/fresh-machine-check.sh [WORK_DIR]    as root; WORK_DIR default /tmp/nupmpc-fresh
# WORK_DIR/root is the root file system (made anew each run), WORK_DIR/*.log the outputs.
set -euo pipefail
cd "$(dirname "$0")/.."
[ "$(id -u)" -eq 0 ] || { echo "fresh-machine-check: run as root (chroot, mounts)" >&2; exit 2; }
work=$(realpath -m "${1:-/tmp/nupmpc-fresh}")
root=$work/root
say() { echo "== fresh-machine-check: $*"; }

# The README's lines, word for word: the check runs what a user reads.
readme_line() {
  local line
  line=$(grep -E "^    $1" README.md | head -1 | sed -E 's/^    //; s/ +#.*$//')
  [ -n "$line" ] || { echo "fresh-machine-check: README.md has no set-up line starting '$1'" >&2; exit 1; }
  echo "$line"
}
get_packages=$(readme_line "apt-get update")
get_code=$(readme_line "git clone")
main_job=$(readme_line "deploy/main.sh")
test_suite=$(readme_line "deploy/test.sh")
for line in "$get_packages" "$get_code" "$main_job" "$test_suite"; do say "README: $line"; done
[[ "$get_code" == *"<repository URL>"* ]] ||
  { echo "fresh-machine-check: the README's clone line no longer has <repository URL>" >&2; exit 1; }

command -v mmdebstrap >/dev/null || { say "installing mmdebstrap"; apt-get install -y -qq mmdebstrap >/dev/null; }

unmount_all() {
  for m in dev/pts dev sys proc; do mountpoint -q "$root/$m" && umount -l "$root/$m"; done
  return 0
}
trap unmount_all EXIT
unmount_all
rm -rf "$root"
mkdir -p "$work"
say "building a minimal Debian 12 root in $root"
mmdebstrap --quiet --variant=minbase bookworm "$root" http://deb.debian.org/debian
[ ! -e "$root/etc/hosts" ] || { echo "fresh-machine-check: the root has an /etc/hosts" >&2; exit 1; }
mount -t proc proc "$root/proc"
mount -t sysfs sys "$root/sys"
mount --bind /dev "$root/dev"
mount --bind /dev/pts "$root/dev/pts"

# The repository the clone line fetches: this checkout's HEAD, as a bare repository inside
# the root (a local path stands for the URL).
git clone --quiet --bare --no-local . "$root/srv/nupmpc.git"
say "cloning $(git rev-parse --short HEAD) ($(git log -1 --format=%s | cut -c1-60)...)"
clone=${get_code//<repository URL>//srv/nupmpc.git}

# in_root NAME COMMAND: runs COMMAND in the root as a login shell of root would, from the
# clone (or /root before it exists); logs to WORK_DIR/NAME.log, records exit code and time.
results=()
in_root() {
  local name=$1 command=$2 start=$SECONDS code
  say "running in the root: $command"
  set +e
  chroot "$root" /usr/bin/env -i HOME=/root TERM=dumb LANG=C.UTF-8 \
    PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    /bin/bash -c "cd /root && { [ ! -d nupmpc ] || cd nupmpc; } && $command" >"$work/$name.log" 2>&1
  code=$?
  set -e
  local elapsed=$((SECONDS - start))
  results+=("$(printf '%-12s exit %-3d %3d min %02d s  %s' "$name" "$code" $((elapsed / 60)) $((elapsed % 60)) "$command")")
  say "$name: exit $code after $((elapsed / 60)) min $((elapsed % 60)) s; its last lines:"
  tail -n "${3:-5}" "$work/$name.log" | sed 's/^/    /'
  return "$code"
}

status=0
in_root get-code "$get_packages && $clone" 2 || status=1
if [ "$status" -eq 0 ]; then
  in_root main-job "$main_job" 8 || status=1
  in_root test-suite "$test_suite" 14 || status=1
fi
echo
say "summary (logs in $work/)"
printf '    %s\n' "${results[@]}"
exit "$status"
