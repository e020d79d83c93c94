//! How a listing of trajectories ([`super::protocol::Response::Trajectories`]) travels:
//! one JSON array per trajectory, `[name, kind, type, source, inputs, policy]`, with
//! `null` for the default policy.
//!
//! Why not the listing's own JSON objects: every CLI verb that lists (`esgm traj list`,
//! `esgm stats`) and every process whose registry changed reads the whole listing. As
//! objects, 1,000 trajectories came to 216 KB, more than half of it field names and
//! the default policy spelled out, and decoding it took a CLI 2.5 ms, the most of what
//! grew with the domain. As arrays they are a quarter of that. The listing's own
//! serde form (what `esgm traj list --json` prints, what recordings keep) is
//! unchanged.
//!
//! Every field of [`TrajectoryInfo`] is taken apart and put together by name, without
//! `..`: a field added there does not compile here until the wire carries it.

use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
use esgm_core::policy::FluentStreamPolicy;
use serde::ser::SerializeSeq as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One trajectory on the wire, borrowed from its listing.
#[derive(Serialize)]
struct Out<'a>(
    &'a str,
    &'a TrajectoryKind,
    &'a str,
    &'a Option<String>,
    &'a [String],
    Option<&'a FluentStreamPolicy>,
);

/// One trajectory as it arrives.
#[derive(Deserialize)]
struct In(String, TrajectoryKind, String, Option<String>, Vec<String>, Option<FluentStreamPolicy>);

/// Writes `listing` as arrays (serde's `with` entry point).
pub fn serialize<S: Serializer>(listing: &[TrajectoryInfo], s: S) -> Result<S::Ok, S::Error> {
    let default = FluentStreamPolicy::default();
    let mut seq = s.serialize_seq(Some(listing.len()))?;
    for info in listing {
        let TrajectoryInfo { name, kind, type_name, source, inputs, policy } = info;
        let policy = (*policy != default).then_some(policy);
        seq.serialize_element(&Out(name, kind, type_name, source, inputs, policy))?;
    }
    seq.end()
}

/// Reads a listing written by [`serialize`] (serde's `with` entry point). Malformed
/// bytes from another process are an error, never a panic.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<TrajectoryInfo>, D::Error> {
    let rows = Vec::<In>::deserialize(d)?;
    Ok(rows
        .into_iter()
        .map(|In(name, kind, type_name, source, inputs, policy)| TrajectoryInfo {
            name,
            kind,
            type_name,
            source,
            inputs,
            policy: policy.unwrap_or_default(),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::super::protocol::{Response, decode, encode};
    use esgm_core::esgm::{TrajectoryInfo, TrajectoryKind};
    use esgm_core::policy::{CacheConstraint, FluentStreamPolicy};

    fn listing() -> Vec<TrajectoryInfo> {
        let plain = TrajectoryInfo::new("robot_state", TrajectoryKind::Primitive, "RobotState");
        let mut computed = TrajectoryInfo::new("blobs", TrajectoryKind::Computed, "BlobSeq");
        computed.source = Some("blob_detection".into());
        computed.inputs = vec!["camera".into(), "robot_state".into()];
        computed.policy = FluentStreamPolicy {
            cache: CacheConstraint::Elements(3),
            filter: Some("x > 2".into()),
            reorder: false,
            ..FluentStreamPolicy::default()
        };
        vec![plain, computed]
    }

    #[test]
    fn a_listing_comes_back_as_it_was_sent() {
        let sent = listing();
        let bytes = encode(&Response::Trajectories(sent.clone())).unwrap();
        match decode::<Response>(&bytes).unwrap() {
            Response::Trajectories(back) => assert_eq!(back, sent),
            other => panic!("not a listing: {other:?}"),
        }
    }

    #[test]
    fn a_default_policy_is_not_spelled_out() {
        let plain = vec![listing().remove(0)];
        let bytes = encode(&Response::Trajectories(plain)).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        assert_eq!(
            text,
            r#"{"Trajectories":[["robot_state","Primitive","RobotState",null,[],null]]}"#
        );
    }

    #[test]
    fn a_malformed_listing_is_an_error() {
        for bytes in [
            &br#"{"Trajectories":[["t","Primitive"]]}"#[..],
            br#"{"Trajectories":[["t","Nonsense","T",null,[],null]]}"#,
            br#"{"Trajectories":[{"name":"t"}]}"#,
        ] {
            assert!(decode::<Response>(bytes).is_err(), "{}", String::from_utf8_lossy(bytes));
        }
    }
}
