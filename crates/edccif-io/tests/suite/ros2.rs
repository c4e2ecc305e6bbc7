//! ROS 2 recordings: every supported message type, topics and frames chosen by
//! name, the messages' own stamps, rows on stamps and resampled, big-endian
//! CDR, and errors that name the record, topic and field.

use std::collections::BTreeMap;
use std::io::Cursor;

use edccif_io::mcap_io::{mcap_to_bytes, ChunkCompression, McapRunData, McapWriteOptions};
use edccif_io::ros2::*;

const T0: u64 = 1_700_000_000_000_000_000;

fn header(ns: u64, frame: &str) -> Header {
    Header {
        stamp: Time {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        },
        frame_id: frame.into(),
    }
}

fn pt(p: [f64; 3]) -> Point {
    Point {
        x: p[0],
        y: p[1],
        z: p[2],
    }
}

const Q: Quaternion = Quaternion {
    x: 0.0,
    y: 0.0,
    z: 0.0,
    w: 1.0,
};

fn pose(p: [f64; 3]) -> Pose {
    Pose {
        position: pt(p),
        orientation: Q,
    }
}

fn pwc(p: [f64; 3]) -> PoseWithCovariance {
    PoseWithCovariance {
        pose: pose(p),
        covariance: Covariance6([0.01; 36]),
    }
}

/// Position of sensor `s` at sample `j`.
fn pos(s: usize, j: usize) -> [f64; 3] {
    [
        s as f64 + 0.1 * j as f64,
        -(j as f64) * 0.25,
        1.0 + 1e-3 * j as f64,
    ]
}

/// A bag as `ros2 bag record` would write it (zstd chunks, CDR): five sources,
/// each 10 samples at 10 Hz; sensor s is stamped `T0 + s·10 ms + j·100 ms`.
fn bag() -> Vec<u8> {
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .create(&mut cur)
            .unwrap();
        let mut chan = |name: &str, topic: &str| {
            let s = w.add_schema(name, "ros2msg", b"").unwrap();
            w.add_channel(s, topic, "cdr", &BTreeMap::new()).unwrap()
        };
        let c_point = chan("geometry_msgs/msg/PointStamped", "/drone1/target");
        let c_pose = chan("geometry_msgs/msg/PoseStamped", "/drone2/target");
        let c_pwc = chan(
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            "/drone3/target",
        );
        let c_odom = chan("nav_msgs/msg/Odometry", "/odom");
        let c_tf = chan("tf2_msgs/msg/TFMessage", "/tf");
        let c_img = chan("sensor_msgs/msg/Image", "/camera/image");
        let mut seq = 0;
        let mut put =
            |w: &mut mcap::Writer<&mut Cursor<Vec<u8>>>, c: u16, ns: u64, data: Vec<u8>| {
                seq += 1;
                // Log time = receive time, a little after the stamp.
                let h = mcap::records::MessageHeader {
                    channel_id: c,
                    sequence: seq,
                    log_time: ns + 3_000_000,
                    publish_time: ns + 3_000_000,
                };
                w.write_to_known_channel(&h, &data).unwrap();
            };
        for j in 0..10 {
            let ns = |s: u64| T0 + s * 10_000_000 + j as u64 * 100_000_000;
            put(
                &mut w,
                c_point,
                ns(0),
                point_stamped_cdr(
                    (ns(0) / 1_000_000_000) as i32,
                    (ns(0) % 1_000_000_000) as u32,
                    "cam1",
                    pos(0, j),
                ),
            );
            put(
                &mut w,
                c_pose,
                ns(1),
                encode_cdr(&PoseStamped {
                    header: header(ns(1), "cam2"),
                    pose: pose(pos(1, j)),
                }),
            );
            put(
                &mut w,
                c_pwc,
                ns(2),
                encode_cdr(&PoseWithCovarianceStamped {
                    header: header(ns(2), "cam3"),
                    pose: pwc(pos(2, j)),
                }),
            );
            let zero = pt([0.0; 3]);
            put(
                &mut w,
                c_odom,
                ns(3),
                encode_cdr(&Odometry {
                    header: header(ns(3), "odom"),
                    child_frame_id: "base_link".into(),
                    pose: pwc(pos(3, j)),
                    twist: TwistWithCovariance {
                        twist: Twist {
                            linear: zero,
                            angular: zero,
                        },
                        covariance: Covariance6([0.0; 36]),
                    },
                }),
            );
            let tf = |child: &str, p: [f64; 3]| TransformStamped {
                header: header(ns(4), "world"),
                child_frame_id: child.into(),
                transform: Transform {
                    translation: pt(p),
                    rotation: Q,
                },
            };
            put(
                &mut w,
                c_tf,
                ns(4),
                encode_cdr(&TfMessage {
                    transforms: vec![tf("vicon/other", [9.0; 3]), tf("vicon/target", pos(4, j))],
                }),
            );
            put(&mut w, c_img, ns(0), vec![0, 1, 0, 0, 1, 2, 3]);
        }
        w.finish().unwrap();
    }
    cur.into_inner()
}

fn src(s: &str) -> Source {
    Source::parse(s).unwrap()
}

#[test]
fn every_message_type_by_topic_and_frame_with_its_own_stamps() {
    let bytes = bag();
    let m = [
        src("/drone1/target"),
        src("/drone2/target#cam2"),
        src("/drone3/target"),
        src("/odom"),
    ];
    let rec = read_ros2(&bytes, &m, Some(&src("/tf#vicon/target"))).unwrap();
    assert_eq!(rec.truncated, None);
    for (s, samples) in rec.measurements.iter().enumerate() {
        assert_eq!(samples.t_ns.len(), 10);
        for j in 0..10 {
            assert_eq!(
                samples.t_ns[j],
                T0 + s as u64 * 10_000_000 + j as u64 * 100_000_000
            );
            assert_eq!(samples.p[j], pos(s, j));
        }
    }
    let (tsrc, truth) = rec.truth.as_ref().unwrap();
    assert_eq!(tsrc.name(), "/tf#vicon/target");
    assert_eq!(truth.p[3], pos(4, 3));

    // On stamps: one row per distinct stamp (4 sensors × 10, none shared).
    let rows = rec.on_stamps().unwrap();
    assert_eq!((rows.steps, rows.nodes), (40, 4));
    assert_eq!(rows.t_ns[0], T0);
    assert_eq!(rows.t_ns[5], T0 + 100_000_000 + 10_000_000);
    // Row 5 is sensor 1's sample 1; the others have none.
    assert_eq!(&rows.z[(5 * 4 + 1) * 3..(5 * 4 + 2) * 3], &pos(1, 1));
    assert!(rows.z[5 * 12..5 * 12 + 3].iter().all(|v| v.is_nan()));
    let dt = rows.dt_s();
    assert_eq!(dt[0], 0.0);
    assert!((dt[1] - 0.01).abs() < 1e-12 && (dt[4] - 0.07).abs() < 1e-12);
    // The truth (stamped +40 ms) is interpolated at the rows, NaN before its start.
    let truth = rows.truth.unwrap();
    assert!(truth[0].is_nan());
    let row = rows
        .t_ns
        .iter()
        .position(|t| *t == T0 + 130_000_000)
        .unwrap();
    let (a, b) = (pos(4, 0), pos(4, 1));
    for c in 0..3 {
        assert!((truth[row * 3 + c] - (a[c] + 0.9 * (b[c] - a[c]))).abs() < 1e-9);
    }
    let row = rows
        .t_ns
        .iter()
        .position(|t| *t == T0 + 200_000_000)
        .unwrap();
    let (a, b) = (pos(4, 1), pos(4, 2));
    assert!((truth[row * 3] - (a[0] + 0.6 * (b[0] - a[0]))).abs() < 1e-9);

    // Resampled at 10 Hz: sensor 0 exact, the others interpolated.
    let rs = rec.resampled(10.0, 0.5).unwrap();
    assert_eq!((rs.steps, rs.nodes), (10, 4));
    assert_eq!(rs.t_ns[9], T0 + 900_000_000);
    assert_eq!(&rs.z[..3], &pos(0, 0));
    assert!(rs.z[3..6].iter().all(|v| v.is_nan())); // before sensor 1's first sample
    let (a, b) = (pos(1, 0), pos(1, 1));
    assert!((rs.z[12 + 3] - (a[0] + 0.9 * (b[0] - a[0]))).abs() < 1e-9);
}

#[test]
fn a_round_trip_of_a_run_through_the_ros2_topics() {
    let (t, k) = (12, 3);
    let mut z: Vec<f64> = (0..t * k * 3).map(|v| (v as f64 * 0.37).sin()).collect();
    z[(4 * k + 1) * 3..(4 * k + 2) * 3].fill(f64::NAN);
    let data = McapRunData {
        dt: 0.05,
        t0_ns: T0,
        steps: t,
        nodes: k,
        n: 3,
        truth: Some((0..t * 3).map(|v| v as f64).collect()),
        position_dim: None,
        sensors: vec![0.0; k * 3],
        meas_dims: None,
        z: z.clone(),
        triggered: vec![true; t * k],
        local_estimates: None,
        fused_estimates: vec![0.0; t * k * 3],
        fused_covariances: None,
        node_ids: None,
    };
    for comp in [ChunkCompression::Zstd, ChunkCompression::None] {
        let opt = McapWriteOptions {
            ros2: true,
            compression: comp,
            ..McapWriteOptions::default()
        };
        let bytes = mcap_to_bytes(&data, &opt).unwrap();
        let m: Vec<Source> = (0..k).map(|i| src(&format!("/node{i}/point"))).collect();
        let rows = read_ros2(&bytes, &m, Some(&src("/truth/point")))
            .unwrap()
            .on_stamps()
            .unwrap();
        assert_eq!(rows.steps, t);
        let want: Vec<u64> = (0..t as u64)
            .map(|j| T0 + (j as f64 * 0.05e9).round() as u64)
            .collect();
        assert_eq!(rows.t_ns, want);
        assert!(rows
            .z
            .iter()
            .zip(&z)
            .all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())));
        assert_eq!(rows.truth.unwrap(), data.truth.clone().unwrap());
    }
    // Without ros2 the topics are absent.
    let bytes = mcap_to_bytes(&data, &McapWriteOptions::default()).unwrap();
    let e = read_ros2(&bytes, &[src("/node0/point")], None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no message on topic `/node0/point`"), "{e}");
}

#[test]
fn big_endian_cdr_is_read() {
    use byteorder::BigEndian;
    let msg = PointStamped {
        header: header(T0, "cam"),
        point: pt([1.5, -2.0, 3.25]),
    };
    let mut be = vec![0, 0, 0, 0];
    be.extend(cdr_encoding::to_vec::<_, BigEndian>(&msg).unwrap());
    assert_eq!(decode_cdr::<PointStamped>(&be).unwrap(), msg);
    let e = decode_cdr::<PointStamped>(&[0, 7, 0, 0, 1])
        .unwrap_err()
        .to_string();
    assert!(e.contains("encapsulation 0x00 0x07"), "{e}");
}

/// A bag with one channel of `schema` on `/x` holding `payloads`.
fn one_topic(schema: &str, encoding: &str, payloads: &[Vec<u8>]) -> Vec<u8> {
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new().create(&mut cur).unwrap();
        let s = w.add_schema(schema, "ros2msg", b"").unwrap();
        let c = w.add_channel(s, "/x", encoding, &BTreeMap::new()).unwrap();
        for (j, p) in payloads.iter().enumerate() {
            let h = mcap::records::MessageHeader {
                channel_id: c,
                sequence: j as u32,
                log_time: 10 + j as u64,
                publish_time: 0,
            };
            w.write_to_known_channel(&h, p).unwrap();
        }
        w.finish().unwrap();
    }
    cur.into_inner()
}

#[test]
fn errors_name_the_record_the_topic_and_the_field() {
    let x = [src("/x")];
    let good = point_stamped_cdr(1, 0, "f", [1.0, 2.0, 3.0]);
    let err = |bytes: &[u8], m: &[Source]| read_ros2(bytes, m, None).unwrap_err().to_string();

    let e = err(
        &one_topic("sensor_msgs/msg/Imu", "cdr", std::slice::from_ref(&good)),
        &x,
    );
    assert!(
        e.contains("`/x`") && e.contains("sensor_msgs/msg/Imu") && e.contains("expected one of"),
        "{e}"
    );
    let e = err(
        &one_topic(POINT_STAMPED, "json", std::slice::from_ref(&good)),
        &x,
    );
    assert!(e.contains("expected `cdr`"), "{e}");
    let e = err(
        &one_topic(POINT_STAMPED, "cdr", &[good.clone(), good[..30].to_vec()]),
        &x,
    );
    assert!(
        e.contains("record #") && e.contains("`/x`") && e.contains("log time 11 ns"),
        "{e}"
    );
    assert!(e.contains("does not decode"), "{e}");
    let e = err(
        &one_topic(
            POINT_STAMPED,
            "cdr",
            &[point_stamped_cdr(1, 0, "f", [f64::NAN, 0.0, 0.0])],
        ),
        &x,
    );
    assert!(
        e.contains("point = [NaN, 0.0, 0.0]; expected finite"),
        "{e}"
    );
    let e = err(
        &one_topic(
            POINT_STAMPED,
            "cdr",
            &[point_stamped_cdr(-1, 0, "f", [0.0; 3])],
        ),
        &x,
    );
    assert!(e.contains("header.stamp = (-1, 0)"), "{e}");
    let e = err(
        &one_topic(POINT_STAMPED, "cdr", &[good.clone(), good.clone()]),
        &x,
    );
    assert!(
        e.contains("two samples with the stamp 1000000000 ns"),
        "{e}"
    );
    let e = err(
        &one_topic(POINT_STAMPED, "cdr", std::slice::from_ref(&good)),
        &[src("/x#other")],
    );
    assert!(e.contains("no header.frame_id `other`"), "{e}");
    let e = err(
        &one_topic(POINT_STAMPED, "cdr", std::slice::from_ref(&good)),
        &[src("/y")],
    );
    assert!(e.contains("no message on topic `/y`"), "{e}");
    let tf = one_topic(
        "tf2_msgs/msg/TFMessage",
        "cdr",
        &[encode_cdr(&TfMessage { transforms: vec![] })],
    );
    let e = err(&tf, &x);
    assert!(
        e.contains("name the transform's child frame: `/x#CHILD_FRAME_ID`"),
        "{e}"
    );
    let e = err(&tf, &[src("/x#base")]);
    assert!(e.contains("no transform with child_frame_id `base`"), "{e}");
    assert!(read_ros2(b"nope", &x, None)
        .unwrap_err()
        .to_string()
        .contains("not an MCAP file"));
    assert!(read_ros2(&tf, &[], None).is_err());
    assert!(Source::parse("/x#").is_err());
}

/// A bag of two `PoseWithCovarianceStamped` sources, `/a` in `map` and `/b` in
/// `odom`, and (with `tf`) a `/tf` placing `odom` in `map`: turned 90° about z,
/// moving from (0, 0, 0) at T0 to (2, 0, 0) at T0 + 1 s.
fn frames_bag(tf: bool) -> Vec<u8> {
    let mut cur = Cursor::new(Vec::new());
    {
        let mut w = mcap::Writer::new(&mut cur).unwrap();
        let mut chan = |name: &str, topic: &str| {
            let s = w.add_schema(name, "ros2msg", b"").unwrap();
            w.add_channel(s, topic, "cdr", &BTreeMap::new()).unwrap()
        };
        let (c_a, c_b) = (
            chan("geometry_msgs/msg/PoseWithCovarianceStamped", "/a"),
            chan("geometry_msgs/msg/PoseWithCovarianceStamped", "/b"),
        );
        let c_tf = chan("tf2_msgs/msg/TFMessage", "/tf");
        let mut seq = 0;
        let mut put = |w: &mut mcap::Writer<&mut Cursor<Vec<u8>>>, c: u16, data: Vec<u8>| {
            seq += 1;
            let h = mcap::records::MessageHeader {
                channel_id: c,
                sequence: seq,
                log_time: seq as u64,
                publish_time: seq as u64,
            };
            w.write_to_known_channel(&h, &data).unwrap();
        };
        let s = std::f64::consts::FRAC_1_SQRT_2;
        if tf {
            for (ns, x) in [(T0, 0.0), (T0 + 1_000_000_000, 2.0)] {
                let t = TransformStamped {
                    header: header(ns, "map"),
                    child_frame_id: "odom".into(),
                    transform: Transform {
                        translation: pt([x, 0.0, 0.0]),
                        rotation: Quaternion {
                            x: 0.0,
                            y: 0.0,
                            z: s,
                            w: s,
                        },
                    },
                };
                put(
                    &mut w,
                    c_tf,
                    encode_cdr(&TfMessage {
                        transforms: vec![t],
                    }),
                );
            }
        }
        let mut cov = [0.0; 36];
        cov[0] = 1.0;
        cov[7] = 4.0;
        cov[14] = 9.0;
        for (c, frame, ns, p) in [
            (c_a, "map", T0, [5.0, 5.0, 5.0]),
            (c_b, "odom", T0 + 500_000_000, [1.0, 0.0, 0.0]),
            (c_b, "odom", T0 + 1_500_000_000, [1.0, 0.0, 0.0]),
        ] {
            let msg = PoseWithCovarianceStamped {
                header: header(ns, frame),
                pose: PoseWithCovariance {
                    pose: pose(p),
                    covariance: Covariance6(cov),
                },
            };
            put(&mut w, c, encode_cdr(&msg));
        }
        w.finish().unwrap();
    }
    cur.into_inner()
}

#[test]
fn sources_are_brought_into_one_frame_with_their_covariances() {
    use edccif_io::replay_input::{prepare, InputOptions, NoiseChoice};
    let m = [src("/a"), src("/b")];
    let rec = read_ros2(&frames_bag(true), &m, None).unwrap();
    assert_eq!(rec.measurements[1].frame[0], "odom");
    let input = prepare(&rec, &InputOptions::default(), &[true, true]).unwrap();
    let r = &input.report;
    assert_eq!(r.frame, "map");
    // The message after the last /tf sample is dropped (no extrapolation).
    assert_eq!((r.dropped, r.sources[1].dropped), (1, 1));
    let rows = &input.rows;
    assert_eq!(rows.steps, 2);
    // At T0 + 0.5 s odom is at (1, 0, 0), turned 90°: (1, 0, 0) in odom is (1, 1, 0) in map.
    // Row 1 (T0 + 0.5 s), node 1: cell 1·2 + 1 = 3.
    let z = &rows.z[3 * 3..4 * 3];
    for (got, want) in z.iter().zip([1.0, 1.0, 0.0]) {
        assert!((got - want).abs() < 1e-12, "{z:?}");
    }
    // Its covariance diag(1, 4, 9) becomes diag(4, 1, 9); the message noise is the default.
    let noise = input.noise.as_ref().unwrap();
    let c = &noise[3 * 9..4 * 9];
    let want = [4.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 9.0];
    assert!(
        c.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12),
        "{c:?}"
    );
    assert_eq!(r.noise[1].noise, "message");
    // The model's noise on request.
    let model = InputOptions {
        noise: NoiseChoice::Model,
        ..InputOptions::default()
    };
    assert!(prepare(&rec, &model, &[true, true])
        .unwrap()
        .noise
        .is_none());
    // Without /tf: refused, naming both frames and the missing link.
    let rec = read_ros2(&frames_bag(false), &m, None).unwrap();
    let e = prepare(&rec, &InputOptions::default(), &[true, true])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("`odom`") && e.contains("`map`") && e.contains("missing link"),
        "{e}"
    );
    // A sensor that does not measure a position is never transformed.
    let rec = read_ros2(&frames_bag(true), &m, None).unwrap();
    let e = prepare(&rec, &InputOptions::default(), &[true, false])
        .unwrap_err()
        .to_string();
    assert!(e.contains("cannot be transformed"), "{e}");
}
