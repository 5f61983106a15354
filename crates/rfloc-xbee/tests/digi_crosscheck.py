"""Parse XBee API frames with digi-xbee 1.5.0 and print the fields as JSON, one line per case.

Input (stdin): one JSON object per line: {"id": str, "mode": 1 or 2, "wire": hex string,
"protocol": "zigbee" or "802.15.4"}. Output (stdout): one JSON object per input line with the
fields digi-xbee parsed; the Rust test rfloc-xbee/tests/digi_crosscheck.rs compares them with
rfloc-xbee's own parse. Only public packet classes are used, plus the two private ND helpers of
XBeeNetwork, the same way as in the protocol reference's section 7.2.
"""

import json
import sys

import digi.xbee
from digi.xbee.devices import XBeeNetwork
from digi.xbee.exception import InvalidPacketException
from digi.xbee.models.mode import OperatingMode
from digi.xbee.models.protocol import XBeeProtocol
from digi.xbee.packets.base import XBeeAPIPacket
from digi.xbee.packets.factory import build_frame


class _Local:
    """Stands in for the local device: __get_data_for_remote only asks for its protocol."""

    def __init__(self, protocol):
        self._protocol = protocol

    def get_protocol(self):
        return self._protocol


def _hex(value):
    if value is None:
        return ""
    return bytes(value).hex().upper()


def _code(value):
    """Enum members of digi-xbee carry their wire value in .code."""
    return value.code if hasattr(value, "code") else int(value)


def _int(value):
    """cluster_id/profile_id are ints in 1.5.0; accept bytes too."""
    return value if isinstance(value, int) else int.from_bytes(bytes(value), "big")


def _fields(pkt, frame_type):
    f = {}
    if frame_type in (0x08, 0x09):
        f.update(frame_id=pkt.frame_id, command=pkt.command, parameter=_hex(pkt.parameter))
    elif frame_type == 0x17:
        f.update(frame_id=pkt.frame_id, x64=str(pkt.x64bit_dest_addr),
                 x16=str(pkt.x16bit_dest_addr), options=pkt.transmit_options,
                 command=pkt.command, parameter=_hex(pkt.parameter))
    elif frame_type == 0x88:
        f.update(frame_id=pkt.frame_id, command=pkt.command, status=pkt.real_status,
                 value=_hex(pkt.command_value))
    elif frame_type == 0x97:
        f.update(frame_id=pkt.frame_id, x64=str(pkt.x64bit_source_addr),
                 x16=str(pkt.x16bit_source_addr), command=pkt.command,
                 status=pkt.real_status, value=_hex(pkt.command_value))
    elif frame_type == 0x8A:
        f.update(status=_code(pkt.modem_status))
    elif frame_type == 0x10:
        f.update(frame_id=pkt.frame_id, x64=str(pkt.x64bit_dest_addr),
                 x16=str(pkt.x16bit_dest_addr), radius=pkt.broadcast_radius,
                 options=pkt.transmit_options, data=_hex(pkt.rf_data))
    elif frame_type == 0x8B:
        f.update(frame_id=pkt.frame_id, x16=str(pkt.x16bit_dest_addr),
                 retries=pkt.transmit_retry_count, delivery=_code(pkt.transmit_status),
                 discovery=_code(pkt.discovery_status))
    elif frame_type == 0x90:
        f.update(x64=str(pkt.x64bit_source_addr), x16=str(pkt.x16bit_source_addr),
                 options=pkt.receive_options, data=_hex(pkt.rf_data))
    elif frame_type == 0x91:
        f.update(x64=str(pkt.x64bit_source_addr), x16=str(pkt.x16bit_source_addr),
                 src_ep=pkt.source_endpoint, dst_ep=pkt.dest_endpoint,
                 cluster=_int(pkt.cluster_id), profile=_int(pkt.profile_id),
                 options=pkt.receive_options, data=_hex(pkt.rf_data))
    return f


def _nd(pkt, protocol):
    kind = XBeeNetwork._XBeeNetwork__check_nd_packet(pkt)
    if kind == XBeeNetwork.ND_PACKET_FINISH:
        return {"kind": "finish"}
    if kind != XBeeNetwork.ND_PACKET_REMOTE:
        return None
    net = XBeeNetwork.__new__(XBeeNetwork)
    net._local_xbee = _Local(protocol)
    x16, x64, ni, role, parent = net._XBeeNetwork__get_data_for_remote(pkt.command_value)
    return {"kind": "remote", "x16": str(x16), "x64": str(x64), "ni": ni,
            "role": role.id if role is not None else None,
            "parent": str(parent) if parent is not None else None}


def parse_case(case):
    wire = bytearray.fromhex(case["wire"])
    out = {"id": case["id"]}
    if case["mode"] == 2:
        op_mode = OperatingMode.ESCAPED_API_MODE
        raw = XBeeAPIPacket.unescape_data(wire)
    else:
        op_mode = OperatingMode.API_MODE
        raw = wire
    protocol = (XBeeProtocol.RAW_802_15_4 if case.get("protocol") == "802.15.4"
                else XBeeProtocol.ZIGBEE)
    try:
        pkt = build_frame(raw, op_mode)
    except InvalidPacketException as e:
        out["rejected"] = str(e)
        return out
    frame_type = raw[3]
    out["frame_type"] = frame_type
    out["class"] = type(pkt).__name__
    out["fields"] = _fields(pkt, frame_type)
    out["output"] = pkt.output(escaped=False).hex().upper()
    out["output_escaped"] = pkt.output(escaped=True).hex().upper()
    if frame_type == 0x88 and pkt.command == "ND":
        try:
            out["nd"] = _nd(pkt, protocol)
        except (IndexError, ValueError) as e:
            out["nd_error"] = repr(e)
    return out


def main():
    sys.stderr.write("digi-xbee %s\n" % getattr(digi.xbee, "__version__", "?"))
    for line in sys.stdin:
        line = line.strip()
        if line:
            print(json.dumps(parse_case(json.loads(line))), flush=True)


if __name__ == "__main__":
    main()
