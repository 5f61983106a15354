#!/usr/bin/env python3
"""Drives a SCIP 2.0 laser on a serial port with hokuyolx 0.9.0 and prints JSON.

    urg_hokuyolx.py PORT [--scans 3]

hokuyolx talks to Ethernet sensors over TCP only, so the script bridges PORT (pyserial)
to a loopback TCP socket and hands that address to hokuyolx's default constructor
(time synchronisation with %ST/TM0/TM1/TM2, PP, BM). Then get_dist at groupings 0, 1, 3
(GD), iter_dist over MD for a few scans, standby (QT) and the laser state (%ST). The JSON
has the sensor parameters hokuyolx read, per-grouping value counts and the front range,
the MD scans' value counts and remaining-scan counters; "error" on failure (exit 1).
"""

import argparse
import json
import socket
import sys
import threading

import serial
from hokuyolx import HokuyoLX


def bridge(port_path):
    """Serves one TCP client on 127.0.0.1 and copies bytes to and from the serial port."""
    ser = serial.Serial(port_path, 115200, timeout=0.05)
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    stop = threading.Event()

    def run():
        conn, _ = server.accept()
        conn.settimeout(0.05)

        def from_serial():
            while not stop.is_set():
                data = ser.read(ser.in_waiting or 1)
                if data:
                    conn.sendall(data)

        pump = threading.Thread(target=from_serial, daemon=True)
        pump.start()
        while not stop.is_set():
            try:
                data = conn.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                break
            if not data:
                break
            ser.write(data)
            ser.flush()
        stop.set()
        pump.join(1)
        conn.close()

    threading.Thread(target=run, daemon=True).start()
    return server.getsockname(), stop, ser


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("port")
    ap.add_argument("--scans", type=int, default=3)
    args = ap.parse_args()

    out = {"port": args.port}
    addr, stop, ser = bridge(args.port)
    laser = None
    try:
        laser = HokuyoLX(addr=addr)
        out["model"] = laser.model
        out["params"] = {
            "amin": laser.amin, "amax": laser.amax, "ares": laser.ares,
            "aforw": laser.aforw, "dmin": laser.dmin, "dmax": laser.dmax,
            "scan_freq": laser.scan_freq,
        }
        out["state_after_open"] = laser.laser_state()[0]
        front = laser.aforw - laser.amin
        dist = {}
        for grouping in (0, 1, 3):
            timestamp, scan = laser.get_dist(grouping=grouping)
            step = max(grouping, 1)
            dist[str(grouping)] = {
                "values": int(len(scan)),
                "front_mm": int(scan[front // step]),
                "timestamp_ms": int(timestamp),
            }
        out["get_dist"] = dist
        md = []
        for scan, timestamp, pending in laser.iter_dist(scans=args.scans):
            md.append({"values": int(len(scan)), "pending": pending,
                       "front_mm": int(scan[front]), "timestamp_ms": int(timestamp)})
        out["iter_dist"] = md
        out["state_after_md"] = laser.laser_state()[0]
        laser.activate()
        laser.standby()
        out["state_after_standby"] = laser.laser_state()[0]
        out["version"] = laser.version()
    except Exception as exc:  # reported as JSON for the caller to assert on
        out["error"] = "%s: %s" % (type(exc).__name__, exc)
    finally:
        if laser is not None:
            laser.close()
        stop.set()
        ser.close()
    print(json.dumps(out, sort_keys=True))
    return 1 if "error" in out else 0


if __name__ == "__main__":
    sys.exit(main())
