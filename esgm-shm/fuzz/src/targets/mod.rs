//! The targets: everything esgm decodes from another process.

pub mod codec;
pub mod configuration;
pub mod control;
pub mod sample;

use crate::target::{Broken, Target};

/// The names `--target` takes, in the order a run visits them.
pub const NAMES: [&str; 5] = ["codec", "sample", "request", "response", "config"];

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
        "config" => boxed(Ok(configuration::Configuration::new())),
        _ => return None,
    })
}
