//! The processes a system keeps running: workers declared to the coordinator (by
//! `esgm apply`, say) and started, watched and restarted by the process that hosts the
//! coordinator (`esgm up`).
//!
//! The coordinator only keeps the table: what should run ([`ProcessSpec`]) and what
//! the supervisor last reported about it ([`ProcessStatus`]). Keeping it in the
//! registry means every client sees the same answer to "what runs here, and how often
//! did it crash" (`esgm ps`, `esgm stats`), and a declaration outlives the command that
//! made it.

use std::collections::BTreeMap;

use esgm_core::type_registry::closest_name;
use serde::{Deserialize, Serialize};

/// A process the system keeps running: a program and its arguments.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProcessSpec {
    /// Its name (unique in the system; also its host name in the registry for the
    /// built-in workers).
    pub name: String,
    /// The executable: a path, or a name found on `PATH`.
    pub program: String,
    /// Its arguments.
    pub args: Vec<String>,
    /// Extra environment variables (the domain and the worker's name are always set:
    /// `ESGM_DOMAIN`, `ESGM_WORKER`).
    pub env: Vec<(String, String)>,
}

/// What the supervisor last reported about a process.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProcessStatus {
    /// The running process's id; `None` while it is (re)starting or given up on.
    pub pid: Option<u32>,
    /// Restarts after unexpected exits.
    pub restarts: u32,
    /// How it last ended, if it did (`exit status: 1`, `signal: 9 (SIGKILL)`, or why it
    /// could not be started).
    pub last_exit: Option<String>,
}

/// One row of the process table.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProcessRecord {
    /// What should run.
    pub spec: ProcessSpec,
    /// How it runs (as last reported; all defaults until a supervisor reports).
    pub status: ProcessStatus,
}

/// A process operation failed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
#[non_exhaustive]
pub enum ProcessError {
    /// No process has this name.
    #[error("no process `{name}`{}", suggestion.as_ref().map(|s| format!("; did you mean `{s}`?")).unwrap_or_default())]
    NoSuchProcess {
        /// The name asked for.
        name: String,
        /// A declared name close to it.
        suggestion: Option<String>,
    },
    /// The declaration has no name: give the process one.
    #[error("a process declaration has an empty name")]
    EmptyName,
    /// The declaration names no program to run: give it the executable's path or name.
    #[error("process `{name}` cannot be run: its program is empty")]
    EmptyProgram {
        /// The process.
        name: String,
    },
}

/// The table of declared processes (pure state; the registry holds one).
#[derive(Debug, Default)]
pub struct ProcessTable {
    rows: BTreeMap<String, ProcessRecord>,
}

impl ProcessTable {
    /// Declares `spec`. The same declaration again changes nothing (so applying a
    /// configuration twice is harmless); another one under the same name replaces it
    /// and the supervisor restarts the process with the new one.
    pub fn declare(&mut self, spec: ProcessSpec) -> Result<(), ProcessError> {
        if spec.name.trim().is_empty() {
            return Err(ProcessError::EmptyName);
        }
        if spec.program.trim().is_empty() {
            return Err(ProcessError::EmptyProgram { name: spec.name.clone() });
        }
        match self.rows.get_mut(&spec.name) {
            Some(row) if row.spec == spec => {}
            Some(row) => row.spec = spec,
            None => {
                let name = spec.name.clone();
                self.rows.insert(name, ProcessRecord { spec, status: ProcessStatus::default() });
            }
        }
        Ok(())
    }

    /// Forgets `name`; its supervisor stops it.
    pub fn remove(&mut self, name: &str) -> Result<(), ProcessError> {
        self.rows.remove(name).map(|_| ()).ok_or_else(|| self.missing(name))
    }

    /// Records what the supervisor saw.
    pub fn report(&mut self, name: &str, status: ProcessStatus) -> Result<(), ProcessError> {
        let missing = self.missing(name);
        let row = self.rows.get_mut(name).ok_or(missing)?;
        row.status = status;
        Ok(())
    }

    /// Every row, by name.
    pub fn list(&self) -> Vec<ProcessRecord> {
        self.rows.values().cloned().collect()
    }

    fn missing(&self, name: &str) -> ProcessError {
        ProcessError::NoSuchProcess {
            name: name.to_owned(),
            suggestion: closest_name(name, self.rows.keys().map(String::as_str)),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    fn spec(name: &str, args: &[&str]) -> ProcessSpec {
        ProcessSpec {
            name: name.into(),
            program: "esgm".into(),
            args: args.iter().map(|s| (*s).to_owned()).collect(),
            env: Vec::new(),
        }
    }

    #[test]
    fn declaring_again_keeps_status_and_another_spec_replaces() {
        let mut t = ProcessTable::default();
        t.declare(spec("cam", &["worker", "camera"])).unwrap();
        t.report("cam", ProcessStatus { pid: Some(7), restarts: 2, last_exit: None }).unwrap();
        t.declare(spec("cam", &["worker", "camera"])).unwrap();
        assert_eq!(t.list()[0].status.restarts, 2);
        t.declare(spec("cam", &["worker", "camera", "--seed", "3"])).unwrap();
        assert_eq!(t.list().len(), 1);
        assert_eq!(t.list()[0].spec.args.len(), 4);
    }

    #[test]
    fn unknown_and_illegal_names_are_typed_errors() {
        let mut t = ProcessTable::default();
        t.declare(spec("camera", &[])).unwrap();
        match t.remove("camra") {
            Err(ProcessError::NoSuchProcess { suggestion: Some(s), .. }) => assert_eq!(s, "camera"),
            other => panic!("{other:?}"),
        }
        let mut empty = spec("x", &[]);
        empty.program = " ".into();
        assert!(matches!(t.declare(empty), Err(ProcessError::EmptyProgram { .. })));
        assert!(t.report("nope", ProcessStatus::default()).is_err());
        assert_eq!(t.list().len(), 1);
    }
}
