//! The `esgm` command line. The coordinator and its subcommands arrive with the CLI
//! issue; until then this binary says so plainly instead of pretending.

use std::process::ExitCode;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("--version" | "-V") => {
            println!("esgm {}", env!("CARGO_PKG_VERSION"));
            ExitCode::SUCCESS
        }
        Some(cmd) => {
            eprintln!(
                "esgm: `{cmd}` is not available yet: the coordinator, its subcommands and the \
                 multi-process demo are still being built.\n\
                 The seed's tutorial runs today in one process: cargo run --release --example tutorial"
            );
            ExitCode::from(2)
        }
        None => {
            eprintln!(
                "usage: esgm <command>   (commands arrive with the coordinator; try --version)"
            );
            ExitCode::from(2)
        }
    }
}
