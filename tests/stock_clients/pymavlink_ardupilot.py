"""pymavlink's mavutil (PyPI `pymavlink`, the library MAVProxy and most ArduPilot scripts are
built on) flies an ArduCopter the way its documented examples do: wait for the heartbeat,
ask for data streams with REQUEST_DATA_STREAM, GUIDED, arm, MAV_CMD_NAV_TAKEOFF, a
SET_POSITION_TARGET_LOCAL_NED move, LAND, and the disarm on touchdown.

Usage: python pymavlink_ardupilot.py PORT   (the autopilot listens with udpin on 127.0.0.1:PORT)
Exits 0 only when every step did what ArduCopter does, else 1 naming the step.
"""

import sys
import time

from pymavlink import mavutil


def step(text):
    print(f"pymavlink: {text}", flush=True)


class Gcs:
    def __init__(self, port):
        self.m = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.last_hb = 0.0

    def heartbeat(self):
        if time.time() - self.last_hb > 0.5:
            self.m.mav.heartbeat_send(
                mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
            )
            self.last_hb = time.time()

    def until(self, what, test, timeout_s):
        """Reads messages until `test(message)` gives a value (not None)."""
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            self.heartbeat()
            msg = self.m.recv_match(blocking=True, timeout=0.2)
            if msg is None:
                continue
            value = test(msg)
            if value is not None:
                return value
        raise SystemExit(f"pymavlink: FAILED waiting {timeout_s} s for {what}")

    def command(self, cmd, *params):
        p = list(params) + [0.0] * (7 - len(params))
        self.m.mav.command_long_send(self.m.target_system, self.m.target_component, cmd, 0, *p)
        result = self.until(
            f"COMMAND_ACK of {cmd}",
            lambda m: m.result if m.get_type() == "COMMAND_ACK" and m.command == cmd else None,
            5,
        )
        if result != mavutil.mavlink.MAV_RESULT_ACCEPTED:
            raise SystemExit(f"pymavlink: FAILED: command {cmd} answered {result}")


def fly(port):
    g = Gcs(port)
    g.heartbeat()
    g.until("a heartbeat", lambda m: True if m.get_type() == "HEARTBEAT" else None, 15)
    # wait_heartbeat sets target_system / component and the mode mapping.
    g.m.wait_heartbeat(timeout=5)
    step(f"heartbeat from system {g.m.target_system}, vehicle {g.m.mav_type}")
    if g.m.mode_mapping() is None or "GUIDED" not in g.m.mode_mapping():
        raise SystemExit("pymavlink: FAILED: the heartbeat does not say ArduCopter")
    g.m.mav.request_data_stream_send(
        g.m.target_system, g.m.target_component, mavutil.mavlink.MAV_DATA_STREAM_ALL, 4, 1
    )
    pos = g.until(
        "GLOBAL_POSITION_INT after REQUEST_DATA_STREAM",
        lambda m: m if m.get_type() == "GLOBAL_POSITION_INT" else None,
        10,
    )
    step(f"position lat {pos.lat / 1e7:.6f} lon {pos.lon / 1e7:.6f}")

    def healthy(m):
        if m.get_type() != "SYS_STATUS":
            return None
        want = m.onboard_control_sensors_enabled
        return True if want and (m.onboard_control_sensors_health & want) == want else None

    g.until("SYS_STATUS healthy", healthy, 60)
    step("sensors healthy")

    g.m.set_mode("GUIDED")
    g.until("GUIDED", lambda m: True if m.get_type() == "HEARTBEAT" and g.m.flightmode == "GUIDED" else None, 5)
    step("GUIDED")
    deadline = time.time() + 60
    while True:
        g.m.mav.command_long_send(
            g.m.target_system, g.m.target_component,
            mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0,
        )
        ack = g.until(
            "the arm ACK",
            lambda m: m.result
            if m.get_type() == "COMMAND_ACK"
            and m.command == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM
            else None,
            5,
        )
        if ack == mavutil.mavlink.MAV_RESULT_ACCEPTED:
            break
        if time.time() > deadline:
            raise SystemExit(f"pymavlink: FAILED: arming refused ({ack}) for 60 s")
        time.sleep(1)
    g.until("armed", lambda m: True if m.get_type() == "HEARTBEAT" and g.m.motors_armed() else None, 5)
    step("armed")
    g.command(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 3.0)
    alt = g.until(
        "the climb to 3 m",
        lambda m: m.relative_alt / 1000 if m.get_type() == "GLOBAL_POSITION_INT" and m.relative_alt > 2500 else None,
        30,
    )
    step(f"airborne at {alt:.2f} m")

    here = g.until("LOCAL_POSITION_NED", lambda m: m if m.get_type() == "LOCAL_POSITION_NED" else None, 5)
    goal = here.x + 5.0
    ignore_vel_acc_yaw = 0b0000_1101_1111_1000
    deadline = time.time() + 30
    while True:
        g.m.mav.set_position_target_local_ned_send(
            0, g.m.target_system, g.m.target_component,
            mavutil.mavlink.MAV_FRAME_LOCAL_NED, ignore_vel_acc_yaw,
            goal, here.y, -3.0, 0, 0, 0, 0, 0, 0, 0, 0,
        )
        now = g.until("LOCAL_POSITION_NED", lambda m: m if m.get_type() == "LOCAL_POSITION_NED" else None, 5)
        if abs(now.x - goal) < 0.5:
            break
        if time.time() > deadline:
            raise SystemExit(f"pymavlink: FAILED: 5 m north not reached in 30 s (at {now.x:.2f})")
    step(f"moved north to {now.x:.2f} m")

    g.m.set_mode("LAND")
    g.until("LAND", lambda m: True if m.get_type() == "HEARTBEAT" and g.m.flightmode == "LAND" else None, 5)
    step("LAND")
    g.until(
        "the disarm on touchdown",
        lambda m: True if m.get_type() == "HEARTBEAT" and not g.m.motors_armed() else None,
        60,
    )
    step("disarmed on touchdown")
    step("OK")


if __name__ == "__main__":
    fly(int(sys.argv[1]))
