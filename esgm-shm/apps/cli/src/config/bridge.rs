//! `[[bridge]]`: the host's bridge onto Zenoh (`esgm-bridge`, SPEC P5) as a process the
//! system keeps running, declared beside the sensors and units it carries:
//!
//! ```toml
//! [[bridge]]
//! listen = ["tcp/0.0.0.0:7447"]        # or connect = ["tcp/10.0.0.2:7447"]
//! export = ["robot_state", "images"]   # or all = true
//! import = ["ground/plan"]             # <domain>/<trajectory>, `*` allowed
//! max_rate = ["images=5"]              # Hz, per exported trajectory
//! ```
//!
//! The supervisor runs `esgm-bridge` (next to `esgm`, else on `PATH`) with these
//! settings and restarts it with backoff like any worker. Imports appear in the domain
//! once the other host's bridge sends, so a trajectory computed on an import is applied
//! from a second file (or `esgm traj create`) once the import exists.

use std::path::Path;

use anyhow::{Context, bail};
use esgm_shm::control::ProcessSpec;
use serde::Deserialize;

use super::{Serves, Worker};

/// `[[bridge]]`: what this host's bridge exports, imports and how it joins Zenoh.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeDecl {
    /// Its process name, unique among the system's processes (default `bridge`).
    pub name: Option<String>,
    /// Zenoh mode: `peer` (default) or `client`.
    pub mode: Option<String>,
    /// Zenoh endpoints to listen on (`tcp/0.0.0.0:7447`).
    #[serde(default)]
    pub listen: Vec<String>,
    /// Zenoh endpoints to connect to (`tcp/10.0.0.2:7447`).
    #[serde(default)]
    pub connect: Vec<String>,
    /// A Zenoh configuration file (relative to this file), for everything else.
    pub config: Option<String>,
    /// Trajectories of this domain to export.
    #[serde(default)]
    pub export: Vec<String>,
    /// Export every trajectory of this domain (but the imported ones).
    #[serde(default)]
    pub all: bool,
    /// Remote trajectories to import: `<domain>/<trajectory>` (either may be `*`) or a
    /// key expression under `esgm/`.
    #[serde(default)]
    pub import: Vec<String>,
    /// Exported trajectories that send only their newest waiting sample.
    #[serde(default)]
    pub latest_only: Vec<String>,
    /// Rate limits of exported trajectories, `trajectory=Hz`.
    #[serde(default)]
    pub max_rate: Vec<String>,
    /// Do not answer other hosts' queries (`esgm --remote`).
    #[serde(default)]
    pub no_queries: bool,
}

/// The bridge's process: checked settings as `esgm-bridge` arguments.
pub fn bridge_worker(b: &BridgeDecl, program: &Path, base: &Path) -> anyhow::Result<Worker> {
    if b.export.is_empty() && !b.all && b.import.is_empty() {
        bail!("a bridge needs something to carry: export = [...], all = true or import = [...]");
    }
    if b.all && !b.export.is_empty() {
        bail!("a bridge exports either all = true or the trajectories in export, not both");
    }
    if let Some(mode) = b.mode.as_deref().filter(|m| !["peer", "client"].contains(m)) {
        bail!("bridge mode `{mode}`: expected peer or client");
    }
    for endpoint in b.listen.iter().chain(&b.connect) {
        let Some((protocol, address)) = endpoint.split_once('/') else {
            bail!("endpoint `{endpoint}`: expected <protocol>/<address>, e.g. tcp/10.0.0.2:7447");
        };
        if protocol.is_empty() || address.is_empty() {
            bail!("endpoint `{endpoint}`: expected <protocol>/<address>, e.g. tcp/10.0.0.2:7447");
        }
    }
    for i in &b.import {
        if !(i.starts_with("esgm/")
            || i.split_once('/').is_some_and(|(d, t)| !d.is_empty() && !t.is_empty()))
        {
            bail!("import `{i}`: expected <domain>/<trajectory> or a key expression esgm/…");
        }
    }
    for limit in &b.max_rate {
        let Some((t, hz)) = limit.split_once('=').filter(|(t, _)| !t.is_empty()) else {
            bail!("max_rate `{limit}`: expected <trajectory>=<Hz>, e.g. images=5");
        };
        let Ok(hz) = hz.trim().parse::<f64>() else {
            bail!("max_rate `{limit}`: expected <trajectory>=<Hz>, e.g. images=5");
        };
        if let Err(e) = esgm_core::time::period_from_rate(hz) {
            bail!("max_rate `{limit}` of `{t}`: {e}");
        }
    }
    let mut args: Vec<String> = Vec::new();
    let mut flag = |name: &str, values: &[String]| {
        for v in values {
            args.extend([format!("--{name}"), v.clone()]);
        }
    };
    flag("listen", &b.listen);
    flag("connect", &b.connect);
    flag("export", &b.export);
    flag("import", &b.import);
    flag("latest-only", &b.latest_only);
    flag("max-rate", &b.max_rate);
    if let Some(mode) = &b.mode {
        args.extend(["--mode".into(), mode.clone()]);
    }
    if let Some(config) = &b.config {
        let path = base.join(config);
        if !path.is_file() {
            bail!("Zenoh configuration `{}` not found", path.display());
        }
        args.extend(["--config".into(), path.display().to_string()]);
    }
    if b.all {
        args.push("--all".into());
    }
    if b.no_queries {
        args.push("--no-queries".into());
    }
    let name = b.name.clone().unwrap_or_else(|| "bridge".to_owned());
    let spec = ProcessSpec {
        name: name.clone(),
        program: program.display().to_string(),
        args,
        env: Vec::new(),
    };
    Ok(Worker { spec, serves: Serves::Bridge(name), program: None })
}

/// The `esgm-bridge` executable, or why there is none.
pub fn bridge_program() -> anyhow::Result<std::path::PathBuf> {
    crate::external::find("esgm-bridge", "esgm-bridge")
        .context("a [[bridge]] runs the esgm-bridge executable")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn decl() -> BridgeDecl {
        BridgeDecl {
            listen: vec!["tcp/0.0.0.0:7447".into()],
            export: vec!["robot_state".into(), "images".into()],
            import: vec!["ground/plan".into()],
            max_rate: vec!["images=5".into()],
            ..BridgeDecl::default()
        }
    }

    #[test]
    fn a_bridge_runs_esgm_bridge_with_its_settings() {
        let w = bridge_worker(&decl(), Path::new("/bin/esgm-bridge"), Path::new(".")).unwrap();
        assert_eq!(w.spec.name, "bridge");
        assert_eq!(w.spec.program, "/bin/esgm-bridge");
        let args = w.spec.args.join(" ");
        assert_eq!(
            args,
            "--listen tcp/0.0.0.0:7447 --export robot_state --export images --import ground/plan \
             --max-rate images=5"
        );
        assert_eq!(w.serves, Serves::Bridge("bridge".into()));
    }

    #[test]
    fn bad_settings_say_what_is_wrong() {
        let p = Path::new("/bin/esgm-bridge");
        let cases = [
            (BridgeDecl { export: vec![], import: vec![], ..decl() }, "something to carry"),
            (BridgeDecl { all: true, ..decl() }, "not both"),
            (BridgeDecl { mode: Some("router".into()), ..decl() }, "peer or client"),
            (BridgeDecl { listen: vec!["7447".into()], ..decl() }, "<protocol>/<address>"),
            (BridgeDecl { import: vec!["plan".into()], ..decl() }, "<domain>/<trajectory>"),
            (BridgeDecl { max_rate: vec!["images=fast".into()], ..decl() }, "<trajectory>=<Hz>"),
            (BridgeDecl { max_rate: vec!["images=1e-20".into()], ..decl() }, "100 years"),
            (BridgeDecl { max_rate: vec!["images=inf".into()], ..decl() }, "finite"),
            (BridgeDecl { config: Some("nope.json5".into()), ..decl() }, "not found"),
        ];
        for (d, needle) in cases {
            let e = format!("{:#}", bridge_worker(&d, p, Path::new("/nonexistent")).unwrap_err());
            assert!(e.contains(needle), "{e}");
        }
    }
}
