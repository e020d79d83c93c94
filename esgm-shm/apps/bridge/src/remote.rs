//! `esgm-bridge query` (and `esgm --remote`): the seed's queries answered by the bridge
//! of another host, without importing the trajectory.

use std::time::Duration;

use esgm_core::EntityStructure;
use serde_json::json;

use crate::ask::ask;
use crate::key::{self, Ask};
use crate::session::ZenohArgs;
use crate::wire;

/// `esgm-bridge query` options.
#[derive(Debug, clap::Args)]
pub struct QueryArgs {
    /// How to reach the other host (usually `--connect tcp/<its address>:<port>`).
    #[command(flatten)]
    pub zenoh: ZenohArgs,
    /// How long to wait for the answer.
    #[arg(long, default_value = "5s", value_parser = humantime::parse_duration)]
    pub timeout: Duration,
    /// The query.
    #[command(subcommand)]
    pub query: RemoteQuery,
}

/// A query on a remote domain's trajectory.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum RemoteQuery {
    /// The latest sample.
    Latest {
        /// Trajectory name.
        trajectory: String,
    },
    /// The n-th latest sample (0 = latest).
    Nth {
        /// Trajectory name.
        trajectory: String,
        /// 0 is the latest.
        n: usize,
    },
    /// Samples valid between two times (ns, RFC 3339, or relative to the latest: -5s).
    Between {
        /// Trajectory name.
        trajectory: String,
        /// From.
        #[arg(allow_hyphen_values = true)]
        from: String,
        /// To.
        #[arg(allow_hyphen_values = true)]
        to: String,
    },
    /// The sample valid exactly at a time.
    At {
        /// Trajectory name.
        trajectory: String,
        /// The time.
        #[arg(allow_hyphen_values = true)]
        time: String,
    },
    /// The closest sample at or before a time.
    Closest {
        /// Trajectory name.
        trajectory: String,
        /// The time.
        #[arg(allow_hyphen_values = true)]
        time: String,
    },
}

impl RemoteQuery {
    fn parts(&self) -> (&str, Ask, Vec<(&'static str, String)>) {
        match self {
            RemoteQuery::Latest { trajectory } => (trajectory, Ask::Latest, vec![]),
            RemoteQuery::Nth { trajectory, n } => {
                (trajectory, Ask::Nth, vec![("n", n.to_string())])
            }
            RemoteQuery::Between { trajectory, from, to } => {
                (trajectory, Ask::Between, vec![("from", from.clone()), ("to", to.clone())])
            }
            RemoteQuery::At { trajectory, time } => {
                (trajectory, Ask::At, vec![("t", time.clone())])
            }
            RemoteQuery::Closest { trajectory, time } => {
                (trajectory, Ask::Closest, vec![("t", time.clone())])
            }
        }
    }
}

/// A value as JSON, as `esgm --json` prints it locally (`esgm-cli`'s `show.rs`): byte
/// sequences as their length, plain numbers and strings, anything else in its serde form.
fn value_json(v: &esgm_core::Value) -> serde_json::Value {
    use esgm_core::Value;
    match v {
        Value::NoValue => serde_json::Value::Null,
        Value::Long(v) | Value::Time(v) => json!(v),
        Value::Double(v) | Value::Altitude(v) => json!(v),
        Value::Bool(v) => json!(v),
        Value::String(v) | Value::Symbol(v) => json!(v),
        Value::LongSeq(v) => json!(v),
        Value::DoubleSeq(v) => json!(v),
        Value::SymbolSeq(v) => json!(v),
        Value::OctetSeq(o) => json!({ "octets": o.len() }),
        other => serde_json::to_value(other).unwrap_or(serde_json::Value::Null),
    }
}

fn line(trajectory: &str, add_time: i64, es: &EntityStructure, as_json: bool) -> String {
    if as_json {
        let attributes: serde_json::Map<String, serde_json::Value> =
            es.attributes.iter().map(|a| (a.name.clone(), value_json(&a.value))).collect();
        json!({
            "trajectory": trajectory,
            "name": es.name,
            "valid_time": es.valid_time,
            "create_time": es.create_time,
            "add_time": add_time,
            "attributes": attributes,
        })
        .to_string()
    } else {
        let attrs: Vec<String> =
            es.attributes.iter().map(|a| format!("{}={}", a.name, value_json(&a.value))).collect();
        format!(
            "{}  {}  {}  (add delay {:.3} ms)",
            es.valid_time,
            es.name,
            attrs.join(" "),
            (add_time as f64 - es.valid_time as f64) / 1e6
        )
    }
}

/// Runs the query against `domain` and prints the samples; an error names what the
/// remote bridge said.
pub fn run(domain: &str, as_json: bool, args: &QueryArgs) -> anyhow::Result<()> {
    let mut zenoh = args.zenoh.clone();
    if zenoh.mode.is_none() && zenoh.config.is_none() {
        zenoh.mode = Some("client".into());
    }
    let session = zenoh.open()?;
    let (trajectory, what, params) = args.query.parts();
    anyhow::ensure!(
        key::is_name(domain) && key::is_name(trajectory),
        "invalid domain or trajectory name"
    );
    let k = key::data_key(domain, trajectory);
    let params: Vec<(&str, String)> = params.into_iter().collect();
    let deadline = std::time::Instant::now() + args.timeout;
    // Declarations of the other side may still be on their way: ask again until
    // someone answers.
    let answers = loop {
        let answers = ask(&session, &k, what, &params, args.timeout)?;
        if !answers.ok.is_empty()
            || !answers.errors.is_empty()
            || std::time::Instant::now() >= deadline
        {
            break answers;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    if let Some(e) = answers.errors.first() {
        anyhow::bail!("{e}");
    }
    if answers.ok.is_empty() {
        anyhow::bail!("no bridge of domain `{domain}` answered on `{k}` within {:?}", args.timeout);
    }
    for a in answers.ok.iter().filter(|a| !a.payload.is_empty()) {
        let (header, Some(es)) = wire::decode(&a.payload)? else { continue };
        println!("{}", line(trajectory, header.add_time, &es, as_json));
    }
    Ok(())
}
