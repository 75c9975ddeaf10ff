# shellcheck shell=bash
# Sourced by build-image.sh and run-image-smoke.sh: how to call podman on this machine.
# After nupmpc_podman_setup:
#   podman_base  podman with the storage options (image commands: import, inspect, rmi)
#   ulimits      --ulimit options for build and run
#   nupmpc_podman_runtime IMAGE   sets podman_run (podman_base + --runtime R): the first
#                                 runtime that runs a container from IMAGE
#
# Why (each found in a sandbox with cgroup v1 and a hard nofile limit of 20000):
# - ulimits: podman asks the runtime for nofile=1048576 by default; where the hard limit of
#   the calling process is lower, the runtime may not raise it and every container fails
#   ("error setting rlimit type 7: operation not permitted"). We pass what we have, capped.
# - runtime: crun 1.8 refuses a hybrid cgroup v1/v2 host ("cgroups in hybrid mode not
#   supported, drop all controllers from cgroupv2"); runc works. Debian's podman defaults
#   to crun, so we probe runc first.
# - storage: overlay needs the kernel to allow overlay mounts inside this environment; when
#   podman's default storage does not start we use vfs (a full copy per layer: slower, larger
#   on disk, works anywhere) in a storage root of its own, since containers/storage refuses
#   to switch the driver of an existing one.
# Overrides: NUPMPC_PODMAN_RUNTIME=runc|crun, NUPMPC_PODMAN_STORAGE=overlay|vfs.

nupmpc_podman_say() { echo "${nupmpc_podman_tag:-podman-env}: $*"; }

nupmpc_podman_setup() {
  local hard_nofile hard_nproc nofile nproc cgroup_fs storage_choice
  hard_nofile=$(ulimit -Hn); [ "$hard_nofile" = unlimited ] && hard_nofile=1048576
  hard_nproc=$(ulimit -Hu); [ "$hard_nproc" = unlimited ] && hard_nproc=1048576
  nofile=$(( hard_nofile < 65536 ? hard_nofile : 65536 ))
  nproc=$(( hard_nproc < 32768 ? hard_nproc : 32768 ))
  ulimits=(--ulimit "nofile=$nofile:$nofile" --ulimit "nproc=$nproc:$nproc")

  cgroup_fs=$(stat -fc %T /sys/fs/cgroup 2>/dev/null || echo unknown)
  if [ "$cgroup_fs" != cgroup2fs ] && [ -z "${nupmpc_podman_quiet:-}" ]; then
    nupmpc_podman_say "cgroup v1 (/sys/fs/cgroup is $cgroup_fs): runc preferred, ulimits nofile=$nofile nproc=$nproc"
  fi

  storage_choice=${NUPMPC_PODMAN_STORAGE:-}
  if [ -z "$storage_choice" ]; then
    if podman info >/dev/null 2>&1 && [ "$(podman info --format '{{.Store.GraphDriverName}}')" = overlay ]; then
      storage_choice=overlay
    else
      nupmpc_podman_say "podman's default storage does not start (overlay mounts refused?): using vfs"
      storage_choice=vfs
    fi
  fi
  podman_base=(podman)
  if [ "$storage_choice" = vfs ]; then
    podman_base+=(--storage-driver vfs --root /var/lib/containers/storage-vfs --runroot /run/containers/storage-vfs)
    nupmpc_podman_say "storage: vfs in /var/lib/containers/storage-vfs (every layer a full copy)"
  fi
  NUPMPC_PODMAN_STORAGE=$storage_choice
}

nupmpc_podman_runtime() {
  local image=$1 candidate err candidates=(runc crun)
  [ -n "${NUPMPC_PODMAN_RUNTIME:-}" ] && candidates=("$NUPMPC_PODMAN_RUNTIME")
  for candidate in "${candidates[@]}"; do
    command -v "$candidate" >/dev/null || continue
    if err=$("${podman_base[@]}" --runtime "$candidate" run --rm --network none "${ulimits[@]}" \
               --entrypoint /bin/true "$image" 2>&1); then
      # shellcheck disable=SC2034  # used by the scripts that source this file
      podman_run=("${podman_base[@]}" --runtime "$candidate")
      NUPMPC_PODMAN_RUNTIME=$candidate
      return 0
    fi
    nupmpc_podman_say "runtime $candidate cannot run a container here: $(echo "$err" | tail -n 1)"
  done
  nupmpc_podman_say "no OCI runtime runs a container here (apt-get install runc?)" >&2
  return 1
}
