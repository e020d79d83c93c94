//! `camera-publisher`: the camera process of an esgm system. It connects to the
//! coordinator of `--domain` and serves a synthetic scene (or a directory of frames)
//! as a pull sensor until the coordinator is gone — the same code as
//! `esgm worker camera` ([`camera_publisher::serve`]).
//!
//! `--render-once` renders one frame offline instead, prints its statistics and,
//! with `--out`, writes it as a PPM file to look at.
//!
//! Exit codes: 0 done, 1 an error (one line on stderr), 2 a usage error.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use camera_publisher::serve::{self, CameraArgs, CameraSource};
use camera_publisher::{FrameSource, write_ppm};
use clap::Parser;
use esgm_core::Time;

/// A simulated camera serving `Image`s to an esgm system.
#[derive(Debug, Parser)]
#[command(name = "camera-publisher", version, about)]
struct Cli {
    /// The system to serve (one coordinator per domain).
    #[arg(long, env = esgm_shm::DOMAIN_ENV, default_value = "esgm")]
    domain: String,
    #[command(flatten)]
    camera: CameraArgs,
    /// Render one frame offline and print its statistics instead of serving.
    #[arg(long)]
    render_once: bool,
    /// With --render-once: the time of the frame, in ns.
    #[arg(long, default_value_t = 0, requires = "render_once")]
    time: Time,
    /// With --render-once: also write the frame to this PPM file.
    #[arg(long, requires = "render_once")]
    out: Option<PathBuf>,
}

fn main() -> ExitCode {
    // Usage errors and --help are clap's: printed in full, exit 2 or 0.
    let cli = Cli::parse();
    esgm_shm::process::init_logging();
    let result =
        if cli.render_once { render_once(&cli) } else { serve::run(&cli.domain, &cli.camera) };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("camera-publisher: {}", esgm_shm::process::one_line(err.chain()));
            ExitCode::FAILURE
        }
    }
}

/// Renders the frame at `--time`, writes it to `--out` if given, and prints its mean
/// luminance and, for a scene, where its blobs are.
fn render_once(cli: &Cli) -> anyhow::Result<()> {
    let source = cli.camera.source()?;
    let mut pixels = vec![0u8; source.frame_len()];
    source.render_into(cli.time, &mut pixels).context("cannot render the frame")?;
    if let Some(path) = &cli.out {
        let file = std::fs::File::create(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        write_ppm(std::io::BufWriter::new(file), source.width(), source.height(), &pixels)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    let luminance: u64 = pixels
        .chunks_exact(3)
        .map(|p| (77 * u64::from(p[0]) + 150 * u64::from(p[1]) + 29 * u64::from(p[2])) >> 8)
        .sum();
    println!(
        "{}x{} RGB8 frame at t={} ns: mean luminance {:.1}",
        source.width(),
        source.height(),
        cli.time,
        luminance as f64 / (pixels.len() / 3).max(1) as f64
    );
    if let CameraSource::Scene(scene) = &source {
        for blob in scene.truth(cli.time) {
            println!("  blob at ({}, {}), {} px", blob.x, blob.y, blob.size);
        }
    }
    Ok(())
}
