//! `esgm-bench`: latency scenarios of esgm, each against a baseline measured in the
//! same run. See the `esgm_benches` crate docs for how it is built and `--help` for
//! the options.

use std::process::ExitCode;

use clap::Parser;
use esgm_benches::args::Args;
use esgm_benches::{json, plots, runner, scenarios, table};

fn main() -> ExitCode {
    // The reference system's node program, under its own name (see its docs).
    if esgm_benches::refsys::node_program::called_as_node_program() {
        return esgm_benches::refsys::node_program::main();
    }
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("esgm-bench: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: Args) -> anyhow::Result<()> {
    let config = args.into_config()?;
    let all = scenarios::all();
    if let Some(role) = &config.peer {
        // The measuring process reads these lines back as notes.
        for note in runner::run_peer(role, &all)? {
            println!("{note}");
        }
        return Ok(());
    }
    if config.list {
        for s in runner::select(&all, config.only.as_deref()) {
            println!("{:<26} {}", s.name(), s.summary());
        }
        return Ok(());
    }
    let report = runner::run(&config, &all, &mut std::io::stderr())?;
    print!("{}", table::render(&report, &config));
    if let Some(path) = &config.json {
        json::write(path, &report)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(dir) = &config.plots {
        for file in plots::draw(&report, dir)? {
            eprintln!("wrote {}", file.display());
        }
    }
    // Printed and written first: the rows that did measure are still worth having.
    if !report.failed.is_empty() {
        let rows: Vec<String> =
            report.failed.iter().map(|f| format!("{} ({})", f.name, f.wait.as_str())).collect();
        anyhow::bail!("no samples, so no figures, for {} (see FAILED above)", rows.join(", "));
    }
    Ok(())
}
