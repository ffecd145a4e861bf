#!/usr/bin/env python3
"""A MAVSDK-Python (>= 4, the native binding) flight against `dflat sitl`
and the dflat daemon, with MAVSDK's defaults (ground station 245/190).
Run by scripts/interop-mavsdk.sh, which starts both processes:

    python3 scripts/interop_mavsdk.py udpout://127.0.0.1:PORT

Prints a table of what worked; exits 1 when a required step failed (home,
landed state, in_air, version, hold, the setpoint to 1/191 flown >= 4 m).
"""

import asyncio
import json
import math
import sys
import time

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.info import InfoAsync
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync, MavlinkMessage
from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

REQUIRED = {"home", "landed state", "in_air", "version", "hold", "setpoint to 1/191"}
RESULTS = []
TEXTS = []


async def first(gen, timeout=10.0):
    """The first item of an async generator, within `timeout` seconds."""

    async def take():
        async for x in gen:
            return x

    return await asyncio.wait_for(take(), timeout)


async def step(name, fn, timeout=30.0):
    t0 = time.monotonic()
    try:
        detail = await asyncio.wait_for(fn(), timeout)
        ok = True
    except Exception as e:  # noqa: BLE001 - every failure goes in the table
        detail, ok = f"{type(e).__name__}: {e}", False
    RESULTS.append((name, ok, str(detail), time.monotonic() - t0))
    return ok


async def position(tel):
    pv = await first(tel.subscribe_position_velocity_ned())
    return pv.position.north_m, pv.position.east_m, pv.position.down_m


async def fly_until(tel, goal, tol=0.3, timeout=20.0):
    """Waits until within `tol` m (horizontal) of `goal`; returns the distance."""
    end = time.monotonic() + timeout
    d = float("inf")
    while time.monotonic() < end:
        n, e, _ = await position(tel)
        d = math.hypot(n - goal[0], e - goal[1])
        if d < tol:
            break
        await asyncio.sleep(0.2)
    return d


async def main(url):
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(url)
        system = await mavsdk.first_autopilot(timeout_s=15.0)
        if system is None:
            RESULTS.append(("connect", False, "no autopilot in 15 s", 15.0))
            return
        comps = await system.component_ids()
        RESULTS.append(("connect", True, f"autopilot, components {comps}", 0.0))
        tel, action, info = TelemetryAsync(system), ActionAsync(system), InfoAsync(system)
        param, direct = ParamAsync(system), MavlinkDirectAsync(system)
        offboard, mission = OffboardAsync(system), MissionRawAsync(system)

        async def collect_texts():
            async for t in tel.subscribe_status_text():
                TEXTS.append(t.text)

        texts = asyncio.ensure_future(collect_texts())
        home = {}

        async def get_home():
            h = await first(tel.subscribe_home(), 15.0)
            home.update(lat=h.latitude_deg, lon=h.longitude_deg, alt=h.absolute_altitude_m)
            return f"{h.latitude_deg:.6f}, {h.longitude_deg:.6f}, {h.absolute_altitude_m:.1f} m"

        await step("position/attitude", lambda: position(tel))
        await step("home", get_home)
        await step("landed state", lambda: first(tel.subscribe_landed_state()))
        await step("in_air", lambda: first(tel.subscribe_in_air()))

        async def quaternion():
            q = await first(tel.subscribe_attitude_quaternion())
            return f"w {q.w:.3f}"

        await step("attitude quaternion", quaternion)

        async def battery():
            b = await first(tel.subscribe_battery())
            return f"{b.voltage_v} V, {b.remaining_percent} %"

        await step("battery (unknown)", battery)
        await step("flight mode", lambda: first(tel.subscribe_flight_mode()))

        async def version():
            v = await info.get_version()
            assert v.flight_sw_major or v.flight_sw_minor, "version 0.0.0"
            ident = await info.get_identification()
            return (
                f"{v.flight_sw_major}.{v.flight_sw_minor}.{v.flight_sw_patch}, "
                f"uid {ident.hardware_uid[:16]}"
            )

        await step("version", version)

        async def params():
            hover = await param.get_param_float("MPC_THR_HOVER")
            everything = await param.get_all_params()
            return f"MPC_THR_HOVER {hover}, {len(everything.float_params) + len(everything.int_params)} params"

        await step("parameters", params)

        async def setpoint_to_daemon():
            n, e, d = await position(tel)
            goal = (n + 5.0, e, d)
            fields = {
                "time_boot_ms": 0,
                "target_system": 1,
                "target_component": 191,
                "coordinate_frame": 1,
                "type_mask": 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048,
                "x": goal[0],
                "y": goal[1],
                "z": goal[2],
                "vx": 0.0, "vy": 0.0, "vz": 0.0,
                "afx": 0.0, "afy": 0.0, "afz": 0.0,
                "yaw": 0.0, "yaw_rate": 0.0,
            }
            msg = MavlinkMessage(
                message_name="SET_POSITION_TARGET_LOCAL_NED",
                system_id=245,
                component_id=190,
                target_system_id=1,
                target_component_id=191,
                fields_json=json.dumps(fields),
            )
            for _ in range(3):
                await direct.send_message(msg)
            left = await fly_until(tel, goal, tol=0.3, timeout=15.0)
            n2, e2, _ = await position(tel)
            flown = math.hypot(n2 - n, e2 - e)
            assert flown >= 4.0, f"flown {flown:.2f} m"
            return f"flown {flown:.2f} m ({left:.2f} m from the goal)"

        await step("setpoint to 1/191", setpoint_to_daemon)

        def to_daemon(name, fields):
            return MavlinkMessage(
                message_name=name,
                system_id=245,
                component_id=190,
                target_system_id=1,
                target_component_id=191,
                fields_json=json.dumps(fields),
            )

        async def circle_to_daemon():
            # A planner's stream: a 6 m circle at 4 m/s (2 s cosine speed
            # ramp) with position, velocity and acceleration at 20 Hz.
            r, v, ramp = 6.0, 4.0, 2.0
            n0, e0, d0 = await position(tel)
            cn, ce = n0 - r, e0
            k = math.pi / ramp
            errors = []
            t0 = time.monotonic()
            while (t := time.monotonic() - t0) < 12.0:
                if t < ramp:
                    s = 0.5 * v * (t - math.sin(k * t) / k)
                    sd = 0.5 * v * (1 - math.cos(k * t))
                    sdd = 0.5 * v * k * math.sin(k * t)
                else:
                    s, sd, sdd = 0.5 * v * ramp + v * (t - ramp), v, 0.0
                a = s / r
                c, si = math.cos(a), math.sin(a)
                fields = {
                    "time_boot_ms": 0,
                    "target_system": 1,
                    "target_component": 191,
                    "coordinate_frame": 1,
                    "type_mask": 1024 | 2048,  # yaw, yaw rate ignored
                    "x": cn + r * c, "y": ce + r * si, "z": d0,
                    "vx": -sd * si, "vy": sd * c, "vz": 0.0,
                    "afx": -sdd * si - sd * sd / r * c,
                    "afy": sdd * c - sd * sd / r * si,
                    "afz": 0.0,
                    "yaw": 0.0, "yaw_rate": 0.0,
                }
                await direct.send_message(to_daemon("SET_POSITION_TARGET_LOCAL_NED", fields))
                if t > ramp + 2.0:
                    n, e, _ = await position(tel)
                    errors.append(abs(math.hypot(n - cn, e - ce) - r))
                await asyncio.sleep(0.05)
            errors.sort()
            p95 = errors[int(0.95 * (len(errors) - 1))]
            assert p95 < 0.3, f"radial error p95 {p95:.3f} m"
            return f"radial error p95 {p95:.3f} m over {len(errors)} samples"

        await step("circle streamed to 1/191", circle_to_daemon, timeout=40.0)

        async def mission_to_daemon():
            # The mission protocol with 1/191 through mavlink_direct: two
            # waypoints (local NED, x/y in 1e-4 m), then MISSION_START.
            n, e, d = await position(tel)
            wps = [(n + 3.0, e, d), (n + 3.0, e + 3.0, d)]
            got = []

            async def collect(name):
                async for m in direct.subscribe_message(name):
                    if (m.system_id, m.component_id) == (1, 191):
                        got.append((name, json.loads(m.fields_json)))

            tasks = [asyncio.create_task(collect(n)) for n in ("MISSION_REQUEST_INT", "MISSION_ACK")]
            await asyncio.sleep(0.5)  # the subscriptions are registered
            try:
                await direct.send_message(to_daemon("MISSION_COUNT", {
                    "target_system": 1, "target_component": 191,
                    "count": len(wps), "mission_type": 0, "opaque_id": 0}))
                seen, ack = 0, None
                end = time.monotonic() + 5.0
                while ack is None and time.monotonic() < end:
                    for name, f in got[seen:]:
                        seen += 1
                        if name == "MISSION_ACK":
                            ack = f
                            break
                        seq = int(f["seq"])
                        x, y, z = wps[seq]
                        await direct.send_message(to_daemon("MISSION_ITEM_INT", {
                            "target_system": 1, "target_component": 191, "seq": seq,
                            "frame": 1, "command": 16, "current": 0, "autocontinue": 1,
                            "param1": 0.0, "param2": 0.5, "param3": 0.0, "param4": 0.0,
                            "x": round(x * 1e4), "y": round(y * 1e4), "z": z,
                            "mission_type": 0}))
                    await asyncio.sleep(0.02)
            finally:
                for t in tasks:
                    t.cancel()
            assert ack is not None, f"no MISSION_ACK ({len(got)} messages from 1/191)"
            assert int(ack["type"]) == 0, f"MISSION_ACK {ack['type']}"
            await direct.send_message(to_daemon("COMMAND_LONG", {
                "target_system": 1, "target_component": 191, "command": 300,
                "confirmation": 0, "param1": 0.0, "param2": 0.0, "param3": 0.0,
                "param4": 0.0, "param5": 0.0, "param6": 0.0, "param7": 0.0}))
            left = await fly_until(tel, wps[-1], tol=0.5, timeout=20.0)
            assert left < 0.5, f"{left:.2f} m from the last waypoint"
            return f"2 items accepted, flown to the last ({left:.2f} m off)"

        await step("mission to 1/191", mission_to_daemon, timeout=40.0)

        async def hold():
            await action.hold()
            await asyncio.sleep(0.5)
            mode = await first(tel.subscribe_flight_mode())
            assert mode.name == "HOLD", mode
            return mode.name

        await step("hold", hold)

        async def goto():
            assert home, "no home"
            n, e, d = await position(tel)
            lat = home["lat"] + math.degrees(8.0 / 6_371_000.0)
            await action.goto_location(lat, home["lon"], home["alt"], float("nan"))
            # 8 m north of home, at home's altitude.
            left = await fly_until(tel, (8.0 + 0.0, 0.0), tol=0.5, timeout=20.0)
            assert left < 0.5, f"{left:.2f} m from the goal"
            return f"8 m north of home, {left:.2f} m off"

        await step("goto_location", goto)

        async def rtl():
            await action.return_to_launch()
            left = await fly_until(tel, (0.0, 0.0), tol=0.5, timeout=20.0)
            assert left < 0.5, f"{left:.2f} m from home"
            mode = await first(tel.subscribe_flight_mode())
            return f"{mode.name}, {left:.2f} m from home"

        await step("return_to_launch", rtl)

        async def offboard_to_autopilot():
            n, e, d = await position(tel)
            await offboard.set_position_ned(PositionNedYaw(n, e + 3.0, d, 0.0))
            await offboard.start()
            await asyncio.sleep(4.0)
            n2, e2, _ = await position(tel)
            await offboard.stop()
            conflict = any("2 setpoint streams" in t for t in TEXTS)
            return (
                f"moved {math.hypot(n2 - n, e2 - e):.2f} m; "
                f"conflict with the daemon's stream said: {conflict}"
            )

        await step("offboard to 1/1 (+stop)", offboard_to_autopilot)

        async def mission_to_autopilot():
            try:
                await mission.upload_mission([
                    MissionItem(0, 6, 16, 1, 1, 0, 0, 0, float("nan"),
                                int(home.get("lat", 0) * 1e7), int(home.get("lon", 0) * 1e7), 10.0, 0)
                ])
                return "accepted?"
            except Exception as e:  # noqa: BLE001
                return f"answered, refused: {e}"

        await step("mission upload to 1/1", mission_to_autopilot)

        async def clear():
            await mission.clear_mission()
            return "cleared"

        await step("mission clear", clear)

        async def takeoff():
            try:
                await action.takeoff()
                return "accepted"
            except Exception as e:  # noqa: BLE001
                return f"refused: {e}"

        await step("takeoff (refused in words)", takeoff)

        async def disarm():
            await action.disarm()
            await asyncio.sleep(1.5)
            armed = await first(tel.subscribe_armed())
            assert not armed, "still armed"
            await action.arm()
            return "disarmed, re-armed"

        await step("disarm", disarm)
        await asyncio.sleep(1.0)
        texts.cancel()


def report():
    width = max(len(r[0]) for r in RESULTS)
    print()
    print(f"{'step':<{width}}  ok    time  detail")
    for name, ok, detail, dt in RESULTS:
        mark = "yes" if ok else "NO"
        print(f"{name:<{width}}  {mark:<4} {dt:5.1f}s  {detail}")
    print(f"\nSTATUSTEXTs received: {len(TEXTS)}")
    for t in dict.fromkeys(TEXTS):
        print(f"  {TEXTS.count(t)}x {t}")
    failed = [r[0] for r in RESULTS if not r[1] and r[0] in REQUIRED | {"connect"}]
    missing = REQUIRED - {r[0] for r in RESULTS}
    if failed or missing:
        print(f"\nFAILED: {sorted(set(failed) | missing)}")
        return 1
    print("\nall required steps passed")
    return 0


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "udpout://127.0.0.1:14550"))
    sys.exit(report())
