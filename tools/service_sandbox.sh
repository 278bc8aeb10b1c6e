#!/usr/bin/env bash
# A private systemd for tests, on machines whose PID 1 is not systemd (containers, CI runners):
# /lib/systemd/systemd runs as PID 1 of new PID, mount, cgroup and UTS namespaces, in a cgroup of
# its own below this process's. It must not touch the machine it runs on, so inside
#   - /run, /tmp and /var/tmp are empty tmpfs (SANDBOX_KEEP: directories under /tmp to keep
#     visible, bound back at their paths), /etc and /usr are overlays whose writes go to
#     STATE_DIR (a unit, a user, an `install --prefix /usr` made inside never reach the real ones);
#   - the manager loads units ONLY from /run/poise-sandbox/units (SYSTEMD_UNIT_PATH): the
#     targets every service depends on are empty stand-ins there, so nothing of the machine's
#     boot (sysinit.target: systemd-tmpfiles-setup, which empties /tmp, journald, udev, sysctl,
#     ...) can ever start. Put the units to test into that directory.
# Units run there with every sandboxing option of the real thing (namespaces, seccomp, device
# cgroup, ...). Used by tools/test_service.sh (docs/DEPLOY.md "The sandbox and the watchdog,
# tested").
#   tools/service_sandbox.sh boot STATE_DIR       boots it; prints its PID (this namespace) when it runs
#   tools/service_sandbox.sh exec STATE_DIR CMD... runs CMD inside (systemctl, systemd-analyze, ...)
#   tools/service_sandbox.sh halt STATE_DIR       kills it and removes its cgroups
# Needs root, unshare and nsenter (util-linux), cgroups mounted under /sys/fs/cgroup, overlayfs.
# Exit 77 from boot: this machine cannot host it (the reason on stderr).
set -euo pipefail
cmd="${1:-}"
state="${2:-}"
[[ -n "$cmd" && -n "$state" ]] || { echo "usage: $0 boot|exec|halt STATE_DIR [CMD...]" >&2; exit 2; }
cannot() { echo "service_sandbox: cannot boot a private systemd here: $*" >&2; exit 77; }

inside() {  # runs "$@" in the sandbox's namespaces, talking to its manager on the private bus
  local pid
  pid="$(cat "$state/pid")"
  nsenter -t "$pid" -m -p -u env DBUS_SYSTEM_BUS_ADDRESS=unix:path=/run/systemd/private "$@"
}

case "$cmd" in
boot)
  [[ "$(id -u)" -eq 0 ]] || cannot "needs root"
  for tool in unshare nsenter; do
    command -v "$tool" >/dev/null 2>&1 || cannot "$tool is missing (util-linux)"
  done
  [[ -x /lib/systemd/systemd ]] || cannot "/lib/systemd/systemd is missing (Debian systemd)"
  grep -q overlay /proc/filesystems || modprobe overlay 2>/dev/null || true
  grep -q overlay /proc/filesystems || cannot "no overlayfs in this kernel"
  grep -q ' /sys/fs/cgroup ' /proc/mounts || cannot "no cgroup file system at /sys/fs/cgroup"
  mkdir -p "$state"
  state="$(cd "$state" && pwd)"
  mkdir -p "$state/etc-up" "$state/etc-work" "$state/usr-up" "$state/usr-work"
  name="poise-sandbox-$$"
  : >"$state/cgroups"
  # A cgroup below ours in every hierarchy: the manager's cgroup namespace starts there, so what it
  # creates (init.scope, system.slice, ...) stays below it and goes away with it.
  if [[ "$(stat -f -c %T /sys/fs/cgroup)" == cgroup2fs ]]; then
    cur="$(grep '^0::' /proc/self/cgroup | cut -d: -f3)"
    mkdir "/sys/fs/cgroup$cur/$name" || cannot "cannot create a cgroup below /sys/fs/cgroup$cur"
    echo "/sys/fs/cgroup$cur/$name" >>"$state/cgroups"
  else
    while IFS=: read -r _ controllers path; do
      dir=""
      case "$controllers" in
        "") dir=/sys/fs/cgroup/unified ;;
        name=systemd) dir=/sys/fs/cgroup/systemd ;;
        name=*) continue ;;
        *) dir="/sys/fs/cgroup/$controllers" ;;
      esac
      [[ -d "$dir" ]] || continue
      mkdir "$dir$path/$name" || cannot "cannot create a cgroup below $dir$path"
      if [[ -f "$dir$path/cpuset.cpus" ]]; then  # cgroup v1 cpuset: a new group starts empty
        cat "$dir$path/cpuset.cpus" >"$dir$path/$name/cpuset.cpus"
        cat "$dir$path/cpuset.mems" >"$dir$path/$name/cpuset.mems"
      fi
      if [[ -f "$dir$path/$name/cpu.rt_runtime_us" ]]; then
        # a kernel with RT group scheduling (CONFIG_RT_GROUP_SCHED, cgroup v1): a new group has no
        # real-time budget, so no SCHED_FIFO inside. Give it as much of its parent's as it may
        # have (the services of a host without such groups run with the whole of it).
        budget="$(cat "$dir$path/cpu.rt_runtime_us")"
        while (( budget >= 10000 )) && ! echo "$budget" >"$dir$path/$name/cpu.rt_runtime_us" 2>/dev/null; do
          budget=$((budget / 2))
        done
        (( budget >= 10000 )) \
          || echo "service_sandbox: warning: no real-time budget for $dir$path/$name: SCHED_FIFO will fail inside" >&2
      fi
      echo "$dir$path/$name" >>"$state/cgroups"
    done </proc/self/cgroup
  fi
  cat >"$state/inner.sh" <<'INNER'
set -euo pipefail
state="$1"
mount -t proc proc /proc
# the cgroup file systems again, seen from the new cgroup namespace (their root is ours)
if [[ "$(stat -f -c %T /sys/fs/cgroup)" == cgroup2fs ]]; then
  umount /sys/fs/cgroup
  mount -t cgroup2 cgroup2 /sys/fs/cgroup
else
  mapfile -t subs < <(awk '$2 ~ "^/sys/fs/cgroup/" {print $2 " " $3 " " $4}' /proc/mounts)
  for s in "${subs[@]}"; do umount "${s%% *}"; done
  umount /sys/fs/cgroup
  mount -t tmpfs -o mode=755 tmpfs /sys/fs/cgroup
  for s in "${subs[@]}"; do
    read -r dir type opts <<<"$s"
    mkdir -p "$dir"
    if [[ "$type" == cgroup2 ]]; then
      mount -t cgroup2 cgroup2 "$dir"
    else
      mount -t cgroup -o "$(tr ',' '\n' <<<"$opts" | grep -Ev '^(rw|ro|relatime|nosuid|nodev|noexec)$' | paste -sd,)" cgroup "$dir"
    fi
  done
fi
mount -t tmpfs -o mode=755 tmpfs /run
mount -t overlay overlay -o "lowerdir=/etc,upperdir=$state/etc-up,workdir=$state/etc-work" /etc
mount -t overlay overlay -o "lowerdir=/usr,upperdir=$state/usr-up,workdir=$state/usr-work" /usr
# empty /tmp and /var/tmp, with the directories to keep bound back
keep=()
for d in ${SANDBOX_KEEP:-}; do
  mkdir -p "/run/poise-sandbox/keep/${#keep[@]}"
  mount --bind "$d" "/run/poise-sandbox/keep/${#keep[@]}"
  keep+=("$d")
done
mount -t tmpfs -o mode=1777 tmpfs /tmp
mount -t tmpfs -o mode=1777 tmpfs /var/tmp
for i in "${!keep[@]}"; do
  mkdir -p "${keep[$i]}"
  mount --bind "/run/poise-sandbox/keep/$i" "${keep[$i]}"
done
units=/run/poise-sandbox/units
mkdir -p "$units"
printf '[Unit]\nDescription=poise service sandbox\nDefaultDependencies=no\n' >"$units/poise-sandbox.target"
for t in sysinit basic shutdown network network-online; do  # what services order against: empty
  printf '[Unit]\nDescription=%s (empty in the sandbox)\nDefaultDependencies=no\n' "$t" >"$units/$t.target"
done
printf '[Unit]\nDescription=System Slice\nDefaultDependencies=no\n' >"$units/system.slice"
exec env container=poise-sandbox SYSTEMD_UNIT_PATH="$units" /lib/systemd/systemd --system \
  --unit=poise-sandbox.target --log-target=console
INNER
  (
    while read -r c; do echo "$BASHPID" >"$c/cgroup.procs"; done <"$state/cgroups"
    export SANDBOX_KEEP="${SANDBOX_KEEP:-}"
    exec unshare --cgroup --pid --fork --mount --uts --propagation private bash "$state/inner.sh" "$state"
  ) >"$state/systemd.log" 2>&1 &
  outer=$!
  echo "$outer" >"$state/outer.pid"
  pid=""
  for _ in $(seq 1 100); do  # the manager is unshare's only child (PID 1 inside)
    if [[ "$(cat "/proc/$outer/comm" 2>/dev/null)" == unshare ]]; then
      pid="$(awk '{print $1}' "/proc/$outer/task/$outer/children" 2>/dev/null)" || true
      [[ -n "$pid" ]] && break
    fi
    kill -0 "$outer" 2>/dev/null || break
    sleep 0.1
  done
  [[ -n "$pid" ]] || { cat "$state/systemd.log" >&2; "$0" halt "$state" || true; cannot "the namespaces could not be set up"; }
  echo "$pid" >"$state/pid"
  for _ in $(seq 1 300); do  # bounded: 30 s
    s="$(inside systemctl is-system-running 2>/dev/null || true)"
    if [[ "$s" == running || "$s" == degraded ]]; then
      echo "$pid"
      exit 0
    fi
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  cat "$state/systemd.log" >&2
  "$0" halt "$state" || true
  cannot "systemd did not come up in 30 s"
  ;;
exec)
  shift 2
  inside "$@"
  ;;
halt)
  if [[ -f "$state/pid" ]]; then
    kill -KILL "$(cat "$state/pid")" 2>/dev/null || true  # PID 1 gone: the kernel ends its namespace
  fi
  if [[ -f "$state/outer.pid" ]]; then
    for _ in $(seq 1 100); do kill -0 "$(cat "$state/outer.pid")" 2>/dev/null || break; sleep 0.1; done
  fi
  if [[ -f "$state/cgroups" ]]; then
    for c in $(cat "$state/cgroups"); do
      [[ -d "$c" ]] || continue
      for _ in $(seq 1 50); do  # empty once the processes are reaped
        find "$c" -depth -type d -exec rmdir {} + 2>/dev/null || true
        [[ -d "$c" ]] || break
        sleep 0.1
      done
      [[ ! -d "$c" ]] || echo "service_sandbox: warning: $c could not be removed" >&2
    done
  fi
  rm -f "$state/pid" "$state/outer.pid" "$state/cgroups"
  ;;
*)
  echo "usage: $0 boot|exec|halt STATE_DIR [CMD...]" >&2
  exit 2
  ;;
esac
