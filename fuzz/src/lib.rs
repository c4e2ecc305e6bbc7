//! Helpers shared by the fuzz targets: arbitrary bytes → floats, matrices and
//! model parameters, and the invariants checked on every `Ok`.

use edccif_core::nalgebra::{SMatrix, SVector};
use edccif_core::{Gaussian, InfoPair};

/// Reads values from the fuzzer's bytes; past the end everything is 0.
pub struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Bytes<'a> {
    /// Wraps the input.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }

    /// One byte.
    pub fn u8(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }

    /// A boolean.
    pub fn bool(&mut self) -> bool {
        self.u8() & 1 == 1
    }

    /// A float: mostly moderate values in about [-10, 10], sometimes special
    /// values (NaN, ±∞, 0, huge, tiny) or raw 8-byte patterns.
    pub fn f(&mut self) -> f64 {
        let tag = self.u8();
        match tag {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => 0.0,
            4 => 1e300,
            5 => 1e-300,
            6 => -1.0,
            7 => {
                let mut b = [0u8; 8];
                for v in &mut b {
                    *v = self.u8();
                }
                f64::from_le_bytes(b)
            }
            _ => {
                let v = i16::from_le_bytes([self.u8(), self.u8()]);
                f64::from(v) / 3276.8
            }
        }
    }

    /// A positive scale: `10^(f/2)` for a moderate draw, else a raw [`f`](Self::f).
    pub fn pos(&mut self) -> f64 {
        if self.u8() < 240 {
            10f64.powf(self.f().clamp(-20.0, 20.0) / 2.0)
        } else {
            self.f()
        }
    }

    /// A vector.
    pub fn vec<const D: usize>(&mut self) -> SVector<f64, D> {
        SVector::from_fn(|_, _| self.f())
    }

    /// A covariance: usually `L Lᵀ + ε I` (PD), sometimes an arbitrary matrix.
    pub fn cov<const D: usize>(&mut self) -> SMatrix<f64, D, D> {
        if self.u8() < 230 {
            let l = SMatrix::<f64, D, D>::from_fn(|i, j| if j <= i { self.f() } else { 0.0 });
            let eps = self.pos();
            l * l.transpose() + SMatrix::identity() * eps
        } else {
            SMatrix::from_fn(|_, _| self.f())
        }
    }
}

/// Every entry finite.
pub fn finite<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> bool {
    m.iter().all(|v| v.is_finite())
}

/// Symmetric (exactly, as the core symmetrises) and Cholesky-PD.
pub fn spd<const D: usize>(m: &SMatrix<f64, D, D>) -> bool {
    finite(m) && *m == m.transpose() && m.cholesky().is_some()
}

/// The invariant of an estimate the core returned.
pub fn check_gaussian<const D: usize>(g: &Gaussian<f64, D>, what: &str) {
    assert!(finite(&g.x), "{what}: non-finite x {:?}", g.x);
    assert!(spd(&g.p), "{what}: covariance not symmetric PD {:?}", g.p);
}

/// The invariant of an information pair the core returned (finite, Y symmetric).
pub fn check_info<const D: usize>(p: &InfoPair<f64, D>, what: &str) {
    assert!(finite(&p.y) && finite(&p.ymat), "{what}: non-finite");
    assert!(p.ymat == p.ymat.transpose(), "{what}: Y not symmetric");
}
