//! Sizes checked before allocating, and bounded thread counts.
//!
//! Every entry point that allocates in proportion to its inputs (nodes ×
//! (degree + 1),
//! steps × nodes × n, runs, rows) computes the bytes first and calls
//! [`check_memory`], which refuses with [`Error::TooLarge`] (the size and the
//! limit) what does not fit in the memory available now: `MemAvailable` of
//! `/proc/meminfo`, lowered to what the cgroup (a container's memory limit)
//! still allows, or the environment variable `EDCCIF_MEMORY_LIMIT` (bytes, or
//! with a `K`/`M`/`G`/`T` suffix) when set. Elsewhere (no `/proc`) the limit is
//! 8 GiB unless the variable says otherwise.
//!
//! Thread counts (the network step's `threads`, the Monte Carlo pool) are at
//! most [`THREADS_PER_CORE`] per core ([`max_threads`]).
//!
//! ```
//! use edccif_sim::limits::{check_memory, check_threads_bound, max_threads};
//! assert!(check_memory(|| "a small buffer".into(), 1024).is_ok());
//! let e = check_memory(|| "10¹² steps".into(), 1u128 << 80).unwrap_err().to_string();
//! assert!(e.contains("10¹² steps") && e.contains("available"), "{e}");
//! assert!(check_threads_bound("threads", max_threads()).is_ok());
//! assert!(check_threads_bound("threads", max_threads() + 1).is_err());
//! ```

pub use crate::error::fmt_bytes;
use crate::error::{Error, Result};

/// Threads per core a thread count may ask for at most (the network step's
/// `threads`, the Monte Carlo worker pool).
pub const THREADS_PER_CORE: usize = 4;

/// The memory limit used where the system does not say (no `/proc/meminfo`).
pub const FALLBACK_MEMORY: u64 = 8 << 30;

/// Cores of this machine (`std::thread::available_parallelism`, 1 if unknown).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

/// The largest thread count accepted: [`THREADS_PER_CORE`] × [`cores`].
pub fn max_threads() -> usize {
    THREADS_PER_CORE * cores()
}

/// `Ok` for `1..=max_threads()`; the error names `what`, the bound and why.
pub fn check_threads_bound(what: &str, n: usize) -> Result<()> {
    let max = max_threads();
    if (1..=max).contains(&n) {
        Ok(())
    } else {
        Err(Error::Value {
            what: what.into(),
            problem: format!(
                "expected a thread count in 1..={max} ({THREADS_PER_CORE} per core on this machine's {} cores), got {n}",
                cores()
            ),
        })
    }
}

/// A byte count as `EDCCIF_MEMORY_LIMIT` takes it: a non-negative number of
/// bytes, or of KiB, MiB, GiB or TiB with a `K`, `M`, `G` or `T` suffix (either
/// case); `None` for anything else.
///
/// ```
/// use edccif_sim::limits::parse_bytes;
/// assert_eq!(parse_bytes("1024"), Some(1024));
/// assert_eq!(parse_bytes("2K"), Some(2048));
/// assert_eq!(parse_bytes("1.5G"), Some(3 << 29));
/// assert_eq!(parse_bytes("x"), None);
/// assert_eq!(parse_bytes("-1"), None);
/// ```
pub fn parse_bytes(s: &str) -> Option<u64> {
    let s = s.trim();
    let (num, mult) = match s.chars().last()?.to_ascii_uppercase() {
        'K' => (&s[..s.len() - 1], 1u64 << 10),
        'M' => (&s[..s.len() - 1], 1 << 20),
        'G' => (&s[..s.len() - 1], 1 << 30),
        'T' => (&s[..s.len() - 1], 1 << 40),
        _ => (s, 1),
    };
    let v: f64 = num.trim().parse().ok()?;
    (v.is_finite() && v >= 0.0).then_some((v * mult as f64) as u64)
}

fn meminfo_available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

fn cgroup_available() -> Option<u64> {
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let max: u64 = read("/sys/fs/cgroup/memory.max")?.trim().parse().ok()?;
    let current: u64 = read("/sys/fs/cgroup/memory.current")
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0);
    Some(max.saturating_sub(current))
}

/// Bytes of memory a computation may allocate now (see the module
/// documentation for where the number comes from).
pub fn available_memory() -> u64 {
    if let Some(v) = std::env::var("EDCCIF_MEMORY_LIMIT")
        .ok()
        .as_deref()
        .and_then(parse_bytes)
    {
        return v;
    }
    let sys = meminfo_available().unwrap_or(FALLBACK_MEMORY);
    cgroup_available().map_or(sys, |c| c.min(sys))
}

/// Refuses an allocation of `bytes` that does not fit in [`available_memory`]:
/// [`Error::TooLarge`] naming what needs it (`what()`, e.g. `"steps × nodes ×
/// n = 10⁹ × 4 × 7 estimates"`), the bytes and the limit.
pub fn check_memory(what: impl FnOnce() -> String, bytes: u128) -> Result<()> {
    // Small requests never need the system's figure.
    if bytes <= 64 << 20 {
        return Ok(());
    }
    let limit = available_memory();
    if bytes <= u128::from(limit) {
        Ok(())
    } else {
        Err(Error::TooLarge {
            what: what(),
            needed: bytes,
            limit,
        })
    }
}

/// `a × b × …` without overflow (u128; saturates instead of wrapping).
///
/// ```
/// use edccif_sim::limits::product;
/// assert_eq!(product(&[3, 4]), 12);
/// assert_eq!(product(&[usize::MAX, usize::MAX, usize::MAX]), u128::MAX);
/// ```
pub fn product(factors: &[usize]) -> u128 {
    factors
        .iter()
        .fold(1u128, |acc, &f| acc.saturating_mul(f as u128))
}

/// Bytes a network keeps per node besides its graph: a node's state and the
/// working memory of the serial and the parallel step (for the largest
/// built-in state, 9).
pub fn node_bytes() -> usize {
    use edccif_core::{NodeScratch, NodeState};
    2 * (std::mem::size_of::<NodeScratch<f64, 9, 3>>()
        + std::mem::size_of::<NodeState<f64, 9, 3>>())
}

/// Bytes of a scenario network of `nodes` nodes whose neighbour lists hold
/// `entries` entries (nodes × (degree + 1) at most): an index and a weight
/// per entry and, twice (the lists and the parallel step's copy), plus
/// [`node_bytes`] per node. Linear in the nodes for a graph of bounded
/// degree; `nodes²` only for the complete graph.
pub fn graph_bytes(nodes: usize, entries: u128) -> u128 {
    entries
        .saturating_mul(2 * 16)
        .saturating_add(product(&[nodes, node_bytes() + 16]))
}

/// Refuses a scenario of `nodes` nodes that cannot fit even with the
/// sparsest graph the built-in topologies have (a ring: 3 entries per node);
/// a scenario's own topology is checked when its lists are built
/// ([`Topology::neighbours`](crate::Topology::neighbours)).
///
/// ```
/// let e = edccif_sim::limits::check_nodes(1_000_000_000_000).unwrap_err().to_string();
/// assert!(e.contains("nodes = 1000000000000"), "{e}");
/// assert!(edccif_sim::limits::check_nodes(100_000).is_ok());
/// ```
pub fn check_nodes(nodes: usize) -> Result<()> {
    check_memory(
        || {
            format!(
                "nodes = {nodes}: every node's state and working memory, and the neighbour lists of the graph"
            )
        },
        graph_bytes(nodes, product(&[nodes, 3])),
    )
}
