//! The targets: everything esgm decodes from another process, host or file.

pub mod admin;
pub mod blocking_add;
pub mod codec;
pub mod configuration;
pub mod control;
pub mod kept;
pub mod recording;
pub mod sample;
pub mod wire;

use crate::target::{Broken, Target};

/// The names `--target` takes, in the order a run visits them.
pub const NAMES: [&str; 10] = [
    "codec",
    "sample",
    "request",
    "response",
    "admin",
    "blocking-add",
    "wire",
    "recording",
    "config",
    "kept",
];

/// The target called `name`, with its seeds made; `None` for an unknown name.
pub fn by_name(name: &str) -> Option<Result<Box<dyn Target>, Broken>> {
    fn boxed<T: Target + 'static>(t: Result<T, Broken>) -> Result<Box<dyn Target>, Broken> {
        t.map(|t| Box::new(t) as Box<dyn Target>)
    }
    Some(match name {
        "codec" => boxed(codec::Codec::new()),
        "sample" => boxed(sample::Sample::new()),
        "request" => boxed(control::Requests::new()),
        "response" => boxed(control::Responses::new()),
        "admin" => boxed(admin::Admin::new()),
        "blocking-add" => boxed(blocking_add::BlockingAdd::new()),
        "wire" => boxed(wire::Wire::new()),
        "recording" => boxed(recording::RecordingTarget::new()),
        "config" => boxed(Ok(configuration::Configuration::new())),
        "kept" => boxed(kept::Kept::new()),
        _ => return None,
    })
}
