#!/usr/bin/env bash
# deploy/rollout.sh against two hosts made of namespaces, each with its own systemd
# (docs/services.md, "How the rollout is tested").
#
#   tests/deploy/rollout_test.sh [--build-dir DIR]     (default: the source tree's build/)
#
# Host "a" (10.213.77.1) runs the coordinator, host "b" (10.213.77.2) a node. Each host is a
# network namespace on a bridge, a PID, mount and cgroup namespace whose PID 1 is a real
# /lib/systemd/systemd, and overlays of /etc, /var, /opt, /home and /root (its own files);
# that systemd runs journald, dbus, logind and the sshd rollout.sh logs in to. The test then
# installs, checks files, permissions and running services (a real user manager and an Xvfb
# display stand in for host b's graphical login), kills the services to see them restart,
# installs again (nothing changes), adds and removes a role, uninstalls, and checks that the
# hosts' /etc and /opt are as before. Exit 77 (skipped) only where network namespaces cannot
# be made.
#
# shellcheck disable=SC2016 # commands in single quotes are for the hosts' shells to expand
set -euo pipefail

readonly LAN_PREFIX=10.213.77
readonly ADDR_A=$LAN_PREFIX.1 ADDR_B=$LAN_PREFIX.2 ADDR_LAN=$LAN_PREFIX.254
readonly NODE_ID=5 STATUS_PORT=8080
readonly HOST_UP_TIMEOUT_S=60 EVENT_TIMEOUT_S=30

# --- Inside a host's namespaces: its own files, then systemd as PID 1. --------------------------
if [ "${1:-}" = --host-init ]; then
  dir=$2
  exec >>"$dir/systemd.log" 2>&1 </dev/null
  mount -t cgroup2 cgroup2 /sys/fs/cgroup
  for name in etc var opt home root; do
    mount -t overlay overlay \
      -o "lowerdir=/$name,upperdir=$dir/upper/$name,workdir=$dir/work/$name" "/$name"
  done
  mount -t tmpfs -o mode=0755 tmpfs /run
  mkdir /run/sandtable-test
  mount --bind "$dir/run" /run/sandtable-test
  mount -t tmpfs -o mode=1777 tmpfs /tmp
  mount -t tmpfs -o mode=1777 tmpfs /dev/shm
  export container=sandtable-test
  exec /lib/systemd/systemd --unit=sandtable-test-host.target
fi

SOURCE_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
SELF=$SOURCE_DIR/tests/deploy/rollout_test.sh
ROLLOUT=$SOURCE_DIR/deploy/rollout.sh
BUILD_DIR=$SOURCE_DIR/build
while [ $# -gt 0 ]; do
  case "$1" in
    --build-dir) BUILD_DIR=$2; shift 2 ;;
    *) echo "usage: $0 [--build-dir DIR]" >&2; exit 2 ;;
  esac
done
COORDINATOR_BIN=$BUILD_DIR/coordinator/sandtable-coordinator

STARTED=$SECONDS
step() { echo "== [$((SECONDS - STARTED)) s] $*"; }
ok() { echo "   ok: $*"; }
skip() {
  echo "SKIPPED: $*"
  exit 77
}
fail() {
  echo "FAIL: $*" >&2
  exit 1
}
show() { printf '%s\n' "$1" | while IFS= read -r line; do echo "   | $line"; done; }

# --- Preconditions ------------------------------------------------------------------------------
[ "$(id -u)" -eq 0 ] || skip "needs root to create network namespaces (ip netns add)"
for tool in ip unshare ssh ssh-keygen python3 runuser Xvfb systemd-analyze dbus-daemon; do
  command -v "$tool" >/dev/null || fail "$tool is missing (deploy/install-deps.sh)"
done
[ -x /usr/sbin/sshd ] || fail "/usr/sbin/sshd is missing: install openssh-server (deploy/install-deps.sh)"
[ -x /lib/systemd/systemd ] || fail "/lib/systemd/systemd is missing (package systemd)"
for program in "$COORDINATOR_BIN" "$BUILD_DIR/node/sandtable-node"; do
  [ -x "$program" ] || fail "$program is missing: build it, or pass --build-dir"
done

WORK=$(mktemp -d /tmp/sandtable-rollout-test.XXXXXX)
NS_LAN=sandtable-rollout-$$-lan
declare -A NS=([a]=sandtable-rollout-$$-a [b]=sandtable-rollout-$$-b)
declare -A ADDR=([a]=$ADDR_A [b]=$ADDR_B)
declare -A INIT_PID=() CGROUP=() MASTER_PID=()

cleanup() {
  local rc=$? h
  trap - EXIT
  for h in "${!MASTER_PID[@]}"; do
    kill "${MASTER_PID[$h]}" 2>/dev/null || true
    wait "${MASTER_PID[$h]}" 2>/dev/null || true
  done
  for h in "${!INIT_PID[@]}"; do
    # The host's PID 1 (unshare's child), which ends its namespace; unshare reaps it and exits.
    local init=""
    read -r init _ <"/proc/${INIT_PID[$h]}/task/${INIT_PID[$h]}/children" 2>/dev/null || true
    if [ -n "$init" ]; then
      kill -KILL "$init" 2>/dev/null || true
    else
      kill -KILL "${INIT_PID[$h]}" 2>/dev/null || true
    fi
    wait "${INIT_PID[$h]}" 2>/dev/null || true
  done
  for h in "${!CGROUP[@]}"; do
    # Emptied as the namespace's processes die; children before parents.
    local deadline=$((SECONDS + 10))
    while [ -d "${CGROUP[$h]}" ] && [ $SECONDS -lt $deadline ]; do
      find "${CGROUP[$h]}" -depth -type d -exec rmdir {} + 2>/dev/null || sleep 0.1
    done
    [ ! -d "${CGROUP[$h]}" ] || echo "cleanup: could not remove ${CGROUP[$h]}" >&2
  done
  for h in "${NS[@]}" "$NS_LAN"; do ip netns delete "$h" 2>/dev/null || true; done
  if [ $rc -ne 0 ] && [ $rc -ne 77 ]; then
    for h in a b; do
      [ -f "$WORK/hosts/$h/systemd.log" ] || continue
      echo "--- host $h: its systemd's output (last lines)" >&2
      tail -n 20 "$WORK/hosts/$h/systemd.log" >&2
    done
  fi
  case "$WORK" in /tmp/sandtable-rollout-test.*) rm -rf "$WORK" ;; esac
  exit $rc
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# --- Network: a bridge in the operator's namespace, one veth to each host. -----------------------
step "network namespaces"
ip netns add "$NS_LAN" 2>/dev/null || skip "cannot create a network namespace (ip netns add)"
ip netns add "${NS[a]}" && ip netns add "${NS[b]}"
ip -n "$NS_LAN" link add br0 type bridge 2>/dev/null || skip "no bridge device in this kernel"
ip -n "$NS_LAN" link set lo up
ip -n "$NS_LAN" link set br0 up
ip -n "$NS_LAN" addr add "$ADDR_LAN/24" dev br0
for h in a b; do
  ip -n "$NS_LAN" link add "veth-$h" type veth peer name eth0 netns "${NS[$h]}" 2>/dev/null ||
    skip "no veth devices in this kernel"
  ip -n "$NS_LAN" link set "veth-$h" master br0 up
  ip -n "${NS[$h]}" link set lo up
  ip -n "${NS[$h]}" addr add "${ADDR[$h]}/24" dev eth0
  ip -n "${NS[$h]}" link set eth0 up
done
ok "operator $ADDR_LAN, host a $ADDR_A, host b $ADDR_B"

# --- Keys: the hosts' sshd keys, the operator's client key. --------------------------------------
ssh-keygen -q -t ed25519 -N "" -C rollout-test-client -f "$WORK/client_key"
: >"$WORK/known_hosts"
for h in a b; do
  run=$WORK/hosts/$h/run
  mkdir -p "$run"
  ssh-keygen -q -t ed25519 -N "" -C "rollout-test-host-$h" -f "$run/host_key"
  cp "$WORK/client_key.pub" "$run/authorized_keys"
  echo "${ADDR[$h]} $(cut -d' ' -f1,2 "$run/host_key.pub")" >>"$WORK/known_hosts"
  cat >"$run/sshd_config" <<EOF
ListenAddress ${ADDR[$h]}
HostKey /run/sandtable-test/host_key
AuthorizedKeysFile /run/sandtable-test/authorized_keys
PermitRootLogin prohibit-password
PasswordAuthentication no
KbdInteractiveAuthentication no
UsePAM no
PidFile none
Subsystem sftp /usr/lib/openssh/sftp-server
EOF
done
SSH=(ssh -o BatchMode=yes -o ConnectTimeout=5 -o IdentitiesOnly=yes -i "$WORK/client_key"
  -o "UserKnownHostsFile=$WORK/known_hosts" -o StrictHostKeyChecking=yes)
# The test's own commands share one connection per host (rollout.sh makes its own), held by a
# master the test starts (and ends) itself.
SSH_SHARED=("${SSH[@]}" -o ControlMaster=no -o "ControlPath=$WORK/ssh-%h")
ROLLOUT_SSH=(--ssh-user root -i "$WORK/client_key" -o "UserKnownHostsFile=$WORK/known_hosts"
  -o StrictHostKeyChecking=yes --connect-timeout 5)

# Runs a shell command as root on host a or b, over ssh from the operator's namespace.
on() { ip netns exec "$NS_LAN" "${SSH_SHARED[@]}" "root@${ADDR[$1]}" "$2"; }
# Runs deploy/rollout.sh from the operator's namespace.
rollout() { ip netns exec "$NS_LAN" "$ROLLOUT" "$@"; }

# GET of the coordinator's status page from the operator's namespace, with the token if not
# empty: prints the document on 200, else the HTTP status code.
get_status() {  # TOKEN
  ip netns exec "$NS_LAN" python3 - "http://$ADDR_A:$STATUS_PORT/status" "$1" <<'PY'
import sys, urllib.error, urllib.request
request = urllib.request.Request(sys.argv[1])
if sys.argv[2]:
    request.add_header("Authorization", "Bearer " + sys.argv[2])
try:
    print(urllib.request.urlopen(request, timeout=5).read().decode())
except urllib.error.HTTPError as e:
    print(e.code)
PY
}

# Waits until a command succeeds, at most SECONDS.
wait_for() {  # SECONDS WHAT COMMAND...
  local limit=$1 what=$2 deadline=$((SECONDS + $1))
  shift 2
  until "$@" >/dev/null 2>&1; do
    [ $SECONDS -lt $deadline ] || fail "$what: not within $limit s"
    sleep 0.2
  done
}

# --- Hosts: namespaces with systemd as PID 1. ------------------------------------------------------
if [ "$(stat -fc %T /sys/fs/cgroup)" = cgroup2fs ]; then
  CGROUP_ROOT=/sys/fs/cgroup
elif [ "$(stat -fc %T /sys/fs/cgroup/unified 2>/dev/null)" = cgroup2fs ]; then
  CGROUP_ROOT=/sys/fs/cgroup/unified
else
  fail "no cgroup v2 hierarchy (neither /sys/fs/cgroup nor /sys/fs/cgroup/unified) for the hosts' systemd"
fi

step "hosts: systemd as PID 1 of a namespace each, with sshd"
for h in a b; do
  dir=$WORK/hosts/$h
  for name in etc var opt home root; do mkdir -p "$dir/upper/$name" "$dir/work/$name"; done
  mkdir -p "$dir/upper/etc/systemd/system"
  cat >"$dir/upper/etc/systemd/system/sandtable-test-host.target" <<'EOF'
[Unit]
Description=rollout test host: journal, bus, logins and sshd
Requires=systemd-journald.socket dbus.socket systemd-logind.service sandtable-test-sshd.service
After=systemd-journald.socket dbus.socket systemd-logind.service sandtable-test-sshd.service
EOF
  cat >"$dir/upper/etc/systemd/system/sandtable-test-sshd.service" <<'EOF'
[Unit]
Description=sshd of the rollout test host
[Service]
ExecStart=/usr/sbin/sshd -D -e -f /run/sandtable-test/sshd_config
RuntimeDirectory=sshd
RuntimeDirectoryMode=0755
EOF
  CGROUP[$h]=$CGROUP_ROOT/sandtable-rollout-test-$$-$h
  mkdir "${CGROUP[$h]}"
  # The subshell joins the host's cgroup first: the cgroup namespace is rooted there.
  (
    echo "$BASHPID" >"${CGROUP[$h]}/cgroup.procs"
    exec ip netns exec "${NS[$h]}" unshare --cgroup --mount --pid --fork --kill-child \
      --propagation private --mount-proc "$SELF" --host-init "$dir" >>"$dir/systemd.log" 2>&1
  ) &
  INIT_PID[$h]=$!
done
for h in a b; do
  wait_for "$HOST_UP_TIMEOUT_S" "host $h: ssh login (see its systemd's output below)" on "$h" true
  ip netns exec "$NS_LAN" "${SSH[@]}" -M -N -o "ControlPath=$WORK/ssh-%h" "root@${ADDR[$h]}" &
  MASTER_PID[$h]=$!
  wait_for "$EVENT_TIMEOUT_S" "host $h: the test's shared ssh connection" test -S "$WORK/ssh-${ADDR[$h]}"
  ok "host $h: $(on "$h" 'echo "PID 1 is $(cat /proc/1/comm), $(systemctl is-system-running)"')"
done

# --- The site: CURVE keys, status token, site file, unit file. ------------------------------------
SITE=$WORK/site
mkdir -p "$SITE/keys"
"$COORDINATOR_BIN" --generate-curve-keys "$SITE/keys/site.keys" >/dev/null
(umask 077 && head -c 48 /dev/urandom | base64 | tr -dc 'A-Za-z0-9' >"$SITE/keys/status.token")
TOKEN=$(cat "$SITE/keys/status.token")
cat >"$SITE/site.json" <<EOF
{
  "format": "sandtable.site_config",
  "version": 1,
  "coordinator": {"host": "$ADDR_A", "requests_port": 7000, "events_port": 7001},
  "curve_keys": "keys/site.keys",
  "status": {"listen": "0.0.0.0:$STATUS_PORT", "token_file": "keys/status.token"},
  "heartbeat_ms": 100
}
EOF
cat >"$SITE/unit-$NODE_ID.json" <<EOF
{
  "format": "sandtable.unit_config",
  "version": 1,
  "id": $NODE_ID,
  "bind": "tcp://*:7100",
  "projector": "window:0:windowed:320x240",
  "node_flags": {"render-max-fps": 2}
}
EOF
INSTALL=(--build-dir "$BUILD_DIR" --site-config "$SITE/site.json" --coordinator "$ADDR_A"
  --unit-config "$ADDR_B=$SITE/unit-$NODE_ID.json" "${ROLLOUT_SSH[@]}")

# A host's /etc and /opt as it sees them: every entry's type, mode and owner, every file's size,
# and the content of every file in /etc; less the backups shadow's tools keep (passwd- ...).
snapshot() {  # HOST
  on "$1" 'backups="^/etc/(passwd|group|shadow|gshadow|subuid|subgid)- "
    { find /etc /opt ! -type f -printf "%p %y %m %u:%g %l\n"
      find /etc /opt -type f -printf "%p %m %u:%g %s\n"
      find /etc -type f -exec sha256sum {} + | sed "s/^\([0-9a-f]*\)  \(.*\)/\2 \1/"
    } | grep -vE "$backups" | sort'
}
snapshot a >"$WORK/a.before"

# --- Usage errors --------------------------------------------------------------------------------
step "clear errors: a missing file, an unreachable host"
set +e
out=$(rollout install --build-dir "$BUILD_DIR" --site-config "$SITE/nope.json" --coordinator "$ADDR_A" \
  "${ROLLOUT_SSH[@]}" "$ADDR_A" 2>&1)
rc=$?
set -e
if [ $rc -ne 2 ] || [[ "$out" != *"--site-config $SITE/nope.json: no such readable file"* ]]; then
  fail "missing site file: exit $rc, said: $out"
fi
ok "missing site file: exit 2, \"$out\""
set +e
out=$(rollout status "${ROLLOUT_SSH[@]}" --connect-timeout 2 "$LAN_PREFIX.9" 2>&1)
rc=$?
set -e
if [ $rc -ne 1 ] || [[ "$out" != *"[$LAN_PREFIX.9] error: cannot log in over ssh as root"* ]]; then
  fail "unreachable host: exit $rc, said: $out"
fi
ok "unreachable host: exit 1, \"$(grep -m1 'error:' <<<"$out")\""

# --- Install, first: the node's host has no kiosk user yet. -------------------------------------
step "install: host b has no user 'sandtable' yet"
set +e
out=$(rollout install "${INSTALL[@]}" "$ADDR_A" "$ADDR_B" 2>&1)
rc=$?
set -e
show "$out"
[ $rc -eq 1 ] || fail "install without the node's user: exit $rc, not 1"
[[ "$out" == *"[$ADDR_B] error: user 'sandtable' does not exist"* ]] || fail "no error naming the missing user"
[[ "$out" == *"rollout: install failed on 1 of 2 hosts: $ADDR_B"* ]] || fail "no summary naming host b"
on a 'systemctl is-active --quiet sandtable-coordinator.service' ||
  fail "host a: the coordinator is not running after the first install"
ok "host a installed, host b refused with the reason"

# The site's setup of host b: its kiosk user (the display manager's automatic login).
on b 'useradd --create-home --shell /bin/bash sandtable'
snapshot b >"$WORK/b.before"

step "install: both hosts"
out=$(rollout install "${INSTALL[@]}" "$ADDR_A" "$ADDR_B" 2>&1) || fail "install: $out"
show "$out"
[[ "$out" == *"[$ADDR_A] sandtable-coordinator.service: unchanged, running"* ]] ||
  fail "host a: the second install restarted or changed the coordinator"
[[ "$out" == *"[$ADDR_B] sandtable-node.service: enabled; starts with sandtable's graphical session (sandtable is not logged in now)"* ]] ||
  fail "host b: the node's state after install is not reported"

step "files and permissions"
# Checks a path's type, mode and owner on a host: "TYPE MODE USER:GROUP".
expect_stat() {  # HOST PATH EXPECTED
  local got
  got=$(on "$1" "stat -c '%F %a %U:%G' '$2' 2>&1") || true
  [ "$got" = "$3" ] || fail "host $1: $2 is '$got', not '$3'"
}
for h in a b; do
  expect_stat "$h" /opt/sandtable "directory 755 root:root"
  expect_stat "$h" /etc/sandtable "directory 750 root:sandtable"
  expect_stat "$h" /etc/sandtable/site.json "regular file 640 root:sandtable"
  expect_stat "$h" /etc/sandtable/sandtable.env "regular file 640 root:sandtable"
  expect_stat "$h" /etc/sandtable/keys "directory 700 sandtable:sandtable"
  expect_stat "$h" /etc/sandtable/keys/site.keys "regular file 600 sandtable:sandtable"
  expect_stat "$h" /var/lib/sandtable "directory 750 sandtable:sandtable"
  on "$h" 'cmp -s /etc/sandtable/keys/site.keys -' <"$SITE/keys/site.keys" ||
    fail "host $h: site.keys differs from the site's"
done
expect_stat a /opt/sandtable/bin/sandtable-coordinator "regular file 755 root:root"
expect_stat a /etc/sandtable/keys/status.token "regular file 600 sandtable:sandtable"
expect_stat a /etc/systemd/system/sandtable-coordinator.service "regular file 644 root:root"
expect_stat b /opt/sandtable/bin/sandtable-node "regular file 755 root:root"
expect_stat b /etc/sandtable/unit.json "regular file 640 root:sandtable"
expect_stat b /etc/systemd/user/sandtable-node.service "regular file 644 root:root"
expect_stat b /etc/systemd/user/sandtable-kiosk-session.target "regular file 644 root:root"
on a '! test -e /opt/sandtable/bin/sandtable-node && ! test -e /etc/systemd/user/sandtable-node.service' ||
  fail "host a got the node"
on b '! test -e /etc/sandtable/keys/status.token && ! test -e /opt/sandtable/bin/sandtable-coordinator' ||
  fail "host b got the coordinator's program or its status token"
[ "$(on a 'getent passwd sandtable | cut -d: -f6,7')" = /var/lib/sandtable:/usr/sbin/nologin ] ||
  fail "host a: sandtable is not the system user install creates"
on b 'test "$(readlink /etc/systemd/user/graphical-session.target.wants/sandtable-node.service)" = /etc/systemd/user/sandtable-node.service' ||
  fail "host b: the node is not enabled for graphical-session.target"
ok "programs 755 root, configuration 640 root:sandtable, keys 600 and their folder 700 sandtable, each host only what its role needs"

step "systemd-analyze verify, on the hosts"
out=$(on a 'systemd-analyze verify /etc/systemd/system/sandtable-coordinator.service 2>&1') ||
  fail "host a: systemd-analyze verify: $out"
[ -z "$out" ] || fail "host a: systemd-analyze verify warns: $out"
# The user is not logged in: a runtime folder of its own for the check.
out=$(on b 'runuser -u sandtable -- sh -c "export XDG_RUNTIME_DIR=\$(mktemp -d) &&
  systemd-analyze --user verify /etc/systemd/user/sandtable-node.service \
    /etc/systemd/user/sandtable-kiosk-session.target 2>&1; rc=\$?; rm -rf \$XDG_RUNTIME_DIR; exit \$rc"') ||
  fail "host b: systemd-analyze --user verify: $out"
[ -z "$out" ] || fail "host b: systemd-analyze --user verify warns: $out"
ok "sandtable-coordinator.service (system), sandtable-node.service and sandtable-kiosk-session.target (user): no findings"

step "host a: the coordinator runs as a system service"
[ "$(on a 'systemctl is-enabled sandtable-coordinator.service')" = enabled ] || fail "not enabled"
COORDINATOR_PID=$(on a 'systemctl show -p MainPID --value sandtable-coordinator.service')
[ "$(on a "ps -o user= -p $COORDINATOR_PID")" = sandtable ] || fail "the coordinator does not run as sandtable"
on a "ss -Hltn | grep -q ':7000 ' && ss -Hltn | grep -q ':7001 ' && ss -Hltn | grep -q ':$STATUS_PORT '" ||
  fail "the coordinator does not listen on 7000, 7001, $STATUS_PORT"
on a "journalctl -q -o cat -u sandtable-coordinator.service | grep -q '\"ready\":\"sandtable-coordinator\"'" ||
  fail "no ready line in journalctl -u sandtable-coordinator"
status_code=$(get_status "")
[ "$status_code" = 401 ] || fail "the status page without the token answered $status_code, not 401"
ok "enabled, active, pid $COORDINATOR_PID as sandtable, listening on 7000, 7001, $STATUS_PORT; status page 401 without the token"

step "host b: the kiosk user logs in; the node starts with the graphical session"
# What a display manager and the session's start script do (docs/services.md): the user's
# manager starts, an X server runs, DISPLAY goes into the manager, the session target starts.
on b 'set -e
  uid=$(id -u sandtable)
  systemctl start "user@$uid.service"
  as_user() { runuser -u sandtable -- env XDG_RUNTIME_DIR="/run/user/$uid" "$@"; }
  as_user systemd-run --user --quiet --unit=rollout-test-xvfb /usr/bin/Xvfb :7 -screen 0 640x480x24 -nolisten tcp
  deadline=$((SECONDS + 20))
  until [ -S /tmp/.X11-unix/X7 ]; do
    [ $SECONDS -lt $deadline ] || { echo "Xvfb did not start"; exit 1; }
    sleep 0.1
  done
  as_user systemctl --user set-environment DISPLAY=:7
  as_user systemctl --user start sandtable-kiosk-session.target'
NODE_CTL='runuser -u sandtable -- env XDG_RUNTIME_DIR=/run/user/$(id -u sandtable) systemctl --user'
node_ready() {
  local pid
  pid=$(on b "$NODE_CTL show -p MainPID --value sandtable-node.service")
  [ "$pid" != 0 ] && on b "journalctl -q -o cat _PID=$pid | grep -q '\"ready\":\"sandtable-node\"'"
}
wait_for "$EVENT_TIMEOUT_S" "host b: the node's ready line" node_ready
NODE_PID=$(on b "$NODE_CTL show -p MainPID --value sandtable-node.service")
[ "$(on b "ps -o user= -p $NODE_PID")" = sandtable ] || fail "the node does not run as sandtable"
window=$(on b "journalctl -q -o cat _PID=$NODE_PID | grep -m1 'window:0:windowed'") ||
  fail "the node did not open its window on the session's display"
ok "node pid $NODE_PID as sandtable in the user manager; journal: ${window#*] }"

step "the node registers with the coordinator across hosts (CURVE)"
member_listed() {
  get_status "$TOKEN" | python3 -c "import json, sys
sys.exit(0 if any(m['node_id'] == $NODE_ID for m in json.load(sys.stdin)['members']) else 1)"
}
wait_for "$EVENT_TIMEOUT_S" "node $NODE_ID in the coordinator's /status members" member_listed
ok "GET http://$ADDR_A:$STATUS_PORT/status with the token lists node $NODE_ID"

step "Restart=on-failure: SIGKILL each service"
on a "kill -KILL $COORDINATOR_PID"
coordinator_restarted() {
  local pid
  pid=$(on a 'systemctl show -p MainPID --value sandtable-coordinator.service')
  [ "$pid" != 0 ] && [ "$pid" != "$COORDINATOR_PID" ] &&
    on a 'systemctl is-active --quiet sandtable-coordinator.service'
}
wait_for "$EVENT_TIMEOUT_S" "host a: the coordinator restarted" coordinator_restarted
COORDINATOR_PID=$(on a 'systemctl show -p MainPID --value sandtable-coordinator.service')
on b "kill -KILL $NODE_PID"
node_restarted() {
  local pid
  pid=$(on b "$NODE_CTL show -p MainPID --value sandtable-node.service")
  [ "$pid" != 0 ] && [ "$pid" != "$NODE_PID" ] && node_ready
}
wait_for "$EVENT_TIMEOUT_S" "host b: the node restarted" node_restarted
NODE_PID=$(on b "$NODE_CTL show -p MainPID --value sandtable-node.service")
wait_for "$EVENT_TIMEOUT_S" "node $NODE_ID back in /status after both restarts" member_listed
ok "coordinator now pid $COORDINATOR_PID ($(on a 'systemctl show -p NRestarts --value sandtable-coordinator.service') restart), node now pid $NODE_PID ($(on b "$NODE_CTL show -p NRestarts --value sandtable-node.service") restart); the node is a member again"

step "status"
out=$(rollout status "${ROLLOUT_SSH[@]}" "$ADDR_A" "$ADDR_B" 2>&1) || fail "status: $out"
show "$out"
[[ "$out" == *"[$ADDR_A] sandtable-coordinator.service: enabled, active"* ]] || fail "status: no active coordinator"
[[ "$out" == *"[$ADDR_B] sandtable-node.service: active in sandtable's graphical session"* ]] || fail "status: no active node"

step "install again: nothing changes"
out=$(rollout install "${INSTALL[@]}" "$ADDR_A" "$ADDR_B" 2>&1) || fail "install: $out"
show "$out"
! grep -q ': installed' <<<"$out" || fail "the third install copied files again"
[[ "$out" == *"[$ADDR_B] sandtable-node.service: unchanged, running in sandtable's session"* ]] ||
  fail "host b: the node was not left running"
if [ "$(on a 'systemctl show -p MainPID --value sandtable-coordinator.service')" != "$COORDINATOR_PID" ] ||
  [ "$(on b "$NODE_CTL show -p MainPID --value sandtable-node.service")" != "$NODE_PID" ]; then
  fail "a service was restarted by an install that changed nothing"
fi
ok "no file copied, both services kept their processes"

step "roles change: host a gets a node too, then loses it again"
sed "s/\"id\": $NODE_ID/\"id\": 6/" "$SITE/unit-$NODE_ID.json" >"$SITE/unit-6.json"
out=$(rollout install "${INSTALL[@]}" --unit-config "$ADDR_A=$SITE/unit-6.json" "$ADDR_A" "$ADDR_B" 2>&1) ||
  fail "install with a node on host a: $out"
show "$(grep "^\[$ADDR_A\]" <<<"$out")"
on a 'test -x /opt/sandtable/bin/sandtable-node && test -f /etc/systemd/user/sandtable-node.service' ||
  fail "host a did not get the node"
out=$(rollout install "${INSTALL[@]}" "$ADDR_A" "$ADDR_B" 2>&1) || fail "install without it: $out"
show "$(grep "^\[$ADDR_A\]" <<<"$out")"
on a '! test -e /opt/sandtable/bin/sandtable-node && ! test -e /etc/sandtable/unit.json &&
  ! test -e /etc/systemd/user/sandtable-node.service && ! grep -q node /opt/sandtable/rollout.manifest' ||
  fail "host a kept parts of the node it no longer runs"
[ "$(on a 'systemctl show -p MainPID --value sandtable-coordinator.service')" = "$COORDINATOR_PID" ] ||
  fail "host a: the node's coming and going restarted the coordinator"
ok "the node's program, unit and unit file came and went; the coordinator kept its process"

step "uninstall"
out=$(rollout uninstall "${ROLLOUT_SSH[@]}" "$ADDR_A" "$ADDR_B" 2>&1) || fail "uninstall: $out"
show "$out"
# (pgrep matches the kernel's 15-character process name.)
on a '! systemctl is-active --quiet sandtable-coordinator.service && ! pgrep -x sandtable-coord' ||
  fail "host a: the coordinator still runs"
on b '! pgrep -x sandtable-node' || fail "host b: the node still runs"
for h in a b; do
  on "$h" 'for p in /opt/sandtable /etc/sandtable /etc/systemd/system/sandtable-coordinator.service \
      /etc/systemd/system/sandtable-coordinator.service.d /etc/systemd/user/sandtable-node.service \
      /etc/systemd/user/sandtable-node.service.d /etc/systemd/user/sandtable-kiosk-session.target \
      /etc/systemd/user/graphical-session.target.wants; do
      if [ -e "$p" ]; then echo "$p is still there"; exit 1; fi; done' || fail "host $h: uninstall left files"
  on "$h" 'test -d /var/lib/sandtable' || fail "host $h: uninstall without --purge removed /var/lib/sandtable"
done
! on a 'getent passwd sandtable' >/dev/null || fail "host a: the system user install created is still there"
on b 'getent passwd sandtable' >/dev/null || fail "host b: uninstall removed the kiosk user it did not create"
ok "services stopped, programs, units, configuration and keys gone; /var/lib/sandtable kept; host a's system user gone, host b's own user kept"

step "uninstall --purge (again: idempotent)"
out=$(rollout uninstall --purge "${ROLLOUT_SSH[@]}" "$ADDR_A" "$ADDR_B" 2>&1) || fail "uninstall --purge: $out"
show "$out"
for h in a b; do
  on "$h" '! test -e /var/lib/sandtable' || fail "host $h: /var/lib/sandtable is still there"
  snapshot "$h" >"$WORK/$h.after"
  diff -u "$WORK/$h.before" "$WORK/$h.after" >"$WORK/$h.diff" ||
    fail "host $h: /etc or /opt differ from before the install: $(cat "$WORK/$h.diff")"
done
ok "/etc and /opt of both hosts as before the first install (file by file), /var/lib/sandtable gone"

cat <<EOF
== [$((SECONDS - STARTED)) s] PASSED
   Exercised for real: ssh logins (sshd per host, generated keys), rollout.sh install, status,
   uninstall against two hosts each with its own systemd (PID 1), journald, dbus and logind;
   the coordinator as a system service and the node as a user service of a user manager
   (user@.service) with an X display (Xvfb) and graphical-session.target; Restart=on-failure;
   the node's CURVE registration across hosts, read from the coordinator's status page.
   Not exercised: a boot (the hosts start their own test target, not multi-user.target: the
   coordinator's [Install] is checked as a symlink only), a display manager's login (the test
   starts user@.service and the session target the way one does), a projector (an Xvfb screen).
EOF
