#!/usr/bin/env python3
"""Reads an MCAP file with the mcap package (1.x) and prints what it found as JSON.

    mcap_read.py FILE

The JSON has, per channel topic, its schema name and encoding, its message encoding, the
number of messages read by iterating the file ("count") and the number the summary's
statistics give ("summary_count"); plus the total, the first and last log times, the
header's profile and library. "error" on failure (exit 1).
"""

import json
import sys

from mcap.reader import make_reader


def main():
    if len(sys.argv) != 2:
        print(json.dumps({"error": "usage: mcap_read.py FILE"}))
        return 1
    try:
        with open(sys.argv[1], "rb") as f:
            reader = make_reader(f)
            header = reader.get_header()
            summary = reader.get_summary()
            if summary is None:
                raise ValueError("no summary section")
            channels = {}
            for channel in summary.channels.values():
                schema = summary.schemas.get(channel.schema_id)
                channels[channel.topic] = {
                    "schema": schema.name if schema else None,
                    "schema_encoding": schema.encoding if schema else None,
                    "message_encoding": channel.message_encoding,
                    "count": 0,
                    "summary_count": summary.statistics.channel_message_counts.get(
                        channel.id, 0
                    )
                    if summary.statistics
                    else None,
                }
            total = 0
            first = last = None
            for _schema, channel, message in reader.iter_messages(log_time_order=False):
                channels[channel.topic]["count"] += 1
                total += 1
                first = message.log_time if first is None else min(first, message.log_time)
                last = message.log_time if last is None else max(last, message.log_time)
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
            },
            sort_keys=True,
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
