#!/usr/bin/env python3
"""Drives an XBee on a serial port with digi-xbee 1.5.0 and prints what it saw as JSON.

    xbee_digi.py PORT --api-mode {1,2} --flavor {zigbee,802.15.4} [--baud 9600]

Steps: XBeeDevice(PORT, baud).open() (digi-xbee reads AP, HV, VR, SH, SL, NI, MY, CE),
flat network discovery (NT/N?, ND), local DB and NI, then DB and NI of every discovered
node by remote AT. The JSON has the protocol digi-xbee decided on, the local node's
addresses and role, the nodes found and the remote readings; "error" on failure (exit 1).
"""

import argparse
import json
import sys
import time

from digi.xbee.devices import XBeeDevice
from digi.xbee.models.mode import OperatingMode


def hexs(value):
    return value.hex().upper() if value is not None else None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("port")
    ap.add_argument("--api-mode", type=int, choices=(1, 2), default=1)
    ap.add_argument("--flavor", choices=("zigbee", "802.15.4"), default="zigbee")
    ap.add_argument("--baud", type=int, default=9600)
    ap.add_argument("--discovery-timeout", type=float, default=10.0)
    args = ap.parse_args()

    out = {"port": args.port, "api_mode": args.api_mode, "flavor": args.flavor}
    device = XBeeDevice(args.port, args.baud)
    try:
        device.open()
        out["operating_mode"] = device.operating_mode.name
        out["protocol"] = device.get_protocol().name
        out["hardware_version"] = device.get_hardware_version().code
        out["firmware_version"] = hexs(device.get_firmware_version())
        out["address64"] = str(device.get_64bit_addr())
        out["address16"] = str(device.get_16bit_addr())
        out["node_id"] = device.get_node_id()
        out["role"] = device.get_role().name
        out["api_output_mode"] = hexs(device.get_parameter("AO"))

        network = device.get_network()
        network.start_discovery_process()
        deadline = time.monotonic() + args.discovery_timeout
        while network.is_discovery_running() and time.monotonic() < deadline:
            time.sleep(0.05)
        nodes = network.get_devices()
        out["discovery_finished"] = not network.is_discovery_running()

        out["local_db"] = device.get_parameter("DB")[0]
        out["local_ni"] = device.get_parameter("NI").decode("utf-8", "replace")

        remotes = []
        for node in sorted(nodes, key=lambda n: str(n.get_64bit_addr())):
            db = node.get_parameter("DB")
            ni = node.get_parameter("NI")
            remotes.append({
                "address64": str(node.get_64bit_addr()),
                "address16": str(node.get_16bit_addr()),
                "node_id": node.get_node_id(),
                "remote_db": db[0],
                "remote_ni": ni.decode("utf-8", "replace"),
            })
        out["nodes"] = remotes
    except Exception as exc:  # reported as JSON for the caller to assert on
        out["error"] = "%s: %s" % (type(exc).__name__, exc)
    finally:
        if device.is_open():
            device.close()
    print(json.dumps(out, sort_keys=True))
    return 1 if "error" in out else 0


if __name__ == "__main__":
    sys.exit(main())
