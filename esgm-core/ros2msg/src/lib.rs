//! esgm's structures as ROS 2 messages, without DDS: the standard messages the library
//! types map to ([`mapping`]), the generated `esgm_msgs` messages of every other type
//! ([`generated`]), their definitions as text ([`definitions`]) and their CDR bytes
//! ([`cdr`]). Shared by `esgm ros2` (which sends them over DDS) and recordings in the
//! ROS 2 profile (`esgm record --ros2`), so both write the same bytes.

#![deny(missing_docs)]

pub mod cdr;
pub mod definitions;
pub mod generated;
pub mod generated_in;
pub mod mapping;
pub mod msgs;
