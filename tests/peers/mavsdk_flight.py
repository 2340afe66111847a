#!/usr/bin/env python3
"""A second independent MAVLink peer: MAVSDK (PyPI `mavsdk` 4.x, the native C++
library behind a ctypes binding) flies the `sim` binary with its documented
sequence, as it would fly PX4 SITL: connect, arm, take off (its NAV_TAKEOFF
leaves the altitude to PX4's MIS_TAKEOFF_ALT), an initial position setpoint,
offboard.start(), fly 5 m north, land, disarm. Usage: mavsdk_flight.py PATH_TO_SIM
"""

import sys
import time

from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.action import Action
from mavsdk.plugins.offboard import Offboard, PositionNedYaw
from mavsdk.plugins.telemetry import Telemetry

from peer_common import free_port, running_sim
from peer_common import fail as peer_fail


def fail(msg):
    peer_fail("mavsdk", msg)


def wait(what, pred, timeout):
    end = time.time() + timeout
    while time.time() < end:
        if pred():
            return
        time.sleep(0.05)
    fail(what)


def main():
    if len(sys.argv) != 2:
        fail("usage: mavsdk_flight.py PATH_TO_SIM")
    sim_port, mavsdk_port = free_port(), free_port()
    with running_sim(sys.argv[1], sim_port, mavsdk_port):
        fly(mavsdk_port)
    print("mavsdk peer: 1 passed, 0 failed", flush=True)


def fly(port):
    config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
    drone = Mavsdk(config)
    # The simulator, like PX4 SITL's onboard link, sends to this port.
    drone.add_any_connection(f"udpin://127.0.0.1:{port}")
    system = drone.first_autopilot(15.0)
    if system is None:
        fail("no autopilot discovered")
    action, offboard, telemetry = Action(system), Offboard(system), Telemetry(system)

    def down():
        return telemetry.position_velocity_ned().position.down_m

    def north():
        return telemetry.position_velocity_ned().position.north_m

    wait("no position telemetry", lambda: telemetry.position_velocity_ned() is not None, 5)
    action.arm()
    wait("not armed", telemetry.armed, 5)
    action.takeoff()
    # MIS_TAKEOFF_ALT (2.5 m) above where it stands.
    wait("did not climb to 2.5 m", lambda: down() < -2.2, 20)

    # MAVSDK's documented offboard sequence: one setpoint first, then start.
    offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -2.5, 0.0))
    offboard.start()
    wait("offboard not active", offboard.is_active, 5)
    offboard.set_position_ned(PositionNedYaw(5.0, 0.0, -2.5, 0.0))
    wait("did not fly 5 m north", lambda: abs(north() - 5.0) < 0.3 and abs(down() + 2.5) < 0.3, 20)

    action.land()
    wait("did not land and disarm", lambda: not telemetry.armed(), 40)
    if abs(north() - 5.0) > 0.7:
        fail(f"landed at north {north():.2f} m, not where it was")


if __name__ == "__main__":
    main()
