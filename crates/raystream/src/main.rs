//! `raystream`: render, trace, bench and info over the library crates.

mod bench;
mod centreline;
mod cli;
mod common;
mod dvr;
mod info;
mod iso;
mod labels;
mod measure;
mod overlay;
mod profile;
mod render;
mod trace;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    let result = match args.command {
        cli::Command::Render(a) => render::run(&a),
        cli::Command::Trace(a) => trace::run(&a),
        cli::Command::Iso(a) => iso::run(&a),
        cli::Command::Measure(a) => measure::run(&a),
        cli::Command::Centreline(a) => centreline::run(&a),
        cli::Command::Info(a) => info::run(&a),
        cli::Command::Bench(a) => bench::run(&a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("raystream: error: {e:#}");
            // Bad input and failed runs both exit 2, as clap does for bad arguments.
            ExitCode::from(2)
        }
    }
}
