"""PX4's side of the simulator API, played by pymavlink against `sim --px4-sitl`.

As PX4 v1.16's simulator_mavlink does, it connects over TCP, says HEARTBEAT, reads
HIL_SENSOR and answers each with HIL_ACTUATOR_CONTROLS (lockstep). It checks what a
PX4 developer relies on: the clock steps 4 ms per HIL_SENSOR and stops while PX4 owes
an answer; the IMU is specific force and rates in FRD (about -9.81 m/s^2 on z at rest),
the magnetometer in gauss, the barometer in hPa at the site's altitude;
HIL_STATE_QUATERNION comes at 50 Hz; the iris lifts off above its hover throttle, holds
its vertical speed at it (thrust = weight), and yaws clockwise (FRD z rate > 0) when its
counter-clockwise motors (1, 2) spin faster than its clockwise ones.

Usage: python3 tests/peers/px4_sitl_peer.py target/release/sim
"""

import os
import socket
import subprocess
import sys
import tempfile
import time
import tomllib

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from peer_common import fail, free_port  # noqa: E402

PEER = "px4-sitl"
STEP_US = 4000
G = 9.80665
DEPLOY = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "deploy")
with open(os.path.join(DEPLOY, "config", "airframes", "iris.toml"), "rb") as _f:
    IRIS = tomllib.load(_f)["airframe"]
MASS = IRIS["mass_kg"]
# Full thrust of one motor: thrust_coefficient x motor_speed_max^2.
HOVER = MASS * G / (4 * IRIS["thrust_coefficient"] * IRIS["motor_speed_max_rad_s"] ** 2)
DRAG_Z = IRIS["drag_coefficients_n_s_m"][2]
ARMED = 128 | 1  # MAV_MODE_FLAG_SAFETY_ARMED | CUSTOM_MODE_ENABLED, as PX4 sends


def isa_hpa(alt_m):
    return 1013.25 * (1.0 - 2.25577e-5 * alt_m) ** 5.25588


class Px4:
    """PX4's end of the lockstep: every HIL_SENSOR answered with the current motors."""

    def __init__(self, port):
        self.m = mavutil.mavlink_connection(
            f"tcp:127.0.0.1:{port}", source_system=1, source_component=1, retries=20)
        self.controls = [0.0] * 16
        self.mode = 1
        self.last_us = None
        self.states = []  # HIL_STATE_QUATERNION: (time_usec, msg)

    def recv_sensor(self, timeout=5.0):
        end = time.time() + timeout
        while time.time() < end:
            msg = self.m.recv_match(type=["HIL_SENSOR", "HIL_STATE_QUATERNION"],
                                    blocking=True, timeout=0.5)
            if msg is None:
                continue
            if msg.get_type() == "HIL_STATE_QUATERNION":
                self.states.append(msg)
                continue
            if self.last_us is not None and msg.time_usec - self.last_us != STEP_US:
                fail(PEER, f"HIL_SENSOR time_usec stepped {msg.time_usec - self.last_us} us, "
                           f"not {STEP_US} (250 Hz lockstep)")
            self.last_us = msg.time_usec
            return msg
        fail(PEER, "no HIL_SENSOR within 5 s")

    def answer(self, sensor):
        self.m.mav.hil_actuator_controls_send(sensor.time_usec, self.controls, self.mode, 1)

    def run(self, seconds, motors=None, armed=True):
        """Steps `seconds` of simulated time with `motors` (four values) and returns the
        sensors received."""
        if motors is not None:
            self.controls = list(motors) + [0.0] * 12
        self.mode = ARMED if armed else 1
        out = []
        for _ in range(int(round(seconds * 1e6 / STEP_US))):
            s = self.recv_sensor()
            out.append(s)
            self.answer(s)
        return out


def mean(xs):
    return sum(xs) / len(xs)


def main():
    if len(sys.argv) != 2:
        print(__doc__)
        sys.exit(2)
    port = free_port(socket.SOCK_STREAM)
    env = dict(os.environ, LANDING_LOG="warn", LANDING_IPC_PREFIX=f"px4sitl_peer_{os.getpid()}_")
    # indoor-static flown by the nominal iris (no per-seed mass error: the hover throttle
    # checked is the airframe file's).
    deploy = DEPLOY
    with open(os.path.join(deploy, "scenarios", "indoor-static.toml")) as f:
        text = f.read()
    scenario = tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False)
    scenario.write(text + "\n[airframe_errors]\nmass_spread = 0.0\n")
    scenario.close()
    sim = subprocess.Popen(
        [sys.argv[1], "--scenario", scenario.name, "--airframe", "iris", "--speed", "4",
         "--deploy-dir", deploy, "--duration-s", "120", "--px4-sitl", f"127.0.0.1:{port}"],
        env=env)
    try:
        check(Px4(port))
    finally:
        sim.terminate()
        try:
            code = sim.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sim.kill()
            fail(PEER, "the simulator did not stop on SIGTERM within 10 s")
    os.unlink(scenario.name)
    if code != 0:
        fail(PEER, f"the simulator exited {code} on SIGTERM")
    print(f"{PEER} peer: OK (hover throttle {HOVER:.3f})")


def check(px4):
    px4.m.mav.heartbeat_send(2, 12, 0, 0, 0)  # MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4

    # At rest on the ground, disarmed: units and frames.
    rest = px4.run(1.0, [0.0] * 4, armed=False)
    s = rest[-1]
    if s.id != 0:
        fail(PEER, f"HIL_SENSOR id {s.id}: PX4 steps its clock on id 0 only")
    want = 0b1101000000000 | 0b111111111
    if s.fields_updated & want != want:
        fail(PEER, f"fields_updated {s.fields_updated:#b} lacks accel, gyro, mag or baro bits")
    az = mean([x.zacc for x in rest])
    if abs(az + G) > 0.3 or abs(mean([x.xacc for x in rest])) > 0.3:
        fail(PEER, f"at rest the accelerometer reads z {az:.2f} m/s^2: want specific force "
                   f"in FRD, -{G:.2f} on z")
    if max(abs(x.xgyro) + abs(x.ygyro) + abs(x.zgyro) for x in rest) > 0.1:
        fail(PEER, "at rest the gyro reads over 0.1 rad/s")
    mag = (s.xmag**2 + s.ymag**2 + s.zmag**2) ** 0.5
    if not (0.25 < mag < 0.65) or s.zmag <= 0:
        fail(PEER, f"magnetometer |B| {mag:.3f} gauss, z {s.zmag:.3f}: want gauss, "
                   f"pointing down (+z FRD) in the northern hemisphere")
    p = mean([x.abs_pressure for x in rest])
    alt = mean([x.pressure_alt for x in rest])
    if abs(p - isa_hpa(alt)) > 0.5 or not (300 < alt < 700):
        fail(PEER, f"barometer {p:.2f} hPa at {alt:.1f} m: want hPa of the standard "
                   f"atmosphere at the site's altitude ({isa_hpa(alt):.2f})")
    n_states = len(px4.states)
    if not 45 <= n_states <= 55:
        fail(PEER, f"{n_states} HIL_STATE_QUATERNION in 1 s of simulated time, want 50")
    q = px4.states[-1].attitude_quaternion
    # indoor-static takes off facing east: NED yaw +90 deg.
    if abs(abs(q[0]) - 0.7071) > 0.05 or abs(abs(q[3]) - 0.7071) > 0.05:
        fail(PEER, f"ground-truth attitude {q}: want NED from FRD, nose east")

    # Lockstep: unanswered, the simulator waits.
    pending = px4.recv_sensor()
    late = px4.m.recv_match(type="HIL_SENSOR", blocking=True, timeout=0.5)
    if late is not None:
        fail(PEER, "a HIL_SENSOR came before PX4 answered the last one (not lockstep)")
    px4.answer(pending)

    # Above the hover throttle the iris climbs; at it, thrust equals weight.
    z0 = px4.states[-1].alt
    px4.run(0.6, [HOVER * 1.25] * 4)
    climbed_mm = px4.states[-1].alt - z0
    if climbed_mm < 50:
        fail(PEER, f"at 1.25x the hover throttle the iris rose {climbed_mm} mm in 0.6 s")
    n_before = len(px4.states)
    hover = px4.run(1.0, [HOVER] * 4)
    # Thrust = weight: what the accelerometer feels is then the weight's worth plus the
    # airframe's drag on the vertical speed (HIL_STATE_QUATERNION, cm/s NED).
    states = px4.states[n_before + 10:]
    v_up = mean([-st.vz / 100.0 for st in states])
    want = -G + DRAG_Z * v_up / MASS
    az = mean([x.zacc for x in hover[50:]])
    if abs(az - want) > 0.25:
        fail(PEER, f"at the hover throttle the accelerometer reads {az:.2f} m/s^2 on z, "
                   f"want {want:.2f} (weight plus drag at {v_up:.2f} m/s): thrust is not "
                   f"the weight")
    dv = (states[-1].vz - states[0].vz) / 100.0 / ((len(states) - 1) * 0.02)
    if abs(dv) > 0.6:
        fail(PEER, f"at the hover throttle the vertical speed changes {dv:.2f} m/s^2")

    # Counter-clockwise motors (1, 2) faster: the body yaws clockwise, FRD z rate > 0.
    d = 0.06
    spin = px4.run(0.3, [HOVER + d, HOVER + d, HOVER - d, HOVER - d])
    r = spin[-1].zgyro
    if r < 0.2:
        fail(PEER, f"motors 1, 2 (CCW) above 3, 4 (CW) gave a yaw rate of {r:.2f} rad/s "
                   f"(FRD): want clockwise, > 0.2")
    spin = px4.run(0.3, [HOVER - d, HOVER - d, HOVER + d, HOVER + d])
    if spin[-1].zgyro > r - 0.2:
        fail(PEER, "the opposite yaw torque did not turn the yaw rate back")
    print(f"{PEER} peer: rest az {mean([x.zacc for x in rest]):.2f} m/s^2, |B| {mag:.3f} G, "
          f"{p:.1f} hPa at {alt:.0f} m, {n_states} states/s, climbed {climbed_mm} mm, "
          f"hover az {az:.2f}, yaw rate {r:.2f} rad/s")


if __name__ == "__main__":
    main()
