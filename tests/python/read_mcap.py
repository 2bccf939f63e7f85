"""Reads a pavlov MCAP recording with Foxglove's `mcap` Python package alone, an independent reader
(tests/e2e/storage/recording_python.rs runs it), and prints what it found as one JSON object:

- channels: topic -> schema name, schema encoding, message encoding;
- summary_counts: topic -> message count from the file's summary statistics;
- counted: topic -> messages read by iterating the file;
- metadata: name -> key/value map of every metadata record;
- ticks: one row per `ticks` message, decoded with `mcap-protobuf-support` from the schema in the file
  (no pavlov code): [seq, log_time, t_ms, command left, command right, gate, stimulus,
  prediction values, raw sensor values, link state name];
- events: the `kind` of every `events` message (JSON);
- config_seed, learner_after: from the `config` and `learner` messages (JSON).
"""

import json
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def main(path: str) -> None:
    protobuf = DecoderFactory()
    out = {"channels": {}, "summary_counts": {}, "counted": {}, "metadata": {}, "ticks": [], "events": []}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            out["channels"][channel.topic] = {
                "schema": schema.name,
                "schema_encoding": schema.encoding,
                "message_encoding": channel.message_encoding,
            }
        for channel_id, count in summary.statistics.channel_message_counts.items():
            out["summary_counts"][summary.channels[channel_id].topic] = count
        for record in reader.iter_metadata():
            out["metadata"][record.name] = dict(record.metadata)
        decoders = {}
        # In file order: the order the recorder wrote them.
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            out["counted"][topic] = out["counted"].get(topic, 0) + 1
            if channel.message_encoding == "json":
                value = json.loads(message.data)
            else:
                if channel.id not in decoders:
                    decoders[channel.id] = protobuf.decoder_for(channel.message_encoding, schema)
                value = decoders[channel.id](message.data)
            if topic == "ticks":
                enum = value.DESCRIPTOR.fields_by_name["link"].message_type.fields_by_name["state"].enum_type
                out["ticks"].append([
                    value.seq,
                    message.log_time,
                    value.t_ms,
                    value.command.left_mm_s,
                    value.command.right_mm_s,
                    value.gate,
                    value.stimulus,
                    [p.value for p in value.predictions],
                    list(value.inputs.values.values),
                    enum.values_by_number[value.link.state].name,
                ])
            elif topic == "events":
                out["events"].append(value["kind"])
            elif topic == "config":
                out["config_seed"] = value["sim"]["seed"]
            elif topic == "learner":
                out["learner_after"] = value["after"]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
