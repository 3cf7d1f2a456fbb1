//! The `campro` command line, end to end: outputs, bad input (one-line errors, non-zero
//! exit, no panic, no partial files), overwrite rules. One module a command family.

#[path = "../common/mod.rs"]
mod common;

mod commands;
mod convert;
mod eval;
mod photos;
mod train;

use campro::Params;
use common::{bundled, campro, fails_with, write_pt};
use std::io::Write;
use std::path::{Path, PathBuf};

fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        walk(dir).into_iter().map(|p| p.strip_prefix(dir).unwrap().display().to_string()).collect();
    v.sort();
    v
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p))
        } else {
            out.push(p)
        }
    }
    out
}
