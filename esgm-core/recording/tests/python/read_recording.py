#!/usr/bin/env python3
"""An independent reader of esgm recordings: the `mcap` package from PyPI, not esgm.

Usage: read_recording.py FILE.mcap

Reads the file twice, as Foxglove-style tools do:
  1. the summary section (it must exist, with a Statistics record), and
  2. every record of the data section, linearly, checking chunk and data CRCs.
Every message must have its channel, and that channel its schema. Messages of the
view encodings are decoded as the file's schemas say: `protobuf` through the schema's
FileDescriptorSet (mcap-protobuf-support), `json` with json.loads and validated against
the channel's JSON Schema (jsonschema). Messages in any other encoding (esgm's own
lossless channels) are read and counted but not decoded. The message counts and times
seen must equal the summary's statistics.

Prints one JSON object to stdout:
  summary              statistics counts and times, and the summary's own record counts
  header               profile and library
  schemas              [{id, name, encoding}]
  channels             [{id, topic, message_encoding, schema_name, metadata}]
  messages_per_topic   {topic: n}
  not_decoded_per_topic  {topic: n} for topics in encodings this reader does not decode
  first_image          the first foxglove.RawImage message in file order, or null:
                       {topic, width, height, encoding, step, frame_id, data_length,
                        first_pixel, last_pixel, timestamp_ns, log_time_ns}
  first_json           {topic: first decoded message} for every json topic
On any failure it prints one line naming the file and the problem to stderr and exits 1.
"""

import json
import sys

import jsonschema
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

RAW_IMAGE = "foxglove.RawImage"

# Bytes per pixel of Foxglove's RawImage encodings.
BYTES_PER_PIXEL = {
    "mono8": 1,
    "8UC1": 1,
    "rgb8": 3,
    "bgr8": 3,
    "8UC3": 3,
    "rgba8": 4,
    "bgra8": 4,
    "mono16": 2,
    "16UC1": 2,
    "32FC1": 4,
}


class Failure(Exception):
    """A recording this reader cannot read as it should be."""


def read_summary(path):
    with open(path, "rb") as f:
        reader = SeekingReader(f, validate_crcs=True)
        header = reader.get_header()
        summary = reader.get_summary()
    if summary is None:
        raise Failure("no summary section")
    if summary.statistics is None:
        raise Failure("the summary has no statistics record")
    return header, summary


class JsonDecoders:
    """Decodes `json` messages and validates them against their JSON Schema."""

    def __init__(self):
        self._validators = {}

    def decoder_for(self, channel, schema):
        if schema is None or schema.encoding != "jsonschema":
            raise Failure(f"json channel {channel.topic!r} has no jsonschema schema")
        validator = self._validators.get(schema.id)
        if validator is None:
            try:
                document = json.loads(schema.data)
                cls = jsonschema.validators.validator_for(document)
                cls.check_schema(document)
            except (ValueError, jsonschema.SchemaError) as e:
                raise Failure(f"schema {schema.name!r} is not a valid JSON Schema: {e}")
            validator = cls(document)
            self._validators[schema.id] = validator

        def decode(data):
            value = json.loads(data)
            errors = sorted(validator.iter_errors(value), key=lambda e: list(e.path))
            if errors:
                e = errors[0]
                where = "/".join(str(p) for p in e.path) or "(top)"
                raise Failure(f"does not match schema {schema.name!r} at {where}: {e.message}")
            return value

        return decode


def bytes_per_pixel(image):
    bpp = BYTES_PER_PIXEL.get(image.encoding)
    if bpp is None:
        if image.width == 0:
            raise Failure(f"unknown image encoding {image.encoding!r}")
        bpp = image.step // image.width
    return bpp


def describe_image(topic, message, image):
    bpp = bytes_per_pixel(image)
    data = image.data
    if image.step < image.width * bpp:
        raise Failure(
            f"image on {topic!r}: step {image.step} < width {image.width} x {bpp} bytes"
        )
    if len(data) < image.step * image.height:
        raise Failure(
            f"image on {topic!r}: {len(data)} bytes < step {image.step} x height {image.height}"
        )
    last = (image.height - 1) * image.step + (image.width - 1) * bpp
    empty = image.width == 0 or image.height == 0
    return {
        "topic": topic,
        "width": image.width,
        "height": image.height,
        "encoding": image.encoding,
        "step": image.step,
        "frame_id": image.frame_id,
        "data_length": len(data),
        "first_pixel": [] if empty else list(data[0:bpp]),
        "last_pixel": [] if empty else list(data[last : last + bpp]),
        "timestamp_ns": image.timestamp.seconds * 1_000_000_000 + image.timestamp.nanos,
        "log_time_ns": message.log_time,
    }


def read_messages(path, summary):
    protobuf = ProtobufDecoderFactory()
    json_decoders = JsonDecoders()
    decoders = {}
    counts = {}
    per_topic = {}
    not_decoded = {}
    first_image = None
    first_json = {}
    times = []
    with open(path, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            known = summary.channels.get(channel.id)
            if known is None or known.topic != channel.topic:
                raise Failure(f"channel {channel.id} ({channel.topic!r}) is not in the summary")
            if channel.schema_id != 0 and channel.schema_id not in summary.schemas:
                raise Failure(f"schema {channel.schema_id} of {channel.topic!r} is not in the summary")
            counts[channel.id] = counts.get(channel.id, 0) + 1
            per_topic[channel.topic] = per_topic.get(channel.topic, 0) + 1
            times.append(message.log_time)

            encoding = channel.message_encoding
            if encoding not in ("protobuf", "json"):
                not_decoded[channel.topic] = not_decoded.get(channel.topic, 0) + 1
                continue
            decode = decoders.get(channel.id)
            if decode is None:
                if encoding == "protobuf":
                    decode = protobuf.decoder_for(encoding, schema)
                    if decode is None:
                        raise Failure(f"protobuf channel {channel.topic!r} has no protobuf schema")
                else:
                    decode = json_decoders.decoder_for(channel, schema)
                decoders[channel.id] = decode
            try:
                decoded = decode(message.data)
            except Failure as e:
                raise Failure(f"message {message.sequence} on {channel.topic!r}: {e}")
            except Exception as e:  # the decoders' own errors (DecodeError, ValueError, …)
                raise Failure(
                    f"message {message.sequence} on {channel.topic!r} does not decode: "
                    f"{type(e).__name__}: {e}"
                )

            if encoding == "protobuf" and schema.name == RAW_IMAGE and first_image is None:
                first_image = describe_image(channel.topic, message, decoded)
            if encoding == "json" and channel.topic not in first_json:
                first_json[channel.topic] = decoded
    return counts, per_topic, not_decoded, first_image, first_json, times


def check_statistics(stats, summary, counts, times):
    total = sum(counts.values())
    if total != stats.message_count:
        raise Failure(f"read {total} messages, the statistics say {stats.message_count}")
    expected = {k: v for k, v in stats.channel_message_counts.items() if v}
    if counts != expected:
        raise Failure(f"messages per channel {counts} differ from the statistics' {expected}")
    if stats.channel_count != len(summary.channels):
        raise Failure(
            f"statistics count {stats.channel_count} channels, the summary lists {len(summary.channels)}"
        )
    if stats.schema_count != len(summary.schemas):
        raise Failure(
            f"statistics count {stats.schema_count} schemas, the summary lists {len(summary.schemas)}"
        )
    if times and (min(times), max(times)) != (stats.message_start_time, stats.message_end_time):
        raise Failure(
            f"log times {min(times)}..{max(times)} differ from the statistics' "
            f"{stats.message_start_time}..{stats.message_end_time}"
        )


def read(path):
    header, summary = read_summary(path)
    stats = summary.statistics
    counts, per_topic, not_decoded, first_image, first_json, times = read_messages(path, summary)
    check_statistics(stats, summary, counts, times)
    schema_names = {s.id: s.name for s in summary.schemas.values()}
    return {
        "summary": {
            "message_count": stats.message_count,
            "channel_count": stats.channel_count,
            "schema_count": stats.schema_count,
            "chunk_count": stats.chunk_count,
            "attachment_count": stats.attachment_count,
            "metadata_count": stats.metadata_count,
            "message_start_time": stats.message_start_time,
            "message_end_time": stats.message_end_time,
            "summary_channels": len(summary.channels),
            "summary_schemas": len(summary.schemas),
            "chunk_indexes": len(summary.chunk_indexes),
        },
        "header": {"profile": header.profile, "library": header.library},
        "schemas": [
            {"id": s.id, "name": s.name, "encoding": s.encoding}
            for s in sorted(summary.schemas.values(), key=lambda s: s.id)
        ],
        "channels": [
            {
                "id": c.id,
                "topic": c.topic,
                "message_encoding": c.message_encoding,
                "schema_name": schema_names.get(c.schema_id),
                "metadata": dict(c.metadata),
            }
            for c in sorted(summary.channels.values(), key=lambda c: c.id)
        ],
        "messages_per_topic": per_topic,
        "not_decoded_per_topic": not_decoded,
        "first_image": first_image,
        "first_json": first_json,
    }


def main(argv):
    if len(argv) != 2:
        print("usage: read_recording.py FILE.mcap", file=sys.stderr)
        return 2
    path = argv[1]
    try:
        result = read(path)
    except (Failure, McapError, OSError, ValueError, KeyError) as e:
        print(f"read_recording: {path}: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    json.dump(result, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
