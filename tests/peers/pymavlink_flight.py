#!/usr/bin/env python3
"""An independent MAVLink peer flies the simulator the way a companion flies PX4 SITL.

pymavlink (not this project's code) connects over UDP, decodes the autopilot's PX4
custom modes with its own PX4 mode table, arms, takes off, streams offboard setpoints,
switches to OFFBOARD, flies 5 m, and lands. Usage: pymavlink_flight.py PATH_TO_SIM
"""
import sys
import time

from pymavlink import mavutil

from peer_common import free_port, running_sim
from peer_common import fail as peer_fail


def fail(msg):
    peer_fail("pymavlink", msg)


def main():
    if len(sys.argv) != 2:
        fail("usage: pymavlink_flight.py PATH_TO_SIM")
    port, companion = free_port(), free_port()
    # The simulator takes datagrams from its companion's address only (as px4-link takes
    # them from the autopilot's): pymavlink listens there and answers from there.
    with running_sim(sys.argv[1], port, companion):
        fly(companion)
    print("pymavlink peer: 1 passed, 0 failed")


def fly(companion):
    time.sleep(0.5)
    m = mavutil.mavlink_connection(f"udpin:127.0.0.1:{companion}", source_system=1,
                                   source_component=191)
    deadline = time.time() + 10
    hb = None
    while hb is None and time.time() < deadline:
        m.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                             mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
    if hb is None:
        fail("no HEARTBEAT")
    if hb.autopilot != mavutil.mavlink.MAV_AUTOPILOT_PX4:
        fail(f"autopilot {hb.autopilot}, expected PX4")
    m.target_system, m.target_component = 1, 1

    def command(cmd, p1=0, p2=0, p7=float("nan")):
        m.mav.command_long_send(1, 1, cmd, 0, p1, p2, 0, float("nan"), float("nan"),
                                float("nan"), p7)
        end = time.time() + 5
        while time.time() < end:
            a = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.5)
            if a is not None and a.command == cmd:
                return a.result
        fail(f"no COMMAND_ACK for {cmd}")

    def wait_mode(name, timeout):
        end = time.time() + timeout
        while time.time() < end:
            if m.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5) is not None \
                    and m.flightmode == name:
                return
        fail(f"mode {name} not reached (pymavlink reads {m.flightmode})")

    def wait_position(pred, timeout, what):
        end = time.time() + timeout
        while time.time() < end:
            p = m.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.5)
            if p is not None and pred(p):
                return p
            if stream is not None:
                stream()
        fail(what)

    stream = None
    # NAV_TAKEOFF's param7 is an altitude above mean sea level (PX4's takeoff.cpp):
    # the home altitude plus 2 m, as a ground station computes it.
    home = m.recv_match(type="HOME_POSITION", blocking=True, timeout=5)
    if home is None:
        fail("no HOME_POSITION")
    home_amsl = home.altitude / 1000.0
    if command(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) != 0:
        fail("arming refused")
    if command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, p7=home_amsl + 2.0) != 0:
        fail("takeoff refused")
    wait_mode("TAKEOFF", 5)
    wait_position(lambda p: p.z < -1.8, 15, "did not climb to 2 m")
    wait_mode("LOITER", 10)

    target = (5.0, 0.0, -2.0)
    last = [0.0]

    def send_setpoint():
        now = time.time()
        if now - last[0] >= 0.05:
            last[0] = now
            m.mav.set_position_target_local_ned_send(
                0, 1, 1, mavutil.mavlink.MAV_FRAME_LOCAL_NED, 0b0000110111111000,
                target[0], target[1], target[2], 0, 0, 0, 0, 0, 0, 0, 0)

    stream = send_setpoint
    end = time.time() + 1.5
    while time.time() < end:
        send_setpoint()
        time.sleep(0.01)
    # pymavlink packs PX4's DO_SET_MODE from its own mode table.
    m.set_mode("OFFBOARD")
    end = time.time() + 5
    while m.flightmode != "OFFBOARD" and time.time() < end:
        send_setpoint()
        m.recv_match(type="HEARTBEAT", blocking=True, timeout=0.1)
    if m.flightmode != "OFFBOARD":
        fail(f"OFFBOARD not entered (pymavlink reads {m.flightmode})")
    wait_position(lambda p: abs(p.x - 5.0) < 0.3 and abs(p.y) < 0.3, 20, "did not fly 5 m north")
    stream = None
    if command(mavutil.mavlink.MAV_CMD_NAV_LAND) != 0:
        fail("land refused")
    wait_mode("LAND", 5)
    end = time.time() + 30
    while time.time() < end:
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        if hb is not None and not hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            return
    fail("did not land and disarm")


if __name__ == "__main__":
    main()
