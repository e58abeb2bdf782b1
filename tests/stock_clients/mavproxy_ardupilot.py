"""MAVProxy itself (PyPI `MAVProxy`), typed at as an operator would: it connects to an
ArduCopter, asks for its data streams, and is told `mode GUIDED`, `arm throttle`,
`takeoff 3`, then `mode LAND`. What MAVProxy heard is read, with pymavlink, from what it
forwards to a GCS on its `--out` (live: its own tlog is written in buffered blocks that a
stopped MAVProxy may not have flushed): the position stream it asked for, GUIDED, armed,
the climb, LAND and the disarm.

Usage: python mavproxy_ardupilot.py PORT WORKDIR   (the autopilot listens with udpin on
127.0.0.1:PORT). Exits 0 only when what it forwarded shows every step, else 1 naming the missing one.
"""

import os
import socket
import subprocess
import sys
import threading
import time

from pymavlink import mavutil


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def forwarded(out_port, into, stop):
    """Keeps every message MAVProxy forwards to its output on `out_port`."""
    gcs = mavutil.mavlink_connection(f"udpin:127.0.0.1:{out_port}")
    while not stop.is_set():
        m = gcs.recv_match(blocking=True, timeout=0.2)
        if m is not None:
            into.append((m, gcs.flightmode))


def main(port, workdir):
    tlog = os.path.join(workdir, "mavproxy.tlog")
    mavproxy = os.path.join(os.path.dirname(sys.executable), "mavproxy.py")
    out_port = free_udp_port()
    heard, stop = [], threading.Event()
    listener = threading.Thread(target=forwarded, args=(out_port, heard, stop), daemon=True)
    listener.start()
    proc = subprocess.Popen(
        [sys.executable, mavproxy, f"--master=udpout:127.0.0.1:{port}",
         f"--out=udpout:127.0.0.1:{out_port}", f"--logfile={tlog}",
         "--streamrate=4", "--default-modules=mode,cmdlong,arm", f"--state-basedir={workdir}"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True, cwd=workdir,
    )
    said = []

    def read():
        for line in proc.stdout:
            said.append(line.rstrip())
            print(f"mavproxy> {line.rstrip()}", flush=True)

    threading.Thread(target=read, daemon=True).start()

    def wait_for(text, timeout_s):
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            if any(text in s for s in said):
                return
            time.sleep(0.2)
        raise SystemExit(f"mavproxy: FAILED: MAVProxy never said {text!r} within {timeout_s} s")

    def type_(line):
        print(f"mavproxy< {line}", flush=True)
        proc.stdin.write(line + "\n")
        proc.stdin.flush()

    try:
        wait_for("online system", 20)
        time.sleep(2)
        type_("mode GUIDED")
        wait_for("GUIDED", 10)
        for _ in range(30):
            type_("arm throttle")
            time.sleep(2)
            if any("ARMED" in s and "DISARMED" not in s for s in said):
                break
        wait_for("ARMED", 5)
        type_("takeoff 3")
        time.sleep(10)
        type_("mode LAND")
        deadline = time.time() + 60
        while time.time() < deadline and not any("DISARMED" in s for s in said):
            time.sleep(0.5)
        time.sleep(1)
    finally:
        stop.set()
        listener.join(timeout=5)
        # MAVProxy has no quit command on a piped console; it ends on SIGTERM.
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    check(heard)


def check(heard):
    positions, modes, armed_seen, disarmed_after_armed, max_alt = 0, set(), False, False, 0.0
    for m, flightmode in heard:
        kind = m.get_type()
        if kind == "GLOBAL_POSITION_INT":
            positions += 1
            max_alt = max(max_alt, m.relative_alt / 1000)
        elif kind == "HEARTBEAT" and m.get_srcSystem() == 1 and m.type != mavutil.mavlink.MAV_TYPE_GCS:
            modes.add(flightmode)
            armed = bool(m.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            armed_seen |= armed
            disarmed_after_armed |= armed_seen and not armed
    print(f"mavproxy: forwarded: {positions} GLOBAL_POSITION_INT, modes {sorted(modes)}, "
          f"highest {max_alt:.2f} m, armed {armed_seen}, disarmed after {disarmed_after_armed}")
    for ok, what in [
        # A vehicle that ignores REQUEST_DATA_STREAM sends none (the fault this guards);
        # the stream over the ~25 s flight gives well over ten.
        (positions >= 10, "the position stream MAVProxy asked for (REQUEST_DATA_STREAM)"),
        ("GUIDED" in modes, "GUIDED"),
        (armed_seen, "armed"),
        (max_alt > 2.5, "the climb to 3 m"),
        ("LAND" in modes, "LAND"),
        (disarmed_after_armed, "the disarm on touchdown"),
    ]:
        if not ok:
            raise SystemExit(f"mavproxy: FAILED: what MAVProxy forwarded does not show {what}")
    print("mavproxy: OK", flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2])
