//! `--json FILE`: the report as JSON (see [`crate::report`] for the schema).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::Context as _;

use crate::report::Report;

/// Writes `report` to `path`, replacing the file.
pub fn write(path: &Path, report: &Report) -> anyhow::Result<()> {
    let file =
        File::create(path).with_context(|| format!("could not create {}", path.display()))?;
    let mut out = BufWriter::new(file);
    serde_json::to_writer_pretty(&mut out, report)
        .with_context(|| format!("could not write {}", path.display()))?;
    writeln!(out)
        .and_then(|()| out.flush())
        .with_context(|| format!("could not write {}", path.display()))?;
    Ok(())
}
