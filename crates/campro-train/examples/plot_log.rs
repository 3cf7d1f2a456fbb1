//! Redraws the loss and accuracy plots of a training log: `cargo run --release -p
//! campro-train --example plot_log -- LOG.csv` writes `LOG-losses.svg` and
//! `LOG-accuracy.svg` beside it (as `campro train --log` does at the end of a run), e.g.
//! for a log merged from the parts of a run resumed from checkpoints without a log.

fn main() {
    let Some(path) = std::env::args().nth(1).map(std::path::PathBuf::from) else {
        eprintln!("usage: plot_log LOG.csv");
        std::process::exit(2);
    };
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        eprintln!("{}: {e}", path.display());
        std::process::exit(1)
    });
    let log = campro_train::log::parse_log_csv(&text).unwrap_or_else(|e| {
        eprintln!("{}: {e}", path.display());
        std::process::exit(1)
    });
    let (losses, acc) = campro_train::log::plot_log(&log);
    let stem = path.with_extension("");
    for (suffix, svg) in [("losses", losses), ("accuracy", acc)] {
        let out = std::path::PathBuf::from(format!("{}-{suffix}.svg", stem.display()));
        if let Err(e) = campro::file::atomic::write(&out, svg.as_bytes(), true) {
            eprintln!("{}: {e}", out.display());
            std::process::exit(1);
        }
        eprintln!("{}", out.display());
    }
}
