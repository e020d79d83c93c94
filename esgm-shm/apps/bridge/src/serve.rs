//! The bridge's queryable on `esgm/<domain>/*`: what other hosts ask about this domain.
//!
//! - `?esgm=meta`: type, cache and session of every exported trajectory the key
//!   matches (JSON [`crate::wire::Meta`], one reply each);
//! - `?esgm=history`: the last messages sent of an exported trajectory, up to its
//!   cache bound, oldest first (late joiners, and an importer after this bridge
//!   restarted);
//! - `?esgm=latest|nth|between|at|closest` (parameters `n`, `from`, `to`, `t`): the
//!   seed's queries on any trajectory of the domain, answered from this bridge's replica
//!   of it (`esgm --remote`); no parameter at all is `latest`, so `z_get` works too.
//!   One message per sample, header and codec bytes as on the data key, with the
//!   domain's add time, then an empty reply that ends the answer.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use esgm_core::{EntityTrajectoryStructure, Esgm, InProcessTrajectory, Sample};
use esgm_shm::ShmEsgm;
use zenoh::Wait as _;
use zenoh::key_expr::KeyExpr;
use zenoh::query::Query;

use crate::export::Catalog;
use crate::key::{self, ASK, Ask};
use crate::times;
use crate::wire::{self, Header};

/// What the queryable needs.
#[derive(Debug, Clone)]
pub struct ServeSite {
    /// The local domain.
    pub domain: String,
    /// The local connection (replicas for queries).
    pub esgm: ShmEsgm,
    /// The Zenoh session.
    pub session: zenoh::Session,
    /// Random per run of this bridge.
    pub session_id: u64,
    /// The exported trajectories.
    pub catalog: Catalog,
    /// Answer the seed's queries on any trajectory (`--no-queries` turns it off).
    pub queries: bool,
    /// Set when the bridge stops.
    pub stop: Arc<AtomicBool>,
}

/// Declares the queryable and answers on its own thread until `site.stop`.
pub fn spawn(site: ServeSite) -> anyhow::Result<std::thread::JoinHandle<()>> {
    let key = key::domain_key(&site.domain);
    let queryable = site
        .session
        .declare_queryable(key.clone())
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh queryable on `{key}`: {e}"))?;
    let thread = std::thread::Builder::new().name("serve".into()).spawn(move || {
        let mut handles = HashMap::new();
        while !site.stop.load(Ordering::Relaxed) {
            match queryable.recv_timeout(Duration::from_millis(100)) {
                Ok(Some(query)) => {
                    if let Err(e) = answer(&site, &mut handles, &query) {
                        if let Err(z) = query.reply_err(e.clone()).wait() {
                            tracing::debug!(error = %z, "could not send an error reply");
                        }
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    tracing::warn!(error = %e, "the queryable closed");
                    return;
                }
            }
        }
    })?;
    Ok(thread)
}

fn matches(query: &Query, key: &str) -> bool {
    KeyExpr::try_from(key).is_ok_and(|k| query.key_expr().intersects(&k))
}

fn send(query: &Query, key: &str, payload: impl Into<zenoh::bytes::ZBytes>) -> Result<(), String> {
    query.reply(key.to_owned(), payload).wait().map_err(|e| format!("zenoh reply: {e}"))
}

fn answer(
    site: &ServeSite,
    handles: &mut HashMap<String, InProcessTrajectory>,
    query: &Query,
) -> Result<(), String> {
    let ask = match query.parameters().get(ASK) {
        None => Ask::Latest,
        Some(a) => Ask::parse(a).ok_or_else(|| format!("unknown {ASK}={a}"))?,
    };
    match ask {
        Ask::Meta | Ask::History => {
            let catalog = site.catalog.lock();
            for (name, exported) in catalog.iter() {
                let k = key::data_key(&site.domain, name);
                if !matches(query, &k) {
                    continue;
                }
                if ask == Ask::Meta {
                    let json = serde_json::to_string(&exported.meta).map_err(|e| e.to_string())?;
                    send(query, &k, json)?;
                } else {
                    for message in &exported.history {
                        send(query, &k, message.clone())?;
                    }
                }
            }
            Ok(())
        }
        _ => {
            let (domain, name) = key::parse(query.key_expr().as_str()).ok_or_else(|| {
                "a query names one trajectory: esgm/<domain>/<trajectory>".to_owned()
            })?;
            if domain != site.domain {
                return Ok(());
            }
            if !site.queries {
                return Err("this bridge does not answer queries (--no-queries)".into());
            }
            let handle = replica(site, handles, name)?;
            let samples = samples(&handle, ask, query)?;
            let k = key::data_key(domain, name);
            // Only a trajectory destroyed since it was opened has no type; its samples still go.
            let type_name = handle.entity_type().map(|t| t.name).unwrap_or_default();
            for (i, s) in samples.iter().enumerate() {
                let header = Header {
                    session: site.session_id,
                    writer: 0,
                    sequence: i as u64,
                    add_time: s.add_time,
                    skipped: 0,
                    type_hash: 0,
                    type_name: type_name.clone(),
                    kind: wire::Kind::Structure,
                    lineage: s.lineage.as_deref().cloned(),
                };
                let bytes = s.structure.to_codec_bytes().map_err(|e| e.to_string())?;
                send(query, &k, wire::encode(&header, &bytes))?;
            }
            // An empty reply ends the answer, so an empty one is told from no bridge.
            send(query, &k, Vec::<u8>::new())
        }
    }
}

/// This bridge's replica of `name`, with the writer's history received the first time
/// (as the `esgm` command waits for it: until samples stop arriving, at most 500 ms).
fn replica(
    site: &ServeSite,
    handles: &mut HashMap<String, InProcessTrajectory>,
    name: &str,
) -> Result<InProcessTrajectory, String> {
    if let Some(h) = handles.get(name) {
        if h.stats().is_ok() {
            return Ok(h.clone());
        }
    }
    let h = site.esgm.get_entity_trajectory_structure(name).map_err(|e| e.to_string())?;
    let deadline = Instant::now() + Duration::from_millis(500);
    let mut last = (u64::MAX, Instant::now());
    while Instant::now() < deadline {
        let added = h.stats().map(|s| s.added).unwrap_or(0);
        if added != last.0 {
            last = (added, Instant::now());
        } else if added > 0 && last.1.elapsed() > Duration::from_millis(50) {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    handles.insert(name.to_owned(), h.clone());
    Ok(h)
}

fn param<'a>(query: &'a Query, name: &str) -> Result<&'a str, String> {
    query.parameters().get(name).ok_or_else(|| format!("missing parameter `{name}`"))
}

fn samples(h: &InProcessTrajectory, ask: Ask, query: &Query) -> Result<Vec<Sample>, String> {
    // Empty has no latest; a relative time then says it needs one.
    let latest = h.get_latest().ok().map(|s| s.structure.valid_time());
    let time = |name| times::resolve(param(query, name)?, latest);
    let one =
        |r: Result<Sample, esgm_core::QueryError>| r.map(|s| vec![s]).map_err(|e| e.to_string());
    match ask {
        Ask::Latest => one(h.get_latest()),
        Ask::Nth => {
            let n = param(query, "n")?.parse::<usize>().map_err(|e| format!("n: {e}"))?;
            one(h.get_nth_latest(n))
        }
        Ask::Between => h.get_between(time("from")?, time("to")?).map_err(|e| e.to_string()),
        Ask::At => one(h.get_at(time("t")?)),
        Ask::Closest => one(h.get_closest_at_or_before(time("t")?)),
        Ask::Meta | Ask::History => Ok(Vec::new()),
    }
}
