//! Which configuration a timing measures, printed in the header of every timing
//! tool: the build's CPU level (the target features compiled in, and what the
//! CPU running it offers), the trigonometry path and the ET-CIF's untriggered
//! form.
//!
//! A [`Config`] starts from the library's defaults (those of
//! [`Scenario::paper`]) and is changed by the timing tools' flags
//! ([`Config::parse_flag`]):
//!
//! | flag | meaning |
//! |---|---|
//! | `--fast-trig` | the models' fast trigonometry ([`edccif_core::trig`]) |
//! | `--libm-trig` | the platform libm's `atan2` and `sin_cos` (bit-exact reference) |
//! | `--closed-form` | the ET-CIF's untriggered contribution in closed form |
//! | `--stable-form` | the paper's stable form of it |
//! | `--reference` | `--libm-trig --stable-form`: the bit-exact reference path |
//!
//! ```
//! use edccif_bench::config::Config;
//! let mut c = Config::library_default();
//! assert!(c.parse_flag("--fast-trig") && c.fast_trig);
//! assert!(c.parse_flag("--reference") && !c.fast_trig && !c.closed_form);
//! assert!(!c.parse_flag("--reps"));
//! assert!(c.describe().contains("platform libm"));
//! ```

use edccif_sim::Scenario;
use serde_json::{json, Value};

/// The trigonometry path and the ET-CIF's untriggered form of a timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// The models' fast trigonometry (`Scenario::fast_trig`).
    pub fast_trig: bool,
    /// The ET-CIF's untriggered contribution in closed form
    /// (`Scenario::untriggered_closed_form`).
    pub closed_form: bool,
}

/// The flags [`Config::parse_flag`] takes, for the tools' usage lines.
pub const FLAGS: &str = "[--fast-trig|--libm-trig] [--closed-form|--stable-form] [--reference]";

impl Config {
    /// The library's defaults: what [`Scenario::paper`] sets.
    pub fn library_default() -> Self {
        let sc = Scenario::paper(1);
        Self {
            fast_trig: sc.fast_trig,
            closed_form: sc.untriggered_closed_form,
        }
    }

    /// The bit-exact reference path: the platform libm's trigonometry and the
    /// paper's stable form.
    pub const fn reference() -> Self {
        Self {
            fast_trig: false,
            closed_form: false,
        }
    }

    /// Applies one of [`FLAGS`]; `false` when `arg` is not one of them.
    pub fn parse_flag(&mut self, arg: &str) -> bool {
        match arg {
            "--fast-trig" => self.fast_trig = true,
            "--libm-trig" => self.fast_trig = false,
            "--closed-form" => self.closed_form = true,
            "--stable-form" => self.closed_form = false,
            "--reference" => *self = Self::reference(),
            _ => return false,
        }
        true
    }

    /// Sets the scenario's `fast_trig` and `untriggered_closed_form` (the
    /// filters' models only: a simulation's truth does not depend on them).
    pub fn apply(&self, scenario: &mut Scenario) {
        scenario.fast_trig = self.fast_trig;
        scenario.untriggered_closed_form = self.closed_form;
    }

    /// `"fast"` or `"libm"`.
    pub fn trig_name(&self) -> &'static str {
        if self.fast_trig {
            "fast"
        } else {
            "libm"
        }
    }

    /// `"closed"` or `"stable"`.
    pub fn form_name(&self) -> &'static str {
        if self.closed_form {
            "closed"
        } else {
            "stable"
        }
    }

    /// Short label, e.g. `"trig fast, closed form"`.
    pub fn label(&self) -> String {
        format!("trig {}, {} form", self.trig_name(), self.form_name())
    }

    /// One line for a tool's header: the build, the CPU, the trigonometry, the
    /// untriggered form.
    pub fn describe(&self) -> String {
        format!(
            "configuration: build {} ({}); CPU offers {}; trigonometry: {}; untriggered ET-CIF: {}",
            build_level(),
            build_profile(),
            cpu_level(),
            if self.fast_trig {
                "fast (edccif_core::trig)"
            } else {
                "platform libm (bit-exact reference)"
            },
            if self.closed_form {
                "closed form"
            } else {
                "stable form"
            },
        )
    }

    /// The same as JSON: `{"build", "profile", "cpu", "trig", "untriggered"}`.
    pub fn to_json(&self) -> Value {
        json!({
            "build": build_level(),
            "profile": build_profile(),
            "cpu": cpu_level(),
            "trig": self.trig_name(),
            "untriggered": self.form_name(),
        })
    }
}

/// The x86-64 level this binary was compiled for (its target features, e.g.
/// from `RUSTFLAGS="-C target-cpu=x86-64-v3"`).
pub fn build_level() -> &'static str {
    level(
        cfg!(target_arch = "x86_64"),
        cfg!(all(
            target_feature = "sse3",
            target_feature = "ssse3",
            target_feature = "sse4.1",
            target_feature = "sse4.2",
            target_feature = "popcnt"
        )),
        cfg!(all(
            target_feature = "avx",
            target_feature = "avx2",
            target_feature = "fma",
            target_feature = "bmi1",
            target_feature = "bmi2"
        )),
        cfg!(all(
            target_feature = "avx512f",
            target_feature = "avx512bw",
            target_feature = "avx512dq",
            target_feature = "avx512vl"
        )),
    )
}

/// The highest x86-64 level the CPU running this offers.
pub fn cpu_level() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        level(
            true,
            has!("sse3") && has!("ssse3") && has!("sse4.1") && has!("sse4.2") && has!("popcnt"),
            has!("avx") && has!("avx2") && has!("fma") && has!("bmi1") && has!("bmi2"),
            has!("avx512f") && has!("avx512bw") && has!("avx512dq") && has!("avx512vl"),
        )
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        level(false, false, false, false)
    }
}

fn level(x86_64: bool, v2: bool, v3: bool, v4: bool) -> &'static str {
    match (x86_64, v2 && v3, v4) {
        (false, _, _) => std::env::consts::ARCH,
        (true, true, true) => "x86-64-v4",
        (true, true, false) => "x86-64-v3",
        (true, false, _) if v2 => "x86-64-v2",
        _ => "x86-64 (baseline)",
    }
}

/// `"release"` or `"debug (not for timing)"`.
pub fn build_profile() -> &'static str {
    if cfg!(debug_assertions) {
        "debug assertions on: not for timing"
    } else {
        "optimised"
    }
}
