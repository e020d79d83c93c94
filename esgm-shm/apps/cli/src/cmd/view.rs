//! `esgm view …`: the domain live in Foxglove, served by the `esgm-view` executable
//! (crate `esgm-view`, which holds the Foxglove SDK so this command does not build it).

/// `esgm view` options: everything is esgm-view's own (`esgm view --help`).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Arguments of `esgm-view` (e.g. `--port 8765 --host 0.0.0.0`).
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    pub args: Vec<String>,
}

/// Runs `esgm-view --domain <domain> args…`.
pub fn run(domain: &str, a: &Args) -> anyhow::Result<()> {
    crate::external::run("esgm-view", "esgm-view", domain, &a.args)
}
