//! `esgm down`: stop the coordinator; the system's processes leave when it is gone.

use std::time::{Duration, Instant};

use anyhow::Context;
use esgm_shm::control::server::cleanup_dead_nodes;
use esgm_shm::control::{ControlClient, Request};

/// Stops the coordinator of `domain` and waits until its service is gone.
pub fn run(domain: &str) -> anyhow::Result<()> {
    let client = ControlClient::connect(domain, Duration::from_secs(3))
        .with_context(|| format!("cannot stop `{domain}`"))?;
    let answer = client.call(&Request::Shutdown);
    drop(client);
    // No answer but gone is stopped too (the answer may be lost as the server leaves).
    if let Err(e) = answer {
        if ControlClient::connect(domain, Duration::from_millis(200)).is_ok() {
            return Err(anyhow::Error::new(e).context(format!("cannot stop `{domain}`")));
        }
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while ControlClient::connect(domain, Duration::from_millis(200)).is_ok() {
        if Instant::now() > deadline {
            anyhow::bail!("the coordinator of `{domain}` acknowledged but is still serving");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    cleanup_dead_nodes();
    println!("stopped `{domain}`");
    Ok(())
}
