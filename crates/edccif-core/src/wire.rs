//! The wire format: what one node's packet looks like as bytes on a real network
//! (version 1). Compact little-endian binary, no allocation: [`encode`] writes
//! into the caller's buffer, [`decode`] validates a received packet and returns a
//! borrowed [`Frame`] from which the typed value is read.
//!
//! Every packet is a 28-byte header followed by `f64` payload values:
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 2 | magic `0xED 0xCF` |
//! | 2 | 1 | format version ([`VERSION`]) |
//! | 3 | 1 | [`Kind`]: 1 measurement, 2 contribution, 3 estimate, 4 information pair |
//! | 4 | 1 | dimension `d` (`M` for a measurement, `N` otherwise), `1..=`[`MAX_DIM`] |
//! | 5 | 1 | round (consensus iteration, 0 otherwise) |
//! | 6 | 2 | sender id (`u16`) |
//! | 8 | 4 | swarm id (`u32`) |
//! | 12 | 8 | step (`u64`) |
//! | 20 | 8 | timestamp in nanoseconds (`u64`) |
//! | 28 | 8·d | the vector (`z`, `ī`, `x̂` or `ŷ`) |
//! | 28 + 8·d | 8·d(d+1)/2 | the symmetric matrix (`Ī`, `P` or `Y`) as its upper triangle, row by row (not for a measurement) |
//!
//! All multi-byte fields are little-endian; the packet length is exactly
//! [`packet_len`]`(kind, d)`. The decoder mirrors the upper triangle, so only the
//! upper triangle of a matrix is sent. A packet that is shorter or longer than its
//! header says, of another version, of an unknown kind, or holding NaN/±∞ is
//! rejected with a named [`WireError`].
//!
//! ## Authenticated packets
//!
//! [`sign`] appends a [`TAG_LEN`]-byte tag to an encoded packet: HMAC-SHA256
//! (RustCrypto `hmac` + `sha2`) of the whole packet under a key shared by the
//! swarm, truncated to its first 16 bytes (HMAC-SHA-256-128, RFC 4868).
//! [`decode_signed`] checks the tag in constant time before it reads anything but
//! the header's kind and dimension: a packet of the exact unsigned length is
//! refused with [`WireError::MissingTag`], one whose tag does not verify with
//! [`WireError::BadTag`]. The tag covers every header field (swarm, sender, step,
//! round, timestamp) and the payload, so none can be changed without the key; it
//! does not stop a packet from being replayed (receivers compare its step with
//! their own) and does not hide the payload.
//!
//! ```
//! use edccif_core::wire::{self, Header, Kind, WireError};
//! let key = [7u8; 32];
//! let mut buf = [0u8; wire::MAX_SIGNED_PACKET_LEN];
//! let h = Header { swarm: 1, sender: 2, step: 3, ..Header::default() };
//! let n = wire::encode(Kind::Measurement, &h, &[1.0, 2.0, 3.0], None, &mut buf)?;
//! let n = wire::sign(&key, &mut buf, n)?;
//! assert_eq!(n, wire::packet_len(Kind::Measurement, 3) + wire::TAG_LEN);
//! assert_eq!(wire::decode_signed(&buf[..n], &key)?.header, h);
//! assert_eq!(wire::decode_signed(&buf[..n], &[8u8; 32]), Err(WireError::BadTag));
//! assert_eq!(wire::decode_signed(&buf[..n - wire::TAG_LEN], &key), Err(WireError::MissingTag));
//! buf[12] ^= 1; // another step
//! assert_eq!(wire::decode_signed(&buf[..n], &key), Err(WireError::BadTag));
//! # Ok::<(), WireError>(())
//! ```
//!
//! ```
//! use edccif_core::wire::{self, Header};
//! use edccif_core::Gaussian;
//! use nalgebra::{Matrix2, Vector2};
//!
//! let g = Gaussian::new(Vector2::new(1.0, 2.0), Matrix2::new(2.0, 0.5, 0.5, 1.0))?;
//! let h = Header { swarm: 7, sender: 3, step: 42, round: 0, stamp_ns: 4_200_000_000 };
//! let mut buf = [0u8; wire::MAX_PACKET_LEN];
//! let n = wire::encode_estimate(&h, &g, &mut buf)?;
//! assert_eq!(n, 28 + 8 * (2 + 3));
//! let frame = wire::decode(&buf[..n])?;
//! assert_eq!(frame.header, h);
//! assert_eq!(frame.estimate::<2>()?, g);
//! assert!(wire::decode(&buf[..n - 1]).is_err()); // truncated
//! # Ok::<(), Box<dyn core::error::Error>>(())
//! ```

use core::fmt;

use hmac::{Hmac, Mac};
use nalgebra::{SMatrix, SVector};
use sha2::Sha256;

use crate::message::{Contribution, Gaussian, InfoPair};

/// The two bytes every packet starts with.
pub const MAGIC: [u8; 2] = [0xED, 0xCF];
/// The format version this module writes and reads.
pub const VERSION: u8 = 1;
/// Length of the header in bytes.
pub const HEADER_LEN: usize = 28;
/// Largest dimension a packet may carry.
pub const MAX_DIM: usize = 32;
/// Length of the largest valid packet (an estimate of dimension [`MAX_DIM`]).
pub const MAX_PACKET_LEN: usize = packet_len(Kind::Estimate, MAX_DIM);
/// Length of the authentication tag [`sign`] appends: HMAC-SHA256 truncated to
/// its first 16 bytes (HMAC-SHA-256-128, RFC 4868).
pub const TAG_LEN: usize = 16;
/// Shortest key [`sign`] and [`decode_signed`] accept, in bytes.
pub const MIN_KEY_LEN: usize = 16;
/// Length of the largest valid signed packet.
pub const MAX_SIGNED_PACKET_LEN: usize = MAX_PACKET_LEN + TAG_LEN;

/// What a packet carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Kind {
    /// A sensor's measurement `z` (sent only when its trigger fired).
    Measurement = 1,
    /// A node's information contribution `(ī, Ī)` for the diffusion adaptation.
    Contribution = 2,
    /// An estimate in covariance form `(x̂, P)`.
    Estimate = 3,
    /// An information pair `(ŷ, Y)` (adapted estimates, consensus iterations).
    Information = 4,
}

impl Kind {
    /// The kind of a header byte.
    ///
    /// ```
    /// use edccif_core::wire::Kind;
    /// assert_eq!(Kind::from_byte(2), Some(Kind::Contribution));
    /// assert_eq!(Kind::from_byte(9), None);
    /// ```
    pub const fn from_byte(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::Measurement),
            2 => Some(Kind::Contribution),
            3 => Some(Kind::Estimate),
            4 => Some(Kind::Information),
            _ => None,
        }
    }

    /// Whether packets of this kind carry a symmetric matrix after the vector.
    pub const fn has_matrix(self) -> bool {
        !matches!(self, Kind::Measurement)
    }

    /// A short lower-case name (`"measurement"`, `"contribution"`, `"estimate"`,
    /// `"information"`), as used in key expressions and error messages.
    pub const fn name(self) -> &'static str {
        match self {
            Kind::Measurement => "measurement",
            Kind::Contribution => "contribution",
            Kind::Estimate => "estimate",
            Kind::Information => "information",
        }
    }
}

/// Exact length in bytes of a packet of `kind` and dimension `dim`.
///
/// ```
/// use edccif_core::wire::{packet_len, Kind};
/// assert_eq!(packet_len(Kind::Measurement, 3), 28 + 24);
/// assert_eq!(packet_len(Kind::Contribution, 7), 28 + 8 * (7 + 28));
/// ```
pub const fn packet_len(kind: Kind, dim: usize) -> usize {
    let matrix = if kind.has_matrix() {
        dim * (dim + 1) / 2
    } else {
        0
    };
    HEADER_LEN + 8 * (dim + matrix)
}

/// Who sent a packet, for which step: every field of the header except the kind
/// and the dimension (which follow from the payload).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Header {
    /// Swarm id: packets of another swarm are not for this node.
    pub swarm: u32,
    /// The sending node (or sensor) id.
    pub sender: u16,
    /// The step the payload belongs to.
    pub step: u64,
    /// Consensus iteration within the step (0 when not iterating).
    pub round: u8,
    /// Timestamp of the payload in nanoseconds (e.g. the measurement time).
    pub stamp_ns: u64,
}

/// Why a packet could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum WireError {
    /// Fewer bytes than the header, or than the header's kind and dimension need.
    Truncated {
        /// Bytes needed.
        needed: usize,
        /// Bytes received.
        got: usize,
    },
    /// More bytes than the header's kind and dimension allow.
    Oversized {
        /// The exact length expected.
        expected: usize,
        /// Bytes received.
        got: usize,
    },
    /// The packet does not start with [`MAGIC`].
    BadMagic,
    /// A format version this decoder does not read.
    WrongVersion {
        /// The version byte received.
        got: u8,
    },
    /// A kind byte that is not a [`Kind`].
    UnknownKind {
        /// The kind byte received.
        got: u8,
    },
    /// A dimension of 0 or above [`MAX_DIM`].
    BadDimension {
        /// The dimension received (or given to the encoder).
        got: usize,
    },
    /// A payload value (or a value given to the encoder) is NaN or ±∞.
    NonFinite {
        /// `"vector"` or `"matrix"`.
        field: &'static str,
        /// Index of the value within the field (row-major for the matrix).
        index: usize,
    },
    /// A typed read found another kind of packet.
    WrongKind {
        /// The kind asked for.
        expected: Kind,
        /// The kind of the packet.
        got: Kind,
    },
    /// A typed read (or the encoder) found another dimension.
    DimensionMismatch {
        /// The dimension asked for.
        expected: usize,
        /// The dimension of the packet (or the length given).
        got: usize,
    },
    /// The output buffer of the encoder is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes available.
        got: usize,
    },
    /// [`decode_signed`]: the packet has exactly the unsigned length (no tag).
    MissingTag,
    /// [`decode_signed`]: the tag does not verify under the key (another key, or
    /// a changed byte).
    BadTag,
    /// A key shorter than [`MIN_KEY_LEN`] bytes.
    KeyTooShort {
        /// The key's length in bytes.
        got: usize,
    },
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            WireError::Truncated { needed, got } => {
                write!(f, "truncated packet: {got} bytes, expected {needed}")
            }
            WireError::Oversized { expected, got } => {
                write!(f, "oversized packet: {got} bytes, expected {expected}")
            }
            WireError::BadMagic => write!(
                f,
                "not an edccif packet: expected the magic bytes 0xED 0xCF"
            ),
            WireError::WrongVersion { got } => write!(
                f,
                "wrong wire format version {got}, expected {VERSION}"
            ),
            WireError::UnknownKind { got } => write!(
                f,
                "unknown packet kind {got}, expected 1 (measurement), 2 (contribution), 3 (estimate) or 4 (information)"
            ),
            WireError::BadDimension { got } => {
                write!(f, "packet dimension {got}, expected 1..={MAX_DIM}")
            }
            WireError::NonFinite { field, index } => {
                write!(f, "packet {field}[{index}] is NaN or infinite")
            }
            WireError::WrongKind { expected, got } => write!(
                f,
                "packet kind {}, expected {}",
                got.name(),
                expected.name()
            ),
            WireError::DimensionMismatch { expected, got } => {
                write!(f, "packet dimension {got}, expected {expected}")
            }
            WireError::BufferTooSmall { needed, got } => write!(
                f,
                "output buffer of {got} bytes is too small, expected at least {needed}"
            ),
            WireError::MissingTag => write!(
                f,
                "packet without an authentication tag, expected {TAG_LEN} more bytes"
            ),
            WireError::BadTag => write!(
                f,
                "packet authentication tag does not verify under this key"
            ),
            WireError::KeyTooShort { got } => write!(
                f,
                "authentication key of {got} bytes, expected at least {MIN_KEY_LEN}"
            ),
        }
    }
}

impl core::error::Error for WireError {}

/// Encodes one packet from raw values: `vector` of length `d` and, for every kind
/// but [`Kind::Measurement`], `matrix` as a row-major `d × d` slice of which only
/// the upper triangle is written. Returns the number of bytes written to `out`.
/// The dimension-generic form behind the typed `encode_*` functions (and the
/// Python binding).
///
/// ```
/// use edccif_core::wire::{encode, decode, Header, Kind};
/// let mut buf = [0u8; 64];
/// let n = encode(Kind::Measurement, &Header::default(), &[1.0, 2.0, 3.0], None, &mut buf)?;
/// assert_eq!(decode(&buf[..n])?.value(1), 2.0);
/// # Ok::<(), edccif_core::wire::WireError>(())
/// ```
pub fn encode(
    kind: Kind,
    header: &Header,
    vector: &[f64],
    matrix: Option<&[f64]>,
    out: &mut [u8],
) -> Result<usize, WireError> {
    let d = vector.len();
    if d == 0 || d > MAX_DIM {
        return Err(WireError::BadDimension { got: d });
    }
    let matrix = match (kind.has_matrix(), matrix) {
        (true, Some(m)) if m.len() == d * d => Some(m),
        (true, Some(m)) => {
            return Err(WireError::DimensionMismatch {
                expected: d * d,
                got: m.len(),
            })
        }
        (true, None) => {
            return Err(WireError::DimensionMismatch {
                expected: d * d,
                got: 0,
            })
        }
        (false, Some(m)) => {
            return Err(WireError::DimensionMismatch {
                expected: 0,
                got: m.len(),
            })
        }
        (false, None) => None,
    };
    let len = packet_len(kind, d);
    if out.len() < len {
        return Err(WireError::BufferTooSmall {
            needed: len,
            got: out.len(),
        });
    }
    if let Some(index) = vector.iter().position(|v| !v.is_finite()) {
        return Err(WireError::NonFinite {
            field: "vector",
            index,
        });
    }
    if let Some(m) = matrix {
        for r in 0..d {
            for c in r..d {
                if !m[r * d + c].is_finite() {
                    return Err(WireError::NonFinite {
                        field: "matrix",
                        index: r * d + c,
                    });
                }
            }
        }
    }
    let out = &mut out[..len];
    out[0..2].copy_from_slice(&MAGIC);
    out[2] = VERSION;
    out[3] = kind as u8;
    out[4] = d as u8; // d ≤ MAX_DIM < 256
    out[5] = header.round;
    out[6..8].copy_from_slice(&header.sender.to_le_bytes());
    out[8..12].copy_from_slice(&header.swarm.to_le_bytes());
    out[12..20].copy_from_slice(&header.step.to_le_bytes());
    out[20..28].copy_from_slice(&header.stamp_ns.to_le_bytes());
    let mut pos = HEADER_LEN;
    let mut put = |v: f64| {
        out[pos..pos + 8].copy_from_slice(&v.to_le_bytes());
        pos += 8;
    };
    vector.iter().for_each(|v| put(*v));
    if let Some(m) = matrix {
        for r in 0..d {
            for c in r..d {
                put(m[r * d + c]);
            }
        }
    }
    Ok(len)
}

/// A validated received packet, borrowing the bytes: header, kind, dimension and
/// the payload values (all finite).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame<'a> {
    /// Sender, swarm, step, round and timestamp.
    pub header: Header,
    /// What the payload is.
    pub kind: Kind,
    /// The payload's dimension (`M` of a measurement, `N` otherwise).
    pub dim: usize,
    payload: &'a [u8],
}

/// Decodes and validates one packet: magic, version, kind, dimension, exact length
/// and every payload value finite. Allocation-free; nothing is copied until a
/// typed read ([`Frame::measurement`], …) or [`Frame::value`].
///
/// ```
/// use edccif_core::wire::{decode, WireError};
/// assert_eq!(decode(&[0xED, 0xCF, 1]), Err(WireError::Truncated { needed: 28, got: 3 }));
/// assert_eq!(decode(&[0u8; 28]), Err(WireError::BadMagic));
/// ```
pub fn decode(bytes: &[u8]) -> Result<Frame<'_>, WireError> {
    if bytes.len() < HEADER_LEN {
        return Err(WireError::Truncated {
            needed: HEADER_LEN,
            got: bytes.len(),
        });
    }
    if bytes[0..2] != MAGIC {
        return Err(WireError::BadMagic);
    }
    if bytes[2] != VERSION {
        return Err(WireError::WrongVersion { got: bytes[2] });
    }
    let kind = Kind::from_byte(bytes[3]).ok_or(WireError::UnknownKind { got: bytes[3] })?;
    let dim = usize::from(bytes[4]);
    if dim == 0 || dim > MAX_DIM {
        return Err(WireError::BadDimension { got: dim });
    }
    let len = packet_len(kind, dim);
    if bytes.len() < len {
        return Err(WireError::Truncated {
            needed: len,
            got: bytes.len(),
        });
    }
    if bytes.len() > len {
        return Err(WireError::Oversized {
            expected: len,
            got: bytes.len(),
        });
    }
    let u64_at = |o: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&bytes[o..o + 8]);
        u64::from_le_bytes(b)
    };
    let header = Header {
        round: bytes[5],
        sender: u16::from_le_bytes([bytes[6], bytes[7]]),
        swarm: u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]),
        step: u64_at(12),
        stamp_ns: u64_at(20),
    };
    let frame = Frame {
        header,
        kind,
        dim,
        payload: &bytes[HEADER_LEN..],
    };
    for idx in 0..frame.values() {
        if !frame.value(idx).is_finite() {
            return Err(if idx < dim {
                WireError::NonFinite {
                    field: "vector",
                    index: idx,
                }
            } else {
                let (r, c) = upper_position(idx - dim, dim);
                WireError::NonFinite {
                    field: "matrix",
                    index: r * dim + c,
                }
            });
        }
    }
    Ok(frame)
}

fn mac(key: &[u8]) -> Result<Hmac<Sha256>, WireError> {
    if key.len() < MIN_KEY_LEN {
        return Err(WireError::KeyTooShort { got: key.len() });
    }
    // HMAC takes keys of any length: this cannot fail.
    Hmac::<Sha256>::new_from_slice(key).map_err(|_| WireError::KeyTooShort { got: key.len() })
}

/// Appends the authentication tag of the packet `buf[..len]` (as written by
/// [`encode`] or an `encode_*` function) under `key` at `buf[len..len + TAG_LEN]`
/// and returns the signed length `len + TAG_LEN`. Allocation-free.
///
/// Errors: [`WireError::KeyTooShort`], [`WireError::BufferTooSmall`] when `buf`
/// cannot hold the tag; `len` is not checked against the header (a signed
/// garbage packet is still refused by [`decode_signed`]'s decoding).
pub fn sign(key: &[u8], buf: &mut [u8], len: usize) -> Result<usize, WireError> {
    let total = len.saturating_add(TAG_LEN);
    if buf.len() < total {
        return Err(WireError::BufferTooSmall {
            needed: total,
            got: buf.len(),
        });
    }
    let mut m = mac(key)?;
    m.update(&buf[..len]);
    let tag = m.finalize().into_bytes();
    buf[len..total].copy_from_slice(&tag[..TAG_LEN]);
    Ok(total)
}

/// Decodes a signed packet ([`sign`]): checks the header's magic, version, kind
/// and dimension, then the tag under `key` (in constant time), then everything
/// [`decode`] checks. Returns the packet as a [`Frame`].
///
/// Errors: [`WireError::MissingTag`] for a packet of exactly the unsigned length,
/// [`WireError::BadTag`] when the tag does not verify, [`WireError::KeyTooShort`],
/// and those of [`decode`] (lengths counted with the tag).
pub fn decode_signed<'a>(bytes: &'a [u8], key: &[u8]) -> Result<Frame<'a>, WireError> {
    let m = mac(key)?;
    if bytes.len() < HEADER_LEN {
        return Err(WireError::Truncated {
            needed: HEADER_LEN + TAG_LEN,
            got: bytes.len(),
        });
    }
    if bytes[0..2] != MAGIC {
        return Err(WireError::BadMagic);
    }
    if bytes[2] != VERSION {
        return Err(WireError::WrongVersion { got: bytes[2] });
    }
    let kind = Kind::from_byte(bytes[3]).ok_or(WireError::UnknownKind { got: bytes[3] })?;
    let dim = usize::from(bytes[4]);
    if dim == 0 || dim > MAX_DIM {
        return Err(WireError::BadDimension { got: dim });
    }
    let len = packet_len(kind, dim);
    if bytes.len() == len {
        return Err(WireError::MissingTag);
    }
    if bytes.len() < len + TAG_LEN {
        return Err(WireError::Truncated {
            needed: len + TAG_LEN,
            got: bytes.len(),
        });
    }
    if bytes.len() > len + TAG_LEN {
        return Err(WireError::Oversized {
            expected: len + TAG_LEN,
            got: bytes.len(),
        });
    }
    let mut m = m;
    m.update(&bytes[..len]);
    m.verify_truncated_left(&bytes[len..])
        .map_err(|_| WireError::BadTag)?;
    decode(&bytes[..len])
}

/// Row and column of the `t`-th entry of a `d × d` upper triangle stored row by row.
fn upper_position(mut t: usize, d: usize) -> (usize, usize) {
    let mut r = 0;
    while t >= d - r {
        t -= d - r;
        r += 1;
    }
    (r, r + t)
}

impl Frame<'_> {
    /// Number of payload values (`d`, plus `d(d+1)/2` with a matrix).
    pub fn values(&self) -> usize {
        self.payload.len() / 8
    }

    /// Payload value `idx` (`0..d`: the vector, then the upper triangle row by
    /// row). Panics when `idx >= self.values()`.
    pub fn value(&self, idx: usize) -> f64 {
        let mut b = [0u8; 8];
        b.copy_from_slice(&self.payload[8 * idx..8 * idx + 8]);
        f64::from_le_bytes(b)
    }

    /// Entry `(r, c)` of the symmetric matrix (either triangle). Panics when the
    /// packet has no matrix or an index is `>= dim`.
    pub fn matrix_entry(&self, r: usize, c: usize) -> f64 {
        assert!(self.kind.has_matrix() && r < self.dim && c < self.dim);
        let (r, c) = if r <= c { (r, c) } else { (c, r) };
        // rows before r hold d + (d−1) + … + (d−r+1) entries
        let before = r * self.dim - r * (r.saturating_sub(1)) / 2;
        self.value(self.dim + before + (c - r))
    }

    fn expect(&self, kind: Kind, dim: usize) -> Result<(), WireError> {
        if self.kind != kind {
            return Err(WireError::WrongKind {
                expected: kind,
                got: self.kind,
            });
        }
        if self.dim != dim {
            return Err(WireError::DimensionMismatch {
                expected: dim,
                got: self.dim,
            });
        }
        Ok(())
    }

    fn vector<const D: usize>(&self) -> SVector<f64, D> {
        SVector::from_fn(|i, _| self.value(i))
    }

    fn matrix<const D: usize>(&self) -> SMatrix<f64, D, D> {
        SMatrix::from_fn(|r, c| self.matrix_entry(r, c))
    }

    /// The measurement `z` of a [`Kind::Measurement`] packet of dimension `M`.
    pub fn measurement<const M: usize>(&self) -> Result<SVector<f64, M>, WireError> {
        self.expect(Kind::Measurement, M)?;
        Ok(self.vector())
    }

    /// The contribution `(ī, Ī)` of a [`Kind::Contribution`] packet.
    pub fn contribution<const N: usize>(&self) -> Result<Contribution<f64, N>, WireError> {
        self.expect(Kind::Contribution, N)?;
        Ok(Contribution {
            i: self.vector(),
            imat: self.matrix(),
        })
    }

    /// The estimate `(x̂, P)` of a [`Kind::Estimate`] packet. `P` is symmetric
    /// and finite; check it with [`Gaussian::new`] before trusting it as a
    /// covariance.
    pub fn estimate<const N: usize>(&self) -> Result<Gaussian<f64, N>, WireError> {
        self.expect(Kind::Estimate, N)?;
        Ok(Gaussian {
            x: self.vector(),
            p: self.matrix(),
        })
    }

    /// The information pair `(ŷ, Y)` of a [`Kind::Information`] packet.
    pub fn information<const N: usize>(&self) -> Result<InfoPair<f64, N>, WireError> {
        self.expect(Kind::Information, N)?;
        Ok(InfoPair {
            y: self.vector(),
            ymat: self.matrix(),
        })
    }
}

fn encode_pair<const D: usize>(
    kind: Kind,
    header: &Header,
    v: &SVector<f64, D>,
    m: &SMatrix<f64, D, D>,
    out: &mut [u8],
) -> Result<usize, WireError> {
    // nalgebra stores column-major: the storage of mᵀ is m row by row.
    let t = m.transpose();
    encode(kind, header, v.as_slice(), Some(t.as_slice()), out)
}

/// Encodes a measurement `z` (dimension `M`); returns the bytes written.
///
/// ```
/// use edccif_core::wire::{decode, encode_measurement, Header};
/// let mut buf = [0u8; 64];
/// let n = encode_measurement(&Header::default(), &nalgebra::Vector3::new(1.0, 2.0, 3.0), &mut buf)?;
/// assert_eq!(decode(&buf[..n])?.measurement::<3>()?.y, 2.0);
/// # Ok::<(), edccif_core::wire::WireError>(())
/// ```
pub fn encode_measurement<const M: usize>(
    header: &Header,
    z: &SVector<f64, M>,
    out: &mut [u8],
) -> Result<usize, WireError> {
    encode(Kind::Measurement, header, z.as_slice(), None, out)
}

/// Encodes a contribution `(ī, Ī)`; returns the bytes written.
pub fn encode_contribution<const N: usize>(
    header: &Header,
    c: &Contribution<f64, N>,
    out: &mut [u8],
) -> Result<usize, WireError> {
    encode_pair(Kind::Contribution, header, &c.i, &c.imat, out)
}

/// Encodes an estimate `(x̂, P)`; returns the bytes written.
pub fn encode_estimate<const N: usize>(
    header: &Header,
    g: &Gaussian<f64, N>,
    out: &mut [u8],
) -> Result<usize, WireError> {
    encode_pair(Kind::Estimate, header, &g.x, &g.p, out)
}

/// Encodes an information pair `(ŷ, Y)`; returns the bytes written.
pub fn encode_information<const N: usize>(
    header: &Header,
    p: &InfoPair<f64, N>,
    out: &mut [u8],
) -> Result<usize, WireError> {
    encode_pair(Kind::Information, header, &p.y, &p.ymat, out)
}
