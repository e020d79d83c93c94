//! `esgm completions SHELL` and `esgm man`: the shell completions and manual pages of
//! the command, generated from its own definition (clap_complete, clap_mangen), so they
//! list exactly the subcommands and options this build has. Neither needs a system.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap_complete::Shell;

/// `esgm completions` options.
#[derive(Debug, clap::Args)]
pub struct CompletionArgs {
    /// The shell: bash, zsh, fish, elvish or powershell. Install, e.g. for bash:
    /// `esgm completions bash > ~/.local/share/bash-completion/completions/esgm`.
    pub shell: Shell,
}

/// `esgm man` options.
#[derive(Debug, clap::Args)]
pub struct ManArgs {
    /// Write `esgm.1` and a page per subcommand (`esgm-latest.1`, …) into this
    /// directory (e.g. `/usr/local/share/man/man1`); without it, print `esgm.1`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Prints the completion script of `command` for `shell`.
pub fn completions(mut command: clap::Command, a: &CompletionArgs) -> anyhow::Result<()> {
    let name = command.get_name().to_owned();
    let mut script = Vec::new();
    clap_complete::generate(a.shell, &mut command, name, &mut script);
    print(&script)
}

/// Writes `bytes` to stdout; a reader that went (`| head`) is not an error.
fn print(bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(bytes).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Prints `esgm.1`, or writes every page into `--out`.
pub fn man(command: clap::Command, a: &ManArgs) -> anyhow::Result<()> {
    match &a.out {
        None => {
            let mut page = Vec::new();
            clap_mangen::Man::new(command).render(&mut page)?;
            print(&page)
        }
        Some(dir) => {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            let written = write_pages(&command, dir, "")?;
            eprintln!("wrote {written} manual pages into {}", dir.display());
            Ok(())
        }
    }
}

/// Writes the page of `command` (named after its parents, `esgm-traj-list`) and of
/// every visible subcommand; the number written.
fn write_pages(command: &clap::Command, dir: &Path, parents: &str) -> anyhow::Result<usize> {
    let name = if parents.is_empty() {
        command.get_name().to_owned()
    } else {
        format!("{parents}-{}", command.get_name())
    };
    let page = command.clone().name(name.clone());
    let path = dir.join(format!("{name}.1"));
    let mut file =
        std::fs::File::create(&path).with_context(|| format!("cannot write {}", path.display()))?;
    clap_mangen::Man::new(page).render(&mut file)?;
    let mut written = 1;
    for sub in command.get_subcommands().filter(|s| !s.is_hide_set()) {
        written += write_pages(sub, dir, &name)?;
    }
    Ok(written)
}
