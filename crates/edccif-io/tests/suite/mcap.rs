//! MCAP through the `mcap` crate: write → replay (zstd and uncompressed), the
//! Foxglove schemas, streaming files without a summary, attachments and metadata,
//! truncated tails, corrupted bytes (an error or the exact data, never a panic),
//! lz4 chunks, and errors that name the record and topic.

use std::collections::BTreeMap;
use std::io::Cursor;

use edccif_io::mcap_io::{
    ellipsoid, mcap_to_bytes, measurement_schema, read_measurements, read_measurements_file,
    read_measurements_watched, write_mcap_file, ChunkCompression, McapRunData, McapWriteOptions,
    MEASUREMENT_SCHEMA_NAME,
};
use edccif_io::Error;
use nalgebra::{Rotation3, Vector3};

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// Deterministic values in [-1, 1).
fn noise(seed: u64, len: usize) -> Vec<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..len)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        })
        .collect()
}

/// A 30-step, 4-node, 7-state run: node 1 misses steps 5..8, every node step 12.
fn run_data() -> McapRunData {
    let (t, k, n) = (30, 4, 7);
    let mut z: Vec<f64> = noise(1, t * k * 3).iter().map(|v| 10.0 * v).collect();
    for s in 5..8 {
        z[(s * k + 1) * 3..(s * k + 2) * 3].fill(f64::NAN);
    }
    z[12 * k * 3..13 * k * 3].fill(f64::NAN);
    let triggered = noise(2, t * k).iter().map(|v| *v > 0.0).collect();
    let mut cov = vec![0.0; t * k * n * n];
    for c in cov.chunks_exact_mut(n * n) {
        for d in 0..n {
            c[d * n + d] = 0.01 * (d + 1) as f64;
        }
        c[1] = 0.002;
        c[n] = 0.002;
    }
    McapRunData {
        dt: 0.1,
        t0_ns: 0,
        steps: t,
        nodes: k,
        n,
        truth: Some(noise(3, t * n)),
        position_dim: None,
        sensors: noise(4, k * 3).iter().map(|v| 20.0 * v).collect(),
        meas_dims: None,
        z,
        triggered,
        local_estimates: Some(noise(5, t * k * n)),
        fused_estimates: noise(6, t * k * n),
        fused_covariances: Some(cov),
        node_ids: None,
    }
}

fn opts(compression: ChunkCompression) -> McapWriteOptions {
    McapWriteOptions {
        compression,
        ..McapWriteOptions::default()
    }
}

fn expected_triggered(d: &McapRunData) -> Vec<bool> {
    d.triggered
        .iter()
        .enumerate()
        .map(|(c, t)| *t && d.z[c * 3].is_finite())
        .collect()
}

#[test]
fn write_then_replay_equals_input_zstd_and_uncompressed() {
    let d = run_data();
    let mut sizes = Vec::new();
    for comp in [ChunkCompression::Zstd, ChunkCompression::None] {
        let bytes = mcap_to_bytes(&d, &opts(comp)).unwrap();
        sizes.push(bytes.len());
        let r = read_measurements(&bytes).unwrap();
        assert_eq!((r.steps, r.nodes), (30, 4));
        assert!(same_bits(&r.z, &d.z), "{comp:?}: replayed z differs");
        assert_eq!(r.triggered, expected_triggered(&d));
        let expect: Vec<u64> = (0..30).map(|t| t * 100_000_000).collect();
        assert_eq!(r.t_ns, expect);
        assert!((r.times_s()[29] - 2.9).abs() < 1e-12);
        assert_eq!(r.truncated, None);
        // The chunks are compressed as asked.
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert!(!summary.chunk_indexes.is_empty());
        let want = match comp {
            ChunkCompression::Zstd => "zstd",
            ChunkCompression::None => "",
        };
        assert!(summary.chunk_indexes.iter().all(|c| c.compression == want));
    }
    assert!(
        sizes[0] * 2 < sizes[1],
        "zstd {} vs none {}",
        sizes[0],
        sizes[1]
    );
    // Through a file as well.
    let path = std::env::temp_dir().join(format!("edccif-mcap-{}.mcap", std::process::id()));
    write_mcap_file(&path, &d, &McapWriteOptions::default()).unwrap();
    let r2 = read_measurements_file(&path).unwrap();
    std::fs::remove_file(&path).ok();
    assert!(same_bits(&r2.z, &d.z));
    let e = read_measurements_file(&path).unwrap_err().to_string();
    assert!(
        e.contains("cannot read") && e.contains("edccif-mcap"),
        "{e}"
    );
}

#[test]
fn readable_by_the_mcap_crate_with_foxglove_schemas() {
    let d = run_data();
    let bytes = mcap_to_bytes(&d, &McapWriteOptions::default()).unwrap();
    let mut counts = BTreeMap::<String, usize>::new();
    let mut scene: Option<serde_json::Value> = None;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        assert_eq!(m.channel.message_encoding, "json");
        let expected_schema = match m.channel.topic.as_str() {
            "/scene" => "foxglove.SceneUpdate",
            t if t.ends_with("/measurement") => "edccif.Measurement",
            _ => "foxglove.PoseInFrame",
        };
        assert_eq!(schema.name, expected_schema, "{}", m.channel.topic);
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        assert!(v.is_object());
        if m.channel.topic == "/scene" && m.log_time == 100_000_000 {
            scene = Some(v);
        }
        *counts.entry(m.channel.topic.clone()).or_default() += 1;
    }
    assert_eq!(counts["/truth"], 30);
    assert_eq!(counts["/scene"], 30);
    for i in 0..4 {
        for kind in ["measurement", "local", "fused"] {
            assert_eq!(counts[&format!("/node{i}/{kind}")], 30, "/node{i}/{kind}");
        }
    }
    let scene = scene.unwrap();
    let ids: Vec<&str> = scene["entities"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "sensors",
            "target",
            "node0/covariance",
            "node1/covariance",
            "node2/covariance",
            "node3/covariance"
        ]
    );
    assert_eq!(scene["entities"][0]["cubes"].as_array().unwrap().len(), 4);
    let sphere = &scene["entities"][2]["spheres"][0];
    assert!(sphere["size"]["x"].as_f64().unwrap() > 0.0);
}

#[test]
fn ellipsoid_axes_follow_the_eigenvectors() {
    // Covariance with principal axes rotated 30° about z: variances 9, 1, 0.25.
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 30f64.to_radians());
    let d = nalgebra::Matrix3::from_diagonal(&Vector3::new(9.0, 1.0, 0.25));
    let p = r.matrix() * d * r.matrix().transpose();
    let rows: Vec<f64> = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| p[(i, j)])
        .collect();
    let (q, size) = ellipsoid(&rows, 2.0).unwrap();
    let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        q[3], q[0], q[1], q[2],
    ));
    let m = uq.to_rotation_matrix();
    // Each local axis j, scaled by (size_j / 2k)², reproduces P.
    let mut back = nalgebra::Matrix3::zeros();
    for (j, s) in size.iter().enumerate() {
        let a = m.matrix().column(j);
        back += a * a.transpose() * (s / 4.0).powi(2);
    }
    assert!((back - p).abs().max() < 1e-9);
    assert!(ellipsoid(&[f64::NAN; 9], 2.0).is_none());
}

#[test]
fn bad_shapes_are_refused() {
    let mut d = run_data();
    d.z.pop();
    assert!(matches!(
        mcap_to_bytes(&d, &McapWriteOptions::default()),
        Err(Error::Shape { .. })
    ));
    let mut d = run_data();
    d.dt = 0.0;
    assert!(mcap_to_bytes(&d, &McapWriteOptions::default()).is_err());
}

/// A file written by the mcap crate directly: `/node{i}/measurement` messages
/// for steps `0..steps` of 2 nodes (`z = [t, i, 0.5]`, log time `1000 + t·50 ms`),
/// a schema-less `/diagnostics` channel, an attachment and a metadata record,
/// with the given writer options.
fn custom_bytes(options: mcap::WriteOptions, steps: u64) -> Vec<u8> {
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = options.create(&mut cur).unwrap();
        let schema = w
            .add_schema(
                MEASUREMENT_SCHEMA_NAME,
                "jsonschema",
                measurement_schema().as_bytes(),
            )
            .unwrap();
        let chans: Vec<u16> = (0..2)
            .map(|i| {
                w.add_channel(
                    schema,
                    &format!("/node{i}/measurement"),
                    "json",
                    &BTreeMap::new(),
                )
                .unwrap()
            })
            .collect();
        let other = w
            .add_channel(0, "/diagnostics", "json", &BTreeMap::new())
            .unwrap();
        w.attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: "calibration.yaml".into(),
            media_type: "application/yaml".into(),
            data: std::borrow::Cow::Borrowed(b"camera: {fx: 500}"),
        })
        .unwrap();
        w.write_metadata(&mcap::records::Metadata {
            name: "rig".into(),
            metadata: BTreeMap::from([("site".to_string(), "lab".to_string())]),
        })
        .unwrap();
        for t in 0..steps {
            for (i, c) in chans.iter().enumerate() {
                let msg = format!(
                    r#"{{"timestamp": {{"sec": 0, "nsec": 0}}, "frame_id": "world", "node": {i}, "z": [{t}, {i}, 0.5], "triggered": true}}"#
                );
                let h = mcap::records::MessageHeader {
                    channel_id: *c,
                    sequence: t as u32,
                    log_time: 1_000 + t * 50_000_000,
                    publish_time: 0,
                };
                w.write_to_known_channel(&h, msg.as_bytes()).unwrap();
            }
            let h = mcap::records::MessageHeader {
                channel_id: other,
                sequence: 0,
                log_time: 1_000 + t * 50_000_000,
                publish_time: 0,
            };
            w.write_to_known_channel(&h, b"{\"ok\": true}").unwrap();
        }
        w.finish().unwrap();
    }
    cur.into_inner()
}

fn check_custom(bytes: &[u8], steps: usize) {
    let r = read_measurements(bytes).unwrap();
    assert_eq!((r.steps, r.nodes), (steps, 2));
    assert_eq!(r.truncated, None);
    for t in 0..steps {
        assert_eq!(r.t_ns[t], 1_000 + t as u64 * 50_000_000);
        for i in 0..2 {
            assert_eq!(
                r.z[(t * 2 + i) * 3..(t * 2 + i) * 3 + 3],
                [t as f64, i as f64, 0.5]
            );
        }
    }
    assert!(r.triggered.iter().all(|t| *t));
}

#[test]
fn indexed_streaming_and_unchunked_files_with_attachments_and_metadata() {
    // Indexed (summary, chunk and message indexes), zstd.
    let indexed = custom_bytes(mcap::WriteOptions::new(), 20);
    assert!(mcap::Summary::read(&indexed).unwrap().is_some());
    check_custom(&indexed, 20);
    // Streaming: no summary section, no indexes, no statistics.
    let streaming = custom_bytes(
        mcap::WriteOptions::new()
            .emit_summary_records(false)
            .emit_summary_offsets(false)
            .emit_statistics(false)
            .emit_message_indexes(false)
            .emit_chunk_indexes(false)
            .emit_attachment_indexes(false)
            .emit_metadata_indexes(false)
            .repeat_channels(false)
            .repeat_schemas(false),
        20,
    );
    check_custom(&streaming, 20);
    // Unchunked and unseekable, as a live recorder writes.
    let unchunked = custom_bytes(mcap::WriteOptions::new().use_chunks(false), 20);
    check_custom(&unchunked, 20);
}

#[test]
fn truncated_tails_give_the_messages_before_the_cut() {
    let d = run_data();
    for comp in [ChunkCompression::Zstd, ChunkCompression::None] {
        let bytes = mcap_to_bytes(&d, &opts(comp)).unwrap();
        let full = read_measurements(&bytes).unwrap();
        let n = bytes.len();
        let mut cuts: Vec<usize> = vec![
            0,
            1,
            7,
            8,
            9,
            12,
            30,
            100,
            n - 200,
            n - 30,
            n - 9,
            n - 8,
            n - 1,
        ];
        cuts.extend((1..60).map(|i| i * n / 60));
        let mut partial = 0;
        for cut in cuts {
            match read_measurements(&bytes[..cut]) {
                Ok(r) => {
                    let why = r
                        .truncated
                        .as_deref()
                        .expect("a cut file is reported truncated");
                    assert!(why.contains("truncated"), "{why}");
                    // Every row read is the original row at that time.
                    for (row, t) in r.t_ns.iter().enumerate() {
                        let j = full.t_ns.iter().position(|u| u == t).unwrap();
                        for i in 0..r.nodes {
                            let got = &r.z[(row * r.nodes + i) * 3..(row * r.nodes + i) * 3 + 3];
                            let want = &full.z[(j * 4 + i) * 3..(j * 4 + i) * 3 + 3];
                            assert!(same_bits(got, want) || got.iter().all(|v| v.is_nan()));
                        }
                    }
                    if r.steps < 30 {
                        partial += 1;
                    }
                }
                Err(e) => {
                    // Only a file cut before any message may fail.
                    assert!(matches!(e, Error::Value { .. }), "cut {cut}: {e:?}");
                    let m = e.to_string();
                    assert!(m.starts_with("MCAP input: "), "cut {cut}: {m}");
                }
            }
        }
        assert!(partial > 10, "{comp:?}: only {partial} partial reads");
        // Trailing bytes after the closing magic are refused.
        let mut longer = bytes.clone();
        longer.extend_from_slice(b"junk");
        let e = read_measurements(&longer).unwrap_err().to_string();
        assert!(e.contains("after end magic"), "{e}");
    }
}

#[test]
fn corrupted_bytes_give_an_error_or_the_exact_data_never_a_panic() {
    let d = run_data();
    for comp in [ChunkCompression::Zstd, ChunkCompression::None] {
        let bytes = mcap_to_bytes(&d, &opts(comp)).unwrap();
        let full = read_measurements(&bytes).unwrap();
        let n = bytes.len();
        let mut positions: Vec<usize> = (0..64).collect(); // magic, header, schemas
        positions.extend((0..200).map(|i| i * n / 200));
        positions.extend(n - 64..n); // footer and closing magic
        let (mut detected, mut harmless) = (0, 0);
        for pos in positions {
            for flip in [0xFFu8, 0x01, 0x80] {
                let mut bad = bytes.clone();
                bad[pos] ^= flip;
                match read_measurements(&bad) {
                    Err(e) => {
                        assert!(e.to_string().starts_with("MCAP input: "), "{e}");
                        detected += 1;
                    }
                    // A byte that no check covers and the replay does not use
                    // (e.g. the Header's library string): the same data back;
                    // or a damaged Footer opcode, which makes the file look cut
                    // after its last message: reported as truncated.
                    Ok(r) => {
                        let same = same_bits(&r.z, &full.z) && r.t_ns == full.t_ns;
                        assert!(
                            same && (r.truncated.is_none() || pos >= n - 64),
                            "corruption at byte {pos} (xor {flip:#04x}) changed the data: {r:?}"
                        );
                        harmless += 1;
                    }
                }
            }
        }
        assert!(
            detected > 20 * harmless,
            "{comp:?}: {detected} detected, {harmless} harmless"
        );
    }
    assert!(read_measurements(b"hello")
        .unwrap_err()
        .to_string()
        .contains("not an MCAP file"));
    assert!(read_measurements(&[]).is_err());
}

#[test]
fn errors_name_the_record_the_topic_and_what_was_expected() {
    // A measurement topic with the wrong schema.
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new().create(&mut cur).unwrap();
        let s = w
            .add_schema("foxglove.Point3", "jsonschema", b"{}")
            .unwrap();
        let c = w
            .add_channel(s, "/node0/measurement", "json", &BTreeMap::new())
            .unwrap();
        let h = mcap::records::MessageHeader {
            channel_id: c,
            sequence: 0,
            log_time: 5,
            publish_time: 5,
        };
        w.write_to_known_channel(&h, b"{}").unwrap();
        w.finish().unwrap();
    }
    let e = read_measurements(cur.get_ref()).unwrap_err().to_string();
    assert!(
        e.contains("record #") && e.contains("`/node0/measurement`"),
        "{e}"
    );
    assert!(
        e.contains("expected `edccif.Measurement`") && e.contains("foxglove.Point3"),
        "{e}"
    );

    // A measurement message that is not valid JSON of the schema.
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new().create(&mut cur).unwrap();
        let s = w
            .add_schema(MEASUREMENT_SCHEMA_NAME, "jsonschema", b"{}")
            .unwrap();
        let c = w
            .add_channel(s, "/node1/measurement", "json", &BTreeMap::new())
            .unwrap();
        let h = mcap::records::MessageHeader {
            channel_id: c,
            sequence: 0,
            log_time: 7,
            publish_time: 7,
        };
        w.write_to_known_channel(&h, br#"{"node": 1, "z": [1, 2]}"#)
            .unwrap();
        w.finish().unwrap();
    }
    let e = read_measurements(cur.get_ref()).unwrap_err().to_string();
    assert!(
        e.contains("`/node1/measurement`") && e.contains("log time 7 ns"),
        "{e}"
    );
    assert!(e.contains("expected 3 finite numbers"), "{e}");

    // No measurement topic at all.
    let bytes = custom_bytes(mcap::WriteOptions::new(), 0);
    let e = read_measurements(&bytes).unwrap_err().to_string();
    assert!(e.contains("no `/node{i}/measurement` channel"), "{e}");
}

#[test]
fn lz4_chunks_are_read() {
    // Written by the Python `mcap` writer with lz4 chunks (see tests/data/README.md).
    let bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/lz4_measurements.mcap"
    ))
    .unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == "lz4"));
    check_custom(&bytes, 20);
}

#[test]
fn node_ids_name_the_topics() {
    let mut d = run_data();
    d.node_ids = Some(vec![7, 2, 5, 0]);
    let bytes = mcap_to_bytes(&d, &McapWriteOptions::default()).unwrap();
    let r = read_measurements(&bytes).unwrap();
    assert_eq!(r.nodes, 8);
    for (i, id) in [7, 2, 5, 0].into_iter().enumerate() {
        for t in 0..r.steps {
            let got = &r.z[(t * 8 + id) * 3..(t * 8 + id) * 3 + 3];
            let want = &d.z[(t * 4 + i) * 3..(t * 4 + i) * 3 + 3];
            assert!(same_bits(got, want));
        }
    }
    assert!(r.z[3..6].iter().all(|v| v.is_nan())); // node 1 is absent
    d.node_ids = Some(vec![1, 1, 2, 3]);
    assert!(mcap_to_bytes(&d, &McapWriteOptions::default()).is_err());
    d.node_ids = Some(vec![1]);
    assert!(mcap_to_bytes(&d, &McapWriteOptions::default()).is_err());
}

/// Writes one `/node0/measurement` message with `z` on a channel whose
/// metadata is `meta`, as another writer would.
fn one_measurement(meta: &[(&str, &str)], z: &str) -> Vec<u8> {
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new().create(&mut cur).unwrap();
        let s = w
            .add_schema(MEASUREMENT_SCHEMA_NAME, "jsonschema", b"{}")
            .unwrap();
        let meta: BTreeMap<String, String> = meta
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let c = w
            .add_channel(s, "/node0/measurement", "json", &meta)
            .unwrap();
        let h = mcap::records::MessageHeader {
            channel_id: c,
            sequence: 0,
            log_time: 3,
            publish_time: 3,
        };
        let msg = format!(r#"{{"node": 0, "z": {z}, "triggered": true}}"#);
        w.write_to_known_channel(&h, msg.as_bytes()).unwrap();
        w.finish().unwrap();
    }
    cur.into_inner()
}

#[test]
fn per_node_sizes_round_trip_and_are_checked() {
    // Three nodes measuring 2, 1 and 3 values of a planar 5-state target.
    let (t, k, n) = (12, 3, 5);
    let dims = vec![2, 1, 3];
    let mut z: Vec<f64> = noise(5, t * 6);
    z[6..8].fill(f64::NAN); // node 0 has no measurement at step 1
    z[5 * 6 + 2] = f64::NAN; // node 1 none at step 5
    let d = McapRunData {
        dt: 0.1,
        t0_ns: 0,
        steps: t,
        nodes: k,
        n,
        position_dim: Some(2),
        truth: Some(noise(6, t * n)),
        sensors: vec![1.0, 2.0, 0.0, f64::NAN, f64::NAN, f64::NAN, 0.0, 1.0, 2.0],
        meas_dims: Some(dims.clone()),
        z: z.clone(),
        triggered: noise(7, t * k).iter().map(|v| *v > 0.0).collect(),
        local_estimates: None,
        fused_estimates: noise(8, t * k * n),
        fused_covariances: Some(
            (0..t * k)
                .flat_map(|_| (0..n * n).map(move |j| if j % (n + 1) == 0 { 0.1 } else { 0.0 }))
                .collect(),
        ),
        node_ids: None,
    };
    for ros2 in [false, true] {
        let opt = McapWriteOptions {
            ros2,
            ..McapWriteOptions::default()
        };
        let bytes = mcap_to_bytes(&d, &opt).unwrap();
        let r = read_measurements(&bytes).unwrap();
        assert_eq!(
            (r.steps, r.nodes, r.meas_dims.clone()),
            (t, k, dims.clone())
        );
        assert!(same_bits(&r.z, &z) && !r.uniform());
        let s = mcap::Summary::read(&bytes).unwrap().unwrap();
        let topics: Vec<&str> = s.channels.values().map(|c| c.topic.as_str()).collect();
        // a point only for the node measuring 3 values
        assert_eq!(topics.contains(&"/node2/point"), ros2);
        assert!(!topics.contains(&"/node0/point") && !topics.contains(&"/node1/point"));
        let m = s
            .channels
            .values()
            .find(|c| c.topic == "/node1/measurement")
            .unwrap();
        assert_eq!(m.metadata.get("m").map(String::as_str), Some("1"));
    }
    // the shapes are checked when written
    let mut bad = d.clone();
    bad.z.pop();
    assert!(mcap_to_bytes(&bad, &McapWriteOptions::default())
        .unwrap_err()
        .to_string()
        .contains("(12, 6)"));
    bad = d.clone();
    bad.meas_dims = Some(vec![2, 0, 4]);
    assert!(mcap_to_bytes(&bad, &McapWriteOptions::default())
        .unwrap_err()
        .to_string()
        .contains("meas_dims[1]"));
    bad = d.clone();
    bad.position_dim = Some(4);
    assert!(mcap_to_bytes(&bad, &McapWriteOptions::default()).is_err());

    // A channel without `m` holds 3 values (files written before it existed).
    let r = read_measurements(&one_measurement(&[], "[1.0, 2.0, 3.0]")).unwrap();
    assert_eq!(
        (r.meas_dims.clone(), r.z.clone()),
        (vec![3], vec![1.0, 2.0, 3.0])
    );
    let e = read_measurements(&one_measurement(&[], "[1.0, 2.0]"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("expected 3 finite numbers"), "{e}");
    // With `m`, exactly m values.
    let r = read_measurements(&one_measurement(&[("m", "2")], "[1.0, 2.0]")).unwrap();
    assert_eq!((r.meas_dims, r.z), (vec![2], vec![1.0, 2.0]));
    let e = read_measurements(&one_measurement(&[("m", "2")], "[1.0, 2.0, 3.0]"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("expected 2 finite numbers (the channel's m)")
            && e.contains("/node0/measurement"),
        "{e}"
    );
    let e = read_measurements(&one_measurement(&[("m", "zero")], "[1.0]"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("metadata `m` is \"zero\""), "{e}");
}

/// Cancelled after `after` looks.
struct CancelAfter {
    after: u64,
    looks: std::sync::atomic::AtomicU64,
}

impl edccif_io::watch::Watch for CancelAfter {
    fn add_total(&self, _: u64) {}
    fn advance(&self, _: u64) {}
    fn is_cancelled(&self) -> bool {
        self.looks
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            >= self.after
    }
}

#[test]
fn reading_stops_soon_after_a_cancel() {
    let bytes = mcap_to_bytes(&run_data(), &McapWriteOptions::default()).unwrap();
    let watch = |after| CancelAfter {
        after,
        looks: std::sync::atomic::AtomicU64::new(0),
    };
    // Never cancelled: the whole file, as read_measurements reads it.
    let all = watch(u64::MAX);
    let full = read_measurements_watched(&bytes, &all).unwrap();
    let plain = read_measurements(&bytes).unwrap();
    assert!(same_bits(&full.z, &plain.z) && full.t_ns == plain.t_ns);
    let looks = all.looks.load(std::sync::atomic::Ordering::Relaxed);
    assert!(looks > 100, "{looks}");
    // Cancelled in the middle: Interrupted, and not one look more.
    let w = watch(looks / 2);
    let e = read_measurements_watched(&bytes, &w).unwrap_err();
    assert!(matches!(e, Error::Interrupted), "{e}");
    assert_eq!(
        w.looks.load(std::sync::atomic::Ordering::Relaxed),
        looks / 2 + 1
    );
}
