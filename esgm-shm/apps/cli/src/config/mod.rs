//! Configuration files: a whole system — types, sensors, units, robots and
//! trajectories with their policies — declared in TOML and brought up by `esgm apply`
//! or `esgm up --config`. The declarative face of DyKnow's policies.
//!
//! The format is documented by example in `esgm-shm/apps/cli/tutorial.toml` (the seed's
//! tutorial as a file, which `esgm demo` itself runs). In short:
//!
//! ```toml
//! [[type]]                       # an entity structure type
//! name = "Pose"
//! attributes = ["x: Double", "y: Double"]
//!
//! [[sensor]]                     # a pull sensor in a process esgm keeps running
//! name = "camera"
//! camera = "synthetic"           # or a directory of PNG/JPEG frames, or your own
//!                                #   program = "name" (found on PATH) or "path"
//!
//! [[unit]]                       # a computational unit: built in, your own
//! name = "BlobDetection"         #   program = "name" or "path" (exec: its older
//!                                #   name), or python = "blobs.py:BlobDetection"
//!
//! [[robot]]                      # the tutorial's robot (pushes robot_state)
//!
//! [[trajectory]]                 # exactly one of primitive/sampled/computed/sync/
//! name = "images"                #   merge/generate
//! sampled = "camera"
//! period = "250ms"
//! policy = { cache = 5, order = "monotone", delay = "100ms" }
//!
//! [[trajectory]]                 # fluent generators sampled every period (G4)
//! name = "pose_10hz"
//! generate = ["robot_state:linear"]   # TRAJ[:APPROXIMATION[:MERGE]], one or more
//! period = "100ms"               # function = "UNIT": its temporal function of them
//! align = true                   # samples on multiples of the period (sampled too)
//! ```
//!
//! Every error names the file and line of the declaration it is about. A file is
//! checked whole — syntax, policies, sorts, the programs it runs (see [`program`]), and
//! every name it uses against itself and the running system — before anything is
//! changed, so a file with an error leaves the running system as it was.

pub mod apply;
pub mod bridge;
pub mod decl;
pub mod program;
pub mod python;
pub mod ros2;

use std::path::{Path, PathBuf};

use anyhow::Context;
use esgm_core::EntityStructureType;
use esgm_core::esgm::TrajectorySpec;
use esgm_shm::control::ProcessSpec;
use serde::Deserialize;
use toml::Spanned;

use decl::{BUILTIN_UNITS, RobotDecl, SensorDecl, TrajectoryDecl, TypeDecl, UnitDecl};

/// A configuration file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SystemFile {
    #[serde(default, rename = "type")]
    types: Vec<Spanned<TypeDecl>>,
    #[serde(default, rename = "sensor")]
    sensors: Vec<Spanned<SensorDecl>>,
    #[serde(default, rename = "unit")]
    units: Vec<Spanned<UnitDecl>>,
    #[serde(default, rename = "robot")]
    robots: Vec<Spanned<RobotDecl>>,
    #[serde(default, rename = "trajectory")]
    trajectories: Vec<Spanned<TrajectoryDecl>>,
    #[serde(default, rename = "bridge")]
    bridges: Vec<Spanned<bridge::BridgeDecl>>,
    #[serde(default, rename = "ros2")]
    ros2: Vec<Spanned<ros2::Ros2Decl>>,
}

/// Something wrong in a configuration file, at a line.
#[derive(Debug, thiserror::Error)]
#[error("{file}:{line}: {message}")]
pub struct ConfigError {
    /// The file, as given.
    pub file: String,
    /// 1-based line of the declaration (or of the syntax error).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// One declaration of a plan, with the line it came from.
#[derive(Debug, Clone)]
pub struct Item<T> {
    /// 1-based line in the file.
    pub line: usize,
    /// The declaration, checked.
    pub what: T,
}

/// What a worker process serves, so `apply` knows what to wait for.
#[derive(Debug, Clone, PartialEq)]
pub enum Serves {
    /// A sensor of this name.
    Sensor(String),
    /// A unit of this name.
    Unit(String),
    /// Structures pushed into this trajectory.
    Pushes(String),
    /// Trajectories carried to and from other hosts or a ROS 2 graph, by this bridge
    /// (nothing to register: its imports appear when the other side sends).
    Bridge(String),
}

/// A process the system keeps running and what it serves.
#[derive(Debug, Clone)]
pub struct Worker {
    /// How to run it.
    pub spec: ProcessSpec,
    /// What it registers.
    pub serves: Serves,
    /// The user's program it runs, as declared: `spec.program` is that program as
    /// written until [`Plan::find_programs`] puts the absolute path found there.
    pub program: Option<program::UserProgram>,
}

/// A trajectory to create and the process that writes it (for primitive ones).
#[derive(Debug, Clone)]
pub struct PlannedTrajectory {
    /// What to create.
    pub spec: TrajectorySpec,
    /// Trajectories it reads.
    pub inputs: Vec<String>,
    /// Primitive trajectories: the pushing process; `None`: decided by the source.
    pub writer: Option<String>,
    /// Sampled on multiples of its period (`align = true`): see [`Self::spec_at`].
    pub align: bool,
}

impl PlannedTrajectory {
    /// What to create at `now`: the spec, its first sample time resolved now if it is
    /// aligned ([`decl::aligned`]).
    pub fn spec_at(&self, now: esgm_core::Time) -> TrajectorySpec {
        if self.align { decl::aligned(self.spec.clone(), now) } else { self.spec.clone() }
    }
}

/// A checked configuration: everything in it is well-formed; names it uses may still
/// be unknown to the running system (checked by `apply`).
#[derive(Debug, Clone)]
pub struct Plan {
    /// The file, as given.
    pub file: String,
    /// Types to register.
    pub types: Vec<Item<(String, EntityStructureType)>>,
    /// Processes to keep running.
    pub workers: Vec<Item<Worker>>,
    /// Trajectories to create, in the file's order.
    pub trajectories: Vec<Item<PlannedTrajectory>>,
    /// The units as declared (for `esgm replay --in-process`, which runs built-in
    /// units itself instead of starting their processes).
    pub units: Vec<Item<UnitDecl>>,
}

impl Plan {
    /// Every declaration as (line, kind, name), in file order.
    pub fn items(&self) -> Vec<(usize, &'static str, String)> {
        let mut out: Vec<_> = self
            .types
            .iter()
            .map(|i| (i.line, "type", i.what.0.clone()))
            .chain(self.workers.iter().map(|i| (i.line, "process", i.what.spec.name.clone())))
            .chain(
                self.trajectories.iter().map(|i| (i.line, "trajectory", i.what.spec.name.clone())),
            )
            .collect();
        out.sort();
        out
    }

    /// An error about line `line` of this plan's file.
    pub fn error(&self, line: usize, message: impl std::fmt::Display) -> ConfigError {
        ConfigError { file: self.file.clone(), line, message: message.to_string() }
    }

    /// The order to create the trajectories in (indices into [`Self::trajectories`]):
    /// each after the ones of the file it reads, otherwise in the file's order; a
    /// trajectory that reads itself through others is an error naming its line.
    pub fn creation_order(&self) -> Result<Vec<usize>, ConfigError> {
        let declared: std::collections::BTreeMap<&str, usize> = self
            .trajectories
            .iter()
            .enumerate()
            .map(|(i, t)| (t.what.spec.name.as_str(), i))
            .collect();
        let mut order = Vec::new();
        let mut state = vec![0u8; self.trajectories.len()]; // 0 new, 1 visiting, 2 done
        fn visit(
            i: usize,
            plan: &Plan,
            declared: &std::collections::BTreeMap<&str, usize>,
            state: &mut [u8],
            order: &mut Vec<usize>,
        ) -> Result<(), ConfigError> {
            match state[i] {
                2 => return Ok(()),
                1 => {
                    let t = &plan.trajectories[i];
                    return Err(plan.error(
                        t.line,
                        format!("trajectory `{}` depends on itself", t.what.spec.name),
                    ));
                }
                _ => {}
            }
            state[i] = 1;
            for input in &plan.trajectories[i].what.inputs {
                if let Some(&j) = declared.get(input.as_str()) {
                    visit(j, plan, declared, state, order)?;
                }
            }
            state[i] = 2;
            order.push(i);
            Ok(())
        }
        for i in 0..self.trajectories.len() {
            visit(i, self, &declared, &mut state, &mut order)?;
        }
        Ok(order)
    }

    /// Finds every user's program the plan runs (a bare name on this process's `PATH`,
    /// a path from the file's directory) and has the supervisor run the absolute path
    /// found; the first that cannot run is an error naming its line, what it serves and
    /// the program.
    pub fn find_programs(&mut self) -> Result<(), ConfigError> {
        let file = &self.file;
        for Item { line, what } in &mut self.workers {
            let Some(program) = &what.program else { continue };
            let serving = match &what.serves {
                Serves::Sensor(n) => format!("sensor `{n}`"),
                Serves::Unit(n) => format!("unit `{n}`"),
                Serves::Pushes(t) => format!("process pushing `{t}`"),
                Serves::Bridge(n) => format!("bridge `{n}`"),
            };
            what.spec.program = program.find().map_err(|e| ConfigError {
                file: file.clone(),
                line: *line,
                message: format!("{serving}: {e}"),
            })?;
        }
        Ok(())
    }
}

/// Reads and checks a configuration file, and finds the programs it runs (see
/// [`Plan::find_programs`]): the plan to apply.
pub fn load(path: &Path) -> anyhow::Result<Plan> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the configuration `{}`", path.display()))?;
    let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut plan = parse(&path.display().to_string(), &text, &base)?;
    plan.find_programs()?;
    Ok(plan)
}

/// Checks a configuration given as text; `base` resolves relative paths in it. The
/// users' programs it runs are as written, not looked for: [`load`] (or
/// [`Plan::find_programs`]) finds them before a plan is applied.
pub fn parse(file: &str, text: &str, base: &Path) -> Result<Plan, ConfigError> {
    let line_of = |offset: usize| text[..offset.min(text.len())].matches('\n').count() + 1;
    let parsed: SystemFile = toml::from_str(text).map_err(|e| ConfigError {
        file: file.to_owned(),
        line: e.span().map_or(1, |s| line_of(s.start)),
        message: e.message().trim().to_owned(),
    })?;
    let esgm = std::env::current_exe().unwrap_or_else(|_| PathBuf::from("esgm"));
    let mut plan = Plan {
        file: file.to_owned(),
        types: Vec::new(),
        workers: Vec::new(),
        trajectories: Vec::new(),
        units: Vec::new(),
    };

    for t in &parsed.types {
        let line = line_of(t.span().start);
        let ty = t.get_ref().to_type().map_err(|e| plan.error(line, format!("{e:#}")))?;
        plan.types.push(Item { line, what: (t.get_ref().name.clone(), ty) });
    }
    for s in &parsed.sensors {
        let line = line_of(s.span().start);
        let worker = sensor_worker(s.get_ref(), &esgm, base)
            .map_err(|e| plan.error(line, format!("{e:#}")))?;
        plan.workers.push(Item { line, what: worker });
    }
    for u in &parsed.units {
        let line = line_of(u.span().start);
        let worker = unit_worker(u.get_ref(), &esgm, base)
            .map_err(|e| plan.error(line, format!("{e:#}")))?;
        plan.workers.push(Item { line, what: worker });
        plan.units.push(Item { line, what: u.get_ref().clone() });
    }
    for r in &parsed.robots {
        let line = line_of(r.span().start);
        let worker =
            robot_worker(r.get_ref(), &esgm).map_err(|e| plan.error(line, format!("{e:#}")))?;
        plan.workers.push(Item { line, what: worker });
    }
    if !parsed.bridges.is_empty() {
        let line = line_of(parsed.bridges[0].span().start);
        let program = bridge::bridge_program().map_err(|e| plan.error(line, format!("{e:#}")))?;
        for b in &parsed.bridges {
            let line = line_of(b.span().start);
            let worker = bridge::bridge_worker(b.get_ref(), &program, base)
                .map_err(|e| plan.error(line, format!("{e:#}")))?;
            plan.workers.push(Item { line, what: worker });
        }
    }
    if !parsed.ros2.is_empty() {
        let line = line_of(parsed.ros2[0].span().start);
        let program = ros2::ros2_program().map_err(|e| plan.error(line, format!("{e:#}")))?;
        for d in &parsed.ros2 {
            let line = line_of(d.span().start);
            let worker = ros2::ros2_worker(d.get_ref(), &program)
                .map_err(|e| plan.error(line, format!("{e:#}")))?;
            plan.workers.push(Item { line, what: worker });
        }
    }
    for t in &parsed.trajectories {
        let line = line_of(t.span().start);
        let decl = t.get_ref();
        let spec = decl.to_spec().map_err(|e| plan.error(line, format!("{e:#}")))?;
        // A primitive trajectory a robot pushes is written by the robot's process.
        let pusher = plan.workers.iter().find_map(|w| match &w.what.serves {
            Serves::Pushes(t) if *t == decl.name => Some(w.what.spec.name.clone()),
            _ => None,
        });
        let writer = decl.writer.clone().or(if decl.primitive.is_some() { pusher } else { None });
        let what = PlannedTrajectory { spec, inputs: decl.inputs(), writer, align: decl.align };
        plan.trajectories.push(Item { line, what });
    }
    check_duplicates(&plan)?;
    Ok(plan)
}

fn check_duplicates(plan: &Plan) -> Result<(), ConfigError> {
    let mut seen = std::collections::BTreeMap::new();
    let names = plan
        .types
        .iter()
        .map(|i| (i.line, format!("type `{}`", i.what.0)))
        .chain(plan.workers.iter().map(|i| (i.line, format!("process `{}`", i.what.spec.name))))
        .chain(
            plan.trajectories
                .iter()
                .map(|i| (i.line, format!("trajectory `{}`", i.what.spec.name))),
        );
    for (line, name) in names {
        if let Some(first) = seen.insert(name.clone(), line) {
            return Err(
                plan.error(line, format!("{name} is declared twice (first at line {first})"))
            );
        }
    }
    Ok(())
}

/// The environment variable naming the sensor or unit a user's program was declared
/// for (one program can serve differently named units).
pub const NAME_ENV: &str = "ESGM_NAME";

/// The process name of a worker serving sensor `name` (also its registry host): a
/// camera's own name for itself when it runs by hand.
pub fn sensor_process(name: &str) -> String {
    camera_publisher::serve::process_name(name)
}

/// The process name of a worker serving unit `name`.
pub fn unit_process(name: &str) -> String {
    format!("unit-{name}")
}

/// The process name of a robot pushing into `trajectory`: the robot's own name for
/// itself when it runs by hand.
pub fn robot_process(trajectory: &str) -> String {
    robot_publisher::serve::process_name(trajectory)
}

/// A duration of a configuration file (`250ms`, or integer nanoseconds) as a worker's
/// command line takes it (`250ms`), checked.
fn duration_arg(word: &str) -> anyhow::Result<String> {
    let ns = crate::policy_args::duration(word)?;
    let ns = u64::try_from(ns).context("a duration must be positive")?;
    Ok(humantime::format_duration(std::time::Duration::from_nanos(ns)).to_string())
}

fn spec(name: String, program: &Path, args: Vec<String>) -> ProcessSpec {
    ProcessSpec { name, program: program.display().to_string(), args, env: Vec::new() }
}

/// A user's program serving `declared` as process `name`: run as written until
/// [`Plan::find_programs`] finds it (a relative path is taken from the configuration's
/// directory already); `ESGM_NAME` tells it the sensor or unit name it was declared for.
fn user_worker(
    name: String,
    declared: &str,
    program: program::UserProgram,
    args: &[String],
    env: &std::collections::BTreeMap<String, String>,
    serves: Serves,
) -> Worker {
    let written = &program.declared;
    let path = if written.contains('/') && Path::new(written).is_relative() {
        program.base.join(written).display().to_string()
    } else {
        written.clone()
    };
    let spec = ProcessSpec {
        name,
        program: path,
        args: args.to_vec(),
        env: std::iter::once((NAME_ENV.to_owned(), declared.to_owned()))
            .chain(env.iter().map(|(k, v)| (k.clone(), v.clone())))
            .collect(),
    };
    Worker { spec, serves, program: Some(program) }
}

fn sensor_worker(s: &SensorDecl, esgm: &Path, base: &Path) -> anyhow::Result<Worker> {
    let process = sensor_process(&s.name);
    let serves = Serves::Sensor(s.name.clone());
    let what = format!("sensor `{}`", s.name);
    let own = program::declared(&what, s.program.as_deref(), s.exec.as_deref(), base)?;
    let sources = [s.camera.is_some(), own.is_some(), s.python.is_some()];
    if sources.iter().filter(|set| **set).count() > 1 {
        anyhow::bail!("{what}: give one of camera, program and python");
    }
    if s.interpreter.is_some() && s.python.is_none() {
        anyhow::bail!("sensor `{}`: interpreter is for python sensors", s.name);
    }
    let only_for_cameras = |kind: &str| -> anyhow::Result<()> {
        for (set, what) in [
            (s.seed.is_some(), "seed"),
            (s.blobs.is_some(), "blobs"),
            (s.width.is_some(), "width"),
            (s.height.is_some(), "height"),
            (s.frame_period.is_some(), "frame_period"),
        ] {
            if set {
                anyhow::bail!(
                    "sensor `{}`: `{what}` is only for built-in cameras, not {kind} sensors",
                    s.name
                );
            }
        }
        Ok(())
    };
    let spec = match (&s.camera, own, &s.python) {
        (_, _, Some(target)) => {
            only_for_cameras("python")?;
            let decl = python::PythonDecl {
                target,
                interpreter: s.interpreter.as_deref(),
                args: &s.args,
                env: &s.env,
            };
            python::python_worker(python::PythonRole::Sensor, process, &s.name, decl, base)?
        }
        (None, Some(own), None) => {
            only_for_cameras(own.key)?;
            return Ok(user_worker(process, &s.name, own, &s.args, &s.env, serves));
        }
        (None, None, None) => anyhow::bail!(
            "sensor `{}` needs camera = \"synthetic\" (or a frame directory), program = \"name or path\" or python = \"FILE.py:CLASS\"",
            s.name
        ),
        (Some(camera), _, None) => {
            let mut args = vec!["worker".into(), "camera".into(), "--name".into(), s.name.clone()];
            let mut push = |flag: &str, v: Option<String>| {
                if let Some(v) = v {
                    args.extend([flag.to_owned(), v]);
                }
            };
            if camera == "synthetic" {
                if s.frame_period.is_some() {
                    anyhow::bail!("sensor `{}`: frame_period is for directory cameras", s.name);
                }
                push("--seed", s.seed.map(|v| v.to_string()));
                push("--blobs", s.blobs.map(|v| v.to_string()));
                push("--width", s.width.map(|v| v.to_string()));
                push("--height", s.height.map(|v| v.to_string()));
            } else {
                let dir = base.join(camera);
                if !dir.is_dir() {
                    anyhow::bail!(
                        "sensor `{}`: camera = \"{camera}\" is neither \"synthetic\" nor a directory ({} does not exist)",
                        s.name,
                        dir.display()
                    );
                }
                push("--dir", Some(dir.display().to_string()));
                if let Some(p) = &s.frame_period {
                    push("--frame-period", Some(duration_arg(p).context("frame_period")?));
                }
            }
            if !s.args.is_empty() || !s.env.is_empty() {
                anyhow::bail!(
                    "sensor `{}`: args and env are for program and python sensors",
                    s.name
                );
            }
            spec(process, esgm, args)
        }
    };
    Ok(Worker { spec, serves, program: None })
}

fn unit_worker(u: &UnitDecl, esgm: &Path, base: &Path) -> anyhow::Result<Worker> {
    let process = unit_process(&u.name);
    let serves = Serves::Unit(u.name.clone());
    let what = format!("unit `{}`", u.name);
    let own = program::declared(&what, u.program.as_deref(), u.exec.as_deref(), base)?;
    if let (Some(own), Some(_)) = (&own, &u.python) {
        anyhow::bail!("{what}: give either {} or python, not both", own.key);
    }
    if u.interpreter.is_some() && u.python.is_none() {
        anyhow::bail!("{what}: interpreter is for python units");
    }
    let kind = match (&own, &u.python) {
        (_, Some(_)) => "python",
        (Some(own), None) => own.key,
        (None, None) => "",
    };
    if (own.is_some() || u.python.is_some())
        && (u.builtin.is_some() || u.type_name.is_some() || u.window.is_some())
    {
        anyhow::bail!("{what}: builtin, type and window are for built-in units, not {kind} units");
    }
    if let Some(target) = &u.python {
        let decl = python::PythonDecl {
            target,
            interpreter: u.interpreter.as_deref(),
            args: &u.args,
            env: &u.env,
        };
        let spec = python::python_worker(python::PythonRole::Unit, process, &u.name, decl, base)?;
        return Ok(Worker { spec, serves, program: None });
    }
    if let Some(own) = own {
        return Ok(user_worker(process, &u.name, own, &u.args, &u.env, serves));
    }
    let builtin = u.builtin.clone().unwrap_or_else(|| u.name.clone());
    if !BUILTIN_UNITS.contains(&builtin.as_str()) {
        anyhow::bail!(
            "unknown built-in unit `{builtin}`; built in: {}; or give your own program = \"name or path\" or python = \"FILE.py:CLASS\"",
            BUILTIN_UNITS.join(", ")
        );
    }
    let mut args =
        vec!["worker".into(), "unit".into(), u.name.clone(), "--builtin".into(), builtin.clone()];
    if builtin == "MovingAverage" {
        let t = u.type_name.clone().with_context(|| {
            format!("unit `{}`: MovingAverage needs the type it averages: type = \"Blob\"", u.name)
        })?;
        let window = u.window.unwrap_or(5);
        if window == 0 {
            anyhow::bail!("unit `{}`: window must be at least 1", u.name);
        }
        args.extend(["--type".into(), t, "--window".into(), window.to_string()]);
    } else if u.type_name.is_some() || u.window.is_some() {
        anyhow::bail!("unit `{}`: type and window are for MovingAverage", u.name);
    }
    if !u.args.is_empty() || !u.env.is_empty() {
        anyhow::bail!("unit `{}`: args and env are for program and python units", u.name);
    }
    Ok(Worker { spec: spec(process, esgm, args), serves, program: None })
}

fn robot_worker(r: &RobotDecl, esgm: &Path) -> anyhow::Result<Worker> {
    let period = duration_arg(r.period.as_deref().unwrap_or("100ms")).context("period")?;
    let args = vec![
        "worker".into(),
        "robot".into(),
        "--trajectory".into(),
        r.trajectory.clone(),
        "--follow".into(),
        r.follow.clone(),
        "--period".into(),
        period,
    ];
    Ok(Worker {
        spec: spec(robot_process(&r.trajectory), esgm, args),
        serves: Serves::Pushes(r.trajectory.clone()),
        program: None,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    /// The shipped example is the demo's own system; it must always parse.
    #[test]
    fn the_tutorial_file_parses() {
        let plan =
            parse("tutorial.toml", include_str!("../../tutorial.toml"), Path::new(".")).unwrap();
        assert_eq!(plan.workers.len(), 5);
        assert_eq!(plan.trajectories.len(), 5);
        let robot_state =
            plan.trajectories.iter().find(|t| t.what.spec.name == "robot_state").unwrap();
        assert_eq!(robot_state.what.writer.as_deref(), Some("robot-robot_state"));
    }

    #[test]
    fn errors_point_at_the_line() {
        let text = "[[trajectory]]\nname = \"a\"\nprimitive = \"Blob\"\n\n[[trajectory]]\nname = \"b\"\nprimitive = \"Blob\"\npolicy = { cahce = 3 }\n";
        let e = parse("f.toml", text, Path::new(".")).unwrap_err();
        assert_eq!(e.line, 8, "{e}");
        assert!(e.to_string().contains("cahce"), "{e}");

        let text = "[[trajectory]]\nname = \"a\"\nprimitive = \"Blob\"\n\n[[trajectory]]\nname = \"b\"\nprimitive = \"Blob\"\npolicy = { order = \"sorted\" }\n";
        let e = parse("f.toml", text, Path::new(".")).unwrap_err();
        assert!(e.line >= 5 && e.line <= 8, "{e}");
        assert!(e.to_string().starts_with("f.toml:"), "{e}");
        assert!(e.to_string().contains("order"), "{e}");

        let text = "[[unit]]\nname = \"Blobby\"\n";
        let e = parse("f.toml", text, Path::new(".")).unwrap_err();
        assert!(e.to_string().contains("unknown built-in unit `Blobby`"), "{e}");

        let text = "[[type]]\nname = \"P\"\nattributes = [\"x: Double\"]\n[[type]]\nname = \"P\"\nattributes = [\"y: Double\"]\n";
        let e = parse("f.toml", text, Path::new(".")).unwrap_err();
        assert!(e.to_string().contains("declared twice (first at line 1)"), "{e}");
    }

    /// `parse` takes a program as written; finding it is an error naming the file, the
    /// line, what it serves and the program, under the key it was given.
    #[test]
    fn programs_are_found_after_parsing_and_named_with_their_line() {
        let text = "[[type]]\nname = \"P\"\nattributes = [\"x: Double\"]\n\n\
                    [[sensor]]\nname = \"lidar\"\nprogram = \"esgm-no-such-program\"\n";
        let mut plan = parse("system.toml", text, Path::new("/nonexistent")).unwrap();
        assert_eq!(plan.workers[0].what.spec.program, "esgm-no-such-program");
        let e = plan.find_programs().unwrap_err().to_string();
        assert!(
            e.starts_with(
                "system.toml:5: sensor `lidar`: program `esgm-no-such-program` is not on PATH ("
            ),
            "{e}"
        );

        let text = "[[unit]]\nname = \"Detect\"\nexec = \"bin/detect\"\nargs = [\"-v\"]\n";
        let mut plan = parse("system.toml", text, Path::new("/nonexistent")).unwrap();
        assert_eq!(plan.workers[0].what.spec.args, ["-v"]);
        let e = plan.find_programs().unwrap_err().to_string();
        assert_eq!(
            e,
            "system.toml:1: unit `Detect`: exec `bin/detect` does not exist (/nonexistent/bin/detect)"
        );
    }

    #[test]
    fn program_and_exec_together_are_refused_naming_both() {
        for section in ["unit", "sensor"] {
            let text =
                format!("[[{section}]]\nname = \"X\"\nprogram = \"x_unit\"\nexec = \"./x_unit\"\n");
            let e = parse("f.toml", &text, Path::new(".")).unwrap_err().to_string();
            assert!(
                e.starts_with(&format!(
                    "f.toml:1: {section} `X`: give program = \"x_unit\" or exec"
                )) && e.contains("not both"),
                "{e}"
            );
        }
        let text = "[[unit]]\nname = \"X\"\nprogram = \"x\"\nbuiltin = \"BlobDetection\"\n";
        let e = parse("f.toml", text, Path::new(".")).unwrap_err().to_string();
        assert!(e.contains("not program units"), "{e}");
    }
}
