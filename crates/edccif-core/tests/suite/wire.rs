//! The wire format: typed round trips (bit-exact), the byte layout of
//! docs/formats.md, every named decode error, and the fuzz harness on seeded
//! random inputs (proptest) so the fuzz target's invariants run in `cargo test`.

use crate::harness;

use edccif_core::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use edccif_core::wire::{self, Header, Kind, WireError};
use edccif_core::{Contribution, Gaussian, InfoPair};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

const H: Header = Header {
    swarm: 0xA1B2_C3D4,
    sender: 513,
    step: 1 << 40 | 7,
    round: 3,
    stamp_ns: 123_456_789_012,
};

fn sym7(seed: f64) -> SMatrix<f64, 7, 7> {
    let a = SMatrix::<f64, 7, 7>::from_fn(|r, c| (seed * (r * 7 + c + 1) as f64).sin());
    a * a.transpose() + SMatrix::identity() * 0.1
}

#[test]
fn typed_round_trips_are_bit_exact() {
    let mut buf = [0u8; wire::MAX_PACKET_LEN];
    let z = Vector3::new(1.5, -0.25, std::f64::consts::PI);
    let n = wire::encode_measurement(&H, &z, &mut buf).unwrap();
    assert_eq!(n, 28 + 3 * 8);
    let f = wire::decode(&buf[..n]).unwrap();
    assert_eq!((f.header, f.kind, f.dim), (H, Kind::Measurement, 3));
    assert_eq!(f.measurement::<3>().unwrap(), z);

    let x = SVector::<f64, 7>::from_fn(|i, _| i as f64 * 0.3 - 1.0);
    let c = Contribution {
        i: x,
        imat: sym7(0.7),
    };
    let n = wire::encode_contribution(&H, &c, &mut buf).unwrap();
    assert_eq!(n, 28 + 8 * (7 + 28));
    assert_eq!(
        wire::decode(&buf[..n])
            .unwrap()
            .contribution::<7>()
            .unwrap(),
        c
    );

    let g = Gaussian::new(x, sym7(1.3)).unwrap();
    let n = wire::encode_estimate(&H, &g, &mut buf).unwrap();
    assert_eq!(wire::decode(&buf[..n]).unwrap().estimate::<7>().unwrap(), g);

    let p = InfoPair {
        y: x,
        ymat: sym7(2.1),
    };
    let n = wire::encode_information(&H, &p, &mut buf).unwrap();
    assert_eq!(
        wire::decode(&buf[..n]).unwrap().information::<7>().unwrap(),
        p
    );
}

#[test]
fn byte_layout_matches_docs() {
    let mut buf = [0u8; 128];
    let p = InfoPair {
        y: edccif_core::nalgebra::Vector2::new(1.0, 2.0),
        ymat: edccif_core::nalgebra::Matrix2::new(3.0, 4.0, 4.0, 5.0),
    };
    let n = wire::encode_information(&H, &p, &mut buf).unwrap();
    assert_eq!(n, 28 + 8 * 5);
    assert_eq!(&buf[0..2], &[0xED, 0xCF]);
    assert_eq!(buf[2], wire::VERSION);
    assert_eq!(buf[3], 4);
    assert_eq!(buf[4], 2);
    assert_eq!(buf[5], 3);
    assert_eq!(&buf[6..8], &513u16.to_le_bytes());
    assert_eq!(&buf[8..12], &0xA1B2_C3D4u32.to_le_bytes());
    assert_eq!(&buf[12..20], &(1u64 << 40 | 7).to_le_bytes());
    assert_eq!(&buf[20..28], &123_456_789_012u64.to_le_bytes());
    // vector, then the upper triangle row by row: Y00, Y01, Y11
    for (k, v) in [1.0f64, 2.0, 3.0, 4.0, 5.0].iter().enumerate() {
        assert_eq!(&buf[28 + 8 * k..36 + 8 * k], &v.to_le_bytes());
    }
}

#[test]
fn decode_errors_are_named() {
    let mut buf = [0u8; 128];
    let n = wire::encode_measurement(&H, &Vector3::new(1.0, 2.0, 3.0), &mut buf).unwrap();
    let good = &buf[..n];
    assert_eq!(
        wire::decode(&good[..10]),
        Err(WireError::Truncated {
            needed: 28,
            got: 10
        })
    );
    assert_eq!(
        wire::decode(&good[..n - 3]),
        Err(WireError::Truncated {
            needed: n,
            got: n - 3
        })
    );
    assert_eq!(
        wire::decode(&buf[..n + 2]),
        Err(WireError::Oversized {
            expected: n,
            got: n + 2
        })
    );
    let mut bad = good.to_vec();
    bad[2] = 2;
    assert_eq!(wire::decode(&bad), Err(WireError::WrongVersion { got: 2 }));
    let mut bad = good.to_vec();
    bad[3] = 9;
    assert_eq!(wire::decode(&bad), Err(WireError::UnknownKind { got: 9 }));
    let mut bad = good.to_vec();
    bad[0] = b'{';
    assert_eq!(wire::decode(&bad), Err(WireError::BadMagic));
    let mut bad = good.to_vec();
    bad[4] = 0;
    assert_eq!(wire::decode(&bad), Err(WireError::BadDimension { got: 0 }));
    let mut bad = good.to_vec();
    bad[28 + 8..28 + 16].copy_from_slice(&f64::NAN.to_le_bytes());
    assert_eq!(
        wire::decode(&bad),
        Err(WireError::NonFinite {
            field: "vector",
            index: 1
        })
    );
    let f = wire::decode(good).unwrap();
    assert_eq!(
        f.measurement::<2>(),
        Err(WireError::DimensionMismatch {
            expected: 2,
            got: 3
        })
    );
    assert_eq!(
        f.estimate::<3>(),
        Err(WireError::WrongKind {
            expected: Kind::Estimate,
            got: Kind::Measurement
        })
    );
    // a non-finite matrix entry names its row-major index
    let mut m = Matrix3::<f64>::identity();
    m[(1, 2)] = f64::INFINITY;
    m[(2, 1)] = f64::INFINITY;
    let e = wire::encode_estimate(
        &H,
        &Gaussian {
            x: Vector3::zeros(),
            p: m,
        },
        &mut buf,
    );
    assert_eq!(
        e,
        Err(WireError::NonFinite {
            field: "matrix",
            index: 5
        })
    );
    assert_eq!(
        wire::encode_measurement(&H, &Vector3::new(1.0, 2.0, 3.0), &mut buf[..20]),
        Err(WireError::BufferTooSmall {
            needed: 52,
            got: 20
        })
    );
    assert!(WireError::Truncated { needed: 52, got: 3 }
        .to_string()
        .contains("truncated packet: 3 bytes, expected 52"));
}

/// RFC 4231 test case 1 (key 0x0b × 20, data "Hi There"): `sign` appends the
/// first 16 bytes of HMAC-SHA256, the published value.
#[test]
fn sign_is_truncated_hmac_sha256() {
    let key = [0x0b_u8; 20];
    let mut buf = [0u8; 8 + wire::TAG_LEN];
    buf[..8].copy_from_slice(b"Hi There");
    assert_eq!(wire::sign(&key, &mut buf, 8), Ok(8 + wire::TAG_LEN));
    let expected: [u8; 16] = [
        0xb0, 0x34, 0x4c, 0x61, 0xd8, 0xdb, 0x38, 0x53, 0x5c, 0xa8, 0xaf, 0xce, 0xaf, 0x0b, 0xf1,
        0x2b,
    ];
    assert_eq!(buf[8..], expected);
}

#[test]
fn signed_packets_round_trip_and_every_change_is_refused() {
    let key = *b"0123456789abcdef0123456789abcdef";
    let mut buf = [0u8; wire::MAX_SIGNED_PACKET_LEN];
    let g = Gaussian {
        x: SVector::<f64, 7>::from_fn(|i, _| i as f64 - 2.5),
        p: sym7(0.3),
    };
    let n = wire::encode_estimate(&H, &g, &mut buf).unwrap();
    let signed = wire::sign(&key, &mut buf, n).unwrap();
    assert_eq!(signed, n + wire::TAG_LEN);
    let f = wire::decode_signed(&buf[..signed], &key).unwrap();
    assert_eq!((f.header, f.estimate::<7>().unwrap()), (H, g));
    // every single bit of the header, payload or tag matters
    for i in 0..signed {
        for bit in 0..8 {
            let mut b = buf;
            b[i] ^= 1 << bit;
            let e = wire::decode_signed(&b[..signed], &key).unwrap_err();
            assert!(i < 5 || e == WireError::BadTag, "byte {i} bit {bit}: {e}");
        }
    }
    assert_eq!(
        wire::decode_signed(&buf[..signed], b"another key of 32 bytes........."),
        Err(WireError::BadTag)
    );
    assert_eq!(
        wire::decode_signed(&buf[..n], &key),
        Err(WireError::MissingTag)
    );
    assert_eq!(
        wire::decode_signed(&buf[..signed - 1], &key),
        Err(WireError::Truncated {
            needed: signed,
            got: signed - 1
        })
    );
    assert_eq!(
        wire::decode_signed(&buf[..signed + 1], &key),
        Err(WireError::Oversized {
            expected: signed,
            got: signed + 1
        })
    );
    // an unsigned decoder refuses a signed packet (the tag is extra bytes)
    assert!(matches!(
        wire::decode(&buf[..signed]),
        Err(WireError::Oversized { .. })
    ));
    assert_eq!(
        wire::decode_signed(&buf[..signed], b"short"),
        Err(WireError::KeyTooShort { got: 5 })
    );
    assert_eq!(
        wire::sign(b"short", &mut buf, n),
        Err(WireError::KeyTooShort { got: 5 })
    );
    assert_eq!(
        wire::sign(&key, &mut buf[..n + 3], n),
        Err(WireError::BufferTooSmall {
            needed: n + wire::TAG_LEN,
            got: n + 3
        })
    );
    assert!(WireError::BadTag.to_string().contains("does not verify"));
    assert!(WireError::MissingTag
        .to_string()
        .contains("without an authentication tag"));
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 512,
        rng_seed: RngSeed::Fixed(0xC6),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config())]

    /// The fuzz target's invariants on random bytes.
    #[test]
    fn fuzz_harness_on_random_bytes(data in prop::collection::vec(any::<u8>(), 0..400)) {
        harness::wire_case(&data);
    }

    /// A signed decoder on random bytes under a fixed key never panics and never
    /// accepts (a forged tag would have to match 128 bits).
    #[test]
    fn signed_decoder_refuses_random_bytes(data in prop::collection::vec(any::<u8>(), 0..400)) {
        prop_assert!(wire::decode_signed(&data, &[5u8; 32]).is_err());
    }

    /// The fuzz target's invariants on valid packets with random bit flips.
    #[test]
    fn fuzz_harness_on_corrupted_packets(seed in any::<u64>(), flip in 0usize..400, bit in 0u8..8) {
        let mut bytes = [0u8; 64];
        for (i, b) in bytes.iter_mut().enumerate() {
            *b = (seed.rotate_left(i as u32) & 0xff) as u8;
        }
        let mut buf = [0u8; wire::MAX_PACKET_LEN];
        let x = SVector::<f64, 7>::from_fn(|i, _| (seed as f64 + i as f64).sin());
        let g = Gaussian { x, p: sym7(seed as f64 * 1e-19 + 0.5) };
        let n = wire::encode_estimate(&H, &g, &mut buf).unwrap();
        buf[flip % n] ^= 1 << bit;
        harness::wire_case(&buf[..n]);
        harness::wire_case(&bytes);
    }
}
