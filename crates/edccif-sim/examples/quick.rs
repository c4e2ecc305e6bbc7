//! Quick look at every row on the default scenario: `cargo run --release -p edccif-sim --example quick -- 4 50`.
use edccif_sim::{monte_carlo, Algorithm, McSettings, Scenario, Variant};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let nodes = args.get(1).map_or(Ok(4), |s| s.parse())?;
    let runs = args.get(2).map_or(Ok(50), |s| s.parse())?;
    let variants: Vec<Variant> = Algorithm::ALL.iter().map(|a| (*a).into()).collect();
    let r = monte_carlo(
        &Scenario::paper(nodes),
        &variants,
        &McSettings {
            runs,
            seed: 0,
            progress: true,
        },
    )?;
    println!("{}", r.to_markdown());
    Ok(())
}
