//! Units and sensors written in Python (`python = "blobs.py:BlobDetection"`): the
//! worker process that serves one is the `esgm` package's own `python -m esgm.worker`,
//! run by the interpreter the declaration names. The file, the class's name and the
//! interpreter are checked when the file is applied, so that a typo or a missing
//! `pip install` is one error naming the declaration, not a worker the supervisor
//! restarts forever.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use esgm_shm::control::ProcessSpec;

use super::NAME_ENV;

/// The environment variable naming the default interpreter of Python workers.
pub const PYTHON_ENV: &str = "ESGM_PYTHON";

/// What a Python worker serves: the word `python -m esgm.worker` takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PythonRole {
    /// A computational unit (`compute`).
    Unit,
    /// A pull sensor (`get_current_value`).
    Sensor,
}

impl PythonRole {
    fn word(self) -> &'static str {
        match self {
            PythonRole::Unit => "unit",
            PythonRole::Sensor => "sensor",
        }
    }
}

/// A Python declaration as written: `python`, `interpreter`, `args`, `env`.
#[derive(Debug, Clone, Copy)]
pub struct PythonDecl<'a> {
    /// `FILE.py:CLASS`.
    pub target: &'a str,
    /// The interpreter, if the declaration names one.
    pub interpreter: Option<&'a str>,
    /// Extra arguments for the worker (after its own).
    pub args: &'a [String],
    /// Extra environment.
    pub env: &'a BTreeMap<String, String>,
}

/// The process serving the unit or sensor `declared` from a Python class, as process
/// `process`; paths are taken from the configuration's directory `base`.
pub fn python_worker(
    role: PythonRole,
    process: String,
    declared: &str,
    decl: PythonDecl<'_>,
    base: &Path,
) -> anyhow::Result<ProcessSpec> {
    let what = format!("{} `{declared}`", role.word());
    let (file, class) = decl
        .target
        .rsplit_once(':')
        .filter(|(file, class)| !file.is_empty() && is_identifier(class))
        .ok_or_else(|| {
            anyhow::anyhow!(
                "{what}: python = \"{}\" must be FILE.py:CLASS, e.g. \"blobs.py:BlobDetection\"",
                decl.target
            )
        })?;
    let file = absolute(base, file);
    if !file.is_file() {
        anyhow::bail!("{what}: python = \"{}\": {} does not exist", decl.target, file.display());
    }
    let interpreter = interpreter(decl.interpreter);
    can_serve(&interpreter).map_err(|why| anyhow::anyhow!("{what}: {why}"))?;
    let mut args = vec![
        "-m".to_owned(),
        "esgm.worker".to_owned(),
        role.word().to_owned(),
        format!("{}:{class}", file.display()),
        "--name".to_owned(),
        declared.to_owned(),
    ];
    args.extend(decl.args.iter().cloned());
    Ok(ProcessSpec {
        name: process,
        program: interpreter,
        args,
        env: std::iter::once((NAME_ENV.to_owned(), declared.to_owned()))
            .chain(decl.env.iter().map(|(k, v)| (k.clone(), v.clone())))
            .collect(),
    })
}

/// The interpreter to run: the declaration's, else `ESGM_PYTHON`, else `python3`.
/// A relative path with a slash is taken from the current directory (where
/// `esgm apply` runs), as a shell would.
fn interpreter(declared: Option<&str>) -> String {
    let chosen = declared
        .map(str::to_owned)
        .or_else(|| std::env::var(PYTHON_ENV).ok().filter(|p| !p.is_empty()))
        .unwrap_or_else(|| "python3".to_owned());
    if chosen.contains('/') && Path::new(&chosen).is_relative() {
        if let Ok(cwd) = std::env::current_dir() {
            return cwd.join(&chosen).display().to_string();
        }
    }
    chosen
}

fn absolute(base: &Path, file: &str) -> PathBuf {
    let path = Path::new(file);
    if path.is_absolute() { path.to_path_buf() } else { base.join(path) }
}

fn is_identifier(word: &str) -> bool {
    let mut chars = word.chars();
    chars.next().is_some_and(|c| c == '_' || c.is_alphabetic())
        && chars.all(|c| c == '_' || c.is_alphanumeric())
}

/// How long an interpreter may take to import the worker module.
const IMPORT_PATIENCE: Duration = Duration::from_secs(20);

/// Whether `interpreter` runs and imports `esgm.worker`: else why not, with what to do.
fn can_serve(interpreter: &str) -> Result<(), String> {
    let mut child = Command::new(interpreter)
        .args(["-c", "import esgm.worker"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| {
            format!(
                "cannot run the Python interpreter `{interpreter}` ({e}); name one with interpreter = \"path\" or {PYTHON_ENV}"
            )
        })?;
    let deadline = Instant::now() + IMPORT_PATIENCE;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            Ok(None) => {
                // Best effort: it is already late, and its error is the one to report.
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!(
                    "`{interpreter} -c 'import esgm.worker'` took more than {IMPORT_PATIENCE:?}"
                ));
            }
            Err(e) => return Err(format!("cannot wait for `{interpreter}`: {e}")),
        }
    };
    if status.success() {
        return Ok(());
    }
    let mut said = String::new();
    if let Some(mut stderr) = child.stderr.take() {
        use std::io::Read as _;
        // What it said is only the detail of the error below.
        let _ = stderr.read_to_string(&mut said);
    }
    let last = said.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no output");
    Err(format!(
        "the Python interpreter `{interpreter}` cannot import esgm ({last}); install the package into it (pip install ./esgm-shm/python) or name another with interpreter = \"path\" or {PYTHON_ENV}"
    ))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_class_name_is_an_identifier() {
        assert!(is_identifier("BlobDetection"));
        assert!(is_identifier("_Private2"));
        assert!(!is_identifier(""));
        assert!(!is_identifier("2Blob"));
        assert!(!is_identifier("Blob.Detection"));
    }

    #[test]
    fn a_target_without_a_class_is_refused_before_anything_runs() {
        let env = BTreeMap::new();
        let decl =
            PythonDecl { target: "blobs.py", interpreter: Some("python3"), args: &[], env: &env };
        let e = python_worker(PythonRole::Unit, "unit-B".into(), "B", decl, Path::new("/"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unit `B`") && e.contains("FILE.py:CLASS"), "{e}");
    }

    #[test]
    fn a_missing_file_is_named() {
        let env = BTreeMap::new();
        let decl = PythonDecl {
            target: "no/such.py:Unit",
            interpreter: Some("python3"),
            args: &[],
            env: &env,
        };
        let e = python_worker(PythonRole::Sensor, "camera-x".into(), "x", decl, Path::new("/tmp"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sensor `x`") && e.contains("/tmp/no/such.py does not exist"), "{e}");
    }

    #[test]
    fn an_interpreter_that_does_not_run_is_named() {
        let env = BTreeMap::new();
        let file = std::env::temp_dir().join(format!("esgm-py-{}.py", std::process::id()));
        std::fs::write(&file, "class U: pass\n").unwrap();
        let target = format!("{}:U", file.display());
        let decl = PythonDecl {
            target: &target,
            interpreter: Some("/no/such/python"),
            args: &[],
            env: &env,
        };
        let e = python_worker(PythonRole::Unit, "unit-U".into(), "U", decl, Path::new("/"))
            .unwrap_err()
            .to_string();
        std::fs::remove_file(&file).unwrap();
        assert!(e.contains("cannot run the Python interpreter `/no/such/python`"), "{e}");
    }
}
