#!/bin/sh
# `make systemd`: the stack under a live systemd. systemd as PID 1 of a systemd-nspawn
# container whose root is an overlay of this machine's (nothing of the host is written),
# its own network namespace, the units installed by deploy/install.sh (CPU sets for this
# machine's CPUs), the simulator started beside them as a unit of the test. Checks, each
# one line, exit 1 on the first failure:
#   - every landing@ unit reaches active (READY=1) and stays so;
#   - a stage killed ten times in ten seconds is restarted every time (NRestarts, a new
#     main PID each time), and landing-clean never runs out of starts;
#   - every stage killed three times is back (READY=1) each time; the time from each
#     death to the new process's READY=1 is printed (p50, p95);
#   - a hung stage (SIGSTOP) is killed by WatchdogSec and restarted;
#   - the units start on this machine's CPUs (a 2-core machine here);
#   - a unit that cannot start is given up (start-limit-hit), the system reads degraded
#     and `landing status` says DEGRADED.
# Needs root, mount (overlayfs) and systemd-nspawn (apt: systemd-container). About a
# minute. docs/jetson.md.
set -eu

REPO=$(cd "$(dirname "$0")/../.." && pwd)
BIN=${BIN:-$REPO/target/release}
STAGES="camera-ingest aruco-pnp depth-map planner fsm px4-link watchdog"

fail() {
    echo "systemd live: FAIL: $*" >&2
    exit 1
}
[ "$(id -u)" = 0 ] || { echo "tests/systemd/live.sh: needs root (overlay mount, systemd-nspawn)" >&2; exit 2; }
command -v systemd-nspawn >/dev/null || { echo "tests/systemd/live.sh: needs systemd-nspawn (apt: systemd-container)" >&2; exit 2; }
for b in sim landing fsm; do
    [ -x "$BIN/$b" ] || { echo "tests/systemd/live.sh: $BIN/$b missing (cargo build --release --workspace)" >&2; exit 2; }
done

WORK=$(mktemp -d /tmp/landing-systemd.XXXXXX)
ROOT=$WORK/root
mkdir -p "$WORK/upper" "$WORK/work" "$ROOT"
mount -t overlay overlay -o "lowerdir=/,upperdir=$WORK/upper,workdir=$WORK/work" "$ROOT"
NSPAWN=
cleanup() {
    if [ -n "$NSPAWN" ]; then
        kill "$NSPAWN" 2>/dev/null || true
        wait "$NSPAWN" 2>/dev/null || true
    fi
    umount "$ROOT" 2>/dev/null || umount -l "$ROOT" 2>/dev/null || true
    if [ -n "${KEEP:-}" ]; then echo "kept $WORK"; else rm -rf "$WORK"; fi
}
trap cleanup EXIT INT TERM

# A machine of its own: its id, the stack installed, nothing else of the host started.
systemd-id128 new >"$ROOT/etc/machine-id"
"$REPO/deploy/install.sh" --root "$ROOT" --bin-dir "$BIN" >"$WORK/install.log"
install -m 0755 "$BIN/sim" "$ROOT/usr/local/bin/sim"
cat >"$ROOT/etc/systemd/system/landing-test-sim.service" <<'EOF'
# The simulator beside the stack (this test only): the world the stack flies in.
[Unit]
Description=landing test: the simulator
After=landing.target
[Service]
User=landing
Group=landing
Environment=LANDING_IPC_PREFIX=landing_
ExecStart=/usr/local/bin/sim --config /etc/landing/config/landing.toml --deploy-dir /etc/landing --scenario /etc/landing/scenarios/indoor-static.toml --duration-s 600 --ipc-prefix landing_
RemoveIPC=no
EOF
cat >"$ROOT/etc/systemd/system/landing-test.target" <<'EOF'
[Unit]
Description=landing test: the stack and the simulator on a basic system
Requires=basic.target
After=basic.target
Wants=landing.target landing-test-sim.service
AllowIsolate=yes
EOF

systemd-nspawn -q -D "$ROOT" --register=no --keep-unit --link-journal=no --private-network \
    -b systemd.unit=landing-test.target >"$WORK/console.log" 2>&1 &
NSPAWN=$!

# The container's PID 1 (systemd), as the host sees it.
PID1=
for _ in $(seq 1 100); do
    for c in $(pgrep -P "$NSPAWN" 2>/dev/null || true); do
        if [ "$(cat "/proc/$c/comm" 2>/dev/null)" = systemd ]; then PID1=$c; fi
    done
    [ -n "$PID1" ] && break
    kill -0 "$NSPAWN" 2>/dev/null || { cat "$WORK/console.log" >&2; fail "systemd-nspawn ended"; }
    sleep 0.1
done
[ -n "$PID1" ] || { cat "$WORK/console.log" >&2; fail "no systemd in the container"; }
inside() { nsenter -t "$PID1" -a "$@"; }
# Before the container's systemd is up, systemctl finds no bus: an empty answer.
prop() { inside systemctl show -P "$2" "landing@$1.service" 2>/dev/null || true; }

# 1. Every unit active, with READY=1 (Type=notify: active only once it said so).
for _ in $(seq 1 300); do
    up=0
    for s in $STAGES; do
        [ "$(prop "$s" ActiveState)" = active ] && up=$((up + 1))
    done
    [ "$up" = 7 ] && break
    sleep 0.2
done
for s in $STAGES; do
    state=$(prop "$s" ActiveState)
    [ "$state" = active ] || {
        inside systemctl status "landing@$s.service" --no-pager -n 20 >&2 || true
        fail "landing@$s is $state, not active"
    }
done
echo "systemd live: all 7 units active on $(nproc) CPUs ($(sed -n 's/^CPU sets\(: \| for \)//p' "$WORK/install.log"))"

# CLOCK_MONOTONIC in microseconds: the container's systemd stamps with the same clock.
monotonic_us() { python3 -c 'import time; print(time.monotonic_ns() // 1000)'; }

# 2. Killed ten times in ten seconds: restarted every time. From each death to the new
# process's READY=1 (systemd's ActiveEnterTimestampMonotonic: its ports open, beating):
# systemd's RestartSec and the process's start, what a restart costs the flight.
before=$(prop planner NRestarts)
pids=""
killed_us=""
back_ms=""
for k in $(seq 1 11); do
    pid=""
    for _ in $(seq 1 50); do
        pid=$(prop planner MainPID)
        [ "$pid" != 0 ] && [ "$(prop planner ActiveState)" = active ] && break
        sleep 0.05
    done
    [ "$pid" != 0 ] || fail "planner not back before kill $k"
    case " $pids " in *" $pid "*) fail "planner's main PID $pid did not change before kill $k" ;; esac
    pids="$pids $pid"
    if [ -n "$killed_us" ]; then
        active_us=$(prop planner ActiveEnterTimestampMonotonic)
        back_ms="$back_ms $(((active_us - killed_us) / 1000))"
    fi
    [ "$k" = 11 ] && break
    killed_us=$(monotonic_us)
    inside kill -KILL "$pid"
    sleep 0.55
done
after=$(prop planner NRestarts)
[ "$(prop planner ActiveState)" = active ] || fail "planner not active after ten kills ($(prop planner Result))"
[ $((after - before)) = 10 ] || fail "planner restarted $((after - before)) times after ten kills"
[ "$(inside systemctl show -P ActiveState landing-clean.service)" != failed ] || fail "landing-clean failed"
sorted=$(echo "$back_ms" | tr ' ' '\n' | grep . | sort -n | tr '\n' ' ')
echo "systemd live: planner killed 10 times in 10 s, restarted 10 times, active; death to READY=1 (ms, sorted): $sorted"

# 2b. Every stage killed three times: death to READY=1 for each (docs/faults.md).
all_ms="$back_ms"
for s in $STAGES; do
    for k in 1 2 3; do
        pid=$(prop "$s" MainPID)
        [ "$pid" != 0 ] || fail "$s has no main PID before kill $k"
        killed_us=$(monotonic_us)
        inside kill -KILL "$pid"
        new=$pid
        for _ in $(seq 1 100); do
            new=$(prop "$s" MainPID)
            [ "$new" != "$pid" ] && [ "$new" != 0 ] && [ "$(prop "$s" ActiveState)" = active ] && break
            sleep 0.02
        done
        [ "$new" != "$pid" ] && [ "$(prop "$s" ActiveState)" = active ] || fail "$s not back after kill $k"
        ms=$((($(prop "$s" ActiveEnterTimestampMonotonic) - killed_us) / 1000))
        all_ms="$all_ms $ms"
        echo "systemd live: $s killed, READY=1 again after $ms ms"
        sleep 0.3
    done
done
stats=$(echo "$all_ms" | tr ' ' '\n' | grep . | sort -n | awk '{v[NR]=$1} END {
    p50 = v[int((NR + 1) / 2)]; k = int(0.95 * NR + 0.999); p95 = v[k];
    printf "%d deaths: p50 %d ms, p95 %d ms, max %d ms", NR, p50, p95, v[NR] }')
echo "systemd live: death to READY=1 under systemd, $stats"

# 3. Hung: WatchdogSec kills it and it comes back.
before=$(prop depth-map NRestarts)
pid=$(prop depth-map MainPID)
inside kill -STOP "$pid"
t0=$(date +%s%N)
for _ in $(seq 1 100); do
    new=$(prop depth-map MainPID)
    [ "$new" != "$pid" ] && [ "$new" != 0 ] && [ "$(prop depth-map ActiveState)" = active ] && break
    sleep 0.1
done
t1=$(date +%s%N)
[ "$(prop depth-map NRestarts)" -gt "$before" ] || fail "a hung depth-map was not restarted"
[ "$(prop depth-map ActiveState)" = active ] || fail "depth-map not active after its hang"
echo "systemd live: hung depth-map killed by WatchdogSec and back in $(((t1 - t0) / 1000000)) ms"

# 4. Nothing failed meanwhile.
failed=$(inside systemctl list-units --failed --plain --no-legend 'landing*' | wc -l)
[ "$failed" = 0 ] || { inside systemctl list-units --failed --no-pager >&2; fail "$failed landing units failed"; }
# 5. A unit that cannot start is given up and says so: the planner's binary replaced by
# one that exits 1 at once, the planner killed; systemd restarts it until its start limit,
# the unit fails, the system reads degraded and `landing status` names it.
rm -f "$ROOT/usr/local/bin/planner" # the running one keeps its file until it exits
printf '#!/bin/sh\nexit 1\n' >"$ROOT/usr/local/bin/planner"
chmod 0755 "$ROOT/usr/local/bin/planner"
starts_before=$(prop planner NRestarts)
inside kill -KILL "$(prop planner MainPID)"
# Failed between two restarts for a moment; given up once it stays failed (systemd 252
# keeps the last run's Result, exit-code, and logs the start limit).
given_up=""
for _ in $(seq 1 60); do
    n=$(prop planner NRestarts)
    sleep 0.5
    if [ "$(prop planner ActiveState)" = failed ] && [ "$(prop planner NRestarts)" = "$n" ]; then
        given_up=1
        break
    fi
done
[ -n "$given_up" ] || fail "a planner that cannot start is $(prop planner ActiveState) after 30 s, not given up"
result=$(prop planner Result)
inside journalctl -u landing@planner.service --no-pager 2>/dev/null | grep -q "Start request repeated too quickly" || {
    inside systemctl status landing@planner.service --no-pager -n 30 >&2 || true
    fail "the planner failed ($result) without reaching its start limit"
}
system=$(inside systemctl is-system-running 2>/dev/null || true)
[ "$system" = degraded ] || fail "the system reads $system, not degraded"
status=""
for _ in $(seq 1 20); do
    status=$(inside runuser -u landing -- env LANDING_IPC_PREFIX=landing_ /usr/local/bin/landing status 2>&1 || true)
    case "$status" in *"DEGRADED: planner is dead and not back"*) break ;; esac
    sleep 0.2
done
case "$status" in
    *"DEGRADED: planner is dead and not back"*) ;;
    *) echo "$status" >&2; fail "landing status does not say the planner is gone" ;;
esac
echo "systemd live: a planner that cannot start given up after $(($(prop planner NRestarts) - starts_before)) restarts (start limit, $result), the system degraded, landing status: DEGRADED: planner is dead and not back"

echo "systemd live: ok"
