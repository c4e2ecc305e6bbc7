//! The seeded randomness of the stochastic trigger: a counter-based generator
//! (splitmix64) with one independent, reproducible stream per `(seed, node)`.

use nalgebra::RealField;

use crate::linalg::c;

/// One step of the splitmix64 generator (Steele, Lea, Flood 2014): a bijective
/// mix of `x`. Counter-based: `splitmix64(state + k·0x9E37…)` is the k-th draw.
///
/// ```
/// use edccif_core::rng::splitmix64;
/// assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
/// assert_ne!(splitmix64(1), splitmix64(2));
/// ```
pub fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The random stream of one sensor: a key from `(seed, node)`, so that every node
/// of every seeded run draws independent, reproducible numbers.
///
/// ```
/// use edccif_core::rng::stream_key;
/// assert_eq!(stream_key(7, 2), stream_key(7, 2));
/// assert_ne!(stream_key(7, 2), stream_key(7, 3));
/// assert_ne!(stream_key(7, 2), stream_key(8, 2));
/// ```
pub fn stream_key(seed: u64, node: u64) -> u64 {
    splitmix64(splitmix64(seed) ^ node.wrapping_mul(0xD1B5_4A32_D192_ED03))
}

/// The `draw`-th uniform number in `[0, 1)` of stream `key` (53 random bits).
///
/// ```
/// use edccif_core::rng::{stream_key, uniform};
/// let u: f64 = uniform(stream_key(0, 0), 5);
/// assert!((0.0..1.0).contains(&u));
/// assert_eq!(u, uniform::<f64>(stream_key(0, 0), 5));
/// ```
pub fn uniform<T: RealField + Copy>(key: u64, draw: u64) -> T {
    let bits = splitmix64(key.wrapping_add(draw.wrapping_mul(0x9E37_79B9_7F4A_7C15))) >> 11;
    c(bits as f64 * (1.0 / (1u64 << 53) as f64))
}
