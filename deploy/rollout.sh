#!/usr/bin/env bash
# Installs, removes or reports Sandtable's services on a site's hosts over ssh
# (docs/services.md). Run `deploy/rollout.sh --help` for the options.
#
# Every host gets one ssh connection to check it (reachable, systemd, service user, which
# programs it already has), then one that carries a tar of what it needs plus the remote half
# of this script (the remote_* functions below, sent with `declare -f`), which installs as
# root (directly, or with `sudo -n` for another ssh user).
set -euo pipefail

readonly PREFIX=/opt/sandtable
readonly CONFIG_DIR=/etc/sandtable
readonly STATE_DIR=/var/lib/sandtable
readonly SYSTEM_UNIT_DIR=/etc/systemd/system
readonly USER_UNIT_DIR=/etc/systemd/user
readonly MANIFEST=/opt/sandtable/rollout.manifest
readonly READY_TIMEOUT_S=30

SCRIPT_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
readonly SCRIPT_DIR

usage() {
  cat <<EOF
Usage: deploy/rollout.sh [options] install|uninstall|status HOST...

  install    copies the programs, unit files, site configuration and keys each HOST needs,
             enables and (re)starts its services; a second run changes nothing that is
             already in place (only changed files are copied, services restart only then)
  uninstall  stops and disables the services and removes what install put there; the
             state directory $STATE_DIR is kept unless --purge
  status     the services' state on each HOST

Programs (install; one of):
  --build-dir DIR        a build tree: DIR/coordinator/sandtable-coordinator, DIR/node/sandtable-node
  --from-prefix DIR      an installed tree: DIR/bin/sandtable-coordinator, DIR/bin/sandtable-node

Site (install):
  --coordinator HOST     HOST runs the coordinator (a system service)
  --unit-config HOST=FILE  HOST runs a node with this unit file (a user service of the
                         service user's graphical session); once per node host
  --site-config FILE     the site file (docs/config-file.md); with every relative file it
                         names (curve_keys, status.token_file, model) and the unit files'
                         (factory, saved_calibration), it goes to $CONFIG_DIR
  --env-file FILE        extra flags for the services (default: deploy/systemd/sandtable.env)
  --user NAME            the service user (default: sandtable). On a node host it must exist
                         and be the user whose graphical session shows the node; on a
                         coordinator-only host it is created as a system user when missing

uninstall:
  --purge                also remove $STATE_DIR (calibrations, annotation databases)

ssh:
  --ssh-user USER        log in as USER (default: ssh's own choice); not root: needs sudo -n
  -p, --port PORT        ssh port
  -i, --identity FILE    ssh identity (private key) file
  -o, --ssh-option OPT   an ssh -o option (KEY=VALUE), repeatable
  --connect-timeout S    seconds to wait for a host to answer (default: 10)

Exit status: 0 done everywhere, 1 failed on some host (each named), 2 bad usage or file.
EOF
}

die() {
  echo "rollout: $*" >&2
  exit 2
}

# ---------------------------------------------------------------------------------------------
# Remote half: runs as root on a host, after the settings remote_script writes before it.
# ---------------------------------------------------------------------------------------------

remote_say() { printf '%s\n' "$*"; }

remote_fail() {
  printf 'error: %s\n' "$*"
  exit 3
}

remote_check_systemd() {
  [ -d /run/systemd/system ] ||
    remote_fail "systemd is not this host's service manager (no /run/systemd/system)"
}

remote_user_uid() { id -u "$SERVICE_USER"; }

# systemctl --user for the service user, when the user's manager runs (else returns 1).
remote_user_ctl() {
  local uid
  uid=$(remote_user_uid 2>/dev/null) || return 1
  [ -S "/run/user/$uid/systemd/private" ] || return 1
  runuser -u "$SERVICE_USER" -- env XDG_RUNTIME_DIR="/run/user/$uid" systemctl --user "$@"
}

remote_user_manager_runs() {
  local uid
  uid=$(remote_user_uid 2>/dev/null) || return 1
  [ -S "/run/user/$uid/systemd/private" ]
}

# Records that this install put PATH there (KIND f: a file, d: a folder it created, u: a user
# it created): uninstall removes what the manifest names, install what it no longer puts.
remote_manifest_add() {  # KIND PATH
  mkdir -p "$(dirname "$MANIFEST")"
  touch "$MANIFEST"
  grep -qxF "$1 $2" "$MANIFEST" || printf '%s %s\n' "$1" "$2" >>"$MANIFEST"
  printf '%s %s\n' "$1" "$2" >>"$REMOTE_TOUCHED"
}

# Keeps an earlier install's record of PATH, if any (a folder or user it created then).
remote_manifest_keep() {  # KIND PATH
  if [ -f "$MANIFEST" ] && grep -qxF "$1 $2" "$MANIFEST"; then
    printf '%s %s\n' "$1" "$2" >>"$REMOTE_TOUCHED"
  fi
}

remote_dir() {  # PATH MODE OWNER GROUP: creates it (recorded) or sets its mode and owner
  if [ ! -d "$1" ]; then
    remote_manifest_add d "$1"
  else
    remote_manifest_keep d "$1"
  fi
  install -d -m "$2" -o "$3" -g "$4" "$1"
}

# Installs SRC as DEST; sets PUT_CHANGED to 1 when DEST changed (content, mode or owner), to 0
# when it was already so. A running program's file is replaced by a rename, never rewritten.
# Called as a plain command, never in a condition, so that `set -e` stops at a failure in it.
remote_put() {  # SRC DEST MODE OWNER GROUP
  remote_manifest_add f "$2"
  PUT_CHANGED=0
  if [ -f "$2" ] && cmp -s "$1" "$2" && [ "$(stat -c '%a %U %G' "$2")" = "${3#0} $4 $5" ]; then
    return 0
  fi
  install -m "$3" -o "$4" -g "$5" "$1" "$2.rollout-new"
  mv -f "$2.rollout-new" "$2"
  PUT_CHANGED=1
}

remote_put_text() {  # TEXT DEST MODE OWNER GROUP
  local tmp
  tmp=$(mktemp)
  printf '%s' "$1" >"$tmp"
  remote_put "$tmp" "$2" "$3" "$4" "$5"
  rm -f "$tmp"
}

# Waits for the ready line ({"ready":"sandtable-...",...}) the service's current process writes
# to the journal; on failure prints the service's last journal lines and fails.
remote_wait_ready() {  # system|user UNIT PROGRAM
  local scope=$1 unit=$2 program=$3 pid state line deadline
  deadline=$((SECONDS + READY_TIMEOUT_S))
  while :; do
    if [ "$scope" = system ]; then
      state=$(systemctl show -p ActiveState --value "$unit")
      pid=$(systemctl show -p MainPID --value "$unit")
    else
      state=$(remote_user_ctl show -p ActiveState --value "$unit")
      pid=$(remote_user_ctl show -p MainPID --value "$unit")
    fi
    if [ "$state" = active ] && [ "$pid" != 0 ]; then
      line=$(journalctl -q -o cat "_PID=$pid" 2>/dev/null | grep -m1 "\"ready\":\"$program\"" || true)
      if [ -n "$line" ]; then
        remote_say "$unit: running as $SERVICE_USER, pid $pid: $line"
        return 0
      fi
    fi
    if [ "$state" = failed ] || [ $SECONDS -ge $deadline ]; then
      remote_say "$unit: $state, no ready line after $READY_TIMEOUT_S s; its journal:"
      if [ "$scope" = system ]; then
        journalctl -q -n 15 -u "$unit" --no-pager | sed 's/^/  /'
      else
        journalctl -q -n 15 --user-unit "$unit" --no-pager "_UID=$(remote_user_uid)" | sed 's/^/  /'
      fi
      remote_fail "$unit did not start"
    fi
    sleep 0.2
  done
}

# Probe before install: prints the installed programs' sha256, or an error.
remote_probe() {
  remote_check_systemd
  if [ "$WANT_NODE" = 1 ] && ! getent passwd "$SERVICE_USER" >/dev/null; then
    remote_fail "user '$SERVICE_USER' does not exist: the node runs in that user's graphical" \
      "session; create it and set up its automatic graphical login (docs/services.md)," \
      "or name another user with --user"
  fi
  local program
  for program in sandtable-coordinator sandtable-node; do
    if [ -f "$PREFIX/bin/$program" ]; then
      printf 'sha256 %s %s\n' "$(sha256sum <"$PREFIX/bin/$program" | cut -d' ' -f1)" "$program"
    fi
  done
}

# The node's user, as the installed drop-in names it (whatever --user says now).
remote_node_user() {
  local dropin="$USER_UNIT_DIR/sandtable-node.service.d/rollout.conf"
  if [ -f "$dropin" ]; then sed -n 's/^ConditionUser=\(..*\)$/\1/p' "$dropin" | tail -n1; fi
}

remote_stop_coordinator() {
  if [ -f "$SYSTEM_UNIT_DIR/sandtable-coordinator.service" ]; then
    systemctl disable --now --quiet sandtable-coordinator.service 2>/dev/null || true
    systemctl reset-failed sandtable-coordinator.service 2>/dev/null || true
    remote_say "sandtable-coordinator.service: stopped and disabled"
  fi
}

remote_stop_node() {
  if [ -f "$USER_UNIT_DIR/sandtable-node.service" ]; then
    local user
    user=$(remote_node_user)
    if [ -n "$user" ]; then
      SERVICE_USER=$user remote_user_ctl stop sandtable-node.service 2>/dev/null || true
      SERVICE_USER=$user remote_user_ctl reset-failed sandtable-node.service 2>/dev/null || true
    fi
    systemctl --global disable --quiet sandtable-node.service 2>/dev/null || true
    remote_say "sandtable-node.service: stopped and disabled${user:+ (user $user)}"
    if [ -n "$user" ] && SERVICE_USER=$user remote_user_manager_runs; then
      SERVICE_USER=$user remote_user_ctl daemon-reload || true
    fi
  fi
}

# Removes the manifest's files that are not in KEEP (a file of "KIND PATH" lines; empty: all),
# then its directories that are empty; rewrites the manifest with what is left.
remote_prune() {  # KEEP
  local keep=$1 kind path left old
  [ -f "$MANIFEST" ] || return 0
  left=$(mktemp)
  old=$(mktemp)
  cp "$MANIFEST" "$old"
  while read -r kind path; do
    if grep -qxF "$kind $path" "$keep"; then
      printf '%s %s\n' "$kind" "$path" >>"$left"
    elif [ "$kind" = f ] && [ -e "$path" ]; then
      rm -f "$path"
      remote_say "removed $path"
    fi
  done <"$old"
  # Deepest first, so that a folder empties before its parent is tried.
  while read -r kind path; do
    grep -qxF "$kind $path" "$keep" && continue
    [ "$path" = "$STATE_DIR" ] && continue
    if [ -d "$path" ] && ! rmdir "$path" 2>/dev/null; then
      remote_say "kept $path: it holds files rollout did not install"
    fi
  done < <(grep '^d ' "$old" | awk '{ print length($2), $0 }' | sort -rn | cut -d' ' -f2-)
  if [ -s "$left" ]; then
    cp "$left" "$MANIFEST"
  else
    rm -f "$MANIFEST"
    rmdir "$PREFIX" 2>/dev/null || true
  fi
  rm -f "$left" "$old"
}

remote_install() {
  # What changed for each service: its program, its unit, the files it reads.
  local payload=$1 group changed_coordinator=0 changed_node=0 rel dest mode owner dir program
  remote_check_systemd
  REMOTE_TOUCHED=$(mktemp)
  # First, so that the manifest inside it records every later step.
  remote_dir "$PREFIX" 0755 root root

  if ! getent passwd "$SERVICE_USER" >/dev/null; then
    [ "$WANT_NODE" = 0 ] || remote_fail "user '$SERVICE_USER' does not exist"
    remote_manifest_add u "$SERVICE_USER"
    useradd --system --user-group --home-dir "$STATE_DIR" --no-create-home \
      --shell /usr/sbin/nologin --comment "Sandtable services" "$SERVICE_USER"
    remote_say "created system user $SERVICE_USER"
  else
    remote_manifest_keep u "$SERVICE_USER"
  fi
  group=$(id -gn "$SERVICE_USER")

  remote_dir "$PREFIX/bin" 0755 root root
  remote_dir "$CONFIG_DIR" 0750 root "$group"
  remote_dir "$STATE_DIR" 0750 "$SERVICE_USER" "$group"

  # Programs: the payload carries only those that differ from the installed ones.
  for program in sandtable-coordinator sandtable-node; do
    if [ -f "$payload/bin/$program" ]; then
      remote_put "$payload/bin/$program" "$PREFIX/bin/$program" 0755 root root
      remote_say "$PREFIX/bin/$program: installed"
      if [ "$program" = sandtable-node ]; then changed_node=1; else changed_coordinator=1; fi
    elif [ -f "$PREFIX/bin/$program" ] && [ -f "$payload/roles/$program" ]; then
      remote_manifest_add f "$PREFIX/bin/$program"
      remote_say "$PREFIX/bin/$program: unchanged"
    fi
  done

  # Configuration: secrets are the service user's alone (0600, in 0700 folders).
  while IFS= read -r rel; do
    dest="$CONFIG_DIR/$rel"
    dir=$(dirname "$rel")
    if [ "$dir" != . ]; then
      local sub="" part
      local -a parts
      IFS=/ read -ra parts <<<"$dir"
      for part in "${parts[@]}"; do
        sub=${sub:+$sub/}$part
        if awk -v p="$sub/" 'index($0, p) == 1 { found = 1 } END { exit !found }' \
          "$payload/secrets"; then
          remote_dir "$CONFIG_DIR/$sub" 0700 "$SERVICE_USER" "$group"
        else
          remote_dir "$CONFIG_DIR/$sub" 0750 root "$group"
        fi
      done
    fi
    if grep -qxF "$rel" "$payload/secrets"; then
      mode=0600 owner=$SERVICE_USER
    else
      mode=0640 owner=root
    fi
    remote_put "$payload/etc/$rel" "$dest" "$mode" "$owner" "$group"
    if [ "$PUT_CHANGED" = 1 ]; then
      remote_say "$dest: installed ($mode $owner)"
      changed_node=1
      [ "$rel" = unit.json ] || changed_coordinator=1
    fi
  done < <(cd "$payload/etc" && find . -type f -printf '%P\n' | sort)

  if [ "$WANT_COORDINATOR" = 1 ]; then
    remote_put "$payload/units/sandtable-coordinator.service" \
      "$SYSTEM_UNIT_DIR/sandtable-coordinator.service" 0644 root root
    [ "$PUT_CHANGED" = 0 ] || changed_coordinator=1
    remote_dir "$SYSTEM_UNIT_DIR/sandtable-coordinator.service.d" 0755 root root
    remote_put_text "$(printf '[Service]\nUser=%s\nGroup=%s\n' "$SERVICE_USER" "$group")" \
      "$SYSTEM_UNIT_DIR/sandtable-coordinator.service.d/rollout.conf" 0644 root root
    [ "$PUT_CHANGED" = 0 ] || changed_coordinator=1
    systemctl daemon-reload
    systemctl enable --quiet sandtable-coordinator.service
    systemctl reset-failed sandtable-coordinator.service 2>/dev/null || true
    if [ "$changed_coordinator" = 1 ] ||
      ! systemctl is-active --quiet sandtable-coordinator.service; then
      systemctl restart sandtable-coordinator.service
      remote_wait_ready system sandtable-coordinator.service sandtable-coordinator
    else
      remote_say "sandtable-coordinator.service: unchanged, running"
    fi
  fi

  if [ "$WANT_NODE" = 1 ]; then
    local wants_dir="$USER_UNIT_DIR/graphical-session.target.wants"
    remote_dir "$USER_UNIT_DIR" 0755 root root
    remote_put "$payload/units/sandtable-node.service" \
      "$USER_UNIT_DIR/sandtable-node.service" 0644 root root
    [ "$PUT_CHANGED" = 0 ] || changed_node=1
    remote_put "$payload/units/sandtable-kiosk-session.target" \
      "$USER_UNIT_DIR/sandtable-kiosk-session.target" 0644 root root
    remote_dir "$USER_UNIT_DIR/sandtable-node.service.d" 0755 root root
    remote_put_text "$(printf '[Unit]\nConditionUser=\nConditionUser=%s\n' "$SERVICE_USER")" \
      "$USER_UNIT_DIR/sandtable-node.service.d/rollout.conf" 0644 root root
    [ "$PUT_CHANGED" = 0 ] || changed_node=1
    if [ -d "$wants_dir" ]; then
      remote_manifest_keep d "$wants_dir"
    else
      remote_manifest_add d "$wants_dir"
    fi
    systemctl --global enable --quiet sandtable-node.service
    if ! remote_user_manager_runs; then
      remote_say "sandtable-node.service: enabled; starts with $SERVICE_USER's graphical session" \
        "($SERVICE_USER is not logged in now)"
    else
      remote_user_ctl daemon-reload
      remote_user_ctl reset-failed sandtable-node.service 2>/dev/null || true
      if ! remote_user_ctl is-active --quiet graphical-session.target; then
        remote_say "sandtable-node.service: enabled; starts with $SERVICE_USER's graphical" \
          "session (none runs now)"
      elif [ "$changed_node" = 1 ] ||
        ! remote_user_ctl is-active --quiet sandtable-node.service; then
        remote_user_ctl restart sandtable-node.service
        remote_wait_ready user sandtable-node.service sandtable-node
      else
        remote_say "sandtable-node.service: unchanged, running in $SERVICE_USER's session"
      fi
    fi
  fi

  # A role this host no longer has, and files an earlier install left that this one did not
  # install, go.
  if [ "$WANT_COORDINATOR" = 0 ]; then remote_stop_coordinator; fi
  if [ "$WANT_NODE" = 0 ]; then remote_stop_node; fi
  remote_manifest_add f "$MANIFEST"
  remote_prune "$REMOTE_TOUCHED"
  systemctl daemon-reload
  rm -f "$REMOTE_TOUCHED"
  remote_say "install done"
}

remote_uninstall() {
  local empty user
  remote_check_systemd
  remote_stop_coordinator
  remote_stop_node
  user=""
  if [ -f "$MANIFEST" ]; then user=$(sed -n 's/^u //p' "$MANIFEST" | head -n1); fi
  empty=$(mktemp)
  remote_prune "$empty"
  rm -f "$empty"
  systemctl daemon-reload
  if [ -n "$user" ] && getent passwd "$user" >/dev/null; then
    userdel "$user"
    remote_say "removed system user $user (install created it)"
  fi
  if [ -d "$STATE_DIR" ]; then
    if [ "$PURGE" = 1 ]; then
      rm -rf "$STATE_DIR"
      remote_say "removed $STATE_DIR (--purge)"
    else
      remote_say "kept $STATE_DIR (calibrations, annotations): --purge removes it"
    fi
  fi
  remote_say "uninstall done"
}

remote_status() {
  local bad=0 state
  remote_check_systemd
  if [ -f "$SYSTEM_UNIT_DIR/sandtable-coordinator.service" ]; then
    state=$(systemctl is-active sandtable-coordinator.service || true)
    remote_say "sandtable-coordinator.service: $(systemctl is-enabled sandtable-coordinator.service \
      2>/dev/null || true), $state, pid $(systemctl show -p MainPID --value \
      sandtable-coordinator.service), restarts $(systemctl show -p NRestarts --value \
      sandtable-coordinator.service)"
    [ "$state" = active ] || bad=1
  fi
  if [ -f "$USER_UNIT_DIR/sandtable-node.service" ]; then
    SERVICE_USER=$(remote_node_user)
    if ! remote_user_manager_runs; then
      remote_say "sandtable-node.service: installed for $SERVICE_USER, who is not logged in"
    elif ! remote_user_ctl is-active --quiet graphical-session.target; then
      remote_say "sandtable-node.service: installed for $SERVICE_USER, no graphical session now"
    else
      state=$(remote_user_ctl is-active sandtable-node.service || true)
      remote_say "sandtable-node.service: $state in $SERVICE_USER's graphical session, pid" \
        "$(remote_user_ctl show -p MainPID --value sandtable-node.service), restarts" \
        "$(remote_user_ctl show -p NRestarts --value sandtable-node.service)"
      [ "$state" = active ] || bad=1
    fi
  fi
  if [ ! -f "$SYSTEM_UNIT_DIR/sandtable-coordinator.service" ] &&
    [ ! -f "$USER_UNIT_DIR/sandtable-node.service" ]; then
    remote_say "no Sandtable service installed"
  fi
  exit "$bad"
}

remote_main() {  # ACTION [PAYLOAD]
  case "$1" in
    probe) remote_probe ;;
    install) remote_install "$2" ;;
    uninstall) remote_uninstall ;;
    status) remote_status ;;
  esac
}

# ---------------------------------------------------------------------------------------------
# Local half.
# ---------------------------------------------------------------------------------------------

# The remote script: the settings for one host, the remote_* functions, and the call; its
# first argument, if any, is the folder the payload was unpacked in.
remote_script() {  # ACTION
  local name
  printf '#!/bin/bash\nset -eEuo pipefail\n'
  # shellcheck disable=SC2016 # expanded by the remote bash
  printf 'trap '\''echo "error: \\`$BASH_COMMAND\\` failed (exit $?)"'\'' ERR\n'
  for name in PREFIX CONFIG_DIR STATE_DIR SYSTEM_UNIT_DIR USER_UNIT_DIR MANIFEST READY_TIMEOUT_S \
    SERVICE_USER WANT_COORDINATOR WANT_NODE PURGE; do
    printf '%s=%q\n' "$name" "${!name}"
  done
  printf 'REMOTE_TOUCHED=/dev/null PUT_CHANGED=0\n'
  declare -F | awk '$3 ~ /^remote_/ && $3 != "remote_script" { print $3 }' |
    while read -r name; do declare -f "$name"; done
  # shellcheck disable=SC2016 # expanded by the remote bash
  printf 'remote_main %q "${1:-}"\n' "$1"
}

# As root on the host: directly when the ssh user is root, else through sudo -n. A shell
# command for the remote login shell (POSIX sh).
# shellcheck disable=SC2016 # expanded by the remote shell
readonly AS_ROOT='if [ "$(id -u)" -eq 0 ]; then set --; else set -- sudo -n; fi'

prefix_lines() {  # HOST
  local line
  while IFS= read -r line; do printf '[%s] %s\n' "$1" "$line"; done
}

# The functions below run in a host's own subshell (see the loop at the end): a failure ends
# that host's work with `exit`, and the other hosts go on.

# Runs the remote script for ACTION on HOST, with its lines prefixed.
run_remote() {  # HOST ACTION
  local rc=0
  # With pipefail the status is ssh's (the remote script's) whenever that is not 0.
  remote_script "$2" | "${SSH[@]}" "$1" "$AS_ROOT; exec \"\$@\" bash -s" 2>&1 |
    prefix_lines "$1" || rc=$?
  [ "$rc" = 0 ] || exit "$rc"
}

# Ends the host's work with a message naming it when ssh cannot log in there.
check_reachable() {  # HOST
  local err
  if ! err=$("${SSH[@]}" "$1" true 2>&1 </dev/null); then
    echo "[$1] error: cannot log in over ssh${SSH_USER:+ as $SSH_USER}${SSH_PORT:+ on port $SSH_PORT}:" \
      "$(printf '%s' "$err" | tr '\n' ' ')"
    exit 1
  fi
}

# Lists the files the site and unit files name (tab-separated: KIND, path relative to the
# file's folder, the local path), or errors.
named_files() {  # SITE_CONFIG [UNIT_CONFIG]
  python3 - "$@" <<'PY'
import json, os, sys

def load(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        print(f"error\t{path}: {e}")
        sys.exit(0)

def named(path, entries, doc):
    base = os.path.dirname(os.path.abspath(path))
    for kind, keys in entries:
        value = doc
        for key in keys:
            value = value.get(key) if isinstance(value, dict) else None
        if not isinstance(value, str) or not value:
            continue
        name = ".".join(keys)
        if os.path.isabs(value):
            print(f"warn\t{path}: {name} is an absolute path ({value}): not copied, "
                  "it must exist on every host that needs it")
            continue
        rel = os.path.normpath(value)
        if rel.startswith(".."):
            print(f"error\t{path}: {name} ({value}) leaves the file's folder: keep the files "
                  "a site file names in its folder or below")
            continue
        print(f"{kind}\t{rel}\t{os.path.join(base, rel)}")

site = sys.argv[1]
named(site, [("secret", ["curve_keys"]), ("coordinator-secret", ["status", "token_file"]),
             ("file", ["model"])], load(site))
if len(sys.argv) > 2:
    unit = sys.argv[2]
    doc = load(unit)
    export_dir = doc.get("export_dir") if isinstance(doc, dict) else None
    if isinstance(export_dir, str) and not os.path.isabs(export_dir):
        print(f"error\t{unit}: export_dir ({export_dir}) must be an absolute path, for example "
              f"{os.path.join('/var/lib/sandtable', export_dir)}: /etc/sandtable is not writable "
              "by the service")
    named(unit, [("file", ["factory"]), ("file", ["saved_calibration"])], doc)
PY
}

# Dies on what named_files finds wrong, or on a named file that is missing; says its warnings.
check_named_files() {  # SITE_CONFIG [UNIT_CONFIG]
  local kind rel src
  local -A seen=()
  while IFS=$'\t' read -r kind rel src; do
    case "$kind" in
      error) die "$rel" ;;
      warn) echo "rollout: warning: $rel" ;;
      *)
        [[ -f "$src" && -r "$src" ]] || die "$src (named by ${2:-$1}) is not a readable file"
        if [ -n "${seen[$rel]:-}" ] && ! cmp -s "${seen[$rel]}" "$src"; then
          die "$1 and $2 name different files for $CONFIG_DIR/$rel"
        fi
        seen[$rel]=$src ;;
    esac
  done < <(named_files "$@")
}

# Fills STAGE with what HOST needs (symbolic links to the local files; tar follows them).
stage_host() {  # HOST STAGE
  local host=$1 stage=$2 kind rel src program
  mkdir -p "$stage/bin" "$stage/etc" "$stage/units" "$stage/roles"
  : >"$stage/secrets"
  ln -s "$SITE_CONFIG" "$stage/etc/site.json"
  ln -s "$ENV_FILE" "$stage/etc/sandtable.env"
  if [ "$WANT_COORDINATOR" = 1 ]; then
    ln -s "$SCRIPT_DIR/systemd/sandtable-coordinator.service" "$stage/units/"
    touch "$stage/roles/sandtable-coordinator"
  fi
  if [ "$WANT_NODE" = 1 ]; then
    ln -s "$(readlink -f "${UNIT_CONFIGS[$host]}")" "$stage/etc/unit.json"
    ln -s "$SCRIPT_DIR/systemd/sandtable-node.service" "$stage/units/"
    ln -s "$SCRIPT_DIR/systemd/sandtable-kiosk-session.target" "$stage/units/"
    touch "$stage/roles/sandtable-node"
  fi
  while IFS=$'\t' read -r kind rel src; do
    case "$kind" in
      coordinator-secret | secret | file)
        [ "$kind" != coordinator-secret ] || [ "$WANT_COORDINATOR" = 1 ] || continue
        [ ! -e "$stage/etc/$rel" ] || continue
        mkdir -p "$(dirname "$stage/etc/$rel")"
        ln -s "$src" "$stage/etc/$rel"
        [ "$kind" = file ] || printf '%s\n' "$rel" >>"$stage/secrets"
        ;;
    esac
  done < <(if [ "$WANT_NODE" = 1 ]; then
    named_files "$SITE_CONFIG" "$(readlink -f "${UNIT_CONFIGS[$host]}")"
  else
    named_files "$SITE_CONFIG"
  fi)
  for program in sandtable-coordinator sandtable-node; do
    [ -f "$stage/roles/$program" ] || continue
    if [ "${REMOTE_SHA[$program]:-}" != "${LOCAL_SHA[$program]}" ]; then
      ln -s "${PROGRAM_PATH[$program]}" "$stage/bin/$program"
    fi
  done
  remote_script install >"$stage/rollout-remote.sh"
}

install_host() {  # HOST
  local host=$1 stage probe line rc sha program
  WANT_COORDINATOR=0 WANT_NODE=0
  [ "$host" != "$COORDINATOR" ] || WANT_COORDINATOR=1
  [ -z "${UNIT_CONFIGS[$host]:-}" ] || WANT_NODE=1
  echo "[$host] install:$([ $WANT_COORDINATOR = 0 ] || echo ' coordinator')$([ $WANT_NODE = 0 ] || echo ' node')"
  check_reachable "$host"
  rc=0
  probe=$(remote_script probe | "${SSH[@]}" "$host" "$AS_ROOT; exec \"\$@\" bash -s" 2>&1) || rc=$?
  REMOTE_SHA=()
  while IFS= read -r line; do
    case "$line" in
      "sha256 "*) read -r _ sha program <<<"$line" && REMOTE_SHA[$program]=$sha ;;
      "") ;;
      *) echo "[$host] $line" ;;
    esac
  done <<<"$probe"
  [ "$rc" = 0 ] || exit 1

  stage=$(mktemp -d "$WORK/stage.XXXXXX")
  stage_host "$host" "$stage"
  rc=0
  tar -C "$stage" -chf - . | "${SSH[@]}" "$host" \
    "set -e; $AS_ROOT; d=\$(mktemp -d /var/tmp/sandtable-rollout.XXXXXX); trap 'rm -rf \"\$d\"' EXIT; tar -xf - -C \"\$d\"; \"\$@\" bash \"\$d/rollout-remote.sh\" \"\$d\"" \
    2>&1 | prefix_lines "$host" || rc=$?
  rm -rf "$stage"
  [ "$rc" = 0 ] || exit "$rc"
}

# ---------------------------------------------------------------------------------------------

ACTION="" HOSTS=() BUILD_DIR="" FROM_PREFIX="" SITE_CONFIG="" COORDINATOR=""
ENV_FILE="$SCRIPT_DIR/systemd/sandtable.env" SERVICE_USER=sandtable PURGE=0
SSH_USER="" SSH_PORT="" IDENTITY="" CONNECT_TIMEOUT_S=10 SSH_OPTIONS=()
WANT_COORDINATOR=0 WANT_NODE=0
declare -A UNIT_CONFIGS=() REMOTE_SHA=() LOCAL_SHA=() PROGRAM_PATH=()

while [ $# -gt 0 ]; do
  case "$1" in
    -h | --help) usage; exit 0 ;;
    --build-dir | --from-prefix | --coordinator | --unit-config | --site-config | --env-file | \
      --user | --ssh-user | -p | --port | -i | --identity | -o | --ssh-option | --connect-timeout)
      [ $# -ge 2 ] || die "$1 needs a value (--help)"
      case "$1" in
        --build-dir) BUILD_DIR=$2 ;;
        --from-prefix) FROM_PREFIX=$2 ;;
        --coordinator) COORDINATOR=$2 ;;
        --unit-config)
          [[ "$2" == ?*=?* ]] || die "--unit-config takes HOST=FILE, not '$2'"
          UNIT_CONFIGS[${2%%=*}]=${2#*=} ;;
        --site-config) SITE_CONFIG=$2 ;;
        --env-file) ENV_FILE=$2 ;;
        --user) SERVICE_USER=$2 ;;
        --ssh-user) SSH_USER=$2 ;;
        -p | --port) SSH_PORT=$2 ;;
        -i | --identity) IDENTITY=$2 ;;
        -o | --ssh-option) SSH_OPTIONS+=(-o "$2") ;;
        --connect-timeout) CONNECT_TIMEOUT_S=$2 ;;
      esac
      shift 2 ;;
    --purge) PURGE=1; shift ;;
    install | uninstall | status)
      [ -z "$ACTION" ] || die "one action at a time ('$ACTION', then '$1')"
      ACTION=$1; shift ;;
    -*) die "unknown option '$1' (--help)" ;;
    *) HOSTS+=("$1"); shift ;;
  esac
done

[ -n "$ACTION" ] || die "no action: install, uninstall or status (--help)"
[ ${#HOSTS[@]} -gt 0 ] || die "no HOST given (--help)"
[[ "$SERVICE_USER" =~ ^[a-z_][a-z0-9_-]*$ ]] || die "--user '$SERVICE_USER' is not a user name"
[[ "$CONNECT_TIMEOUT_S" =~ ^[0-9]+$ ]] || die "--connect-timeout takes seconds, not '$CONNECT_TIMEOUT_S'"
[ -z "$IDENTITY" ] || [ -r "$IDENTITY" ] || die "--identity $IDENTITY: no such readable file"

SSH=(ssh -o BatchMode=yes -o "ConnectTimeout=$CONNECT_TIMEOUT_S")
[ -z "$SSH_USER" ] || SSH+=(-l "$SSH_USER")
[ -z "$SSH_PORT" ] || SSH+=(-p "$SSH_PORT")
[ -z "$IDENTITY" ] || SSH+=(-i "$IDENTITY" -o IdentitiesOnly=yes)
SSH+=("${SSH_OPTIONS[@]}")

if [ "$ACTION" = install ]; then
  [ -n "$SITE_CONFIG" ] || die "install needs --site-config FILE"
  [[ -f "$SITE_CONFIG" && -r "$SITE_CONFIG" ]] || die "--site-config $SITE_CONFIG: no such readable file"
  SITE_CONFIG=$(readlink -f "$SITE_CONFIG")
  [ -f "$ENV_FILE" ] || die "--env-file $ENV_FILE: no such file"
  ENV_FILE=$(readlink -f "$ENV_FILE")
  command -v python3 >/dev/null || die "python3 is needed to read the site file (deploy/install-deps.sh)"
  [ -n "$COORDINATOR" ] || [ ${#UNIT_CONFIGS[@]} -gt 0 ] ||
    die "install needs --coordinator HOST and/or --unit-config HOST=FILE: which host runs what"
  if [ -n "$COORDINATOR" ] && [[ " ${HOSTS[*]} " != *" $COORDINATOR "* ]]; then
    die "--coordinator $COORDINATOR is not one of the hosts (${HOSTS[*]})"
  fi
  for host in "${!UNIT_CONFIGS[@]}"; do
    [[ " ${HOSTS[*]} " == *" $host "* ]] || die "--unit-config $host=...: $host is not one of the hosts (${HOSTS[*]})"
    [ -f "${UNIT_CONFIGS[$host]}" ] || die "--unit-config $host=${UNIT_CONFIGS[$host]}: no such file"
  done
  for host in "${HOSTS[@]}"; do
    [ "$host" = "$COORDINATOR" ] || [ -n "${UNIT_CONFIGS[$host]:-}" ] ||
      die "$host has nothing to run: neither --coordinator $host nor --unit-config $host=FILE"
  done
  if [ -n "$BUILD_DIR" ] && [ -n "$FROM_PREFIX" ]; then die "--build-dir or --from-prefix, not both"; fi
  if [ -n "$BUILD_DIR" ]; then
    PROGRAM_PATH[sandtable-coordinator]=$BUILD_DIR/coordinator/sandtable-coordinator
    PROGRAM_PATH[sandtable-node]=$BUILD_DIR/node/sandtable-node
  elif [ -n "$FROM_PREFIX" ]; then
    PROGRAM_PATH[sandtable-coordinator]=$FROM_PREFIX/bin/sandtable-coordinator
    PROGRAM_PATH[sandtable-node]=$FROM_PREFIX/bin/sandtable-node
  else
    die "install needs the programs: --build-dir DIR or --from-prefix DIR"
  fi
  for program in sandtable-coordinator sandtable-node; do
    if [ "$program" = sandtable-coordinator ] && [ -z "$COORDINATOR" ]; then continue; fi
    if [ "$program" = sandtable-node ] && [ ${#UNIT_CONFIGS[@]} -eq 0 ]; then continue; fi
    [ -x "${PROGRAM_PATH[$program]}" ] || die "${PROGRAM_PATH[$program]}: no such program (build it, or fix --build-dir / --from-prefix)"
    PROGRAM_PATH[$program]=$(readlink -f "${PROGRAM_PATH[$program]}")
    LOCAL_SHA[$program]=$(sha256sum <"${PROGRAM_PATH[$program]}" | cut -d' ' -f1)
  done
  check_named_files "$SITE_CONFIG"
  for host in "${!UNIT_CONFIGS[@]}"; do
    check_named_files "$SITE_CONFIG" "$(readlink -f "${UNIT_CONFIGS[$host]}")"
  done
  # The coordinator's host first: nodes started before it only wait for it.
  if [ -n "$COORDINATOR" ]; then
    ordered=("$COORDINATOR")
    for host in "${HOSTS[@]}"; do [ "$host" = "$COORDINATOR" ] || ordered+=("$host"); done
    HOSTS=("${ordered[@]}")
  fi
fi

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

host_action() {  # HOST
  case "$ACTION" in
    install) install_host "$1" ;;
    uninstall | status)
      echo "[$1] $ACTION"
      check_reachable "$1"
      run_remote "$1" "$ACTION"
      ;;
  esac
}

failed=()
for host in "${HOSTS[@]}"; do
  # In a subshell that is no condition, so that `set -e` holds inside it.
  set +e
  (
    set -eE
    trap 'echo "[$host] error: \`$BASH_COMMAND\` failed (exit $?)"' ERR
    host_action "$host"
  )
  rc=$?
  set -e
  [ "$rc" = 0 ] || failed+=("$host")
done

if [ ${#failed[@]} -gt 0 ]; then
  echo "rollout: $ACTION failed on ${#failed[@]} of ${#HOSTS[@]} hosts: ${failed[*]}" >&2
  exit 1
fi
echo "rollout: $ACTION done on ${#HOSTS[@]} hosts: ${HOSTS[*]}"
