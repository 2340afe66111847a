#!/bin/sh
# Installs the landing stack on a vehicle (a Jetson): the `landing` user, the binaries,
# the deploy directory as /etc/landing, the systemd units and the tmpfiles rule.
# Idempotent: run it again after a rebuild. docs/jetson.md.
set -eu

usage() {
    cat <<'EOF'
usage: deploy/install.sh [--root DIR] [--bin-dir DIR] [--cpus N] [--uninstall]

  --root DIR     install into DIR instead of / (an image being built, a test); the
                 user goes into DIR/etc/passwd and DIR/etc/group
  --bin-dir DIR  where the release binaries are (default: target/release of this
                 checkout)
  --cpus N       the CPUs of the machine the stack runs on (default: this machine's,
                 nproc): the drop-ins' CPU sets are made to fit it (docs/jetson.md)
  --uninstall    remove what an install put there (binaries, /etc/landing, units,
                 tmpfiles rule, the user)
  -h, --help     this text
EOF
}

DEPLOY=$(cd "$(dirname "$0")" && pwd)
ROOT=/
BIN_DIR="$DEPLOY/../target/release"
UNINSTALL=0
CPUS=$(nproc 2>/dev/null || echo 1)
while [ $# -gt 0 ]; do
    case "$1" in
    --cpus)
        [ $# -ge 2 ] || { echo "install.sh: --cpus needs a number" >&2; exit 2; }
        case "$2" in
        '' | *[!0-9]*) echo "install.sh: --cpus $2 is not a number of CPUs (1 to 1024)" >&2; exit 2 ;;
        esac
        [ "$2" -ge 1 ] && [ "$2" -le 1024 ] || { echo "install.sh: --cpus $2 is not a number of CPUs (1 to 1024)" >&2; exit 2; }
        CPUS=$2; shift 2 ;;
    --root) [ $# -ge 2 ] || { echo "install.sh: --root needs a directory" >&2; exit 2; }; ROOT=$2; shift 2 ;;
    --bin-dir) [ $# -ge 2 ] || { echo "install.sh: --bin-dir needs a directory" >&2; exit 2; }; BIN_DIR=$2; shift 2 ;;
    --uninstall) UNINSTALL=1; shift ;;
    -h | --help) usage; exit 0 ;;
    *) echo "install.sh: unknown argument '$1' (allowed: --root DIR, --bin-dir DIR, --cpus N, --uninstall, --help)" >&2; exit 2 ;;
    esac
done
[ -d "$ROOT" ] || { echo "install.sh: --root $ROOT is not a directory" >&2; exit 2; }
R=${ROOT%/}

# What runs on the vehicle (the simulator does not), the flight recorder, and `landing`
# for `landing clean`.
BINARIES="camera-ingest depth-ingest aruco-pnp depth-map planner fsm px4-link watchdog recorder landing"
UNITS_DIR="$R/etc/systemd/system"
USER_NAME=landing

systemd_live() {
    [ "$ROOT" = / ] && command -v systemctl >/dev/null 2>&1 && [ -d /run/systemd/system ]
}

add_user() {
    if [ "$ROOT" = / ]; then
        if ! getent passwd "$USER_NAME" >/dev/null; then
            useradd --system --user-group --no-create-home --home-dir /nonexistent \
                --shell /usr/sbin/nologin "$USER_NAME"
        fi
        for g in video dialout plugdev; do
            if getent group "$g" >/dev/null; then usermod -a -G "$g" "$USER_NAME"; fi
        done
    else
        mkdir -p "$R/etc"
        touch "$R/etc/passwd" "$R/etc/group"
        grep -q "^$USER_NAME:" "$R/etc/group" || echo "$USER_NAME:x:990:" >>"$R/etc/group"
        grep -q "^$USER_NAME:" "$R/etc/passwd" ||
            echo "$USER_NAME:x:990:990:landing stack:/nonexistent:/usr/sbin/nologin" >>"$R/etc/passwd"
    fi
}

remove_user() {
    if [ "$ROOT" = / ]; then
        if getent passwd "$USER_NAME" >/dev/null; then userdel "$USER_NAME"; fi
    else
        for f in passwd group; do
            if [ -f "$R/etc/$f" ]; then
                grep -v "^$USER_NAME:" "$R/etc/$f" >"$R/etc/$f.new" || true
                mv "$R/etc/$f.new" "$R/etc/$f"
            fi
        done
    fi
}

if [ "$UNINSTALL" = 1 ]; then
    if systemd_live; then
        systemctl disable --now landing.target 2>/dev/null || true
    fi
    for b in $BINARIES; do rm -f "$R/usr/local/bin/$b"; done
    rm -rf "$R/etc/landing"
    rm -f "$UNITS_DIR/landing@.service" "$UNITS_DIR/landing-clean.service" \
        "$UNITS_DIR/landing-recorder.service" "$UNITS_DIR/landing.target" \
        "$UNITS_DIR/multi-user.target.wants/landing.target"
    rm -rf "$UNITS_DIR/landing.target.wants"
    rm -rf "$UNITS_DIR"/landing@*.service.d
    rm -f "$R/etc/tmpfiles.d/landing.conf"
    remove_user
    if systemd_live; then systemctl daemon-reload; fi
    echo "landing stack removed from $ROOT"
    exit 0
fi

for b in $BINARIES; do
    [ -x "$BIN_DIR/$b" ] || {
        echo "install.sh: $BIN_DIR/$b missing (build first: cargo build --release --workspace)" >&2
        exit 2
    }
done

add_user
mkdir -p "$R/usr/local/bin" "$R/etc/landing" "$UNITS_DIR" "$R/etc/tmpfiles.d"
for b in $BINARIES; do install -m 0755 "$BIN_DIR/$b" "$R/usr/local/bin/$b"; done
# The deploy directory, replaced whole (a file removed from it goes on the vehicle too).
rm -rf "$R/etc/landing"
mkdir -p "$R/etc/landing"
cp -R "$DEPLOY/config" "$DEPLOY/scenarios" "$DEPLOY/graph.toml" "$DEPLOY/README.md" "$R/etc/landing/"
for u in "$DEPLOY"/systemd/*.service "$DEPLOY"/systemd/*.target; do
    install -m 0644 "$u" "$UNITS_DIR/"
done
# The drop-ins pin the real-time path for an Orin NX's 8 cores: camera and detection on
# 2-3, the mission and the autopilot link on 4, mapping and planning on 5-7, 0-1 left to
# the system. A CPU the machine lacks fails the unit (status=215/CPUAFFINITY), so the
# sets are made to fit the CPUs it has; below 4 nothing is pinned (priorities stay).
if [ "$CPUS" -ge 8 ]; then
    PERCEPTION="2 3"; MISSION="4"; OFF_PATH="5 6 7"
elif [ "$CPUS" -ge 6 ]; then
    PERCEPTION="2 3"; MISSION="4"; OFF_PATH="5"
elif [ "$CPUS" -ge 4 ]; then
    PERCEPTION="2"; MISSION="3"; OFF_PATH="1"
else
    PERCEPTION=""; MISSION=""; OFF_PATH=""
fi
for d in "$DEPLOY"/systemd/*.service.d; do
    name=$(basename "$d")
    mkdir -p "$UNITS_DIR/$name"
    for conf in "$d"/*.conf; do
        out="$UNITS_DIR/$name/$(basename "$conf")"
        if [ -n "$PERCEPTION" ]; then
            sed -e "s/^CPUAffinity=2 3\$/CPUAffinity=$PERCEPTION/" \
                -e "s/^CPUAffinity=4\$/CPUAffinity=$MISSION/" \
                -e "s/^CPUAffinity=5 6 7\$/CPUAffinity=$OFF_PATH/" "$conf" >"$out"
        else
            sed -e '/^CPUAffinity=/d' "$conf" >"$out"
        fi
        chmod 0644 "$out"
    done
done
install -m 0644 "$DEPLOY/tmpfiles.d/landing.conf" "$R/etc/tmpfiles.d/landing.conf"
mkdir -p "$UNITS_DIR/multi-user.target.wants" "$UNITS_DIR/landing.target.wants"
ln -sf ../landing.target "$UNITS_DIR/multi-user.target.wants/landing.target"
# The recorder starts with the stack (its [Install] WantedBy=landing.target).
ln -sf ../landing-recorder.service "$UNITS_DIR/landing.target.wants/landing-recorder.service"
if [ -n "$PERCEPTION" ]; then
    echo "CPU sets for $CPUS CPUs: camera and detection $PERCEPTION, mission and link $MISSION, mapping and planning $OFF_PATH"
else
    echo "CPU sets: none ($CPUS CPUs: fewer than 4, nothing pinned; real-time priorities kept)"
fi
if systemd_live; then
    systemd-tmpfiles --create /etc/tmpfiles.d/landing.conf
    systemctl daemon-reload
    echo "installed; start with: systemctl start landing.target"
else
    echo "installed into $ROOT; landing.target is enabled (starts at boot)"
fi
