//! One file per subcommand.

pub mod apply;
pub mod bridge;
pub mod chaos;
pub mod compare;
pub mod demo;
pub mod docs;
pub mod down;
pub mod echo;
pub mod graph;
pub mod hz;
pub mod info;
pub mod load;
pub mod log_level;
pub mod logs;
pub mod plot;
pub mod ps;
pub mod push;
pub mod query;
pub mod record;
pub mod registry;
pub mod replay;
pub mod reset;
pub mod ros2;
pub mod scale;
pub mod soak;
pub mod stats;
pub mod top;
pub mod trace;
pub mod traj;
pub mod types;
pub mod up;
pub mod view;
pub mod violations;
pub mod why;
pub mod worker;

use crate::{Cli, Command};

/// The name this process's log lines carry.
pub fn process_name(c: &Command) -> String {
    match c {
        Command::Up(_) => "coordinator".into(),
        Command::Demo(_) => "demo".into(),
        Command::Soak(_) => "soak".into(),
        Command::Scale(_) => "scale".into(),
        Command::ScaleWorker(a) => format!("scale-worker-{}", a.index),
        Command::Chaos(_) => "chaos".into(),
        Command::ChaosWorker(a) => chaos::worker::name(a.index),
        Command::Worker(role) => role.process_name(),
        _ => "cli".into(),
    }
}

/// Runs the command line's command.
pub fn run(cli: &Cli) -> anyhow::Result<()> {
    let (domain, json) = (cli.domain.as_str(), cli.json);
    if let Some(endpoint) = &cli.remote {
        return remote(domain, json, endpoint, &cli.command);
    }
    match &cli.command {
        Command::Up(a) => up::run(domain, a),
        Command::Down => down::run(domain),
        Command::Apply(a) => apply::run(domain, json, a),
        Command::Ps => ps::run(domain, json),
        Command::Logs(a) => logs::run(domain, json, a),
        Command::Demo(a) => demo::run(domain, a),
        Command::Type(c) => types::run(domain, json, c),
        Command::Traj(c) => traj::run(domain, json, c),
        Command::Sensor(c) => registry::sensors(domain, json, c),
        Command::Unit(c) => registry::units(domain, json, c),
        Command::Latest(a) => query::latest(domain, json, a),
        Command::Nth(a) => query::nth(domain, json, a),
        Command::Between(a) => query::between(domain, json, a),
        Command::At(a) => query::at(domain, json, a, false),
        Command::Closest(a) => query::at(domain, json, a, true),
        Command::Approx(a) => query::approx(domain, json, a),
        Command::Echo(a) => echo::run(domain, json, a),
        Command::Trace(a) => trace::run(domain, json, a),
        Command::Why(a) => why::run(domain, json, a),
        Command::Hz(a) => hz::run(domain, json, a),
        Command::Stats => stats::run(domain, json),
        Command::Reset(a) => reset::run(domain, json, a),
        Command::LogLevel(a) => log_level::run(domain, json, a),
        Command::Push(a) => push::run(domain, json, a),
        Command::Top(a) => top::run(domain, json, a),
        Command::Plot(a) => plot::run(domain, json, a),
        Command::View(a) => view::run(domain, a),
        Command::Graph(a) => graph::run(domain, json, a),
        Command::Violations(a) => violations::run(domain, json, a),
        Command::Record(a) => record::run(domain, json, a),
        Command::Info(a) => info::run(json, a),
        Command::Replay(a) => replay::run(domain, json, a),
        Command::Compare(a) => compare::run(json, a),
        Command::Load(a) => load::run(domain, json, a),
        Command::Bridge(a) => bridge::run(domain, json, a),
        Command::Ros2(a) => ros2::run(domain, a),
        Command::Soak(a) => soak::run(domain, a),
        Command::Scale(a) => scale::run(domain, a),
        Command::ScaleWorker(a) => scale::worker::run(domain, a),
        Command::Chaos(a) => chaos::run(domain, a),
        Command::ChaosWorker(a) => chaos::worker::run(domain, a),
        Command::Worker(role) => worker::run(domain, role),
        // Answered in main, before anything connects.
        Command::Completions(_) | Command::Man(_) => Ok(()),
    }
}

/// `--remote`: the queries another host's bridge answers.
fn remote(domain: &str, json: bool, endpoint: &str, c: &Command) -> anyhow::Result<()> {
    use bridge::Remote;
    let q = match c {
        Command::Latest(a) => Remote::Latest(a),
        Command::Nth(a) => Remote::Nth(a),
        Command::Between(a) => Remote::Between(a),
        Command::At(a) => Remote::At(a, false),
        Command::Closest(a) => Remote::At(a, true),
        _ => anyhow::bail!("--remote works with latest, nth, between, at and closest"),
    };
    bridge::remote(domain, json, endpoint, q)
}
