"""Writes lz4_measurements.mcap with the Python `mcap` writer (lz4 chunks of ~1 KiB):
the same content as `custom_bytes(.., 20)` in ../mcap.rs.

    python3 make_lz4_measurements.py
"""

import json

from mcap.writer import CompressionType, Writer

with open("lz4_measurements.mcap", "wb") as f:
    w = Writer(f, compression=CompressionType.LZ4, chunk_size=1024)
    w.start(profile="", library="edccif test fixture")
    schema = w.register_schema(name="edccif.Measurement", encoding="jsonschema", data=b"{}")
    chans = [w.register_channel(topic=f"/node{i}/measurement", message_encoding="json", schema_id=schema)
             for i in range(2)]
    other = w.register_channel(topic="/diagnostics", message_encoding="json", schema_id=0)
    w.add_attachment(create_time=0, log_time=0, name="calibration.yaml", media_type="application/yaml",
                     data=b"camera: {fx: 500}")
    w.add_metadata(name="rig", data={"site": "lab"})
    for t in range(20):
        for i, c in enumerate(chans):
            msg = {"timestamp": {"sec": 0, "nsec": 0}, "frame_id": "world", "node": i,
                   "z": [t, i, 0.5], "triggered": True}
            w.add_message(channel_id=c, log_time=1000 + t * 50_000_000, data=json.dumps(msg).encode(),
                          publish_time=0, sequence=t)
        w.add_message(channel_id=other, log_time=1000 + t * 50_000_000, data=b'{"ok": true}', publish_time=0)
    w.finish()
