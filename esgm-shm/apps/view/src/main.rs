//! `esgm-view` (`esgm view`): serves a domain's trajectories to Foxglove over its
//! WebSocket protocol until Ctrl-C.

use std::process::ExitCode;
use std::sync::mpsc;

use anyhow::Context;
use clap::Parser;
use esgm_view::ViewServer;

/// esgm-view — a domain's trajectories live in Foxglove.
#[derive(Debug, Parser)]
#[command(name = "esgm-view", version, about)]
struct Args {
    /// The system to show.
    #[arg(long, env = "ESGM_DOMAIN", default_value = "esgm")]
    domain: String,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// Port to listen on (Foxglove connects to 8765 by default; 0 picks a free one).
    #[arg(long, default_value_t = 8765)]
    port: u16,
}

fn main() -> ExitCode {
    let args = Args::parse();
    esgm_shm::process::init_logging();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("esgm-view: {}", esgm_shm::process::one_line(e.chain()));
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> anyhow::Result<()> {
    let server = ViewServer::builder(&args.domain).host(&args.host).port(args.port).start()?;
    // The first line says where to connect (a script or test may read the port).
    println!("serving `{}` on ws://{}:{} (Ctrl-C stops)", args.domain, args.host, server.port());
    let (tx, rx) = mpsc::channel();
    ctrlc::set_handler(move || {
        // A second Ctrl-C finds the receiver gone; there is nothing left to tell.
        let _ = tx.send(());
    })
    .context("cannot install the Ctrl-C handler")?;
    rx.recv().context("the Ctrl-C handler went away")?;
    drop(server);
    Ok(())
}
