//! `campro stress`: the numerical soak. Adversarial random cases (`campro::stress`)
//! checked against every invariant until the time is up.

use crate::args::{Report, StressArgs};
use crate::say;
use anyhow::{bail, Result};
use campro::stress;

pub fn stress(a: &StressArgs) -> Result<()> {
    let (seconds, seed) = (a.seconds, a.seed);
    let start = std::time::Instant::now();
    let (mut converted, mut refused) = (0u64, 0u64);
    let mut s = seed;
    while start.elapsed().as_secs_f64() < seconds {
        match stress::check(&stress::random_case(s)) {
            Ok(stress::Outcome::Converted) => converted += 1,
            Ok(stress::Outcome::Refused) => refused += 1,
            Err(e) => bail!("invariant broken after {} cases: {e}", converted + refused),
        }
        s = s.wrapping_add(1);
    }
    let secs = start.elapsed().as_secs_f64();
    match a.format {
        Report::Text => say!("stress: {} cases in {secs:.1} s (seeds {seed}..{s}): {converted} converted, {refused} refused with a named error, 0 invariants broken", converted + refused),
        Report::Json => say!("{}", serde_json::json!({
            "cases": converted + refused, "seconds": secs, "first_seed": seed, "next_seed": s,
            "converted": converted, "refused": refused, "invariants_broken": 0,
        })),
    }
    Ok(())
}
