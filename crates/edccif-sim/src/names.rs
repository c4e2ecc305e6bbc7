//! Names of the algorithm rows, in table order: the one list that parsing
//! ([`Algorithm::NAMES`](crate::Algorithm::NAMES)) and the errors naming the
//! accepted values read.

/// The rows' names accepted by [`Algorithm`](crate::Algorithm)'s `FromStr`.
pub(crate) const ALGORITHMS: [&str; 9] = [
    "c-ckf", "ec-ekf", "ec-ukf", "ec-ckf", "dec-ckf", "d-cif", "dc-cif", "ed-cif", "edc-cif",
];
