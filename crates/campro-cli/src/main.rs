//! The `campro` binary: the command-line tool of the library beside it (`lib.rs`).

fn main() {
    campro_cli::main_with(std::env::args_os())
}
