//! `raystream`: render, trace, bench and info over the library crates.

mod bench;
mod body;
mod centreline;
mod cli;
mod common;
mod dvr;
mod info;
mod iso;
mod labels;
mod legend;
mod mask_out;
mod measure;
mod overlay;
mod profile;
mod render;
mod scale_bar;
mod segments;
mod shells;
mod structured_report;
mod trace;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Rust ignores SIGPIPE, so a report printed into a pipe that has closed (`raystream info
    // MESH | head -3`) panicked at its next line. With the signal's default action the process
    // ends quietly there, as Unix tools do.
    #[cfg(unix)]
    // SAFETY: called first thing, on the only thread; SIG_DFL is a valid handler for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let args = cli::Cli::parse();
    let result = common::choose_cpu_isa().and_then(|()| match args.command {
        cli::Command::Render(a) => render::run(&a),
        cli::Command::Trace(a) => trace::run(&a),
        cli::Command::Iso(a) => iso::run(&a),
        cli::Command::Measure(a) => measure::run(&a),
        cli::Command::Centreline(a) => centreline::run(&a),
        cli::Command::Info(a) => info::run(&a),
        cli::Command::Bench(a) => bench::run(&a),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("raystream: error: {e:#}");
            // Bad input and failed runs both exit 2, as clap does for bad arguments.
            ExitCode::from(2)
        }
    }
}
