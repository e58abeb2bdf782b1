"""MAVSDK (PyPI `mavsdk`, the real C++ library through its Python binding) flies a PX4
autopilot the way its examples do: connect, wait for health, arm, take off, OFFBOARD move
with position setpoints, land, and wait for the disarm on touchdown.

Usage: python mavsdk_px4.py PORT   (the autopilot listens with udpin on 127.0.0.1:PORT)
Prints one line per step; exits 0 only when every step did what a PX4 does, else 1 with the
step that failed.
"""

import asyncio
import sys

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync


def step(text):
    print(f"mavsdk: {text}", flush=True)


async def until(what, poll, timeout_s):
    """Polls `poll()` (async, returns a value or None) until it gives a value."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while loop.time() < deadline:
        value = await poll()
        if value is not None:
            return value
        await asyncio.sleep(0.2)
    raise SystemExit(f"mavsdk: FAILED waiting {timeout_s} s for {what}")


async def fly(port):
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=15.0)
        if system is None:
            raise SystemExit("mavsdk: FAILED: no autopilot found within 15 s")
        step(f"autopilot found, type {await system.autopilot_type()}")
        action, offboard, telemetry = (
            ActionAsync(system),
            OffboardAsync(system),
            TelemetryAsync(system),
        )

        async def healthy():
            return True if await telemetry.health_all_ok() else None

        await until("health all OK", healthy, 30)
        step("health all OK")
        home = await telemetry.home()
        step(f"home lat {home.latitude_deg:.6f} lon {home.longitude_deg:.6f}")

        await action.set_takeoff_altitude(3.0)
        await action.arm()
        step("armed")
        await action.takeoff()
        step("takeoff accepted")

        async def climbed():
            pv = await telemetry.position_velocity_ned()
            return pv.position.down_m if pv.position.down_m < -2.5 else None

        down = await until("the climb to 3 m", climbed, 30)
        step(f"airborne, down {down:.2f} m")

        here = (await telemetry.position_velocity_ned()).position
        await offboard.set_position_ned(PositionNedYaw(here.north_m, here.east_m, -3.0, 0.0))
        await offboard.start()
        step("offboard started")
        goal_north = here.north_m + 5.0
        await offboard.set_position_ned(PositionNedYaw(goal_north, here.east_m, -3.0, 0.0))

        async def arrived():
            pv = await telemetry.position_velocity_ned()
            return pv.position.north_m if abs(pv.position.north_m - goal_north) < 0.5 else None

        north = await until("the offboard move 5 m north", arrived, 30)
        step(f"moved north to {north:.2f} m")
        await offboard.stop()

        await action.land()
        step("land accepted")

        async def disarmed():
            return True if not await telemetry.armed() else None

        await until("the disarm on touchdown", disarmed, 60)
        landed = await telemetry.landed_state()
        step(f"disarmed on touchdown, landed state {landed.name}")
        if landed.name != "ON_GROUND":
            raise SystemExit(f"mavsdk: FAILED: landed state {landed.name}, not ON_GROUND")
        step("OK")


if __name__ == "__main__":
    asyncio.run(fly(int(sys.argv[1])))
