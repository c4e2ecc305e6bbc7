//! The README's Rust quick start, compiled and run. `readme_snippet_is_this_code`
//! fails when the README block and the code below drift apart.

use edccif_core::{fusion::max_degree_weights, models::*, *};
use nalgebra::{SMatrix, SVector, Vector3};

/// The marker line (with its indentation and newline, so this constant itself
/// does not match).
const SNIPPET_START: &str = "    // snippet start\n";

#[test]
fn readme_quick_start_runs() -> Result<()> {
    // snippet start

    let motion = CoordinatedTurn::new(0.5, 1e-4)?;
    let sensors = [
        RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)?,
        RangePitchAzimuth::new([-10.0, 0.0, 3.0], 0.1, 0.01)?,
    ];
    let mut w = [0.0; 4];
    max_degree_weights(&[false, true, true, false], 2, &mut w)?;
    let cfg = NetworkConfig {
        filter: NodeFilter::Cif,
        trigger: Trigger::SendOnDelta { delta: 0.04 },
        et: EtOptions::default(),
        fusion: Fusion::DiffusionCi,
        rule: FusionRule::CI,
    }; // or "ici", "split-ci", ... (docs/fusion.md)
    let start = Gaussian::new(
        SVector::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
        SMatrix::<f64, 7, 7>::identity() * 0.01,
    )?;
    let mut nodes = [NodeState::new(start, &cfg.trigger); 2];
    let mut scratch = [NodeScratch::default(); 2];
    let obs = [
        Observation::Measured(Vector3::new(5.0, 0.05, 3.1)),
        Observation::Missing,
    ];
    let dt = 0.1; // seconds since the last step; may differ from step to step
    network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, dt),
    )?;
    // snippet end
    assert!(nodes[0].estimate.x.iter().all(|v| v.is_finite()));
    Ok(())
}

#[test]
fn readme_snippet_is_this_code() {
    let readme = include_str!("../../../../README.md");
    let start = readme.find("## Rust quick start").expect("README section");
    let block = &readme[start..];
    let block = &block[block.find("```rust\n").unwrap() + 8..];
    let block = &block[..block.find("```").unwrap()];
    let me = include_str!("readme.rs");
    let body = &me[me.find(SNIPPET_START).unwrap()..];
    let body = &body[SNIPPET_START.len()..body.find("// snippet end").unwrap()];
    // Compare token streams: rustfmt may re-wrap the code here.
    let strip = |s: &str| {
        let code: String = s
            .lines()
            .filter(|l| !l.trim_start().starts_with("use "))
            .flat_map(|l| l.chars())
            .filter(|c| !c.is_whitespace())
            .collect();
        code.replace(",]", "]")
            .replace(",}", "}")
            .replace(",)", ")")
    };
    assert_eq!(
        strip(block),
        strip(body),
        "README's Rust quick start differs from tests/suite/readme.rs"
    );
}
