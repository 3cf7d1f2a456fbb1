//! `campro`: the desktop command-line tool. It only parses arguments (`args`), reads and
//! writes files and prints (`output`); every computation is a call into the libraries.
//! One module per command's body; this file dispatches. The tool is a library too, so that
//! the Python wheel (`crates/campro-py`) runs the very same command ([`main_with`]) and
//! reads, captures and writes photos as `simulate` does ([`api`]).

pub mod api;
mod args;
mod bench;
mod capture;
mod check;
mod convert;
mod demo;
mod eval;
mod icc;
mod inspect;
mod man;
mod metadata;
mod models;
mod output;
mod page;
mod params;
mod presets;
mod record;
mod retrain;
mod simulate;
mod stress;
mod train;
mod video;

use anyhow::Result;
use args::{BenchArgs, BenchWhat, Cli, Cmd, Report};
use clap::Parser;

pub(crate) use output::{
    about, check_output_folder, escape, not_an_input, one_line, output_result, say, say_bytes, short, shown,
    write_atomic, MAX_ERROR_CHARS,
};
pub(crate) use params::load_params;

/// Runs the `campro` command on `args` (the program's name first, as `std::env::args_os`
/// gives them) and exits the process with its status: 0, 1 for an error (one line on
/// stderr), 2 for a usage error, as the binary does.
pub fn main_with(args: impl IntoIterator<Item = std::ffi::OsString>) -> ! {
    // No panic message or backtrace ever reaches the user (RUST_BACKTRACE set or not): a
    // bug is reported as one line, and the process exits 101 as a panic would.
    std::panic::set_hook(Box::new(|info| {
        let what = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown".into());
        let first = what.lines().next().unwrap_or_default();
        eprintln!("error: internal error (a bug in campro, please report it): {}", escape(first));
    }));
    // Ctrl-C or SIGTERM during a long write: the unfinished hidden `.campro-*` files go.
    let _ = ctrlc::set_handler(|| {
        video::kill_children();
        campro::file::atomic::remove_partial_files();
        eprintln!("interrupted");
        std::process::exit(130);
    });
    let args: Vec<std::ffi::OsString> = args.into_iter().collect();
    let cli = match Cli::try_parse_from(&args) {
        Ok(cli) => cli,
        // --help and --version print as clap writes them.
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // Photos where the preset goes: said so, rather than "required arguments".
            if let Some(given) =
                preset_forgotten(&args).filter(|_| e.kind() == clap::error::ErrorKind::MissingRequiredArgument)
            {
                let given = short(&escape(&given), MAX_ERROR_CHARS);
                eprintln!(
                    "error: {given}: is not a preset; the parameter set comes first: campro {} PRESET {given} ... (campro presets lists them)",
                    args[1].to_string_lossy(),
                );
                std::process::exit(2);
            }
            // A usage error is printed whole, as clap words it: the flag and the rule, a
            // "did you mean", the valid values, the usage line. Every line escaped and cut.
            let text = e.render().to_string();
            for line in text.lines().filter(|l| !l.trim().is_empty()) {
                eprintln!("{}", short(&escape(line), MAX_ERROR_CHARS));
            }
            std::process::exit(2);
        }
    };
    // The memory budget is decided once, before any file is read.
    if let Err(e) = campro_eval::image_file::budget_from_env() {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
    if let Err(e) = run(cli) {
        eprintln!("error: {}", one_line(&e));
        std::process::exit(1);
    }
    std::process::exit(0)
}

/// The photos a command was given in place of its preset (`campro simulate photos/ -o out`):
/// the first operand of `simulate`, `inspect` or `check`, when it is an existing file or
/// folder and no bundled preset's name, and nothing else was left to be the photos.
fn preset_forgotten(args: &[std::ffi::OsString]) -> Option<String> {
    let command = args.get(1)?.to_str()?;
    if !matches!(command, "simulate" | "inspect" | "check") {
        return None;
    }
    // Operands: not flags, and not the value after -o / --output.
    let mut operands = Vec::new();
    let mut skip = false;
    for a in &args[2..] {
        let t = a.to_string_lossy();
        if skip {
            skip = false;
        } else if t == "-o" || t == "--output" {
            skip = true;
        } else if !t.starts_with('-') {
            operands.push(a);
        }
    }
    let [only] = operands[..] else { return None };
    let path = std::path::Path::new(only);
    (path.exists() && presets::named(path).is_none() && path.extension().is_none_or(|e| e != "json"))
        .then(|| path.display().to_string())
}

fn run(cli: Cli) -> Result<()> {
    // CAMPRO_ENGINE (the exact 8-bit path's engine, for timing each) is read once here: a
    // value that names no engine is refused, one this CPU lacks is said.
    match campro::pipeline::fast::Engine::from_env() {
        Err(line) => anyhow::bail!("{line}"),
        Ok(Some(e)) if !campro::pipeline::fast::Engine::runs_here(e) => {
            eprintln!(
                "warning: {}={}: not on this CPU; the fastest engine that runs is used",
                campro::pipeline::fast::ENGINE_VARIABLE,
                e.name()
            )
        }
        _ => {}
    }
    match cli.cmd {
        Cmd::Validate(a) => params::validate(&a),
        Cmd::Completions { shell } => {
            let mut buf = Vec::new();
            clap_complete::generate(shell, &mut <Cli as clap::CommandFactory>::command(), "campro", &mut buf);
            say_bytes(&buf);
            Ok(())
        }
        Cmd::Man(a) => man::run(&a.command, a.output.as_deref(), a.markdown, a.force),
        Cmd::ImportPt(a) => params::import_pt(&a),
        Cmd::Convert(a) => convert::convert(a),
        Cmd::Compare(a) => convert::compare(a),
        Cmd::Simulate(a) => simulate::run(a),
        Cmd::Inspect(a) => inspect::run(a),
        Cmd::Check(a) => match check::run(a)? {
            0 => Ok(()),
            code => std::process::exit(code),
        },
        Cmd::Bench(BenchArgs { what: Some(BenchWhat::Train(a)), .. }) => train::bench_train(&a),
        Cmd::Bench(BenchArgs { what: Some(BenchWhat::Enhancer(a)), .. }) => train::bench_enhancer(&a),
        Cmd::Bench(a) => bench::run_command(&a),
        Cmd::Stress(a) => stress::stress(&a),
        Cmd::Eval { what } => eval::run(*what),
        Cmd::Train(a) => train::train(&a),
        Cmd::FinetuneDetector(a) => train::finetune_detector(&a),
        Cmd::TrainEnhancer(a) => train::train_enhancer(&a),
        Cmd::Models(a) => match a.what {
            args::ModelsCmd::List { data, format } => {
                models::list(data.models.as_deref(), data.shared.as_deref(), format == Report::Json)
            }
            args::ModelsCmd::Fetch { force } => models::fetch(force),
            args::ModelsCmd::Add { files, force } => models::add(&files, force),
        },
        Cmd::Presets(a) => presets::list(a.format == Report::Json),
        Cmd::Demo(a) => demo::demo(&a),
    }
}
