//! Blocking adds across processes: the writer's end
//! ([`esgm_shm::unstable::serve_blocking_add`]: a request's bytes decoded, added through
//! a real trajectory's gate, the outcome encoded) and the replica's
//! ([`esgm_shm::unstable::read_blocking_add_answer`]: the writer's answer decoded).
//!
//! An input is a tag byte and a payload: `A` an answer as the replica reads it,
//! anything else a request as the writer serves it. The writer's trajectory is a
//! primitive `RobotState` with a monotone order, a maximum delay and a bounded cache,
//! kept for [`crate::target::RESET_EVERY`] cases so requests meet the store earlier
//! ones filled. Promises checked beyond "no panic": every answer the writer makes reads
//! back as an outcome (the replica can read it), and every seed is served or read.

use std::sync::{LazyLock, Mutex, PoisonError};

use esgm_core::codec;
use esgm_core::esgm::{Esgm, TrajectorySpec};
use esgm_core::{
    AddError, AddOutcome, CacheConstraint, DelayConstraint, FluentStreamPolicy, InProcessEsgm,
    InProcessTrajectory, OrderConstraint,
};
use esgm_shm::control::{decode, encode};
use esgm_shm::unstable::{read_blocking_add_answer, serve_blocking_add};

use crate::json::{json_tokens, mutate_json};
use crate::mutate::mutate;
use crate::rng::Rng;
use crate::structures;
use crate::target::{Broken, Target};
use crate::targets::codec::fix_envelope;
use crate::text::mutate_text;

/// The tag of an answer; any other first byte is a request.
const ANSWER: u8 = b'A';
/// The tag the request seeds carry.
const REQUEST: u8 = b'R';
/// The writer's trajectory.
const TRAJECTORY: &str = "robot_state";

/// JSON's tokens, the outcomes' variant names and a release time at its limit.
static TOKENS: LazyLock<Vec<&str>> = LazyLock::new(|| {
    json_tokens(&[
        "\"Ok\"",
        "\"Err\"",
        "\"Held\"",
        "\"PolicyViolation\"",
        "\"release_at\":-9223372036854775808",
    ])
});

/// The writer's runtime and its trajectory.
struct Writer {
    _esgm: InProcessEsgm,
    handle: InProcessTrajectory,
}

fn writer() -> Result<Writer, Broken> {
    let esgm = InProcessEsgm::default();
    let policy = FluentStreamPolicy::default()
        .order(OrderConstraint::Monotone)
        .delay(DelayConstraint::Max(1_000_000_000))
        .cache(CacheConstraint::Elements(64));
    let handle = esgm
        .create_trajectory(TrajectorySpec::primitive(TRAJECTORY, "RobotState").policy(policy))
        .map_err(|e| Broken::new("the writer's trajectory is created", e))?;
    Ok(Writer { _esgm: esgm, handle })
}

/// The blocking-add target.
pub struct BlockingAdd {
    writer: Mutex<Writer>,
    seeds: Vec<Vec<u8>>,
    /// The answers among the seeds, without their tag.
    answers: Vec<Vec<u8>>,
    /// The requests among the seeds, without their tag.
    requests: Vec<Vec<u8>>,
}

impl std::fmt::Debug for BlockingAdd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlockingAdd").field("seeds", &self.seeds.len()).finish_non_exhaustive()
    }
}

fn tagged(tag: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = vec![tag];
    out.extend_from_slice(payload);
    out
}

impl BlockingAdd {
    /// Requests of every seed structure, and the writer's answers to them (added, a
    /// type refused, a violation, an unreadable structure), with a few outcomes made by
    /// hand.
    pub fn new() -> Result<Self, Broken> {
        let w = writer()?;
        let mut requests = Vec::new();
        for es in structures::valid() {
            let bytes = codec::encode(&es).map_err(|e| Broken::new("a structure encodes", e))?;
            requests.push(bytes.to_vec());
        }
        let mut answers = Vec::new();
        for request in requests.iter().chain([&b"not a structure".to_vec()]) {
            answers.push(answer_to(&w.handle, request)?);
        }
        let by_hand: [Result<AddOutcome, AddError>; 3] = [
            Ok(AddOutcome::Added),
            Ok(AddOutcome::Held { release_at: i64::MAX }),
            Ok(AddOutcome::Forwarded),
        ];
        for outcome in &by_hand {
            answers.push(encode(outcome).map_err(|e| Broken::new("an outcome encodes", e))?);
        }
        let seeds = requests
            .iter()
            .map(|r| tagged(REQUEST, r))
            .chain(answers.iter().map(|a| tagged(ANSWER, a)))
            .collect();
        Ok(Self { writer: Mutex::new(writer()?), seeds, answers, requests })
    }
}

/// The writer's answer to `request`, which must read back.
fn answer_to(handle: &InProcessTrajectory, request: &[u8]) -> Result<Vec<u8>, Broken> {
    let answer = serve_blocking_add(handle, request)
        .map_err(|e| Broken::new("the writer's outcome encodes", e))?;
    // Whichever outcome it is (an error is an answer too): it must read.
    let _outcome: Result<AddOutcome, AddError> =
        decode(&answer).map_err(|e| Broken::new("the writer's answer reads back", e))?;
    Ok(answer)
}

impl Target for BlockingAdd {
    fn name(&self) -> &'static str {
        "blocking-add"
    }

    fn about(&self) -> &'static str {
        "serve_blocking_add (a request through a writer's gate), read_blocking_add_answer"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        if rng.chance(50) {
            let mut data = rng.pick(&self.answers).clone();
            match rng.below(10) {
                0..=5 => {
                    data = mutate_json(rng, &data, &self.answers).unwrap_or(data);
                }
                6..=8 => mutate_text(rng, &mut data, &self.answers, &TOKENS),
                _ => mutate(rng, &mut data, &self.answers),
            }
            tagged(ANSWER, &data)
        } else {
            let mut data = rng.pick(&self.requests).clone();
            if rng.chance(90) {
                mutate(rng, &mut data, &self.requests);
                if rng.chance(80) {
                    fix_envelope(&mut data);
                }
            }
            tagged(REQUEST, &data)
        }
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        let Some((&tag, payload)) = input.split_first() else { return Ok(()) };
        if tag == ANSWER {
            // The replica's caller gets the outcome or a typed error: either is fine.
            let _outcome = read_blocking_add_answer(TRAJECTORY, payload);
            return Ok(());
        }
        // A panic in an earlier case poisons the lock; the runner resets the writer.
        let w = self.writer.lock().unwrap_or_else(PoisonError::into_inner);
        answer_to(&w.handle, payload).map(|_| ())
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        match seed.split_first() {
            Some((&ANSWER, payload)) => decode::<Result<AddOutcome, AddError>>(payload)
                .map(|_| ())
                .map_err(|e| Broken::new("a writer's answer decodes", e)),
            _ => self.run(seed),
        }
    }

    fn reset(&self) {
        match writer() {
            Ok(w) => *self.writer.lock().unwrap_or_else(PoisonError::into_inner) = w,
            Err(e) => eprintln!("esgm-fuzz: the blocking-add writer is kept: {e}"),
        }
    }
}
