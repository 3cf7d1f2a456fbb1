//! `CAMPRO_ENGINE` picks `Exact8`'s engine by name (its own test binary: the variable is
//! process-wide, and the other tests build `Exact8` in parallel threads).

use campro::pipeline::fast::{Engine, Exact8, ENGINE_VARIABLE};
use campro::Params;

#[test]
fn the_engine_variable_is_read_by_name() {
    let p =
        Params::from_file(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/params/campro-omega-0.5.json")))
            .unwrap();
    std::env::set_var(ENGINE_VARIABLE, "scalar");
    assert_eq!(Engine::from_env(), Ok(Some(Engine::Scalar)));
    assert_eq!(Exact8::new(&p).engine(), Engine::Scalar);
    // An engine this CPU lacks is not taken: the fastest that runs is.
    std::env::set_var(ENGINE_VARIABLE, "avx512");
    let e = Exact8::new(&p);
    assert!(e.runs(e.engine()));
    std::env::set_var(ENGINE_VARIABLE, "neon");
    assert_eq!(Engine::from_env(), Err("CAMPRO_ENGINE=neon: not an engine (scalar, avx2 or avx512)".into()));
    std::env::remove_var(ENGINE_VARIABLE);
    assert_eq!(Engine::from_env(), Ok(None));
}
