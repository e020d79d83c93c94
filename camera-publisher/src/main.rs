//! `camera-publisher`: for now, renders one frame of a simulated camera and prints its
//! statistics, or writes it as a PPM file with `--out`.
//!
//! Publishing into an esgm runtime comes with the runtime traits; the rendering is the
//! library's.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use camera_publisher::{FrameSource, ImageDirectory, SyntheticScene, write_ppm};
use esgm_core::time::{Time, millis};

const USAGE: &str = "usage: camera-publisher [--width N] [--height N] [--blobs N] [--seed N] \
[--time NS] [--dir DIR [--period NS]] [--out FILE.ppm]";

/// The validated command line.
#[derive(Debug)]
struct Config {
    width: u32,
    height: u32,
    blobs: usize,
    seed: u64,
    time: Time,
    dir: Option<PathBuf>,
    period: Time,
    out: Option<PathBuf>,
}

/// Parses `--flag value` pairs; `Ok(None)` means help was asked for.
fn parse_args(args: impl IntoIterator<Item = String>) -> anyhow::Result<Option<Config>> {
    let mut config = Config {
        width: 640,
        height: 480,
        blobs: 3,
        seed: 0,
        time: 0,
        dir: None,
        period: millis(100),
        out: None,
    };
    let mut args = args.into_iter();
    while let Some(flag) = args.next() {
        if flag == "-h" || flag == "--help" {
            return Ok(None);
        }
        let value = args.next().with_context(|| format!("{flag} needs a value"))?;
        let number = || format!("{flag} takes a number, got `{value}`");
        match flag.as_str() {
            "--width" => config.width = value.parse().with_context(number)?,
            "--height" => config.height = value.parse().with_context(number)?,
            "--blobs" => config.blobs = value.parse().with_context(number)?,
            "--seed" => config.seed = value.parse().with_context(number)?,
            "--time" => config.time = value.parse().with_context(number)?,
            "--period" => config.period = value.parse().with_context(number)?,
            "--dir" => config.dir = Some(PathBuf::from(value)),
            "--out" => config.out = Some(PathBuf::from(value)),
            _ => bail!("unknown option `{flag}`"),
        }
    }
    Ok(Some(config))
}

fn run(config: Config) -> anyhow::Result<()> {
    let (source, truth): (Box<dyn FrameSource>, _) = match &config.dir {
        Some(dir) => (
            Box::new(
                ImageDirectory::open(dir, config.period)
                    .with_context(|| format!("opening image directory {}", dir.display()))?,
            ),
            None,
        ),
        None => {
            let scene = SyntheticScene::builder()
                .width(config.width)
                .height(config.height)
                .blobs(config.blobs)
                .seed(config.seed)
                .create()
                .context("building the synthetic scene")?;
            let truth = scene.truth(config.time);
            (Box::new(scene), Some(truth))
        }
    };
    let frame = source.frame(config.time);
    if let Some(path) = &config.out {
        let file =
            std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        write_ppm(
            std::io::BufWriter::new(file),
            source.width(),
            source.height(),
            &frame.image_data,
        )
        .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    let pixels = frame.image_data.len() / 3;
    let luminance: u64 = frame
        .image_data
        .chunks_exact(3)
        .map(|p| (77 * u64::from(p[0]) + 150 * u64::from(p[1]) + 29 * u64::from(p[2])) >> 8)
        .sum();
    println!(
        "{}x{} RGB8 frame at t={} ns: mean luminance {:.1}",
        frame.width,
        frame.height,
        config.time,
        luminance as f64 / pixels.max(1) as f64
    );
    for blob in truth.iter().flatten() {
        println!("  blob at ({}, {}), {} px", blob.x, blob.y, blob.size);
    }
    Ok(())
}

fn main() -> ExitCode {
    let config = match parse_args(std::env::args().skip(1)) {
        Ok(Some(config)) => config,
        Ok(None) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(err) => {
            eprintln!("camera-publisher: {err:#}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    match run(config) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("camera-publisher: {err:#}");
            ExitCode::FAILURE
        }
    }
}
