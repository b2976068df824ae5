"""Drive the stub with the official xArm Python SDK (xarm-python-sdk) and print what it saw.

Usage: python xarm_sdk_peer.py '<json args>'
args: host, cmd_port, report ports (real, normal, rich, realtime), q0, q1 (start and goal of a
servo_j stream, rad), limit_q (a servo target just beyond a joint limit), collide_q (a goal whose
path hits the scene). After the collision: clean, motion_enable and set_mode(1) without
set_state(0) (servo_j must not move the arm), set_state(0) (it moves again), a servo_j step too
fast for the firmware (error 24), and recovery. The SDK is used with its defaults; only its port constants are set from the
arguments (a no-op when the stub runs on the box's own ports). The last line printed is one JSON
object with everything the Rust test checks.
"""
import json
import socket
import sys
import time

args = json.loads(sys.argv[1])

try:
    from xarm.core.config.x_config import XCONF
    from xarm.wrapper import XArmAPI
    from xarm.x3.report import ReportDataStructure
except ImportError as e:  # pragma: no cover
    print(json.dumps({"fatal": "xarm-python-sdk missing (run make setup): {}".format(e)}))
    sys.exit(3)

XCONF.SocketConf.TCP_CONTROL_PORT = args["cmd_port"]
XCONF.SocketConf.TCP_REPORT_REAL_PORT = args["real_port"]
XCONF.SocketConf.TCP_REPORT_NORM_PORT = args["normal_port"]
XCONF.SocketConf.TCP_REPORT_RICH_PORT = args["rich_port"]
XCONF.SocketConf.TCP_REPORT_RT_PORT = args["realtime_port"]

out = {}
reports = []


def on_location(data):
    reports.append((time.monotonic(), list(data.get("joints", []))))


def read_raw_report(port, kind_port):
    """One report frame read with the SDK's own report structure."""
    s = socket.create_connection((args["host"], port), timeout=2)
    try:
        buf = b""
        while len(buf) < 4:
            buf += s.recv(4 - len(buf))
        size = int.from_bytes(buf[:4], "big")
        while len(buf) < size:
            buf += s.recv(size - len(buf))
        rd = ReportDataStructure.create(kind_port, is_radian=True)
        rd.update(buf[:size])
        return {"size": size, "state": rd.state, "mode": rd.mode,
                "angles": list(rd.actual_joint_angle)}
    finally:
        s.close()


def stream(arm, q_from, q_to, steps, period=0.01):
    codes = []
    for i in range(1, steps + 1):
        q = [a + (b - a) * i / steps for a, b in zip(q_from, q_to)]
        codes.append(arm.set_servo_angle_j(q, is_radian=True))
        time.sleep(period)
    return codes


def enable(arm):
    return [arm.clean_error(), arm.clean_warn(), arm.motion_enable(enable=True),
            arm.set_mode(1), arm.set_state(0)]


arm = XArmAPI(args["host"], is_radian=True)
out["connected"] = arm.connected
out["reported"] = arm._arm.reported  # report socket connected (no public accessor)
out["version"] = arm.version
out["version_number"] = list(arm.version_number)
out["sn"] = arm.sn
arm.register_report_location_callback(on_location, report_cartesian=False, report_joints=True)
out["enable_codes"] = enable(arm)
time.sleep(0.3)
out["state_after_enable"] = arm.get_state()[1]
out["mode_after_enable"] = arm.mode

codes = stream(arm, args["q0"], args["q1"], 100)
out["servo_codes"] = sorted(set(codes))
time.sleep(0.6)
mark = time.monotonic()
time.sleep(0.5)
code, angles = arm.get_servo_angle(is_radian=True)
out["get_servo_angle"] = {"code": code, "angles": angles}
late = [a for (t, a) in reports if t >= mark]
out["report_angles"] = late[-1] if late else None
out["reports_seen"] = len(reports)
out["raw_real"] = read_raw_report(args["real_port"], 30003)
out["raw_normal"] = read_raw_report(args["normal_port"], 30001)

# A servo target just beyond a joint limit (within the SDK's own 0.1 degree tolerance, so the
# SDK sends it and the box must refuse it).
code = arm.set_servo_angle_j(args["limit_q"], is_radian=True)
time.sleep(0.5)
out["limit"] = {"servo_code": code, "err_warn": arm.get_err_warn_code(),
                "state": arm.get_state()[1], "report_error": arm.error_code}

# Collision with the scene.
out["recover_codes"] = enable(arm)
time.sleep(0.3)
start = arm.get_servo_angle(is_radian=True)[1]
codes = stream(arm, start, args["collide_q"], args.get("collide_steps", 150))
time.sleep(0.5)
out["collision"] = {"servo_codes": sorted(set(codes)), "err_warn": arm.get_err_warn_code(),
                    "state": arm.get_state()[1], "report_error": arm.error_code}
# The SDK's own joint-limit check follows the serial number: J4 at -0.15 rad is inside the first
# arms' table but beyond a current arm's (-0.10472), so the SDK refuses it without sending (-8).
probe = list(args["q1"])
probe[3] = -0.15
out["sdk_range_check"] = arm.set_servo_angle_j(probe, is_radian=True)


def moved_from(q):
    now = arm.get_servo_angle(is_radian=True)[1]
    return max(abs(a - b) for a, b in zip(now[:7], q[:7]))


# System reset: after the collision, clean the error, enable and set mode 1 but do not
# set_state(0): the box stays stopped and servo_j moves nothing.
seq = {}
seq["clean_error"] = arm.clean_error()
seq["state_after_clean"] = arm.get_state()[1]
seq["motion_enable"] = arm.motion_enable(enable=True)
seq["set_mode"] = arm.set_mode(1)
time.sleep(0.3)
seq["state_after_mode"] = arm.get_state()[1]
here = arm.get_servo_angle(is_radian=True)[1][:7]
away = list(here)
away[0] -= 0.02  # joint 1 back, away from the wall
seq["servo_without_state0"] = arm.set_servo_angle_j(away, is_radian=True)
time.sleep(0.3)
seq["moved_without_state0"] = moved_from(here)
seq["set_state0"] = arm.set_state(0)
time.sleep(0.1)
seq["state_after_state0"] = arm.get_state()[1]
seq["servo_after_state0"] = sorted(set(stream(arm, here, away, 20)))
time.sleep(0.3)
seq["moved_after_state0"] = moved_from(here)

# A step the firmware refuses: 0.3 rad on joint 7 right after a setpoint (> 180 deg/s).
cur = arm.get_servo_angle(is_radian=True)[1][:7]
arm.set_servo_angle_j(cur, is_radian=True)
jump = list(cur)
jump[6] += 0.3
seq["speed_servo_code"] = arm.set_servo_angle_j(jump, is_radian=True)
time.sleep(0.4)
seq["speed_err_warn"] = arm.get_err_warn_code()
seq["speed_state"] = arm.get_state()[1]
seq["speed_report_error"] = arm.error_code
seq["speed_moved_j7"] = abs(arm.get_servo_angle(is_radian=True)[1][6] - cur[6])

# Recovery: the SDK's enable sequence makes the arm ready again.
seq["recover_codes"] = enable(arm)
time.sleep(0.4)
seq["recovered_state"] = arm.get_state()[1]
seq["recovered_err_warn"] = arm.get_err_warn_code()
seq["recovered_report_error"] = arm.error_code
seq["recovered_servo"] = arm.set_servo_angle_j(cur, is_radian=True)
out["reset_sequence"] = seq
arm.disconnect()
print(json.dumps(out))
