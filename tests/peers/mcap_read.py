#!/usr/bin/env python3
"""Reads an MCAP file with the mcap package and prints what it found as JSON.

    mcap_read.py FILE

Tested with mcap 1.6.0 and mcap-protobuf-support 0.6.0. The JSON has, per channel topic, its
schema name and encoding, its message encoding, the number of messages read by iterating the
file ("count"), the number the summary's statistics give ("summary_count") and the number
decoded with the protobuf schema stored in the file ("decoded", by mcap-protobuf-support, i.e.
Google's protobuf runtime building the message classes from the file's FileDescriptorSets);
the total, the first and last log times, the header's profile and library; and "samples", a
few decoded fields: the first message of /rfloc/pose (frame, position, heading quaternion z/w)
and of /rfloc/link (device, direction name, bytes in hex). "error" on failure (exit 1).
"""

import json
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def samples_of(topic, proto, samples):
    if topic == "/rfloc/pose" and topic not in samples:
        p = proto.pose
        samples[topic] = {
            "frame_id": proto.frame_id,
            "x": p.position.x,
            "y": p.position.y,
            "qz": p.orientation.z,
            "qw": p.orientation.w,
            "log_time_ns": proto.timestamp.seconds * 1_000_000_000 + proto.timestamp.nanos,
        }
    elif topic == "/rfloc/link" and topic not in samples:
        samples[topic] = {
            "device": proto.device,
            "direction": proto.DESCRIPTOR.fields_by_name["direction"]
            .enum_type.values_by_number[proto.direction]
            .name,
            "data_hex": proto.data.hex(),
        }


def main():
    if len(sys.argv) != 2:
        print(json.dumps({"error": "usage: mcap_read.py FILE"}))
        return 1
    try:
        with open(sys.argv[1], "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            header = reader.get_header()
            summary = reader.get_summary()
            if summary is None:
                raise ValueError("no summary section")
            stats = summary.statistics.channel_message_counts if summary.statistics else {}
            channels = {}
            for channel in summary.channels.values():
                schema = summary.schemas.get(channel.schema_id)
                channels[channel.topic] = {
                    "schema": schema.name if schema else None,
                    "schema_encoding": schema.encoding if schema else None,
                    "message_encoding": channel.message_encoding,
                    "count": 0,
                    "decoded": 0,
                    "summary_count": stats.get(channel.id, 0),
                }
            total = 0
            first = last = None
            for _schema, channel, message in reader.iter_messages(log_time_order=False):
                channels[channel.topic]["count"] += 1
                total += 1
                first = message.log_time if first is None else min(first, message.log_time)
                last = message.log_time if last is None else max(last, message.log_time)
            samples = {}
            for _schema, channel, _message, proto in reader.iter_decoded_messages(
                log_time_order=False
            ):
                channels[channel.topic]["decoded"] += 1
                samples_of(channel.topic, proto, samples)
    except Exception as e:  # noqa: BLE001 - any failure is reported as JSON
        print(json.dumps({"error": f"{type(e).__name__}: {e}"}))
        return 1
    print(
        json.dumps(
            {
                "profile": header.profile,
                "library": header.library,
                "channels": channels,
                "message_count": total,
                "first_log_time": first,
                "last_log_time": last,
                "samples": samples,
            },
            sort_keys=True,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
