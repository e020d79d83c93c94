//! A computational unit in your own executable, the way dora nodes are named by path:
//! a configuration names the program, `esgm up` starts and supervises it, and the
//! program serves its unit with the client library.
//!
//! ```toml
//! [[unit]]
//! name = "LargeBlob"
//! program = "target/release/examples/large_blob_unit"   # relative to the file, or a
//!                                                       # bare name found on PATH
//! args = ["--min-size", "2000"]
//!
//! [[trajectory]]
//! name = "large_blob"
//! computed = "LargeBlob"
//! inputs = ["current_blob"]
//! ```
//!
//! The unit passes a `Blob` on when it covers at least `--min-size` pixels and answers
//! "no value" otherwise (so `large_blob` keeps its last large blob). The supervisor
//! passes the domain (`ESGM_DOMAIN`), the process's name (`ESGM_WORKER`) and the
//! declared unit name (`ESGM_NAME`) in the environment.

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use esgm_core::library::Blob;
use esgm_core::{ComputeError, Entity, Esgm, InputType, Sample, Time};
use esgm_shm::ShmEsgm;

fn main() -> anyhow::Result<()> {
    let mut min_size: i64 = 1000;
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        match flag.as_str() {
            "--min-size" => {
                let v = args.next().context("--min-size needs a value")?;
                min_size =
                    v.parse().with_context(|| format!("--min-size `{v}` is not a number"))?;
            }
            other => {
                anyhow::bail!("unknown option `{other}`; usage: large_blob_unit [--min-size N]")
            }
        }
    }
    let name = std::env::var("ESGM_NAME").unwrap_or_else(|_| "LargeBlob".into());
    let esgm = ShmEsgm::builder().from_env().connect().context("cannot reach the system")?;
    let unit = move |inputs: &[Sample], qtime: Time| {
        let [input] = inputs else {
            return Err(ComputeError::Failed {
                reason: format!("expected one input, got {}", inputs.len()),
            });
        };
        let blob = Blob::from_shared(&input.structure)
            .map_err(|e| ComputeError::Failed { reason: e.to_string() })?;
        if blob.size < min_size {
            return Err(ComputeError::ValueNotAvailable);
        }
        Ok(blob.to_structure("large_blob", input.structure.valid_time(), qtime))
    };
    esgm.add_comp_unit(
        &name,
        Blob::TYPE_NAME,
        vec![InputType::Type(Blob::TYPE_NAME.into())],
        Arc::new(unit),
    )?;
    esgm.serve_until_coordinator_gone(Duration::from_millis(500));
    Ok(())
}
